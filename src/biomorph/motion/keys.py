"""Key lists and curves for the editors: ``"frame:value,frame:value"`` strings, JSON files,
and the spline curves built from them (:mod:`biomorph.core.curves`).

A *key* is ``(frame, value)`` where ``value`` is a number or a vector. Curves are callables
``c(frames) -> values`` over (fractional) frame numbers.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from biomorph.core.curves import MonotoneSpline, NaturalCubicSpline
from biomorph.core.types import Array
from biomorph.errors import FormatError, ParameterError

Keys = Sequence[tuple[float, ArrayLike]] | Mapping[float, ArrayLike]
Curve = Callable[[ArrayLike], Array]


def parse_keys(text: str, dim: int | None = None) -> list[tuple[float, Array]]:
    """Parse ``"10:0.5,40:1"`` (scalars) or ``"10:0/0/30;40:0/0/-10"`` (vectors, ``/``
    between components, ``;`` or ``,`` between keys) or a path to a JSON file holding
    ``[[frame, value], …]`` or ``{"frame": value}``. Returns sorted ``(frame, value)``."""
    text = text.strip()
    if text.endswith(".json") or Path(text).suffix == ".json":
        p = Path(text)
        try:
            data = json.loads(p.read_text())
        except FileNotFoundError:
            raise FormatError(p, "key file does not exist") from None
        except json.JSONDecodeError as exc:
            raise FormatError(
                p, f"not valid JSON ({exc.msg}); expected [[frame, value], ...]", line=exc.lineno
            ) from None
        items = list(data.items()) if isinstance(data, dict) else data
        try:
            keys = [(float(f), np.atleast_1d(np.asarray(v, dtype=float))) for f, v in items]
        except (TypeError, ValueError):
            raise FormatError(p, "keys must be [[frame, value], ...] with numbers") from None
    else:
        sep = ";" if ";" in text else ","
        keys = []
        for part in filter(None, (s.strip() for s in text.split(sep))):
            if ":" not in part:
                raise ParameterError(
                    f"key {part!r} has no ':'; expected frame:value (e.g. 10:0.5,40:1)"
                )
            f, v = part.split(":", 1)
            try:
                vals = [float(x) for x in v.replace("/", " ").replace(",", " ").split()]
                keys.append((float(f), np.asarray(vals, dtype=float)))
            except ValueError:
                raise ParameterError(
                    f"key {part!r} is not frame:number; expected e.g. 10:0.5 or 10:0/0/30"
                ) from None
            if not vals:
                raise ParameterError(f"key {part!r} has no value")
    if not keys:
        raise ParameterError(f"no keys in {text!r}; expected frame:value pairs")
    keys.sort(key=lambda k: k[0])
    sizes = {k[1].size for k in keys}
    if len(sizes) != 1 or (dim is not None and sizes != {dim}):
        want = f"{dim} numbers" if dim else "the same number of values"
        raise ParameterError(
            f"keys {text!r} have values of sizes {sorted(sizes)}; expected {want} per key"
        )
    frames = [k[0] for k in keys]
    if len(set(frames)) != len(frames):
        raise ParameterError(f"keys {text!r} repeat a frame; expected distinct frames")
    return keys


def key_arrays(keys: Keys) -> tuple[Array, Array]:
    """``(frames (k,), values (k, d))`` sorted by frame, from a mapping or a sequence."""
    items = list(keys.items()) if isinstance(keys, Mapping) else list(keys)
    if not items:
        raise ParameterError("no keys given; expected at least one (frame, value)")
    items.sort(key=lambda k: float(k[0]))
    x = np.array([float(k[0]) for k in items])
    y = np.array([np.atleast_1d(np.asarray(k[1], dtype=float)) for k in items])
    if len(np.unique(x)) != len(x):
        raise ParameterError("two keys share a frame; expected distinct frames")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ParameterError("keys hold NaN or inf; expected finite numbers")
    return x, y


def smoothstep(u: ArrayLike) -> Array:
    """C1 ease ``3u² − 2u³`` clamped to [0, 1]."""
    u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def curve_from_keys(keys: Keys | float | Curve, kind: str = "natural") -> Curve:
    """A callable curve: a constant, a callable passed through, or a spline through keys
    (``"natural"`` cubic, or ``"monotone"`` — no overshoot, used for speed and weights).
    One key gives a constant; the curve is held constant beyond the first/last key."""
    if callable(keys):
        return keys
    if isinstance(keys, (int, float, np.floating, np.integer)):
        c = float(keys)
        return lambda t: np.full(np.shape(t), c)
    x, y = key_arrays(keys)
    y = y[:, 0] if y.shape[1] == 1 else y
    if x.size == 1:
        v = y[0]
        return lambda t: np.broadcast_to(v, np.shape(t) + np.shape(v)).astype(float)
    spline = (MonotoneSpline if kind == "monotone" else NaturalCubicSpline)(x, y)
    return spline


__all__ = ["parse_keys", "key_arrays", "smoothstep", "curve_from_keys", "Keys", "Curve"]
