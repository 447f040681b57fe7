"""MotionLab: editing motion capture by signal processing (seed 002, Bruderlin & Williams).

Pure functions over an immutable :class:`Motion` (each returns a new Motion):

==========================  ==========================================================
``equalize``                multiresolution filter bank, gains per band (equalizer.py)
``displace``                displacement map: spline through key offsets (displacement.py)
``apply_layers``/``Layer``  additive "overAnimate" layers (displacement.py)
``reorient``                rotate/move the whole motion about the vertical (align.py)
``to_y_up``                 convert Z-up data (align.py)
``blend``                   N clips with offsets/scales, blend curve, auto-align (blend.py)
``change_speed``            speed curve → time warp (timewarp.py)
``resample``                another frame rate, planted feet kept (timewarp.py)
``make_cycle``/``best_loop``  seamless loops with offset (cycle.py)
``quality_report``          angular rates, Euler wraps, foot skate (quality.py)
==========================  ==========================================================

Names load lazily (PEP 562 ``__getattr__``) so ``biomorph motion --help`` and the CLI module
import no numeric stack; ``Motion`` and its helpers live in :mod:`biomorph.core.motion`.
"""

import importlib
from typing import Any

_WHERE = {
    "Motion": "biomorph.core.motion",
    "concatenate": "biomorph.core.motion",
    "guess_up_axis": "biomorph.core.motion",
    "preview_positions": "biomorph.core.motion",
    "dfs_preorder": "biomorph.core.motion",
    "reorder_joints": "biomorph.core.motion",
    "to_y_up": "biomorph.core.motion",
    "transform_root": "biomorph.core.motion",
    "reorient": "biomorph.motion.align",
    "blend": "biomorph.motion.blending",
    "best_loop": "biomorph.motion.cycle",
    "make_cycle": "biomorph.motion.cycle",
    "Layer": "biomorph.motion.displacement",
    "apply_layers": "biomorph.motion.displacement",
    "displace": "biomorph.motion.displacement",
    "remove_layer": "biomorph.motion.displacement",
    "bands": "biomorph.motion.equalizer",
    "equalize": "biomorph.motion.equalizer",
    "n_bands": "biomorph.motion.equalizer",
    "quality_report": "biomorph.motion.quality",
    "change_speed": "biomorph.motion.timewarp",
    "resample": "biomorph.motion.timewarp",
}

__all__ = list(_WHERE)


def __getattr__(name: str) -> Any:
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module 'biomorph.motion' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
