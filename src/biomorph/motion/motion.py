"""The :class:`Motion` type, re-exported from :mod:`biomorph.core.motion`.

The type moved to ``core/`` (issue 12) so ``io/`` readers and ``render`` need not import the
motion pillar; this module keeps ``biomorph.motion.motion.Motion`` importable.
"""

from biomorph.core.motion import (
    DEFAULT_ORDER,
    POSITION_CHANNELS,
    ROTATION_CHANNELS,
    Motion,
    check_range,
    concatenate,
    dfs_preorder,
    frozen,
    guess_up_axis,
    preview_positions,
    reorder_joints,
    same_skeleton,
    sample_arrays,
    sample_linear,
)

__all__ = [
    "Motion",
    "concatenate",
    "dfs_preorder",
    "reorder_joints",
    "check_range",
    "same_skeleton",
    "guess_up_axis",
    "frozen",
    "preview_positions",
    "sample_arrays",
    "sample_linear",
    "ROTATION_CHANNELS",
    "POSITION_CHANNELS",
    "DEFAULT_ORDER",
]
