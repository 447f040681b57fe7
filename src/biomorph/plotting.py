"""pyplot's ``subplots`` / ``figure`` on matplotlib's object-oriented ``Figure`` API.

Plots never touch pyplot's global state or choose a backend for the whole process (a user's
notebook or GUI keeps its own); figures are plain :class:`matplotlib.figure.Figure` objects
that :func:`save_png` writes atomically.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from biomorph.core.types import PathLike

_FIG_KW = ("figsize", "dpi", "layout", "constrained_layout", "tight_layout", "facecolor")


def figure(**kw: Any) -> Any:
    """A new ``Figure`` (``figsize``, ``dpi``, ``layout`` … as for ``pyplot.figure``)."""
    from matplotlib.figure import Figure

    return Figure(**{k: v for k, v in kw.items() if k in _FIG_KW})


def subplots(nrows: int = 1, ncols: int = 1, **kw: Any) -> tuple[Any, Any]:
    """``(fig, axes)`` like ``pyplot.subplots``, without pyplot."""
    fig = figure(**kw)
    axes = fig.subplots(nrows, ncols, **{k: v for k, v in kw.items() if k not in _FIG_KW})
    return fig, axes


def close(fig: Any) -> None:
    """Nothing to release: a ``Figure`` outside pyplot is freed with its last reference."""


def save_png(fig: Any, path: PathLike, dpi: int = 110, **kw: Any) -> Path:
    """Write ``fig`` as PNG through a temporary file and rename (no partial file)."""
    from biomorph.io.atomic import atomic_path

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, **kw)
    return Path(path)


__all__ = ["close", "figure", "save_png", "subplots"]
