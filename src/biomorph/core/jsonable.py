"""JSON: the one converter from numpy values, paths and dataclasses to strict JSON.

Every JSON biomorph writes or prints (``--json``, ``summary.json``, creature ``.json``,
batch reports) goes through :func:`to_jsonable`, so NaN/inf become ``null`` everywhere (JSON
has no NaN) and the text always parses. Imports only the standard library (the CLI layer
uses it at start-up); numpy values are handled when numpy is already loaded.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
from collections.abc import Mapping
from typing import Any


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


__all__ = ["dumps", "to_jsonable"]
