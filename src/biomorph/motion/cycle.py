"""Cycle: turn a frame range into a seamless loop (seed §7.5 / Cycle.mel), with offset.

Given the range ``S = frames[start:stop]`` (``N`` frames) and a transition of ``T`` frames,
the loop has period ``P = N − T``. Its first ``T`` frames cross-fade from the frames that
*follow* the loop end (``S[P + i]``) into the loop start (``S[i]``) with the C1 ease
``w(i) = smoothstep((i + 1) / (T + 1))``; frames ``T .. P−1`` are ``S`` unchanged. The seam
from the last loop frame ``S[P−1]`` to the next cycle's first frame (≈ ``S[P]``) is therefore
as continuous as the capture itself, in pose and in velocity — exactly the seed's "two
identical animations shifted against each other and blended where they overlap".

Cycle with offset: the root's horizontal position and heading at ``S[P]`` relative to
``S[0]`` define a rigid offset ``D`` (vertical rotation + horizontal translation). The tail
frames are brought into the loop's frame by ``D⁻¹`` before blending, and cycle ``c`` is
placed by ``D^c``, so the character keeps travelling (``offset=False`` loops in place; the
vertical always loops).

:func:`best_loop` searches start/stop (beyond the seed) minimising the pose distance plus
velocity distance between the loop's first frame and the frame after its end.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, check_range, concatenate
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.motion.align import (
    _forward_axis,
    _up_index,
    heading_at,
    pose_features,
    transform_root,
)
from biomorph.motion.keys import smoothstep


def _offset_transform(seg: Motion, p: int, up: str) -> tuple[Array, Array, Array]:
    """Quaternion ``R`` about the vertical, pivot and translation of ``D``: x -> R(x - a) + b
    with a, b the horizontal root positions at frames 0 and ``p``."""
    ui = _up_index(up)
    fwd = _forward_axis(seg, ui)
    dh = heading_at(seg, p, up, fwd) - heading_at(seg, 0, up, fwd)
    axis = np.zeros(3)
    axis[ui] = 1.0
    q = tf.quat_from_axis_angle(axis, float(dh))
    a = np.array(seg.root_position[0])
    b = np.array(seg.root_position[p])
    a[ui] = 0.0
    b[ui] = 0.0
    return q, a, b


CYCLE_MODES = ("world", "in-place", "root-motion")


def make_cycle(
    motion: Motion,
    start: int,
    stop: int,
    transition: int,
    cycles: int = 1,
    offset: bool = True,
    up: str = "y",
    mode: str | None = None,
    lock: Callable[[Motion], Motion] | None = None,
) -> Motion:
    """Loop frames ``start:stop`` with a ``transition``-frame cross-fade; ``cycles`` copies.

    ``lock`` (e.g. :func:`biomorph.motion.contact.lock_feet`) is applied to the world-space
    cycle *before* an in-place or root-motion conversion: planted feet are held where the
    travelling body plants them, and the in-place loop's feet then slide back at the removed
    travel speed as on a treadmill (locking the in-place loop itself held them against the
    drift: stretched, clamped legs, the Xia run's skate 1.40 → 2.32 and feet 3-7 % of the hip
    height below the floor).

    ``mode`` (default ``"world"``; ``offset=False`` means ``"in-place"``):

    * ``"world"``: cycle with offset, each cycle continues where the last one ended;
    * ``"in-place"``: the per-cycle travel (translation and turn) is removed as a steady
      drift (:func:`biomorph.motion.rootmotion.remove_drift`), so the loop stays put, keeps
      its sway and bounce and never jumps at a seam;
    * ``"root-motion"``: the world-space cycle with its path on a ground-level root joint
      (:func:`biomorph.motion.rootmotion.extract_root_motion`).

    Returns ``cycles × (stop − start − transition)`` frames; ``meta["cycle"]`` holds the
    per-cycle root offset (heading change in rad, translation)."""
    mode = mode or ("world" if offset else "in-place")
    if mode not in CYCLE_MODES:
        raise ParameterError(f"cycle mode {mode!r}; expected one of {', '.join(CYCLE_MODES)}")
    check_range(motion, start, stop, "cycle range")
    n = stop - start
    if n < 2:
        raise ParameterError(f"cycle range {start}:{stop} holds {n} frame; expected at least 2")
    offset = True
    if not isinstance(transition, (int, np.integer)) or transition < 1 or transition >= n:
        raise ParameterError(
            f"transition of {transition} frames does not fit the cycle range "
            f"of {n} frames; expected 1 <= transition < {n}"
        )
    if int(cycles) < 1:
        raise ParameterError(f"cycles {cycles}; expected >= 1")
    seg = motion[start:stop]
    p = n - transition
    q, a, b = (
        _offset_transform(seg, p, up) if offset else (tf.quat_identity(), np.zeros(3), np.zeros(3))
    )
    # tail S[P:N] expressed in the loop's frame: D^-1 x = R^-1 (x - b) + a
    tail = seg[p:]
    if offset:
        tail = transform_root(tail, tf.quat_conjugate(q), a - b, pivot=b)
    else:
        ui = _up_index(up)
        shift = np.array(seg.root_position[0] - seg.root_position[p])
        shift[ui] = 0.0
        tail = transform_root(tail, tf.quat_identity(), shift)
    head = seg[:transition]
    w = smoothstep((np.arange(transition) + 1.0) / (transition + 1.0))
    rot = tf.quat_slerp(
        tail.rotation, head.rotation, np.broadcast_to(w[:, None], head.rotation.shape[:-1])
    )
    pos = (1 - w[:, None]) * tail.root_position + w[:, None] * head.root_position
    loop_rot = np.concatenate([rot, seg.rotation[transition:p]])
    loop_pos = np.concatenate([pos, seg.root_position[transition:p]])
    jt = None
    if seg.joint_translation is not None:
        tj = tail.local_translations()
        hj = head.local_translations()
        bl = (1 - w[:, None, None]) * tj + w[:, None, None] * hj
        jt = np.concatenate([bl, seg.joint_translation[transition:p]])
        jt[:, 0] = loop_pos
    loop = seg.with_(
        rotation=tf.quat_continuous(loop_rot, axis=0), root_position=loop_pos, joint_translation=jt
    )
    parts = [loop]
    for _ in range(1, int(cycles)):
        parts.append(transform_root(parts[-1], q, b - a, pivot=a) if offset else loop)
    out = concatenate(parts) if len(parts) > 1 else loop
    meta = dict(out.meta)
    ang = 2.0 * np.arctan2(np.linalg.norm(q[:3]), q[3]) * (1 if q[_up_index(up)] >= 0 else -1)
    meta["cycle"] = {
        "start": start,
        "stop": stop,
        "transition": int(transition),
        "period": p,
        "cycles": int(cycles),
        "heading_offset": float(ang),
        "translation_offset": (b - a).tolist(),
        "mode": mode,
    }
    out = out.with_(meta=meta)
    if lock is not None:
        out = lock(out)
        out = out.with_(meta={**out.meta, "cycle": meta["cycle"]})
    if mode == "in-place":
        from biomorph.motion.rootmotion import remove_drift

        # the offset D maps S[0] to S[P]: x -> R(x - a) + b, a travel of b - a turned by R
        drift = tf.quat_rotate(tf.quat_conjugate(q), b - a)
        out = remove_drift(out, drift, ang, p, up)
        out.meta["cycle"]["drift"] = {"translation": drift.tolist(), "yaw": float(ang)}
    elif mode == "root-motion":
        from biomorph.motion.rootmotion import extract_root_motion

        out = extract_root_motion(out, up)
    return out


MIN_ENERGY = 0.5
"""A loop found by :func:`best_loop` moves at least this fraction of the clip's mean pose
speed (unless no range of the requested length does)."""


def loop_cost(motion: Motion, velocity_weight: float = 1.0) -> tuple[Array, Array]:
    """Per-frame pose features and velocities used by :func:`best_loop`."""
    f = pose_features(motion)
    v = np.gradient(f, axis=0) * velocity_weight * 4.0
    return f, v


def best_loop(
    motion: Motion,
    min_length: int = 30,
    max_length: int | None = None,
    transition: int = 0,
    candidates: int = 400,
    velocity_weight: float = 1.0,
) -> tuple[int, int, float]:
    """``(start, stop, cost)`` for ``make_cycle(motion, start, stop, transition)``: the loop
    period ``P = stop − start − transition`` is chosen minimising
    ``|pose(start) − pose(start + P)|² + |vel(start) − vel(start + P)|²`` over
    ``min_length <= P <= max_length`` (non-root joint
    quaternions; root excluded so travel does not count) among the ranges whose mean pose
    speed is at least :data:`MIN_ENERGY` × the clip's (a still stretch is not a loop).
    Searched on a grid of at most ``candidates`` frames, then refined ±grid step frame by
    frame."""
    if transition < 0:
        raise ParameterError(f"transition {transition}; expected >= 0")
    f_all = motion.n_frames - int(transition)
    max_length = f_all - 1 if max_length is None else int(max_length)
    if min_length < 2 or min_length > max_length or min_length > f_all - 1:
        raise ParameterError(
            f"loop length {min_length}..{max_length} frames does not fit a clip of {f_all} frames"
        )
    feat, vel = loop_cost(motion[:f_all] if f_all > 0 else motion, velocity_weight)
    x = np.concatenate([feat, vel], axis=1)
    # motion energy: a loop must move at least MIN_ENERGY × the clip's mean pose speed (a
    # still stretch of a long take loops at cost ~0 and was chosen: skate 0, nothing moves)
    speed = np.linalg.norm(vel, axis=1)
    csum = np.concatenate([[0.0], np.cumsum(speed)])
    need = MIN_ENERGY * float(speed.mean()) if speed.size else 0.0

    def moving(a: Array, b: Array) -> Array:
        span = np.maximum(b - a, 1)
        return (csum[np.clip(b, 0, speed.size)] - csum[np.clip(a, 0, speed.size)]) / span >= need

    step = max(1, int(np.ceil(f_all / candidates)))
    idx = np.arange(0, f_all, step)
    sq = np.einsum("ij,ij->i", x[idx], x[idx])
    d = sq[:, None] + sq[None, :] - 2 * x[idx] @ x[idx].T
    length = idx[None, :] - idx[:, None]
    fits = (length >= min_length) & (length <= max_length)
    live = fits & moving(idx[:, None], idx[None, :])
    d = np.where(live if live.any() else fits, d, np.inf)
    i, j = np.unravel_index(np.argmin(d), d.shape)
    if not np.isfinite(d[i, j]):
        raise ParameterError("no loop range of the requested length fits the clip")
    s0, e0 = int(idx[i]), int(idx[j])
    best = (s0, e0, float(d[i, j]))
    ss = np.arange(max(0, s0 - step), min(f_all, s0 + step + 1))
    es = np.arange(max(0, e0 - step), min(f_all, e0 + step + 1))
    dd = np.sum((x[ss][:, None] - x[es][None]) ** 2, axis=-1)
    ll = es[None, :] - ss[:, None]
    ok = (ll >= min_length) & (ll <= max_length)
    if live.any():
        ok &= moving(ss[:, None], es[None, :])
    dd = np.where(ok, dd, np.inf)
    a, b = np.unravel_index(np.argmin(dd), dd.shape)
    if dd[a, b] < best[2]:
        best = (int(ss[a]), int(es[b]), float(dd[a, b]))
    # pose(start) ~ pose(start + P): the frames the transition cross-fades
    return best[0], best[1] + int(transition), max(best[2], 0.0)


__all__ = ["make_cycle", "best_loop", "loop_cost"]
