"""Balance repair (new beyond the seed) and the ``finish`` step.

A creature whose centre of mass is not over its support polygon with the required margin is
repaired, cheapest first: bipeds lean the body about the hip (rigid sagittal rotation of the
spine, :func:`pitch_body`); then the leg-bearing girdle on the failing side is shifted along
the spine and its legs re-grounded (:func:`repair_shift`); then the stance is widened.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from biomorph.creature import balance as bal
from biomorph.creature import mass as ms
from biomorph.creature.assembly import (
    assemble,
    balance_px,
    below_ground,
    limb_digits,
    to_creature,
)
from biomorph.creature.creature import Creature
from biomorph.creature.options import Options
from biomorph.creature.stance import RANGES
from biomorph.creature.states import LimbsState, SkullState, SpineState, step_rng
from biomorph.creature.steps import DEG, step_limbs, step_skull, to_creature_px, trunk_pitch
from biomorph.errors import ParameterError


def repair_shift(
    asm: dict,
    report: bal.BalanceReport,
    limbs: dict,
    min_margin: float = 0.02,
    history: dict | None = None,
) -> dict[str, float] | None:
    """Girdle shifts (arc length, px) that move the feet under the centre of mass.

    The first shift is 1.2 × the missing distance; with ``history`` (updated in place: the
    last shift and missing distance per girdle) later shifts are secant steps on the
    measured response — the feet move less than their girdle along a curved, pitched spine
    and the centre of mass moves with the legs — so the repair converges in a few steps."""
    if not report.applicable:
        return None
    com_x = report.com[0]
    patches = asm["patches"]
    x0, x1 = patches[:, 0].min(), patches[:, 0].max()
    span = max(x1 - x0, 1e-6)
    body = float(np.ptp(asm["pos"][:, 0]))
    target_margin = min(0.45 * span, max(1.5 * min_margin * body, 0.08 * span))
    leg_girdles = sorted({p[0] for p in limbs.places if p[2].kind == "leg"})
    shifts = dict(limbs.shifts)
    if com_x > x1 - target_margin:  # too far forward: move the front-most legs forward
        delta = com_x - (x1 - target_margin)
        g = "shoulder" if "shoulder" in leg_girdles and len(leg_girdles) > 1 else leg_girdles[0]
        shifts[g] = shifts.get(g, 0.0) - _step(history, g, -1.0, shifts.get(g, 0.0), delta)
    elif com_x < x0 + target_margin:  # too far back: move the hind-most legs back
        delta = (x0 + target_margin) - com_x
        g = "hip" if "hip" in leg_girdles else leg_girdles[-1]
        shifts[g] = shifts.get(g, 0.0) + _step(history, g, 1.0, shifts.get(g, 0.0), delta)
    elif (
        report.margin < min_margin * body
        and shifts.get("width", 1.0) < 3.0
        and 0.5 * span >= _required(report, min_margin)
    ):
        # lateral margin: widen the stance (useless when the feet are too short fore-aft:
        # the margin can never exceed half their length, and the creature is resampled)
        shifts["width"] = shifts.get("width", 1.0) * 1.35
    else:
        return None
    return shifts


def _required(report: bal.BalanceReport, min_margin: float) -> float:
    """The margin (px) the balance check asks for: ``min_margin`` × its body length."""
    if abs(report.margin_fraction) < 1e-15:
        return 0.0
    return min_margin * report.margin / report.margin_fraction


def _step(history: dict | None, girdle: str, sign: float, now: float, delta: float) -> float:
    """Size of the next shift of ``girdle`` (in the direction ``sign``) for a missing
    distance ``delta``: 1.2 × delta first, then a secant step (delta ÷ the measured response
    per unit shift, clamped to 0.6..1.5 — a re-posed leg may jump — × 1.1)."""
    step = 1.2 * delta
    if history is None:
        return step
    prev = history.get((girdle, sign))
    if prev is not None:
        moved = sign * (now - prev[0])
        if moved > 1e-9:
            response = float(np.clip((prev[1] - delta) / moved, 0.6, 1.5))
            step = 1.1 * delta / response
    history[(girdle, sign)] = (now, delta)
    return step


#: Lean iterations for bipeds (the rotation is solved analytically; re-posed free limbs and
#: a raised tail make a second pass worthwhile).
PITCH_ITERATIONS = 3


def pitch_body(
    spine: dict, limbs: dict, asm: dict, report: bal.BalanceReport, max_deg: float = 40.0
) -> dict | None:
    """Spine rotated rigidly (sagittal plane) about the leg attachment so that the centre of
    mass moves over the middle of the feet; ``None`` if no rotation within ``max_deg`` helps.
    Rigid rotation keeps the C1 joins; legs keep their attachment (the pivot)."""
    legs = [i for i, p in enumerate(limbs.places) if p[2].kind == "leg"]
    if not legs:
        return None
    pivot = limbs.attach[legs[0]][1][:2]
    kinds = np.array(asm["kind"])
    is_leg = kinds == "leg"
    vol = asm["vol"]
    mb, ml = vol[~is_leg].sum(), vol[is_leg].sum()
    if mb <= 0:
        return None
    xb = (vol[~is_leg, None] * asm["mass_c"][~is_leg, :2]).sum(axis=0) / mb
    xl = (vol[is_leg] * asm["mass_c"][is_leg, 0]).sum() / max(ml, 1e-30)
    pts_x = asm["patches"][:, 0]
    target = 0.5 * (pts_x.min() + pts_x.max())
    want = ((mb + ml) * target - ml * xl) / mb  # body COM x needed
    r = xb - pivot
    R = float(np.hypot(*r))
    if R < 1e-9:
        return None
    c = np.clip((want - pivot[0]) / R, -1.0, 1.0)
    phi = np.arctan2(r[1], r[0])
    cands = [np.arccos(c) - phi, -np.arccos(c) - phi]
    cands = [(a + np.pi) % (2 * np.pi) - np.pi for a in cands]
    theta = min(cands, key=abs)
    theta = float(np.clip(theta, -max_deg * DEG, max_deg * DEG))
    # the lean stays inside the bipeds' standing trunk-pitch range (never head-down)
    lo, hi = RANGES["trunk_pitch_biped"]
    p0 = trunk_pitch(spine.points)
    theta = float(np.clip(theta, (lo + 2.0) * DEG - p0, (hi - 2.0) * DEG - p0))
    if abs(theta) < 1e-4:
        return None
    ct, st = np.cos(theta), np.sin(theta)
    pc_ = to_creature_px(spine.points) - pivot
    rot = np.stack([ct * pc_[:, 0] - st * pc_[:, 1], st * pc_[:, 0] + ct * pc_[:, 1]], axis=1)
    return replace(spine, points=to_creature_px(rot + pivot))


def limb_mass_and_patches(limbs: LimbsState, spine: SpineState) -> tuple[float, NDArray, NDArray]:
    """Volume, volume-weighted centre sum and ground contact points (x, z) of all limbs (both
    sides) straight from the poses — the cheap part of a balance re-check."""
    vol, mom, patches = 0.0, np.zeros(3), []
    for (g, _k, spec, _at), pose, L3 in zip(limbs.places, limbs.poses, limbs.lengths, strict=True):
        v = ms.limb_volume(L3, spec.kind)
        mid = 0.5 * (pose.points[:3] + pose.points[1:])
        vol += 2 * v.sum()
        mom += 2 * (v[:, None] * mid * [1, 1, 0]).sum(axis=0)
        if pose.contact is not None:
            # with frames: the final assembly reuses these digits (memoised)
            dg = limb_digits(pose, L3, spec.kind, g, spine, limbs.ground)
            c = dg.contacts[:, [0, 2]]
            patches += [c, c * [1.0, -1.0]]
    return vol, mom, (np.concatenate(patches) if patches else np.zeros((0, 2)))


def finish(
    spine: SpineState,
    girdles,
    limbs: LimbsState,
    skull: SkullState,
    opts: Options,
    rng: np.random.Generator,
    attempt_info: dict | None = None,
) -> Creature:
    """Assemble bones, repair balance, size from weight and return a :class:`Creature`.

    Repair (new beyond the seed): while the centre of mass is not inside the support polygon
    with the required margin, the leg-bearing girdle on the failing side is shifted along the
    spine by the missing distance and its legs are grounded again (up to 6 times); the
    cheap re-check uses the fixed spine/skull masses plus the re-posed limbs.
    """
    asm = assemble(spine, limbs, skull)
    report = balance_px(asm, opts)
    repairs = 0
    leg_girdles = {p[0] for p in limbs.places if p[2].kind == "leg"}
    if report.applicable and not report.stable and len(leg_girdles) == 1:
        # bipeds (legs on one girdle): lean the body about the leg attachment (posture)
        for _ in range(PITCH_ITERATIONS):
            spine2 = pitch_body(spine, limbs, asm, report)
            if spine2 is None:
                break
            limbs2 = step_limbs(
                spine2,
                girdles,
                opts,
                step_rng(opts.seed, "limbs", 100),
                ground=limbs.ground,
                previous=limbs,
            )
            skull2 = step_skull(spine2, limbs2, opts, step_rng(opts.seed, "skull", 100))
            asm2 = assemble(spine2, limbs2, skull2)
            rep2 = balance_px(asm2, opts)
            repairs += 1
            if rep2.margin_fraction < report.margin_fraction - 0.05 or below_ground(asm2):
                break
            spine, limbs, skull, asm, report = spine2, limbs2, skull2, asm2, rep2
            if report.stable:
                break
    limbs0 = limbs
    if report.applicable and not report.stable:
        body = np.isin(np.array(asm["kind"]), ("spine", "skull", "girdle"))
        bvol = float(asm["vol"][body].sum())
        bmom = (asm["vol"][body, None] * asm["mass_c"][body]).sum(axis=0)
        ends = asm["pos"] + asm["W"][:, :, 1] * asm["blen"][:, None]
        bl = float(np.ptp(np.concatenate([asm["pos"], ends])[:, 0]))
        work = dict(asm)
        history: dict = {}
        while repairs < 10:
            shifts = repair_shift(work, report, limbs, opts.min_margin_fraction, history)
            if shifts is None:
                break
            try:
                limbs = step_limbs(
                    spine,
                    girdles,
                    opts,
                    step_rng(opts.seed, "limbs", 100),
                    shifts,
                    ground=limbs0.ground,
                    previous=limbs0,
                )
            except ParameterError:
                break
            lvol, lmom, patches = limb_mass_and_patches(limbs, spine)
            com = (bmom + lmom) / max(bvol + lvol, 1e-30)
            report = bal.evaluate(com, bvol + lvol, patches, bl, opts.min_margin_fraction)
            work = dict(work, patches=patches)
            repairs += 1
            if report.stable:
                break
        asm = assemble(spine, limbs, skull)
        report = balance_px(asm, opts)
    return to_creature(asm, spine, girdles, limbs, skull, report, repairs, opts, attempt_info)
