"""Shared maths and data types: transforms, curves, JointSkeleton, BranchGraph, PointCloud.

The names load lazily: ``biomorph motion info`` needs the skeleton types but not the graph
kernels (numba), so importing ``biomorph.core.skeleton`` does not compile or load them.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "BranchGraph": "biomorph.core.graph",
    "PointCloud": "biomorph.core.pointcloud",
    "JointSkeleton": "biomorph.core.skeleton",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module 'biomorph.core' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
