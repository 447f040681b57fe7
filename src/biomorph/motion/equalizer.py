"""Motion Equalizer: multiresolution filtering of motion signals (Bruderlin & Williams 1995,
the seed's ``calculateBands``).

Filter bank (exactly the seed's)
--------------------------------
Kernel ``w1 = [c b a b c]`` with ``a = 3/8, b = 1/4, c = 1/16``. Instead of down-sampling,
the kernel is expanded "à trous" by inserting zeros (``w2 = [c 0 b 0 a 0 b 0 c]`` …), which
is the same as keeping the kernel and skipping frames::

    G_{k+1}(i) = Σ_{m=-2..2} w1(m) · G_k(i + 2^k m)          G_0 = the signal
    L_k = G_k − G_{k+1}                                        band-pass bands, k = 0 .. K-1
    G_0 = G_K + Σ_k L_k                                        exact reconstruction

``L_0`` is the highest band (noise), ``G_K`` the remaining low-pass ("Hauptbewegung").
The equalizer multiplies each ``L_k`` by ``gains[k]`` and ``G_K`` by ``gains[K]`` — with the
seed's five sliders, ``gains[0..3]`` act on ``L_0..L_3`` and ``gains[4]`` on ``G_4 = L_4 + G_5 + …``
exactly like the MEL code, which multiplies ``(G5 + L5)`` by slider 5. The number of bands a
signal supports follows from its length ``m``: ``fb = floor(log2 m)`` (:func:`n_bands`); asking
for more gains than ``fb + 1`` is an error. The reconstruction is evaluated in the telescoped
form ``g_0 G_0 + Σ_k (g_k − g_{k-1}) G_k`` so unity gains return the input bit for bit.

Boundary handling (the seed zero-pads, which pulls the ends towards 0): ``"edge"`` (default)
holds the first/last value — a frame index outside the clip is clamped to it; ``"reflect"``
mirrors the signal about its end samples (``x[-i] = x[i]``).

Rotations
---------
Each joint's quaternion signal is filtered in a continuous parametrisation, chosen per
joint:

* **mean-log** (the usual case: limbs, spine, a root that does not turn round): when every
  frame lies within 90° of the joint's mean orientation ``M`` (the normalised mean of the
  hemisphere-continuous quaternions), ``x(t) = log(M⁻¹ q(t))`` is a rotation vector far
  from the ±180° cut, so all bands of x get their gains — the last one on the remaining
  low-pass — and ``q' = M · exp(x')``.
* **smooth reference** (a joint turning far from its mean, e.g. the root's heading, or
  spinning): a reference ``R(t)`` (the continuous quaternions box-filtered twice over
  ``2^K + 1`` frames and normalised) and ``x(t) = log(R(t)⁻¹ q(t))`` (small, free of wraps).
  The bands of x get the gains; the reference's own slow motion gets the last gain as
  ``R' = M · exp(g_K · log(M⁻¹ R))`` about its mean ``M`` (the log unwrapped over time;
  skipped when ``g_K = 1``). The result is ``q' = R' · exp(x')``.

Both reproduce the input at unity gains (to 1e-15) and never produce a wrap spike. The
mean-log path also costs one log and one exp per frame and joint instead of two of each
when the last gain is not 1 (the 1-minute 60-joint benchmark clip: 21–25 ms CPU either way,
was 56–70 ms with the reference path for every joint); its log and exp are evaluated as
vectorised series passes over all frames (``_kernels._log_about`` / ``_exp_about``).

Translations (root-aware, issue 15)
-----------------------------------
The root translation is a *trajectory*, not a signal about the world origin: scaling its
low-pass ``G_K`` by the last gain moved the hips toward the origin and through the floor
(the fair1 zombie walk's hips dropped from 33.5 to 26.8 units at gain 0.8). ``root=`` says
what the last gain does to translations (root and any per-joint translations):

* ``"trajectory"`` (default): the band-pass bands ``L_0..L_{K-1}`` get their gains (bounce,
  sway, jitter are filtered), the low-pass path keeps gain 1 — where the character goes and
  how high the hips are stay as captured, for every gain setting;
* ``"start"``: the last gain scales the low-pass path about the first frame (a gain of 0.5
  halves the distance travelled from where the clip starts; the start height is kept);
* ``"world"``: the previous behaviour, about the world origin (only for data whose origin
  means something).

Chosen default: ``"trajectory"``, because the seed's sliders are meant to change the *style*
of a motion (its frequency content), and a path change is a separate, explicit edit
(:mod:`biomorph.motion.rootmotion`, :func:`biomorph.motion.align.reorient`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core.motion import Motion, frozen
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.motion._kernels import equalize_rotations, equalize_rows, lowpass_into, ro

KERNEL = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
DEFAULT_GAINS = (1.0, 1.0, 1.0, 1.0, 1.0)
BOUNDARIES = ("edge", "reflect")


def n_bands(n_frames: int) -> int:
    """Number of band-pass bands a signal of ``n_frames`` supports: ``floor(log2 m)``."""
    return int(np.floor(np.log2(max(int(n_frames), 1))))


def _mode(boundary: str) -> int:
    if boundary not in BOUNDARIES:
        raise ParameterError(f"boundary {boundary!r}; expected one of {', '.join(BOUNDARIES)}")
    return BOUNDARIES.index(boundary)


def _check_gains(gains: ArrayLike, n_frames: int) -> Array:
    g = np.asarray(gains, dtype=float).reshape(-1)
    if g.size < 1 or not np.all(np.isfinite(g)):
        raise ParameterError(f"gains {gains!r}; expected one or more finite numbers")
    fb = n_bands(n_frames)
    if g.size - 1 > fb:
        raise ParameterError(
            f"{g.size} gains need {g.size - 1} band-pass bands but a clip of "
            f"{n_frames} frames supports at most {fb} (floor(log2 frames)); "
            f"give at most {fb + 1} gains"
        )
    return g


def equalize_signal(
    x: ArrayLike, gains: ArrayLike = DEFAULT_GAINS, boundary: str = "edge"
) -> Array:
    """Equalize scalar signals along axis 0: ``x`` is ``(f,)`` or ``(f, c)``."""
    a = np.asarray(x, dtype=float)
    flat = a.reshape(a.shape[0], -1)
    g = _check_gains(gains, flat.shape[0])
    xt = np.ascontiguousarray(flat.T)
    out = np.empty_like(xt)
    equalize_rows(xt, g, _mode(boundary), out)
    return out.T.reshape(a.shape)


def bands(x: ArrayLike, levels: int = 4, boundary: str = "edge") -> Array:
    """The decomposition ``[L_0, …, L_{levels-1}, G_levels]`` of a signal ``(f,)`` as an
    array ``(levels + 1, f)`` (rows sum to the signal) — for plots like the seed's Fig. 7–12."""
    a = np.asarray(x, dtype=float).reshape(-1)
    _check_gains(np.ones(levels + 1), a.size)
    mode = _mode(boundary)
    g = [a.copy()]
    cur = a.copy()
    nxt = np.empty_like(cur)
    step = 1
    for _ in range(levels):
        lowpass_into(cur, nxt, step, mode)
        g.append(nxt.copy())
        cur, nxt = nxt, cur
        step *= 2
    out = np.empty((levels + 1, a.size))
    for k in range(levels):
        out[k] = g[k] - g[k + 1]
    out[levels] = g[levels]
    return out


def _box(x: Array, width: int) -> Array:
    """Centred moving average along axis 0 with edge hold (cumsum, O(f))."""
    r = width // 2
    if r == 0:
        return x
    pad = np.concatenate([np.repeat(x[:1], r, axis=0), x, np.repeat(x[-1:], r, axis=0)])
    c = np.cumsum(pad, axis=0)
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), c])
    return (c[2 * r + 1 :] - c[: -2 * r - 1]) / (2 * r + 1)


def smooth_reference(q: Array, levels: int) -> Array:
    """Smooth reference orientations ``(f, j, 4)`` for the log-map parametrisation: the
    continuous quaternions box-filtered twice over ``2^levels + 1`` frames, normalised.
    Where the average degenerates (a joint spinning a full turn inside the window) the
    reference falls back to the signal itself."""
    width = min(2 ** max(levels, 1) + 1, 2 * (q.shape[0] // 2) + 1)
    r = _box(_box(q, width), width)
    norm = np.linalg.norm(r, axis=-1, keepdims=True)
    bad = norm[..., 0] < 0.3
    r = r / np.where(norm > 1e-12, norm, 1.0)
    if bad.any():
        r[bad] = q[bad]
    return r


def resolve_joints(
    motion: Motion, joints: Sequence[str | int] | str | int | None, hierarchy_below: bool = False
) -> NDArray[np.int64]:
    """Joint indices from names/indices (``None`` = all); ``hierarchy_below`` adds every
    joint below each chosen one (the seed's "Hierarchy Below" checkbox)."""
    sk = motion.skeleton
    if joints is None:
        return np.arange(sk.n_joints)
    if isinstance(joints, (str, int, np.integer)):
        joints = [joints]
    idx = []
    for j in joints:
        if isinstance(j, (int, np.integer)):
            if not 0 <= int(j) < sk.n_joints:
                raise ParameterError(f"joint index {j} outside 0..{sk.n_joints - 1}")
            i = int(j)
        else:
            i = sk.index(j)
        idx.extend(sk.descendants(i).tolist() if hierarchy_below else [i])
    if not idx:
        raise ParameterError("no joints selected; expected at least one joint name")
    return np.unique(np.asarray(idx, dtype=np.int64))


def _equalize_translation(x: Array, g: Array, boundary: str, root: str) -> Array:
    """Translations ``(f, ..., 3)`` filtered under the ``root`` policy (module docstring)."""
    if root == "world" or g[-1] == 1.0:
        return equalize_signal(x, g, boundary)
    if root == "trajectory":
        g1 = np.array(g)
        g1[-1] = 1.0
        return equalize_signal(x, g1, boundary)
    return equalize_signal(x - x[:1], g, boundary) + x[:1]


def equalize(
    motion: Motion,
    gains: ArrayLike = DEFAULT_GAINS,
    joints: Sequence[str | int] | str | int | None = None,
    channels: str = "all",
    hierarchy_below: bool = False,
    boundary: str = "edge",
    root: str = "trajectory",
) -> Motion:
    """The Motion Equalizer: scale each frequency band of the chosen joints' signals.

    Parameters
    ----------
    motion : the input (not modified).
    gains : one gain per band, highest frequency first; the last one scales the remaining
        low-pass. Five by default (the seed's five sliders); unity gains return the input.
    joints : names or indices (``None`` = all joints); ``hierarchy_below`` adds subtrees.
    channels : ``"rotation"``, ``"position"`` (root / joint translations) or ``"all"``.
    boundary : ``"edge"`` (hold end values) or ``"reflect"``.
    root : what the last gain does to translations: ``"trajectory"`` (default: nothing, the
        path is kept), ``"start"`` (scale about the first frame) or ``"world"`` (about the
        origin); see the module docstring.

    Example: ``equalize(mo, [0, 0, 1, 1, 1])`` removes the two highest bands (denoise);
    ``equalize(mo, [1, 1, 1.5, 1.5, 1])`` exaggerates the mid frequencies.
    """
    if channels not in ("all", "rotation", "position"):
        raise ParameterError(f"channels {channels!r}; expected 'all', 'rotation' or 'position'")
    g = _check_gains(gains, motion.n_frames)
    if root not in ("trajectory", "start", "world"):
        raise ParameterError(f"root {root!r}; expected 'trajectory', 'start' or 'world'")
    mode = _mode(boundary)
    levels = g.size - 1
    sel = resolve_joints(motion, joints, hierarchy_below)
    rot = motion.rotation
    pos = motion.root_position
    jt = motion.joint_translation
    if channels in ("all", "rotation"):
        q = rot if sel.size == motion.n_joints else np.ascontiguousarray(rot[:, sel])
        width = min(2 ** max(levels, 1) + 1, 2 * (q.shape[0] // 2) + 1)
        q2 = np.empty(q.shape)
        equalize_rotations(ro(q), ro(g), mode, width // 2, q2)
        if sel.size == motion.n_joints:
            rot = q2
        else:
            rot = np.array(rot)
            rot[:, sel] = q2
    if channels in ("all", "position"):
        if 0 in sel:
            pos = _equalize_translation(pos, g, boundary, root)
        if jt is not None:
            jt = np.array(jt)
            jt[:, sel] = _equalize_translation(jt[:, sel], g, boundary, root)
            jt[:, 0] = pos
    meta = dict(motion.meta)
    meta.setdefault("history", [])
    meta["history"] = [*meta["history"], f"equalize gains={list(map(float, g))}"]
    if rot is not motion.rotation:
        frozen(rot)
    if pos is not motion.root_position:
        frozen(pos)
    return motion.with_(rotation=rot, root_position=pos, joint_translation=jt, meta=meta)


__all__ = [
    "equalize",
    "equalize_signal",
    "bands",
    "n_bands",
    "smooth_reference",
    "resolve_joints",
    "KERNEL",
    "DEFAULT_GAINS",
]
