"""Compiled kernels of the :class:`~biomorph.core.motion.Motion` type (numba, cached):
forward kinematics and slerp sampling, plus the quaternion helpers the operators' kernels in
:mod:`biomorph.motion._kernels` inline.

Kept apart from :mod:`biomorph.core.motion` so that reading, describing and converting a
small file never imports numba (issue 12: ``import numba`` and the cached kernels' loads
were 0.9 s of ``biomorph motion info``'s 1.4 s); ``core.motion`` imports this module only for
work large enough that the compiled loop pays for the load (``COMPILED_MIN_WORK``) or when it
is loaded already. Its NumPy paths evaluate the same expressions in the same order, so both
give the same bits (tested in ``tests/motion/test_fast_paths.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _qmul(ax, ay, az, aw, bx, by, bz, bw):  # pragma: no cover - compiled
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


@njit(cache=True, inline="always")
def _qrot(qx, qy, qz, qw, vx, vy, vz):  # pragma: no cover - compiled
    """``v`` rotated by the unit quaternion ``q``."""
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (
        vx + qw * tx + (qy * tz - qz * ty),
        vy + qw * ty + (qz * tx - qx * tz),
        vz + qw * tz + (qx * ty - qy * tx),
    )


@njit(cache=True, inline="always")
def _slerp(ax, ay, az, aw, bx, by, bz, bw, t):  # pragma: no cover - compiled
    if t == 0.0:
        return ax, ay, az, aw
    d = ax * bx + ay * by + az * bz + aw * bw
    if d < 0:
        bx, by, bz, bw, d = -bx, -by, -bz, -bw, -d
    if t == 1.0:
        return bx, by, bz, bw
    if d > 0.9999999:
        w0 = 1.0 - t
        w1 = t
    else:
        th = np.arccos(min(d, 1.0))
        s = np.sin(th)
        w0 = np.sin((1.0 - t) * th) / s
        w1 = np.sin(t * th) / s
    x = w0 * ax + w1 * bx
    y = w0 * ay + w1 * by
    z = w0 * az + w1 * bz
    w = w0 * aw + w1 * bw
    n = np.sqrt(x * x + y * y + z * z + w * w)
    return x / n, y / n, z / n, w / n


@njit(cache=True, inline="always")
def _store_continuous(out, k, j, x, y, z, w):  # pragma: no cover - compiled
    """``out[k, j] = ±(x, y, z, w)``, the sign that keeps joint ``j`` in the hemisphere of
    frame ``k - 1`` (continuity along k)."""
    if (
        k > 0
        and (
            x * out[k - 1, j, 0]
            + y * out[k - 1, j, 1]
            + z * out[k - 1, j, 2]
            + w * out[k - 1, j, 3]
        )
        < 0
    ):
        x, y, z, w = -x, -y, -z, -w
    out[k, j, 0] = x
    out[k, j, 1] = y
    out[k, j, 2] = z
    out[k, j, 3] = w


@njit(cache=True)
def sample_slerp(rot, i0, frac, out):  # pragma: no cover - compiled
    """``out[k, j] = slerp(rot[i0[k], j], rot[i0[k]+1, j], frac[k])`` (exact at frac 0/1),
    hemisphere-continuous along k."""
    f = rot.shape[0]
    for k in range(i0.size):
        a = i0[k]
        b = min(a + 1, f - 1)
        t = frac[k]
        for j in range(rot.shape[1]):
            x, y, z, w = _slerp(
                rot[a, j, 0],
                rot[a, j, 1],
                rot[a, j, 2],
                rot[a, j, 3],
                rot[b, j, 0],
                rot[b, j, 1],
                rot[b, j, 2],
                rot[b, j, 3],
                t,
            )
            _store_continuous(out, k, j, x, y, z, w)


@njit(cache=True)
def fk_positions(rest, rot, trans, parent, pos_out, quat_out):  # pragma: no cover - compiled
    """Forward kinematics with quaternions: world positions ``(f, n, 3)`` and orientations
    ``(f, n, 4)`` from rest rotations ``(n, 4)``, pose rotations ``(f, n, 4)``, local
    translations ``(f, n, 3)`` and ``parent`` (parents first)."""
    f, n = rot.shape[0], rot.shape[1]
    for t in range(f):
        for j in range(n):
            lx, ly, lz, lw = _qmul(
                rest[j, 0],
                rest[j, 1],
                rest[j, 2],
                rest[j, 3],
                rot[t, j, 0],
                rot[t, j, 1],
                rot[t, j, 2],
                rot[t, j, 3],
            )
            p = parent[j]
            if p < 0:
                quat_out[t, j, 0] = lx
                quat_out[t, j, 1] = ly
                quat_out[t, j, 2] = lz
                quat_out[t, j, 3] = lw
                pos_out[t, j, 0] = trans[t, j, 0]
                pos_out[t, j, 1] = trans[t, j, 1]
                pos_out[t, j, 2] = trans[t, j, 2]
                continue
            px, py, pz, pw = (
                quat_out[t, p, 0],
                quat_out[t, p, 1],
                quat_out[t, p, 2],
                quat_out[t, p, 3],
            )
            wx, wy, wz, ww = _qmul(px, py, pz, pw, lx, ly, lz, lw)
            quat_out[t, j, 0] = wx
            quat_out[t, j, 1] = wy
            quat_out[t, j, 2] = wz
            quat_out[t, j, 3] = ww
            # rotate the local translation by the parent's world orientation
            vx, vy, vz = trans[t, j, 0], trans[t, j, 1], trans[t, j, 2]
            tx = 2.0 * (py * vz - pz * vy)
            ty = 2.0 * (pz * vx - px * vz)
            tz = 2.0 * (px * vy - py * vx)
            rx = vx + pw * tx + (py * tz - pz * ty)
            ry = vy + pw * ty + (pz * tx - px * tz)
            rz = vz + pw * tz + (px * ty - py * tx)
            pos_out[t, j, 0] = pos_out[t, p, 0] + rx
            pos_out[t, j, 1] = pos_out[t, p, 1] + ry
            pos_out[t, j, 2] = pos_out[t, p, 2] + rz
