"""Blend: mix two or more clips on one skeleton (seed §5.6.4, extended to N clips).

Timeline (the seed's timing editor): clip ``i`` starts at output frame ``offsets[i]`` and is
stretched by ``scales[i]`` (2 = twice as long), so its local frame at output frame ``t`` is
``(t − offsets[i]) / scales[i]`` (sampled with slerp). Default offsets chain the clips with
``transition`` frames of overlap.

Weights: between consecutive clips the blend curve ``b(t)`` rises from 0 to 1 over the
transition (default: the C1 ease ``3u² − 2u³`` over the overlap, or a user curve — keys
plus spline, or a callable of the output frame); clip ``i`` gets ``(1 − b)`` towards the
next clip and ``b`` from the previous one, 0 where it does not exist; weights are
normalised per frame. Rotations: two clips by slerp ``slerp(qA, qB, b)`` (exactly ``qA`` at
b = 0 and ``qB`` at b = 1); more clips by the normalised weighted quaternion average (signs
aligned to the heaviest clip). Translations: weighted sums.

Root alignment (``align_root``): each clip's root is rotated about the vertical and moved so
that, at the start of its transition, its position (horizontally) and heading equal those
of the previous clip — the seed's "translation unchanged over the transition".

Automatic timing (``align``): ``"peaks"`` puts the last local maximum of a chosen joint
channel in A onto the first in B (the seed's Autoadjust, :func:`align.peak_offset`);
``"dtw"`` matches A's last and B's first ``window`` frames by dynamic time warping on pose
features and uses the median lag along the warping path.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from biomorph.core.motion import Motion, frozen, same_skeleton, sample_arrays, sample_linear
from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError
from biomorph.motion._kernels import blend_average_sampled, blend_slerp, ro, ro_int
from biomorph.motion.align import (
    align_root_to,
    dtw_path,
    heading_at,
    peak_offset,
    pose_distance,
    pose_features,
)
from biomorph.motion.keys import Curve, Keys, curve_from_keys, smoothstep


@dataclass(frozen=True)
class BlendPlan:
    """Where every clip sits on the output timeline and its weight per output frame."""

    offsets: Array  # (N,) output frame of each clip's first frame
    scales: Array  # (N,)
    weights: Array  # (f, N) normalised
    n_frames: int


def _clip_span(m: Motion, off: float, scale: float) -> tuple[float, float]:
    return off, off + (m.n_frames - 1) * scale


def auto_offset(
    a: Motion,
    b: Motion,
    method: str = "peaks",
    joint: str | None = None,
    channel: str = "Xrotation",
    window: int = 60,
    a_offset: float = 0.0,
    a_scale: float = 1.0,
    b_scale: float = 1.0,
) -> float:
    """Output-frame offset of ``b`` so it continues ``a`` (placed at ``a_offset``).

    ``"peaks"``: last local maximum of ``joint.channel`` in A onto the first one in B.
    ``"dtw"``: dynamic time warping of A's last and B's first ``window`` frames (pose of
    every non-root joint); the offset is the median lag along the warping path."""
    if method == "peaks":
        if joint is None:
            raise ParameterError(
                "peak alignment needs a joint (e.g. the thigh: --align-joint LeftUpLeg)"
            )
        pa, pb = peak_offset(a, b, joint, channel)
        return a_offset + pa * a_scale - pb * b_scale
    if method == "dtw":
        wa = min(window, a.n_frames)
        wb = min(window, b.n_frames)
        fa = pose_features(a[a.n_frames - wa :])  # only the matched windows
        fb = pose_features(b[:wb])
        path, _ = dtw_path(pose_distance(fa, fb))
        lag = np.median((path[:, 0] + a.n_frames - wa) * a_scale - path[:, 1] * b_scale)
        return a_offset + float(lag)
    raise ParameterError(f"align method {method!r}; expected 'peaks' or 'dtw'")


def plan(
    clips: Sequence[Motion],
    offsets: ArrayLike | None = None,
    scales: ArrayLike | None = None,
    transition: float = 30,
    curve: Keys | float | Curve | None = None,
) -> BlendPlan:
    """Timeline and normalised weights ``(f, N)`` for :func:`blend` (see module docstring)."""
    n = len(clips)
    if n < 1:
        raise InputError("nothing to blend; expected at least one clip")
    sc = np.ones(n) if scales is None else np.asarray(scales, dtype=float).reshape(-1)
    if sc.shape != (n,) or np.any(~np.isfinite(sc)) or np.any(sc <= 0):
        raise ParameterError(f"scales {scales!r}; expected {n} positive numbers")
    if transition < 0 or not np.isfinite(transition):
        raise ParameterError(f"transition {transition} frames; expected >= 0")
    if offsets is None:
        off = np.zeros(n)
        for i in range(1, n):
            span_prev = (clips[i - 1].n_frames - 1) * sc[i - 1]
            span_this = (clips[i].n_frames - 1) * sc[i]
            if transition > min(span_prev, span_this):
                raise ParameterError(
                    f"transition of {transition:g} frames is longer than clip "
                    f"{i - 1 if span_prev < span_this else i} "
                    f"({min(span_prev, span_this):g} frames); expected a "
                    "shorter transition"
                )
            off[i] = off[i - 1] + span_prev - transition
    else:
        off = np.asarray(offsets, dtype=float).reshape(-1)
        if off.shape != (n,) or not np.all(np.isfinite(off)):
            raise ParameterError(f"offsets {offsets!r}; expected {n} numbers (frames)")
    off = off - off.min()
    ends = np.array([_clip_span(c, o, s)[1] for c, o, s in zip(clips, off, sc, strict=True)])
    f = int(np.floor(ends.max() + 1e-9)) + 1
    t = np.arange(f, dtype=float)
    eps = 1e-9
    exists = np.stack(
        [(t >= o - eps) & (t <= e + eps) for o, e in zip(off, ends, strict=True)], axis=1
    )
    act = exists.astype(float)
    user = None if curve is None else curve_from_keys(curve, kind="monotone")
    for i in range(1, n):
        s = max(off[i], off[i - 1])
        e = min(ends[i - 1], ends[i])
        if user is not None and n == 2:
            b = np.clip(np.asarray(user(t), dtype=float), 0.0, 1.0)
        elif e > s:
            mid = 0.5 * (s + e)
            half = 0.5 * min(e - s, transition if transition > 0 else e - s)
            lo, hi = mid - half, mid + half
            b = smoothstep((t - lo) / (hi - lo)) if hi > lo else (t >= mid).astype(float)
        else:
            b = (t >= off[i]).astype(float)
        both = exists[:, i - 1] & exists[:, i]
        act[:, i - 1] *= np.where(both, 1.0 - b, 1.0)
        act[:, i] *= np.where(both, b, 1.0)
    total = act.sum(axis=1)
    if np.any(total <= 0):
        gap = int(np.flatnonzero(total <= 0)[0])
        raise ParameterError(
            f"no clip covers output frame {gap} (clips leave a gap or the "
            "blend curve zeroes every clip); overlap the clips"
        )
    return BlendPlan(off, sc, act / total[:, None], f)


def blend(
    clips: Sequence[Motion],
    offsets: ArrayLike | None = None,
    scales: ArrayLike | None = None,
    transition: float = 30,
    curve: Keys | float | Curve | None = None,
    align_root: bool = True,
    align: str | None = None,
    align_joint: str | None = None,
    align_channel: str = "Xrotation",
    up: str = "y",
) -> Motion:
    """Blend clips into one motion (see the module docstring).

    Parameters
    ----------
    clips : two or more motions with the same joint names (the first one's skeleton and frame
        rate are used; clips at other rates are resampled with slerp first).
    offsets, scales : output frame of each clip's start; time stretch per clip.
    transition : frames of each cross-fade (default chaining overlap, and the default ease).
    curve : for two clips, the weight of B per output frame: keys ``{frame: weight}`` (monotone
        spline), a number (constant), or a callable of output frames.
    align_root : move/turn each clip so its root continues the previous clip's.
    align : ``None``, ``"peaks"`` or ``"dtw"`` — compute offsets automatically.

    Example: ``blend([walk, run], transition=40, align="peaks", align_joint="LeftUpLeg")``.
    """
    clips = list(clips)
    if len(clips) < 2 and curve is None:
        if len(clips) == 1:
            return clips[0]
    for c in clips[1:]:
        same_skeleton(clips[0].skeleton, c.skeleton, "clips to blend")
    # one timeline: clips at another frame rate are resampled to the first clip's rate
    clips = [
        c
        if abs(c.frame_time - clips[0].frame_time) <= 1e-9 * clips[0].frame_time
        else c.resample(clips[0].fps)
        for c in clips
    ]
    sc = np.ones(len(clips)) if scales is None else np.asarray(scales, dtype=float)
    if align is not None and offsets is None:
        off = [0.0]
        for i in range(1, len(clips)):
            off.append(
                auto_offset(
                    clips[i - 1],
                    clips[i],
                    align,
                    align_joint,
                    align_channel,
                    window=max(int(2 * transition), 8),
                    a_offset=off[-1],
                    a_scale=float(sc[i - 1]),
                    b_scale=float(sc[i]),
                )
            )
        offsets = np.asarray(off)
    p = plan(clips, offsets, sc, transition, curve)
    t = np.arange(p.n_frames, dtype=float)
    # sample every clip on the output timeline
    rots, poss, jts, us, samples = [], [], [], [], []
    aligned: list[Motion] = []
    for i, c in enumerate(clips):
        if align_root and i > 0:
            prev = aligned[-1]
            overlap = np.flatnonzero((p.weights[:, i] > 0) & (p.weights[:, i - 1] > 0))
            t0 = float(overlap[0]) if overlap.size else float(p.offsets[i])
            up_prev = (t0 - p.offsets[i - 1]) / p.scales[i - 1]
            up_prev = float(np.clip(up_prev, 0, prev.n_frames - 1))
            fb = int(np.clip(round((t0 - p.offsets[i]) / p.scales[i]), 0, c.n_frames - 1))
            fa = int(round(up_prev))
            c = align_root_to(c, prev.root_position[fa], heading_at(prev, fa, up), fb, up)
        aligned.append(c)
        u = np.clip((t - p.offsets[i]) / p.scales[i], 0.0, c.n_frames - 1)
        if len(clips) == 2:
            r, pos, jt = sample_arrays(c, u)
            rots.append(r)
        else:  # rotations are sampled inside the averaging kernel
            i0, frac, pos, jt = sample_linear(c, u)
            samples.append((i0, frac))
        us.append(u)
        poss.append(pos)
        jts.append(jt)
    w = p.weights
    if len(clips) == 2:
        b = w[:, 1]
        qa, qb = rots
        rot = np.empty_like(qa)
        blend_slerp(ro(qa), ro(qb), ro(b), rot)
    else:
        rot = average_rotations(aligned, us, w, samples)
    pos = np.einsum("fi,ifk->fk", w, np.stack(poss))
    exact = w == 1.0
    for i in range(len(clips)):
        pos[exact[:, i]] = poss[i][exact[:, i]]
    jt = None
    if any(j is not None for j in jts):
        sk0 = clips[0].skeleton
        full = [
            j if j is not None else np.broadcast_to(sk0.offset, (p.n_frames,) + sk0.offset.shape)
            for j in jts
        ]
        jt = np.einsum("fi,ifnk->fnk", w, np.stack(full))
        jt[:, 0] = pos
    meta = dict(clips[0].meta)
    meta["blend"] = {"offsets": p.offsets.tolist(), "scales": p.scales.tolist()}
    return Motion(clips[0].skeleton, frozen(rot), frozen(pos), clips[0].frame_time, jt, meta)


def average_rotations(
    clips: Sequence[Motion],
    us: Sequence[Array],
    w: Array,
    samples: Sequence[tuple[Array, Array]] | None = None,
) -> Array:
    """Normalised weighted quaternion average of the clips sampled (slerp) at frames
    ``us[i]`` with weights ``w (f, N)``: one fused kernel that samples a clip only where it
    has weight (equals the stack-then-average oracle in tests/motion/oracles.py, to 1e-12).
    ``samples``: each clip's ``(i0, frac)`` from :func:`sample_linear` at ``us[i]`` when the
    caller has them already."""
    start = np.cumsum([0] + [c.n_frames for c in clips[:-1]])
    length = np.array([c.n_frames for c in clips])
    i0 = np.empty((len(clips), w.shape[0]), dtype=np.int64)
    frac = np.empty((len(clips), w.shape[0]))
    for i, (c, u) in enumerate(zip(clips, us, strict=True)):
        i0[i], frac[i] = sample_linear(c, u)[:2] if samples is None else samples[i]
    rot = np.empty((w.shape[0],) + clips[0].rotation.shape[1:])
    blend_average_sampled(
        ro(np.concatenate([c.rotation for c in clips])),
        ro_int(start),
        ro_int(length),
        ro_int(i0),
        ro(frac),
        ro(w),
        rot,
    )
    return rot


__all__ = ["blend", "plan", "auto_offset", "BlendPlan"]
