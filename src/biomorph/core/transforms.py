"""Homogeneous transforms, quaternions and Euler angles, vectorised over leading axes.

Conventions (used everywhere in biomorph):

* 4x4 homogeneous matrices act on column vectors: ``p_world = T @ [p, 1]``.
  A child's world transform is ``T_parent_world @ T_local``.
* Quaternions are **scalar-last** ``(x, y, z, w)``, the order of scipy and glTF.
* Euler angles follow BVH: a channel order such as ``"ZXY"`` means the rotation matrix
  ``R = Rz(a0) @ Rx(a1) @ Ry(a2)`` (intrinsic rotations in the listed order). All six
  orders ``XYZ XZY YXZ YZX ZXY ZYX`` are supported. Angles are radians unless ``degrees``.

Every function accepts arrays with arbitrary leading shape ``(..., 4)`` / ``(..., 4, 4)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from biomorph.core.types import Array
from biomorph.errors import ParameterError

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


# --------------------------------------------------------------------------- 4x4 matrices
def identity(shape: tuple[int, ...] = ()) -> Array:
    """Identity transforms of leading ``shape``: array ``shape + (4, 4)``."""
    out = np.zeros(shape + (4, 4))
    out[..., 0, 0] = out[..., 1, 1] = out[..., 2, 2] = out[..., 3, 3] = 1.0
    return out


def make_transform(
    rotation: ArrayLike | None = None, translation: ArrayLike | None = None
) -> Array:
    """Build ``(..., 4, 4)`` transforms from a rotation and a translation (metres).

    ``rotation`` is either 3x3 matrices ``(..., 3, 3)`` or quaternions ``(..., 4)``;
    ``translation`` is ``(..., 3)``. Either may be omitted.
    """
    r = None if rotation is None else np.asarray(rotation, dtype=float)
    t = None if translation is None else np.asarray(translation, dtype=float)
    # matrices end in (3, 3); anything else ending in 4 is quaternions (n joints x 4 is
    # quaternions even when n == 4)
    if r is not None and r.shape[-2:] != (3, 3):
        if r.shape[-1] != 4:
            raise ParameterError(
                f"rotation of shape {r.shape}: expected (..., 3, 3) matrices "
                "or (..., 4) quaternions"
            )
        r = quat_to_matrix(r)
    lead: tuple[int, ...] = ()
    if r is not None:
        lead = np.broadcast_shapes(lead, r.shape[:-2])
    if t is not None:
        lead = np.broadcast_shapes(lead, t.shape[:-1])
    out = identity(lead)
    if r is not None:
        out[..., :3, :3] = r
    if t is not None:
        out[..., :3, 3] = t
    return out


def compose(*transforms: ArrayLike) -> Array:
    """Product ``T1 @ T2 @ ...`` of homogeneous transforms (broadcasting leading axes)."""
    if not transforms:
        return identity()
    out = np.asarray(transforms[0], dtype=float)
    for t in transforms[1:]:
        out = out @ np.asarray(t, dtype=float)
    return out


def invert(transform: ArrayLike) -> Array:
    """Inverse of general affine ``(..., 4, 4)`` transforms (rotation, scale, shear allowed)."""
    t = np.asarray(transform, dtype=float)
    out = identity(t.shape[:-2])
    a_inv = np.linalg.inv(t[..., :3, :3])
    out[..., :3, :3] = a_inv
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", a_inv, t[..., :3, 3])
    return out


def invert_rigid(transform: ArrayLike) -> Array:
    """Inverse of rigid transforms (orthonormal rotation + translation): ``[R^T, -R^T t]``."""
    t = np.asarray(transform, dtype=float)
    out = identity(t.shape[:-2])
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, t[..., :3, 3])
    return out


def local_from_world(parent_world: ArrayLike, child_world: ArrayLike) -> Array:
    """``T_local = T_parent^-1 @ T_child``: place a child whose world transform is known."""
    return invert(parent_world) @ np.asarray(child_world, dtype=float)


def apply(transform: ArrayLike, points: ArrayLike) -> Array:
    """Apply ``(..., 4, 4)`` transforms to points ``(..., 3)`` (broadcasting)."""
    t = np.asarray(transform, dtype=float)
    p = np.asarray(points, dtype=float)
    return np.einsum("...ij,...j->...i", t[..., :3, :3], p) + t[..., :3, 3]


def rotation_about_axis(axis: str | ArrayLike, angle: ArrayLike) -> Array:
    """3x3 rotation matrices about ``"x"|"y"|"z"`` or a unit vector by ``angle`` (rad)."""
    return quat_to_matrix(quat_from_axis_angle(axis, angle))


# --------------------------------------------------------------------------- quaternions
def quat_identity(shape: tuple[int, ...] = ()) -> Array:
    """Identity quaternions ``(x, y, z, w) = (0, 0, 0, 1)`` of leading ``shape``."""
    out = np.zeros(shape + (4,))
    out[..., 3] = 1.0
    return out


def quat_normalize(q: ArrayLike) -> Array:
    """Unit quaternions; raises :class:`ParameterError` on zero-length input."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n == 0) or not np.all(np.isfinite(n)):
        raise ParameterError("quaternion of zero or non-finite length; expected a rotation")
    return q / n


def quat_multiply(a: ArrayLike, b: ArrayLike) -> Array:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``), scalar-last."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_conjugate(q: ArrayLike) -> Array:
    """Conjugate (= inverse for unit quaternions)."""
    q = np.array(q, dtype=float)
    q[..., :3] *= -1.0
    return q


def quat_rotate(q: ArrayLike, v: ArrayLike) -> Array:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)``."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_matrix(q: ArrayLike) -> Array:
    """3x3 rotation matrices ``(..., 3, 3)`` from (not necessarily unit) quaternions."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (yy + zz)
    m[..., 0, 1] = 2 * (xy - wz)
    m[..., 0, 2] = 2 * (xz + wy)
    m[..., 1, 0] = 2 * (xy + wz)
    m[..., 1, 1] = 1 - 2 * (xx + zz)
    m[..., 1, 2] = 2 * (yz - wx)
    m[..., 2, 0] = 2 * (xz - wy)
    m[..., 2, 1] = 2 * (yz + wx)
    m[..., 2, 2] = 1 - 2 * (xx + yy)
    return m


def matrix_to_quat(m: ArrayLike) -> Array:
    """Unit quaternions (w >= 0) from 3x3 rotation matrices ``(..., 3, 3)``."""
    m = np.asarray(m, dtype=float)
    lead = m.shape[:-2]
    from scipy.spatial.transform import Rotation  # lazy: scipy.spatial costs ~0.3 s to load

    q = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat()
    q = np.where(q[:, 3:4] < 0, -q, q)
    return q.reshape(lead + (4,))


def quat_from_axis_angle(axis: str | ArrayLike, angle: ArrayLike) -> Array:
    """Quaternions for a rotation by ``angle`` (rad) about ``axis`` (``"x"``/``"y"``/``"z"`` or
    vectors ``(..., 3)``, normalised here)."""
    angle = np.asarray(angle, dtype=float)
    if isinstance(axis, str):
        key = axis.lower()
        if key not in ("x", "y", "z"):
            raise ParameterError(f"axis {axis!r} is not one of 'x', 'y', 'z'")
        vec = np.zeros(3)
        vec["xyz".index(key)] = 1.0
    else:
        vec = np.asarray(axis, dtype=float)
        vec = vec / np.linalg.norm(vec, axis=-1, keepdims=True)
    half = 0.5 * angle[..., None]
    xyz, w = vec * np.sin(half), np.cos(half)
    lead = np.broadcast_shapes(xyz.shape[:-1], w.shape[:-1])
    return np.concatenate(
        [np.broadcast_to(xyz, lead + (3,)), np.broadcast_to(w, lead + (1,))], axis=-1
    )


def quat_to_rotvec(q: ArrayLike) -> Array:
    """Log map: rotation vectors (axis * angle, angle in [0, pi]) from unit quaternions."""
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., 3:4] < 0, -q, q)
    v = q[..., :3]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., 3:4])
    # angle / s -> 2 as s -> 0 (small-angle limit), use the series to stay exact near 0
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0)
    return v * factor


def quat_from_rotvec(r: ArrayLike) -> Array:
    """Exp map: unit quaternions from rotation vectors (axis * angle, rad)."""
    r = np.asarray(r, dtype=float)
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    half = 0.5 * angle
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(
            angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5 - angle**2 / 48.0
        )
    return np.concatenate([r * k, np.cos(half)], axis=-1)


def quat_slerp(q0: ArrayLike, q1: ArrayLike, t: ArrayLike) -> Array:
    """Spherical linear interpolation, shortest path, broadcasting ``t`` over leading axes.

    ``t`` may have the leading shape of the quaternions (no trailing 4). Returns exactly
    ``q0`` at ``t = 0`` and ``q1`` (or ``-q1`` if that is closer) at ``t = 1``.
    """
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    t = np.asarray(t, dtype=float)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-9
    safe = np.where(near, 1.0, sin_theta)
    w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    w1 = np.where(near, t, np.sin(t * theta) / safe)
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def quat_continuous(q: ArrayLike, axis: int = 0) -> Array:
    """Flip signs along ``axis`` (time) so consecutive quaternions lie in one hemisphere.

    ``q`` and ``-q`` are the same rotation; filters and interpolators need the sign that
    keeps the 4-D signal continuous. The first sample keeps its sign.
    """
    q = np.moveaxis(np.array(q, dtype=float), axis, 0)
    if q.shape[0] > 1:
        dots = np.sum(q[1:] * q[:-1], axis=-1)
        flips = np.cumsum(dots < 0, axis=0) % 2 == 1
        q[1:][flips] *= -1.0
    return np.moveaxis(q, 0, axis)


def quat_angle(a: ArrayLike, b: ArrayLike) -> Array:
    """Rotation angle (rad, in [0, pi]) between orientations ``a`` and ``b``."""
    d = np.abs(np.sum(np.asarray(a, float) * np.asarray(b, float), axis=-1))
    return 2.0 * np.arccos(np.clip(d, -1.0, 1.0))


# --------------------------------------------------------------------------- Euler angles
def _check_order(order: str) -> str:
    o = order.upper()
    if o not in EULER_ORDERS:
        raise ParameterError(f"Euler order {order!r} is not one of {', '.join(EULER_ORDERS)}")
    return o


def euler_to_quat(angles: ArrayLike, order: str, degrees: bool = False) -> Array:
    """Quaternions from Euler angles ``(..., 3)`` given in channel ``order`` (BVH meaning:
    ``R = R_order[0](a0) @ R_order[1](a1) @ R_order[2](a2)``)."""
    o = _check_order(order)
    a = np.asarray(angles, dtype=float)
    if degrees:
        a = np.deg2rad(a)
    q = None
    for i, ax in enumerate(o):
        qi = quat_from_axis_angle(ax.lower(), a[..., i])
        q = qi if q is None else quat_multiply(q, qi)
    assert q is not None
    return q


def quat_to_euler(q: ArrayLike, order: str, degrees: bool = False) -> Array:
    """Euler angles ``(..., 3)`` in channel ``order`` (inverse of :func:`euler_to_quat`).

    The middle angle lies in [-pi/2, pi/2]; the outer ones in [-pi, pi]. Use
    :func:`unwrap_euler` to make a time series continuous.

    Plain NumPy (no scipy.spatial, whose import costs ~0.3 s of a CLI call): for
    ``R = R_i(a) R_j(b) R_k(c)`` with parity ``e`` (+1 when ijk is a cyclic permutation of
    xyz), ``b = atan2(e R[i,k], hypot(R[i,i], R[i,j]))``, ``a = atan2(-e R[j,k], R[k,k])``
    and ``c = atan2(-e R[i,j], R[i,i])``. Near gimbal lock (``cos b < 1e-2``, where ``a``
    and ``c`` are not separable) ``c`` is read instead from the remaining rotation
    ``R_j(b)^-1 R_i(a)^-1 R``, so it absorbs the error of ``a`` and the angles rebuild ``q``
    to 2e-13. At lock itself (``cos b < 1e-7``) only ``a +- c`` is defined: the first angle
    takes all of it and ``c`` is 0, as scipy's ``as_euler`` does (rebuild error <= ``cos b``),
    so a file written, read and written again is byte-identical.
    """
    o = _check_order(order)
    q = np.asarray(q, dtype=float)
    lead = q.shape[:-1]
    q = q.reshape(-1, 4)
    i, j, k = ("XYZ".index(ch) for ch in o)
    e = 1.0 if (j - i) % 3 == 1 else -1.0
    m = quat_to_matrix(q)
    cos_b = np.hypot(m[..., i, i], m[..., i, j])
    b = np.arctan2(e * m[..., i, k], cos_b)
    a = np.arctan2(-e * m[..., j, k], m[..., k, k])
    c = np.arctan2(-e * m[..., i, j], m[..., i, i])
    lock = cos_b < 1e-2
    if np.any(lock):
        # at lock itself only a +- c is defined: take c = 0 (as scipy does), so the
        # decomposition of a re-read file is the one written (idempotent round trips)
        hard = cos_b < 1e-7
        a[hard] = np.arctan2(e * m[hard, k, j], m[hard, j, j])
        qa = quat_from_axis_angle(o[0], a[lock])
        qb = quat_from_axis_angle(o[1], b[lock])
        rest = quat_multiply(quat_conjugate(qb), quat_multiply(quat_conjugate(qa), q[lock]))
        cl = 2.0 * np.arctan2(rest[..., k], rest[..., 3])
        c[lock] = np.where(cl > np.pi, cl - 2 * np.pi, np.where(cl < -np.pi, cl + 2 * np.pi, cl))
    eul = np.stack([a, b, c], axis=-1).reshape(lead + (3,))
    return np.degrees(eul) if degrees else eul


def unwrap_euler(angles: ArrayLike, degrees: bool = False, axis: int = 0) -> Array:
    """Remove +-360 degree jumps along ``axis`` (time) channel by channel."""
    period = 360.0 if degrees else 2.0 * np.pi
    return np.unwrap(np.asarray(angles, dtype=float), axis=axis, period=period)
