"""Test oracles for the motion pillar: slow, obviously-correct references of fast kernels."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, _store_flips, sample_arrays
from biomorph.core.types import Array
from biomorph.motion._kernels import blend_average, ro


def average_rotations_reference(clips: Sequence[Motion], us: Sequence[Array], w: Array) -> Array:
    """Reference for :func:`average_rotations`: sample every clip on the whole timeline,
    stack, average."""
    rots = [sample_arrays(c, u)[0] for c, u in zip(clips, us, strict=True)]
    rot = np.empty_like(rots[0])
    blend_average(ro(np.stack(rots)), ro(w), rot)
    return rot


def local_from_world_reference(world: Array, rest: Array, parent: Array) -> Array:
    """``rest[j]⁻¹ · world[:, parent]⁻¹ · world[:, j]`` per joint, hemisphere-continuous
    along frames (the compiled kernels' store-and-compare rule)."""
    out = np.empty(world.shape)
    for j in range(world.shape[1]):
        q = world[:, j]
        p = parent[j]
        if p >= 0:
            q = tf.quat_multiply(tf.quat_conjugate(world[:, p]), q)
        q = tf.quat_multiply(tf.quat_conjugate(rest[j]), q)
        out[:, j] = q
    out[1:][_store_flips(np.sum(out[1:] * out[:-1], axis=-1))] *= -1.0
    return out


def mirror_rotations_reference(motion: Motion, other: Array, sign: Array) -> Array:
    """Reference for the mirror kernel: world rotations by FK, the mirror joint's reflected
    (``[:, other] * sign``), back to local rotations."""
    mw = motion.world_rotations()[:, other] * sign
    return local_from_world_reference(mw, motion.skeleton.rest_rotation, motion.skeleton.parent)


def continuous_reference(q: Array) -> Array:
    """``transforms.quat_continuous`` along axis 0 (parity of the negative dots)."""
    return tf.quat_continuous(q, axis=0)
