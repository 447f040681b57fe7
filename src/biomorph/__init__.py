"""biomorph: skeletons of living things.

Four pillars over a shared core:

* ``biomorph.creature`` -- procedural vertebrate skeletons (PCA over annotated species),
* ``biomorph.tree``     -- tree skeletons from LiDAR point clouds (voxel and graph methods),
* ``biomorph.motion``   -- motion-capture editing by signal processing (MotionLab),
* ``biomorph.leaf``     -- plastic, dynamic, reducible grass leaves and canopies.

Subpackages are imported lazily so ``import biomorph`` stays fast.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_SUBMODULES = {"core", "io", "creature", "tree", "motion", "leaf", "render", "errors", "scale"}


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        module = importlib.import_module(f"biomorph.{name}")
        globals()[name] = module
        return module
    raise AttributeError(f"module 'biomorph' has no attribute {name!r}")


__all__ = sorted(_SUBMODULES) + ["__version__"]
