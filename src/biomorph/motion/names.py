"""Joint-name conventions for the motion pillar: the presets live in
:mod:`biomorph.core.names` (the BVH reader needs them too); this module re-exports them."""

from __future__ import annotations

from biomorph.core.names import (
    CANONICAL,
    PRESETS,
    REQUIRED,
    bare,
    detect_preset,
    foot_joints,
    left_right_pairs,
    mirror_name,
    preset_feet,
    read_map_csv,
    resolve,
)

__all__ = [
    "CANONICAL",
    "REQUIRED",
    "PRESETS",
    "bare",
    "detect_preset",
    "resolve",
    "read_map_csv",
    "mirror_name",
    "left_right_pairs",
    "preset_feet",
    "foot_joints",
]
