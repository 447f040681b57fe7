"""Test oracles for the motion pillar: slow, obviously-correct references of fast kernels."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from biomorph.core.motion import Motion, sample_arrays
from biomorph.core.types import Array
from biomorph.motion._kernels import blend_average, ro


def average_rotations_reference(clips: Sequence[Motion], us: Sequence[Array], w: Array) -> Array:
    """Reference for :func:`average_rotations`: sample every clip on the whole timeline,
    stack, average."""
    rots = [sample_arrays(c, u)[0] for c, u in zip(clips, us, strict=True)]
    rot = np.empty_like(rots[0])
    blend_average(ro(np.stack(rots)), ro(w), rot)
    return rot
