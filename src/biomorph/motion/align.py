"""Root transforms, heading, up-axis conversion and time alignment of clips.

* :func:`transform_root` applies a rigid world transform to a whole motion (rotation of the
  root orientation and root trajectory about a pivot, then a translation); every non-root
  local rotation stays untouched.
* :func:`reorient` (the seed's Edit → re-orient / re-position): rotate about the vertical
  axis by an angle and move, so the character walks another way.
* :func:`to_y_up` converts Z-up data (e.g. the fair1 captures) to Y-up (defined in
  :mod:`biomorph.core.motion` with :func:`transform_root`, re-exported here).
* :func:`heading` yaw of the root per frame; :func:`align_root_to` puts one clip's root onto
  another's at a frame (position and heading, height kept).
* :func:`local_maxima`, :func:`peak_offset` (the seed's auto-adjust: last local maximum of a
  channel in A onto the first one in B) and :func:`dtw_path` (dynamic time warping over a
  pose-distance matrix, compiled with numba).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, to_y_up, transform_root
from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError

_UP = {"x": 0, "y": 1, "z": 2}


def _up_index(up: str) -> int:
    try:
        return _UP[up.lower()]
    except (KeyError, AttributeError):
        raise ParameterError(f"up axis {up!r}; expected 'x', 'y' or 'z'") from None


def reorient(
    motion: Motion,
    angle: float,
    translate: ArrayLike = (0.0, 0.0, 0.0),
    pivot: ArrayLike | None = None,
    up: str = "y",
) -> Motion:
    """Rotate the whole motion by ``angle`` (rad) about the vertical axis through ``pivot``
    (default: the root's horizontal position at frame 0), then move it by ``translate``.

    Root orientation and root translation are recomputed; all other local rotations stay
    as they are, so the character walks the new way."""
    if not np.isfinite(angle):
        raise ParameterError(f"angle {angle!r} is not finite")
    ui = _up_index(up)
    if pivot is None:
        pivot = np.array(motion.root_position[0])
        pivot[ui] = 0.0
    axis = np.zeros(3)
    axis[ui] = 1.0
    return transform_root(motion, tf.quat_from_axis_angle(axis, float(angle)), translate, pivot)


def _forward_axis(motion: Motion, up: int) -> int:
    step = max(1, motion.n_frames // 64)  # a sample of frames is enough to pick the axis
    w = tf.quat_to_matrix(
        tf.quat_multiply(motion.skeleton.rest_rotation[0], motion.rotation[::step, 0])
    )
    vertical = np.abs(w[:, up, :]).mean(axis=0)  # |up component| of each local axis
    vertical[up] += 1e-9  # prefer non-up axes on ties
    return int(np.argmin(vertical))


def heading(motion: Motion, up: str = "y", axis: int | None = None) -> Array:
    """Yaw (rad, unwrapped) of the root about the vertical axis, per frame.

    Measured from the root's most horizontal local axis (or ``axis``) projected onto the
    ground plane; differences of heading are what alignment uses."""
    ui = _up_index(up)
    a = _forward_axis(motion, ui) if axis is None else axis
    w = tf.quat_to_matrix(tf.quat_multiply(motion.skeleton.rest_rotation[0], motion.rotation[:, 0]))
    d = w[:, :, a]
    h1, h2 = [(ui + 1) % 3, (ui + 2) % 3]
    # a rotation by +theta about +up turns h1 towards h2, so this angle grows by theta
    return np.unwrap(np.arctan2(d[:, h2], d[:, h1]))


def heading_at(motion: Motion, frame: int, up: str = "y", axis: int | None = None) -> float:
    """Yaw (rad, in (-pi, pi]) of the root at one frame — :func:`heading` without
    evaluating the whole clip (the forward axis is still chosen from the whole clip)."""
    ui = _up_index(up)
    a = _forward_axis(motion, ui) if axis is None else axis
    w = tf.quat_to_matrix(
        tf.quat_multiply(motion.skeleton.rest_rotation[0], motion.rotation[frame, 0])
    )
    h1, h2 = [(ui + 1) % 3, (ui + 2) % 3]
    return float(np.arctan2(w[h2, a], w[h1, a]))


def align_root_to(
    b: Motion,
    a_position: ArrayLike,
    a_heading: float,
    frame_b: int,
    up: str = "y",
    axis: int | None = None,
) -> Motion:
    """Rotate ``b`` about the vertical so its heading at ``frame_b`` equals ``a_heading`` and
    move it horizontally so its root at ``frame_b`` sits at ``a_position`` (height kept)."""
    ui = _up_index(up)
    hb = heading_at(b, frame_b, up, axis)
    pb = b.root_position[frame_b]
    rotated = reorient(b, float(a_heading - hb), pivot=np.where(np.arange(3) == ui, 0.0, pb), up=up)
    shift = np.asarray(a_position, float) - rotated.root_position[frame_b]
    shift[ui] = 0.0
    return transform_root(rotated, tf.quat_identity(), shift)


# --------------------------------------------------------------------------- peaks
def local_maxima(x: ArrayLike) -> NDArray[np.int64]:
    """Indices ``i`` with ``x[i-1] < x[i] >= x[i+1]`` (strict on the left so plateaus count
    once), ends excluded — the seed's ``Peaks`` test."""
    x = np.asarray(x, dtype=float)
    if x.size < 3:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:])) + 1


def peak_offset(
    a: Motion, b: Motion, joint: str, channel: str = "Xrotation", smooth: int = 2
) -> tuple[int, int]:
    """The seed's auto-align: ``(frame in a, frame in b)`` of the last local maximum of
    ``joint.channel`` in ``a`` and the first in ``b``.

    The channel (Euler, in the joint's own order, unwrapped) is smoothed by ``smooth`` passes
    of the [1/4, 1/2, 1/4] kernel first so capture noise does not create spurious peaks."""

    def peaks(m: Motion, which: str) -> int:
        x = m.channel(joint, channel)
        for _ in range(max(0, smooth)):
            x = np.convolve(np.pad(x, 1, mode="edge"), [0.25, 0.5, 0.25], mode="valid")
        p = local_maxima(x)
        if p.size == 0:
            raise InputError(
                f"{joint}.{channel} has no local maximum in the {which} clip; "
                "choose another joint/channel or set the offset by hand"
            )
        return int(p[-1] if which == "first (A)" else p[0])

    return peaks(a, "first (A)"), peaks(b, "second (B)")


# --------------------------------------------------------------------------- DTW
def pose_features(motion: Motion) -> Array:
    """Per-frame pose feature ``float[f, 4(n-1)]``: non-root joint quaternions (sign fixed to
    w >= 0) — the root is excluded so position and heading do not matter."""
    q = motion.rotation[:, 1:]
    q = np.where(q[..., 3:4] < 0, -q, q)
    return q.reshape(motion.n_frames, -1)


def pose_distance(fa: Array, fb: Array) -> Array:
    """Euclidean distance matrix between two feature sets ``(na, d)``, ``(nb, d)``."""
    aa = np.einsum("ij,ij->i", fa, fa)[:, None]
    bb = np.einsum("ij,ij->i", fb, fb)[None, :]
    return np.sqrt(np.maximum(aa + bb - 2.0 * fa @ fb.T, 0.0))


def dtw_path(cost: ArrayLike) -> tuple[NDArray[np.int64], float]:
    """Dynamic time warping over a cost matrix: monotone path ``(k, 2)`` of index pairs from
    (0, 0) to (n-1, m-1) minimising the summed cost, and that cost."""
    c = np.ascontiguousarray(cost, dtype=float)
    if c.ndim != 2 or 0 in c.shape:
        raise ParameterError(f"DTW cost matrix of shape {c.shape}; expected a non-empty 2-D array")
    from biomorph.motion._kernels import dtw  # numba: loaded only when DTW runs

    return dtw(c)


__all__ = [
    "transform_root",
    "reorient",
    "to_y_up",
    "heading",
    "heading_at",
    "align_root_to",
    "local_maxima",
    "peak_offset",
    "pose_features",
    "pose_distance",
    "dtw_path",
]
