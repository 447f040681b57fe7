"""Root motion: the character's path over the ground, taken out of a clip and put back.

* :func:`extract_root_motion` adds a ground-level root joint (``name``, default ``"root"``)
  above the hips that carries the horizontal path and the heading (yaw about the vertical);
  the hips keep only what is left (height, sway relative to the path, lean). This is the
  layout game engines expect for root-motion clips. :func:`apply_root_motion` folds such a
  root back into the hips (exact inverse: world positions agree to rounding).
* :func:`in_place` removes the path: the hips stay over the start point and face the start
  heading (``heading=False`` keeps the turns).
* :func:`remove_drift` subtracts a steady travel (a translation and heading per ``period``
  frames, linear in time): :func:`biomorph.motion.cycle.make_cycle` uses it for its
  ``"in-place"`` mode, so a loop keeps its sway and bounce, returns to its start exactly
  after each period, and never jumps at a seam.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, frozen, transform_root
from biomorph.core.skeleton import JointSkeleton
from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError
from biomorph.motion._kernels import continuous_inplace
from biomorph.motion.align import _up_index, heading


def _yaw_quat(angle: Array, ui: int) -> Array:
    axis = np.zeros(3)
    axis[ui] = 1.0
    return tf.quat_from_axis_angle(axis, angle)


def ground_path(motion: Motion, up: str = "y", with_heading: bool = True) -> tuple[Array, Array]:
    """``(path (f, 3), yaw (f,))``: the root's horizontal position (height 0) and its heading
    relative to frame 0 (zeros when ``with_heading`` is False)."""
    ui = _up_index(up)
    path = np.array(motion.root_position)
    path[:, ui] = 0.0
    yaw = heading(motion, up) if with_heading else np.zeros(motion.n_frames)
    return path, yaw - yaw[0]


def in_place(motion: Motion, up: str = "y", with_heading: bool = True) -> Motion:
    """The clip without its path: the hips stay above the start point (and face the start
    heading when ``with_heading``); height, sway of the body and all joints are kept."""
    ui = _up_index(up)
    path, yaw = ground_path(motion, up, with_heading)
    q = _yaw_quat(-yaw, ui)
    # p -> R_k^-1 (p - c_k) + c_0, per frame
    trans = -tf.quat_rotate(q, path) + path[0]
    out = transform_root(motion, q, trans)
    return _note(out, "in_place")


def remove_drift(
    motion: Motion,
    translation: ArrayLike,
    yaw: float,
    period: float,
    up: str = "y",
    restore: bool = False,
) -> Motion:
    """Subtract a steady travel of ``translation`` (horizontal) and ``yaw`` (rad) per
    ``period`` frames, growing linearly from frame 0 (frame ``k`` is moved back by
    ``k / period`` of it). ``restore=True`` adds it back exactly (the world path of an
    in-place loop, from the ``drift`` that ``make_cycle``'s ``meta["cycle"]`` and ``cycle
    --json`` report)."""
    if not (np.isfinite(period) and period > 0):
        raise ParameterError(f"period {period}; expected a positive number of frames")
    ui = _up_index(up)
    k = np.arange(motion.n_frames) / float(period)
    t = np.asarray(translation, dtype=float).reshape(3)
    q = _yaw_quat(-k * float(yaw), ui)
    # about the start point: rotate back by the drifted heading, move back by the travel
    c0 = np.array(motion.root_position[0])
    c0[ui] = 0.0
    shift = -k[:, None] * tf.quat_rotate(q, np.broadcast_to(t, (k.size, 3)))
    trans = c0 - tf.quat_rotate(q, np.broadcast_to(c0, (k.size, 3))) + shift
    if restore:  # the inverse map, x -> q⁻¹ (x - trans), about the same start point
        qi = tf.quat_conjugate(q)
        return transform_root(motion, qi, -tf.quat_rotate(qi, trans))
    return transform_root(motion, q, trans)


def extract_root_motion(
    motion: Motion, up: str = "y", name: str | None = None, with_heading: bool = True
) -> Motion:
    """A motion with a new ground-level root joint ``name`` carrying the path (horizontal
    position, height 0) and heading; the former root becomes its child (module docstring).
    ``name=None``: ``"root"``, or ``"root_motion"`` (``root_motion2``, …) when the skeleton
    already has a joint named ``root`` (CMU's ASF/AMC pelvis); an explicit ``name`` that
    is taken is refused."""
    if name is None:
        name, k = "root", 1
        while name in motion.names:
            name = "root_motion" if k == 1 else f"root_motion{k}"
            k += 1
    if name in motion.names:
        raise InputError(
            f"the skeleton already has a joint named {name!r}; pass another "
            "name for the ground-level root"
        )
    ui = _up_index(up)
    path, yaw = ground_path(motion, up, with_heading)
    q = _yaw_quat(yaw, ui)
    sk = motion.skeleton
    rest_h = sk.rest_rotation[0]
    inv = tf.quat_conjugate
    hips = tf.quat_multiply(
        inv(rest_h), tf.quat_multiply(inv(q), tf.quat_multiply(rest_h, motion.rotation[:, 0]))
    )
    f, n = motion.n_frames, sk.n_joints
    rot = np.empty((f, n + 1, 4))
    rot[:, 0] = q
    rot[:, 1] = hips
    rot[:, 2:] = motion.rotation[:, 1:]
    continuous_inplace(rot)
    jt = np.empty((f, n + 1, 3))
    jt[:, 0] = path
    jt[:, 1] = tf.quat_rotate(inv(q), motion.root_position - path)
    inner = motion.joint_translation
    jt[:, 2:] = sk.offset[1:] if inner is None else inner[:, 1:]
    parent = np.concatenate([[-1], np.where(sk.parent >= 0, sk.parent + 1, 0)])
    chans = None
    if sk.channels is not None:
        chans = [
            ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
            *sk.channels,
        ]
        chans[1] = (
            tuple(chans[1])
            if any(c.endswith("position") for c in chans[1])
            else ("Xposition", "Yposition", "Zposition", *chans[1])
        )
    end = np.concatenate([np.full((1, 3), np.nan), sk.end_site])
    new = JointSkeleton(
        [name, *sk.names],
        parent,
        np.concatenate([np.zeros((1, 3)), sk.offset]),
        np.concatenate([tf.quat_identity((1,)), sk.rest_rotation]),
        np.concatenate([np.tile([-np.pi, np.pi], (1, 3, 1)), sk.limits]),
        chans,
        end,
    )
    out = Motion(
        new,
        frozen(rot),
        frozen(path),
        motion.frame_time,
        frozen(jt),
        dict(motion.meta),
    )
    return _note(out, "extract_root_motion")


def apply_root_motion(motion: Motion) -> Motion:
    """Fold a ground-level root (joint 0 with a single child) back into that child (the
    inverse of :func:`extract_root_motion`)."""
    sk = motion.skeleton
    kids = np.flatnonzero(sk.parent == 0)
    if sk.n_joints < 2 or kids.size != 1 or kids[0] != 1:
        raise InputError(
            f"root {sk.names[0]!r} does not have exactly one child joint; "
            "expected a ground-level root above the hips"
        )
    wq = tf.quat_multiply(sk.rest_rotation[0], motion.rotation[:, 0])
    lt = motion.local_translations()
    hips_pos = tf.quat_rotate(wq, lt[:, 1]) + lt[:, 0]
    rest_h = sk.rest_rotation[1]
    inv = tf.quat_conjugate
    hips = tf.quat_multiply(
        inv(rest_h), tf.quat_multiply(wq, tf.quat_multiply(rest_h, motion.rotation[:, 1]))
    )
    rot = np.array(motion.rotation[:, 1:])
    rot[:, 0] = hips
    parent = np.where(sk.parent[1:] > 0, sk.parent[1:] - 1, -1)
    chans = None if sk.channels is None else list(sk.channels[1:])
    new = JointSkeleton(
        list(sk.names[1:]),
        parent,
        sk.offset[1:],
        sk.rest_rotation[1:],
        sk.limits[1:],
        chans,
        sk.end_site[1:],
    )
    jt = None
    inner = lt[:, 2:] - sk.offset[None, 2:]
    if np.any(np.abs(inner) > 0):
        jt = np.array(lt[:, 1:])
        jt[:, 0] = hips_pos
    out = Motion(
        new,
        frozen(tf.quat_continuous(rot, axis=0)),
        frozen(hips_pos),
        motion.frame_time,
        jt,
        dict(motion.meta),
    )
    return _note(out, "apply_root_motion")


def _note(motion: Motion, what: str) -> Motion:
    meta = dict(motion.meta)
    meta["history"] = [*meta.get("history", []), what]
    return motion.with_(meta=meta)


__all__ = ["ground_path", "in_place", "remove_drift", "extract_root_motion", "apply_root_motion"]
