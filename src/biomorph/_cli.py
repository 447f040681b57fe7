"""Shared command-line helpers below the pillars: consoles, one JSON converter, ``emit``,
range-checked option callbacks and output-extension checks.

Every pillar's ``cli.py`` imports from here (never from :mod:`biomorph.cli`, which sits above
the pillars), so every command prints the same way:

* ``emit(summary, as_json)`` prints a summary dict as JSON (``--json``) or as one rich table;
* ``to_jsonable`` is the only JSON converter: numpy scalars/arrays, paths, dataclasses,
  and NaN/inf mapped to ``null`` (JSON has no NaN);
* ``bounded(...)`` builds a typer/click callback that refuses NaN, inf and out-of-range values
  with one line naming the option and the accepted range (a :class:`ParameterError`, exit 2);
* ``check_suffix(path, allowed, option)`` refuses an output whose extension no writer handles.

This module imports only the standard library, ``rich`` and :mod:`biomorph.errors` at import
time, so ``biomorph --help`` stays fast.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from rich.console import Console

from biomorph.errors import ParameterError, UnsupportedFormatError

err_console = Console(stderr=True, soft_wrap=True, highlight=False)
out_console = Console(soft_wrap=True, highlight=False)

__all__ = ["bounded", "check_suffix", "emit", "err_console", "out_console", "print_json",
           "to_jsonable"]


def to_jsonable(obj: Any) -> Any:
    """``obj`` with numpy values, paths, sets, tuples and dataclasses turned into JSON types.

    Non-finite floats become ``None`` so the output is strict JSON (``allow_nan=False``).

    >>> to_jsonable({"a": float("nan"), "b": (1, 2.5)})
    {'a': None, 'b': [1, 2.5]}
    """
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | set | frozenset):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, bool) or obj is None or isinstance(obj, str | int):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable({f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)})
    if "numpy" in sys.modules:
        import numpy as np

        if isinstance(obj, np.ndarray):
            return to_jsonable(obj.tolist())
        if isinstance(obj, np.generic):
            return to_jsonable(obj.item())
    return obj


def dumps(data: Any, indent: int | None = 2) -> str:
    """Strict JSON text of ``data`` (through :func:`to_jsonable`)."""
    return json.dumps(to_jsonable(data), indent=indent, allow_nan=False)


def print_json(data: Any) -> None:
    """Print ``data`` as strict JSON on stdout."""
    sys.stdout.write(dumps(data) + "\n")


def emit(summary: Mapping[str, Any], as_json: bool = False, title: str | None = None) -> None:
    """Print a command's result: JSON with ``--json``, else a two-column rich table."""
    if as_json:
        print_json(summary)
        return
    from rich.table import Table

    table = Table(title=title, show_header=False, title_justify="left")
    for k, v in to_jsonable(summary).items():
        if isinstance(v, float):
            v = f"{v:.6g}"
        elif isinstance(v, dict | list):
            v = json.dumps(v)
        table.add_row(str(k), str(v))
    out_console.print(table)


def _fmt_range(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return "a finite number"


def check_value(name: str, value: float | int, lo: float | None = None,
                hi: float | None = None, *, lo_open: bool = False,
                hi_open: bool = False) -> None:
    """Raise :class:`ParameterError` unless ``value`` is finite and inside the range.

    >>> check_value("--k", 0, lo=1)
    Traceback (most recent call last):
    ...
    biomorph.errors.ParameterError: --k: got 0; expected >= 1
    """
    expected = _fmt_range(lo, hi, lo_open, hi_open)
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(f"{name}: got {value!r}; expected {expected}") from None
    bad = not math.isfinite(v)
    if lo is not None:
        bad |= v <= lo if lo_open else v < lo
    if hi is not None:
        bad |= v >= hi if hi_open else v > hi
    if bad:
        raise ParameterError(f"{name}: got {value!r}; expected {expected}")


def bounded(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            hi_open: bool = False) -> Callable[[Any, Any, Any], Any]:
    """A typer/click option callback checking each given value with :func:`check_value`.

    ``typer.Option(..., callback=bounded(lo=0, lo_open=True))`` refuses 0, negatives, NaN and
    inf at parse time; ``None`` (option not given) passes. Lists are checked element-wise.
    """

    def callback(ctx: Any, param: Any, value: Any) -> Any:
        if value is None:
            return value
        name = "/".join(getattr(param, "opts", []) or [getattr(param, "name", "value")])
        values: Iterable[Any] = value if isinstance(value, list | tuple) else (value,)
        for v in values:
            if v is not None:
                check_value(name, v, lo, hi, lo_open=lo_open, hi_open=hi_open)
        return value

    return callback


def check_suffix(path: str | os.PathLike[str], allowed: Iterable[str], option: str) -> None:
    """Refuse an output path whose extension is not one of ``allowed`` (e.g. ``(".png",)``)."""
    allowed = tuple(a.lower() for a in allowed)
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix not in allowed:
        raise UnsupportedFormatError(
            f"{option} {os.fspath(path)}: extension {suffix or '(none)'!r} not written; "
            f"expected one of {', '.join(allowed)}")
