"""Test oracles for the motion pillar: slow, obviously-correct references of fast kernels."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, _store_flips, sample_arrays
from biomorph.core.types import Array
from biomorph.motion._kernels import (
    _filter_rows,
    _qexp,
    _qlog,
    _qmul,
    _store_continuous,
    blend_average,
    ro,
)


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


def mirror_rotations_reference(
    motion: Motion, other: Array, sign: Array, corr: Array | None = None
) -> Array:
    """Reference for the mirror kernel: world rotations by FK, the mirror joint's reflected
    (``[:, other] * sign``) times its frame correction ``corr`` when given, back to local
    rotations."""
    mw = motion.world_rotations()[:, other] * sign
    if corr is not None:
        mw = tf.quat_multiply(mw, corr[None])
    return local_from_world_reference(mw, motion.skeleton.rest_rotation, motion.skeleton.parent)


def continuous_reference(q: Array) -> Array:
    """``transforms.quat_continuous`` along axis 0 (parity of the negative dots)."""
    return tf.quat_continuous(q, axis=0)


@njit(cache=True)
def _mean_log_joint(q, gains, mode, out):  # pragma: no cover - compiled
    """The equalizer's mean-log path for one joint ``q (f, 4)``, frame by frame with the
    scalar log/exp (the loop the vectorised passes replaced)."""
    f = q.shape[0]
    m = np.zeros(4)
    for i in range(f):
        for c in range(4):
            m[c] += q[i, c]
    mn = np.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2] + m[3] * m[3])
    mx, my, mz, mw = m[0] / mn, m[1] / mn, m[2] / mn, m[3] / mn
    xs = np.empty((3, f))
    xo = np.empty((3, f))
    for i in range(f):
        a, b, cc, d = _qmul(-mx, -my, -mz, mw, q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        xs[0, i], xs[1, i], xs[2, i] = _qlog(a, b, cc, d)
    _filter_rows(xs, xo, gains, mode, np.empty(f), np.empty(f))
    for i in range(f):
        ex, ey, ez, ew = _qexp(xo[0, i], xo[1, i], xo[2, i])
        x, y, z, w = _qmul(mx, my, mz, mw, ex, ey, ez, ew)
        _store_continuous(out, i, 0, x, y, z, w)


def equalize_mean_log_reference(q: Array, gains: Array, mode: int) -> Array:
    """Reference for ``equalize_rotations`` on joints that take the mean-log path."""
    out = np.empty(q.shape)
    for j in range(q.shape[1]):
        col = np.empty((q.shape[0], 1, 4))
        _mean_log_joint(ro(q[:, j]), ro(gains), mode, col)
        out[:, j] = col[:, 0]
    return out


def retarget_rotations_reference(
    ws: Array, src_of: Array, pre: Array, post: Array, rest_t: Array, parent: Array
) -> Array:
    """Reference for the retarget kernel given the source's world rotations ``ws``: target
    world rotations joint by joint (mapped: ``ws[src]·pre·post``, unmapped: parent's world
    times rest), then local poses ``rest⁻¹ · parent⁻¹ · world``, continuous over frames."""
    f, n = ws.shape[0], parent.size
    world = np.empty((f, n, 4))
    ident = np.broadcast_to([0.0, 0.0, 0.0, 1.0], (f, 4))
    for j in range(n):
        par = world[:, parent[j]] if parent[j] >= 0 else ident
        if src_of[j] >= 0:
            world[:, j] = tf.quat_multiply(tf.quat_multiply(ws[:, src_of[j]], pre[j]), post[j])
        else:
            world[:, j] = tf.quat_multiply(par, rest_t[j])
    local = np.empty((f, n, 4))
    for j in range(n):
        par = world[:, parent[j]] if parent[j] >= 0 else ident
        lq = tf.quat_multiply(tf.quat_conjugate(par), world[:, j])
        local[:, j] = tf.quat_multiply(tf.quat_conjugate(rest_t[j]), lq)
    local[1:][_store_flips(np.sum(local[1:] * local[:-1], axis=-1))] *= -1.0
    return local
