"""Speed: retime a motion with a speed curve (seed §5.6.5 / Speed.mel).

The speed curve ``s(t) > 0`` over the *original* frames says how fast the original is played
(1 = unchanged, 2 = twice as fast, 0.5 = half speed): the next key is placed after ``1/s``
frames. Integrating gives the output time of every original frame,
``τ(i) = Σ_{k<i} ½ (1/s(k) + 1/s(k+1))`` (trapezoid rule), and the output has one frame at
every integer ``τ`` up to ``τ(f-1)``, sampled from the original at ``t = τ⁻¹(k)`` with slerp
(translations linearly). Constant 1 is the identity; constant 2 halves the frame count.
"""

from __future__ import annotations

import numpy as np

from biomorph.core.motion import Motion
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.motion.keys import Curve, Keys, curve_from_keys


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


__all__ = ["change_speed", "time_warp", "speed_values"]
