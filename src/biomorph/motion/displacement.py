"""Edit: displacement mapping, re-orient / re-position, additive layers ("overAnimate").

Displacement mapping (seed §5.6.3): the animator sets offsets at a few key frames; an
interpolating cubic spline through the offsets — with zero value *and zero slope* at the
two ends of its support, so the edit fades in and out smoothly — is added to the motion.
The result passes exactly through the keys and keeps all high-frequency detail of the
capture (the offset curve is smooth, the capture is not touched elsewhere).

* Rotation keys are rotation vectors (axis × angle, radians) in the joint's *own* frame:
  ``q'(t) = q(t) · exp(d(t))``. :func:`offsets_to_targets` turns target orientations
  into such offsets.
* Position keys are vectors added to the root trajectory (or to a translated joint).

Support: ``[first key − fade, last key + fade]`` (frames, clamped to the clip; where it
reaches the clip's end the offset is held instead of faded), or given explicitly.
Tangents (``tangent=``, issue 15): ``"auto"`` (default) — auto-clamped cubic Hermite keys as
in Blender's and Maya's graph editors: the slope at a key is the harmonic mean of the two
neighbouring secants (Fritsch–Carlson) and zero where the curve turns, so the curve never
leaves the range of its two neighbouring keys (a lone 30° key reaches exactly 30°, never
34.6°, and never swings below 0); ``"spline"`` — the former ``scipy.interpolate.CubicSpline``
with clamped ends (C2, overshoots); ``"linear"``; ``"flat"`` (zero slope at every key, an
ease in/out between keys).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicHermiteSpline, CubicSpline

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, frozen
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.motion.align import reorient, transform_root
from biomorph.motion.keys import Keys, key_arrays

KINDS = ("rotation", "position")


def _support(
    frames: Array,
    n_frames: int,
    fade: float | None,
    support: tuple[float, float] | None,
    fps: float,
) -> tuple[float, float]:
    if frames.min() < 0 or frames.max() > n_frames - 1:
        bad = frames[(frames < 0) | (frames > n_frames - 1)][0]
        raise ParameterError(
            f"key at frame {bad:g} is outside the clip; expected frames 0..{n_frames - 1}"
        )
    if support is not None:
        s0, s1 = float(support[0]), float(support[1])
        if not (s0 <= frames.min() and frames.max() <= s1) or s0 == s1:
            raise ParameterError(
                f"support {s0:g}:{s1:g} must contain every key ({frames.min():g}..{frames.max():g})"
            )
        return s0, s1
    if fade is None:
        fade = max(2.0, round(0.25 * fps))
    if fade < 0:
        raise ParameterError(f"fade {fade} frames is negative; expected >= 0")
    return float(frames.min() - fade), float(frames.max() + fade)


TANGENTS = ("auto", "spline", "linear", "flat")


def auto_clamped_slopes(x: Array, y: Array) -> Array:
    """Key slopes ``(k, d)``: harmonic mean of neighbouring secants where they agree in sign,
    0 at turning points and at both ends (no overshoot beyond neighbouring keys)."""
    sec = np.diff(y, axis=0) / np.diff(x)[:, None]
    m = np.zeros_like(y)
    a, b = sec[:-1], sec[1:]
    same = a * b > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        hm = np.where(same, 2 * a * b / (a + b), 0.0)
    m[1:-1] = hm
    return m


def _interp(kx: Array, ky: Array, t: Array, tangent: str) -> Array:
    if tangent == "linear":
        return np.stack([np.interp(t, kx, ky[:, c]) for c in range(ky.shape[1])], axis=1)
    if tangent == "spline":
        return CubicSpline(kx, ky, bc_type="clamped", axis=0)(t)
    slopes = auto_clamped_slopes(kx, ky) if tangent == "auto" else np.zeros_like(ky)
    return CubicHermiteSpline(kx, ky, slopes, axis=0)(t)


def displacement_curve(
    keys: Keys,
    n_frames: int,
    fade: float | None = None,
    support: tuple[float, float] | None = None,
    fps: float = 30.0,
    tangent: str = "auto",
) -> Array:
    """Offset per frame ``float[n_frames, d]``: a clamped cubic spline through the keys and
    through 0 (with zero slope) at both support ends; exactly 0 outside the support.

    If the support reaches before frame 0 (after the last frame) there is no zero knot on
    that side: the offset is held flat (zero slope) towards the clip end instead."""
    if tangent not in TANGENTS:
        raise ParameterError(f"tangent {tangent!r}; expected one of {', '.join(TANGENTS)}")
    x, y = key_arrays(keys)
    s0, s1 = _support(x, n_frames, fade, support, fps)
    kx, ky = list(x), list(y)
    if s0 < x[0] and s0 >= 0:
        kx.insert(0, s0)
        ky.insert(0, np.zeros(y.shape[1]))
    if s1 > x[-1] and s1 <= n_frames - 1:
        kx.append(s1)
        ky.append(np.zeros(y.shape[1]))
    out = np.zeros((n_frames, y.shape[1]))
    t = np.arange(n_frames, dtype=float)
    if len(kx) == 1:
        inside = (t >= max(s0, 0)) & (t <= min(s1, n_frames - 1))
        out[inside] = ky[0]
        return out
    lo, hi = kx[0], kx[-1]
    inside = (t >= lo) & (t <= hi)
    out[inside] = _interp(np.array(kx), np.array(ky), t[inside], tangent)
    # beyond a key that is not followed by a zero knot (support past the clip end) hold it
    out[t < lo] = ky[0] if lo == x[0] and s0 < 0 else 0.0
    out[t > hi] = ky[-1] if hi == x[-1] and s1 > n_frames - 1 else 0.0
    # keys exactly (the spline interpolates them up to rounding)
    out[x.astype(np.int64)[x == np.round(x)]] = y[x == np.round(x)]
    return out


def _joint(motion: Motion, joint: str | int) -> int:
    if isinstance(joint, (int, np.integer)):
        if not 0 <= int(joint) < motion.n_joints:
            raise ParameterError(f"joint index {joint} outside 0..{motion.n_joints - 1}")
        return int(joint)
    return motion.skeleton.index(joint)


def apply_offsets(
    motion: Motion, joint: str | int, offset: Array, kind: str = "rotation"
) -> Motion:
    """Add a per-frame offset ``(f, 3)`` to one joint (see module docstring)."""
    if kind not in KINDS:
        raise ParameterError(f"kind {kind!r}; expected 'rotation' or 'position'")
    j = _joint(motion, joint)
    rows = np.flatnonzero(np.any(offset != 0.0, axis=1))
    if kind == "rotation":
        rot = np.array(motion.rotation)
        if rows.size:
            rot[rows, j] = tf.quat_multiply(rot[rows, j], tf.quat_from_rotvec(offset[rows]))
            rot[:, j] = tf.quat_continuous(rot[:, j], axis=0)
        return motion.with_(rotation=frozen(rot))
    if j == 0:
        pos = motion.root_position + offset
        jt = None
        if motion.joint_translation is not None:
            jt = np.array(motion.joint_translation)
            jt[:, 0] = pos
        return motion.with_(root_position=pos, joint_translation=jt)
    jt = motion.local_translations()
    jt[:, j] += offset
    return motion.with_(joint_translation=jt)


def displace(
    motion: Motion,
    joint: str | int,
    keys: Keys,
    kind: str = "rotation",
    fade: float | None = None,
    support: tuple[float, float] | None = None,
    tangent: str = "auto",
) -> Motion:
    """Displacement-map one joint: ``keys`` ``{frame: offset (3,)}`` (rotation vectors in
    radians, or translations), faded in/out over ``fade`` frames (default 0.25 s).

    Example: ``displace(mo, "RightArm", {120: [0, 0, np.radians(30)]}, fade=20)`` raises the
    arm by 30° at frame 120, blending smoothly in over frames 100–120 and out over 120–140.
    """
    x, y = key_arrays(keys)
    if y.shape[1] != 3:
        raise ParameterError(f"{kind} keys need 3 values each, got {y.shape[1]}")
    off = displacement_curve(
        list(zip(x, y, strict=True)), motion.n_frames, fade, support, motion.fps, tangent
    )
    return apply_offsets(motion, joint, off, kind)


def offsets_to_targets(
    motion: Motion, joint: str | int, targets: Keys
) -> list[tuple[float, Array]]:
    """Rotation-vector offsets that bring ``joint`` to target local orientations
    (quaternions ``(4,)``) at integer key frames: ``d = log(q(k)⁻¹ · target)``."""
    j = _joint(motion, joint)
    x, y = key_arrays(targets)
    if y.shape[1] != 4:
        raise ParameterError("targets must be quaternions (x, y, z, w)")
    fr = x.astype(np.int64)
    if np.any(fr != x) or fr.min() < 0 or fr.max() >= motion.n_frames:
        raise ParameterError(f"target frames must be integers in 0..{motion.n_frames - 1}")
    d = tf.quat_to_rotvec(
        tf.quat_multiply(tf.quat_conjugate(motion.rotation[fr, j]), tf.quat_normalize(y))
    )
    return list(zip(x, d, strict=True))


# --------------------------------------------------------------------------- layers
@dataclass(frozen=True)
class Layer:
    """One additive layer ("overAnimate"): offset keys on one joint, weighted.

    ``keys`` as for :func:`displace`; ``weight`` scales the layer (0 mutes it)."""

    name: str
    joint: str
    keys: tuple[tuple[float, tuple[float, ...]], ...]
    kind: str = "rotation"
    weight: float = 1.0
    fade: float | None = None

    @staticmethod
    def make(
        name: str,
        joint: str,
        keys: Keys,
        kind: str = "rotation",
        weight: float = 1.0,
        fade: float | None = None,
    ) -> Layer:
        x, y = key_arrays(keys)
        return Layer(
            name,
            joint,
            tuple((float(f), tuple(map(float, v))) for f, v in zip(x, y, strict=True)),
            kind,
            weight,
            fade,
        )


def apply_layers(motion: Motion, layers: Sequence[Layer]) -> Motion:
    """Evaluate every layer and add the weighted sum of offsets per joint and kind (rotation
    offsets are summed as rotation vectors, then applied once)."""
    names = [layer.name for layer in layers]
    if len(set(names)) != len(names):
        raise ParameterError(f"layer names repeat: {names}; expected unique names")
    total: dict[tuple[int, str], Array] = {}
    for layer in layers:
        if layer.kind not in KINDS:
            raise ParameterError(
                f"layer {layer.name!r}: kind {layer.kind!r}; expected 'rotation' or 'position'"
            )
        j = _joint(motion, layer.joint)
        off = displacement_curve(list(layer.keys), motion.n_frames, layer.fade, None, motion.fps)
        key = (j, layer.kind)
        total[key] = total.get(key, 0.0) + float(layer.weight) * off
    out = motion
    for (j, kind), off in total.items():
        out = apply_offsets(out, j, off, kind)
    return out


def remove_layer(layers: Sequence[Layer], name: str) -> tuple[Layer, ...]:
    """The layer stack without layer ``name`` (error if absent)."""
    if name not in [layer.name for layer in layers]:
        raise ParameterError(
            f"no layer named {name!r}; layers are "
            f"{', '.join(layer.name for layer in layers) or '(none)'}"
        )
    return tuple(layer for layer in layers if layer.name != name)


__all__ = [
    "displace",
    "displacement_curve",
    "apply_offsets",
    "offsets_to_targets",
    "Layer",
    "apply_layers",
    "remove_layer",
    "reorient",
    "transform_root",
]
