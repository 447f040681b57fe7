"""Speed: retime a motion with a speed curve (seed §5.6.5 / Speed.mel); resample with feet kept.

The speed curve ``s(t) > 0`` over the *original* frames says how fast the original is played
(1 = unchanged, 2 = twice as fast, 0.5 = half speed): the next key is placed after ``1/s``
frames. Integrating gives the output time of every original frame,
``τ(i) = Σ_{k<i} ½ (1/s(k) + 1/s(k+1))`` (trapezoid rule), and the output has one frame at
every integer ``τ`` up to ``τ(f-1)``, sampled from the original at ``t = τ⁻¹(k)`` with slerp
(translations linearly). Constant 1 is the identity; constant 2 halves the frame count.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from biomorph.core.motion import Motion
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.motion.keys import Curve, Keys, curve_from_keys

if TYPE_CHECKING:
    from biomorph.motion.contact import ContactOptions


def speed_values(motion: Motion, speed: Keys | float | Curve) -> Array:
    """The speed curve evaluated at every original frame (monotone spline through keys, so
    positive keys never give a non-positive speed in between). Raises on speed <= 0."""
    s = np.asarray(
        curve_from_keys(speed, kind="monotone")(np.arange(motion.n_frames, dtype=float)),
        dtype=float,
    ).reshape(-1)
    if s.shape != (motion.n_frames,):
        raise ParameterError("the speed curve must give one number per frame")
    bad = ~np.isfinite(s) | (s <= 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ParameterError(
            f"speed {s[i]:g} at frame {i}; expected a speed > 0 everywhere "
            "(1 = original, 2 = twice as fast)"
        )
    return s


def time_warp(speed: Array) -> tuple[Array, Array]:
    """``(tau, t_src)``: output time of every original frame, and for every output frame the
    original (fractional) frame to sample."""
    inv = 1.0 / speed
    tau = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]))])
    n_out = int(np.floor(tau[-1] + 1e-9)) + 1
    k = np.arange(n_out, dtype=float)
    t_src = np.interp(k, tau, np.arange(speed.size, dtype=float))
    return tau, t_src


def change_speed(motion: Motion, speed: Keys | float | Curve = 1.0) -> Motion:
    """Retime ``motion`` by a speed curve (constant, keys ``{frame: speed}`` or a callable of
    original frames); output at the original frame rate.

    Example: ``change_speed(mo, {0: 1, 120: 2, 240: 1})`` speeds up towards frame 120."""
    s = speed_values(motion, speed)
    _, t_src = time_warp(s)
    out = motion.sample(t_src)
    meta = dict(out.meta)
    meta["speed"] = {"frames_in": motion.n_frames, "frames_out": out.n_frames}
    return out.with_(meta=meta)


def contacts_at(on: NDArray[np.bool_], t: Array) -> NDArray[np.bool_]:
    """A contact track ``on`` (one bool per source frame) at the fractional source frames
    ``t``: planted where the source is planted on both frames around ``t`` (a frame
    interpolated between a planted and a lifted one is already moving). A contact with no
    output frame strictly inside it (shorter than one output frame) keeps the frame nearest
    to its middle, so no contact of the source is lost."""
    on = np.asarray(on, dtype=bool)
    t = np.clip(np.asarray(t, dtype=float), 0.0, on.size - 1)
    lo = np.floor(t + 1e-9).astype(np.int64)
    hi = np.minimum(np.ceil(t - 1e-9).astype(np.int64), on.size - 1)
    out = on[lo] & on[np.maximum(hi, lo)]
    d = np.diff(np.concatenate([[0], on.astype(np.int8), [0]]))
    for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        inside = (t >= s - 1e-9) & (t <= e - 1 + 1e-9)
        if not inside.any():
            out[int(np.argmin(np.abs(t - 0.5 * (s + e - 1))))] = True
    return out


def resample(
    motion: Motion,
    fps: float,
    lock_feet: bool = True,
    options: ContactOptions | None = None,
) -> Motion:
    """``motion`` at another frame rate (:meth:`Motion.resample`: slerp, linear
    translations, the duration kept) with its planted feet kept planted: contacts are
    detected on the *source* (at its own rate, where the detection's speeds are measured on
    the captured frames), carried to the new frames (:func:`contacts_at`) and locked on the
    resampled clip (:func:`biomorph.motion.contact.lock_feet`, no foot below the source's
    lowest, less :data:`~biomorph.motion.contact.FLOOR_TOLERANCE`). Interpolation alone
    keeps a sliding foot sliding and puts the frames between two captured ones on the chord
    of a turning foot; ``lock_feet=False`` (CLI ``--no-lock-feet``) returns the plain
    resample."""
    out = motion.resample(fps)
    if not lock_feet or (options is not None and not options.enabled) or motion.n_frames < 2:
        return out
    from biomorph.motion.contact import detect_contacts, inputs_floor
    from biomorph.motion.contact import lock_feet as lock

    on = detect_contacts(motion, options)
    if not on:
        return out
    t = np.arange(out.n_frames) * (motion.fps / out.fps)  # as Motion.resample samples
    mapped = {j: contacts_at(v, t) for j, v in on.items()}
    return lock(out, None, options, floor=inputs_floor(out, [motion]), contacts=mapped)


__all__ = ["change_speed", "time_warp", "speed_values", "resample", "contacts_at"]
