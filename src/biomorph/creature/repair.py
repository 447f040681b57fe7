"""Balance repair (new beyond the seed) and the ``finish`` step.

A creature whose centre of mass is not over its support polygon with the required margin is
repaired, cheapest first: bipeds lean the body about the hip (rigid sagittal rotation of the
spine, :func:`pitch_body`); then the leg-bearing girdle on the failing side is shifted along
the spine and its legs re-grounded (:func:`repair_shift`); then the stance is widened.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
from numpy.typing import NDArray

from biomorph.creature import balance as bal
from biomorph.creature import feet
from biomorph.creature import limbs as lb
from biomorph.creature import mass as ms
from biomorph.creature import skulls as sk
from biomorph.creature import spine as sp
from biomorph.creature import vertebrae as vt
from biomorph.creature.assembly import (
    DIGIT_MASS_SHARE,
    _frames_from_dirs,
    _slices_kernel,
    assemble,
    balance_px,
    below_ground,
    limb_digits,
    to_creature,
)
from biomorph.creature.creature import Creature
from biomorph.creature.options import Options
from biomorph.creature.stance import TARGET, trunk_key
from biomorph.creature.states import LimbsState, SkullState, SpineState, step_rng
from biomorph.creature.steps import (
    _DROP,
    DEG,
    _attach_all,
    _flatten,
    _pose_free,
    _trunk_lean,
    carried_ground,
    carried_wing,
    placements,
    step_limbs,
    step_skull,
    to_creature_px,
    trunk_pitch,
    wing_reach,
)
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
    # the size the margin is asked of: body length or centre-of-mass height (balance.py)
    body = max(float(np.ptp(asm["pos"][:, 0])), float(report.com[1] - asm["ground"]))
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
    """The margin (px) the balance check asks for: ``min_margin`` × its size (the larger
    of body length and centre-of-mass height)."""
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
    # the lean stays inside the body plan's target trunk pitch, as the reduced repair's
    # (never head-down; other bipeds at most 50°, birds 21..49°); a trunk outside may only
    # lean back in
    lo, hi = TARGET[trunk_key(spine.cls, 2)]
    p0 = trunk_pitch(spine.points)
    lo_t, hi_t = min(lo * DEG - p0, 0.0), max(hi * DEG - p0, 0.0)
    theta = float(np.clip(theta, lo_t, hi_t))
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


# --------------------------------------------------------------------------- reduced model
#: Margin tolerance (fraction of the body length) inside which the reduced model's verdict is
#: re-checked on the full assembly (the two agree to rounding, ~1e-15).
_EXACT_TOL = 1e-9
#: Extra margin (fraction of the body length) the reduced repair aims for beyond the required
#: one, and the least it accepts (the final pass reproduces the reduced model's state; where
#: the new ground would need the body posed again, it re-poses the free limbs and skull).
_AIM = 0.004
_ACCEPT = 0.0005
#: Girdle-shift evaluations of the reduced repair.
_SHIFT_EVALS = 8


@dataclass
class _Part:
    """Volume, volume moment (x, y; z cancels between the sides), the x extent of joints
    and bone ends and the ground contacts (x, z; both sides) of some bones, creature px."""

    vol: float
    mom: NDArray
    xmin: float
    xmax: float
    patches: NDArray

    @staticmethod
    def join(parts: list[_Part]) -> _Part:
        if not parts:
            return _Part(0.0, np.zeros(2), np.inf, -np.inf, _NO_PATCH)
        return _Part(
            sum(p.vol for p in parts),
            np.sum([p.mom for p in parts], axis=0),
            min(p.xmin for p in parts),
            max(p.xmax for p in parts),
            np.concatenate([p.patches for p in parts]),
        )


_NO_PATCH = np.zeros((0, 2))


def _spine_part(spine: SpineState, pts: NDArray, skull_h: float) -> _Part:
    """The vertebrae's slices (:func:`assembly._slices_kernel`, the assembly's arithmetic)."""
    xy, s, region = sp.sample(pts)
    rl = sp.region_lengths(s, region)
    h, b, off = ms.profile(s, rl, spine.girth, spine.cls, skull_h, spine.legs == 0)
    edges, vreg = vt.boundaries(rl, spine.counts)
    P, vmass, vcen, _, _ = _slices_kernel(xy, s, h, b, off, np.ascontiguousarray(edges), len(vreg))
    mom = np.array([vmass @ vcen[:, 0], vmass @ vcen[:, 1]])
    return _Part(float(vmass.sum()), mom, float(P[:, 0].min()), float(P[:, 0].max()), _NO_PATCH)


def _skull_part(skull: SkullState) -> _Part:
    """Skull and mandible as :func:`assembly._body_blocks` builds them."""
    shape = sk.get(skull.shape)
    d = np.array([np.cos(skull.angle), np.sin(skull.angle), 0.0])
    org = np.array([skull.origin[0], skull.origin[1], 0.0])
    W = _frames_from_dirs(d[None])[0]
    jaw = sk.jaw(shape, skull.length, W, org)
    v = ms.ellipsoid_volume(sk.box_size(shape, skull.length))
    c_sk = org + d * skull.length / 2
    c_jaw = jaw.pos + jaw.W[:, 1] * jaw.length / 2
    mom = (1 - sk.JAW_MASS_FRACTION) * v * c_sk + sk.JAW_MASS_FRACTION * v * c_jaw
    xs = [
        org[0],
        org[0] + W[0, 1] * skull.length,
        jaw.pos[0],
        jaw.pos[0] + jaw.W[0, 1] * jaw.length,
    ]
    return _Part(v, mom[:2], min(xs), max(xs), _NO_PATCH)


def _limb_part(
    spine: SpineState, place, attach, pose: lb.LimbPose, L3: NDArray, ground: float | None
) -> _Part:
    """One limb pair (both sides) as :func:`assembly.assemble` builds it: girdle bone, three
    limb cylinders and the digits with their share of the hand / foot (bone ends taken as
    the next joints: the same points to rounding)."""
    gname, _k, spec, _at = place
    gpt, apt = attach
    dg = limb_digits(
        pose, L3, spec.kind, gname, spine, ground if pose.contact is not None else None
    )
    L3 = np.asarray(L3, float)
    r = ms.LIMB_RADIUS[spec.kind] * L3
    vols = np.pi * r * r * L3
    p = pose.points
    mc = 0.5 * (p[:3, :2] + p[1:, :2])
    px = p[:, 0]
    xmin = min(gpt[0], apt[0], px.min())
    xmax = max(gpt[0], apt[0], px.max())
    ln = dg.length
    if len(ln):
        vd = DIGIT_MASS_SHARE * vols[2] * ln / max(ln.sum(), 1e-30)
        vols[2] *= 1.0 - DIGIT_MASS_SHARE
        w1 = dg.W[:, :2, 1]
        cd = dg.pos[:, :2] + w1 * (0.5 * ln)[:, None]
        mom = vols @ mc + vd @ cd
        vol = vols.sum() + vd.sum()
        dx = dg.pos[:, 0]
        de = dx + w1[:, 0] * ln
        xmin = min(xmin, dx.min(), de.min())
        xmax = max(xmax, dx.max(), de.max())
    else:
        mom, vol = vols @ mc, vols.sum()
    if len(dg.contact_local):
        c = dg.contacts[:, [0, 2]]
        patches = np.concatenate([c, c * _FLIP_Z])
    else:
        patches = _NO_PATCH
    return _Part(2 * float(vol), 2 * mom, float(xmin), float(xmax), patches)


_FLIP_Z = np.array([1.0, -1.0])


def _report(part: _Part, opts: Options, ground: float) -> bal.BalanceReport:
    com = np.array([part.mom[0], part.mom[1], 0.0]) / max(part.vol, 1e-30)
    return bal.evaluate(
        com,
        part.vol,
        part.patches,
        part.xmax - part.xmin,
        opts.min_margin_fraction,
        float(com[1] - ground),
    )


def quick_report(spine: SpineState, limbs: LimbsState, skull: SkullState, opts: Options):
    """The balance report of the assembled creature from only what balance needs (masses,
    extent, contacts) — :func:`assembly.balance_px` to rounding, without the joint arrays.
    Returns ``(report, body part, legs part, {id(free limb pose): (pose, part)})``."""
    skull_h = sk.get(skull.shape).height * skull.length
    body = [_spine_part(spine, limbs.points, skull_h), _skull_part(skull)]
    legs, free = [], {}
    for place, at, pose, L3 in zip(
        limbs.places, limbs.attach, limbs.poses, limbs.lengths, strict=True
    ):
        part = _limb_part(spine, place, at, pose, L3, limbs.ground)
        (legs if place[2].kind == "leg" else body).append(part)
        if place[2].kind != "leg":
            free[id(pose)] = (pose, part)
    b, lg = _Part.join(body), _Part.join(legs)
    return _report(_Part.join([b, lg]), opts, limbs.ground), b, lg, free


def p_len(limbs: LimbsState, i: int) -> NDArray:
    """Segment lengths of placement ``i`` (a free limb keeps its sampled ones)."""
    return np.array(limbs.places[i][2].lengths, float)


def _rotated(spine: SpineState, theta: float, pivot: NDArray) -> SpineState:
    """The spine rotated rigidly by ``theta`` (sagittal plane) about ``pivot`` (creature px),
    as :func:`pitch_body` leans it."""
    ct, st = np.cos(theta), np.sin(theta)
    pc_ = to_creature_px(spine.points) - pivot
    rot = np.stack([ct * pc_[:, 0] - st * pc_[:, 1], st * pc_[:, 0] + ct * pc_[:, 1]], axis=1)
    return replace(spine, points=to_creature_px(rot + pivot))


@dataclass
class _Leaned:
    """A biped leaned by ``theta``: the pieces of ``step_limbs``'s repair pass that do not
    depend on the girdle shift, and the body's (non-leg) part of the balance model."""

    theta: float
    spine: SpineState
    xy: NDArray
    s: NDArray
    rl: NDArray
    lowest: float  # lowest trunk underside (the ground may not lie above it)
    body: _Part  # vertebrae, skull, free limbs
    ground: float  # the ground they were posed for (the legs unshifted)
    flat: NDArray  # spine control points (creature px), tail / neck raised above it
    attach: list  # attachments of all placements (legs unshifted)
    poses: dict  # free limb poses by placement
    skull: SkullState


class _Reduced:
    """Balance repair of a biped on a reduced model: only the quantities balance needs
    (volumes, moments, extent, contacts), computed with the same functions the repair pass
    of :func:`step_limbs` and the assembly use — the legs re-grounded from their poses in
    ``prev`` at the moved attachment, the free limbs posed from the repair's random stream,
    the skull for the leaned neck — so that the one full pass at the end reproduces them."""

    def __init__(self, spine, girdles, limbs: LimbsState, skull, opts: Options) -> None:
        self.spine, self.girdles, self.prev, self.opts = spine, girdles, limbs, opts
        self.legs = [i for i, p in enumerate(limbs.places) if p[2].kind == "leg"]
        self.pivot = np.asarray(limbs.attach[self.legs[0]][1][:2], float)
        self.skull_h = sk.get(spine.skull).height * spine.skull_length
        self.p0 = trunk_pitch(spine.points)
        self.rebased = self.reposed = False
        self._parts: dict = {}  # id(free limb pose) -> (pose, its part)

    def lean(self, theta: float) -> _Leaned:
        """The body (spine, skull, free limbs) leaned by ``theta`` about the legs'
        attachment, as the repair pass of :func:`step_limbs` and :func:`step_skull` pose it
        (the girdle-shift's effect on the ground is left out: it only moves the tail's
        clearance and the skull's floor)."""
        sp0, prev, opts = self.spine, self.prev, self.opts
        spine = _rotated(sp0, theta, self.pivot) if theta else sp0
        legless = spine.legs == 0
        pts = to_creature_px(spine.points)
        xy, s, region = sp.sample(pts)
        rl = sp.region_lengths(s, region)
        places = placements(self.girdles, prev.shifts, rl, s)
        attach = _attach_all(
            xy, s, rl, spine, self.skull_h, legless, places, prev.shifts.get("width", 1.0)
        )
        ground = carried_ground(spine, places, attach, prev, self.legs)
        h_all, _, _ = ms.profile(s, rl, spine.girth, spine.cls, self.skull_h, legless)
        bottom = xy[:, 1] - np.where(region == 1, 0.35, 0.2) * h_all
        trunk = region == 1
        lowest = float(bottom[trunk].min()) if trunk.any() else np.inf
        ground = min(ground, lowest)
        clear = ground + 0.02 * max(s[-1], 1.0)
        flat = pts
        for which, reg in (("tail", 2), ("neck", 0)):
            if (region == reg).any() and xy[region == reg, 1].min() < clear:
                flat = _flatten(flat, which, clear)
        xy_f, s_f, _ = sp.sample(flat)
        parts = [_spine_part(spine, flat, self.skull_h)]
        lean = _trunk_lean(places, attach)
        rng = step_rng(opts.seed, "limbs", 100)  # wings drawn again (carried_wing)
        floor = ground + 0.01 * max(s_f[-1], 1.0)
        clear = 0.01 * max(s_f[-1], 1.0)
        poses = {}
        for i, place in enumerate(places):
            if i in self.legs:
                continue
            L3 = np.array(place[2].lengths, float)
            base = attach[i][1]
            lift = clear
            if place[2].kind == "wing":  # same angles, moved with the attachment
                lift += wing_reach(spine, L3, base[1] - ground)  # its digits clear it too
                pose = lb.moved(prev.poses[i], base, L3)
                if np.all(pose.points[1:, 1] >= ground + lift):  # lift_clear: unchanged
                    parts.append(self._moved_part(i, attach[i], pose))
                    poses[i] = pose
                    continue
                pose = carried_wing(spine, prev.poses[i], base, L3, ground, s_f, rng)
            else:  # arms and fins draw no random numbers
                pose = _pose_free(spine, place[2].kind, base, L3, None, lean, xy_f, floor)
            pose = lb.lift_clear(pose, base, L3, ground, lift)
            parts.append(_limb_part(spine, place, attach[i], pose, L3, None))
            poses[i] = pose
        stub = SimpleNamespace(points=flat, ground=ground)
        skull = step_skull(spine, stub, opts, step_rng(opts.seed, "skull", 100))
        parts.append(_skull_part(skull))
        return _Leaned(
            theta, spine, xy, s, rl, lowest, _Part.join(parts), ground, flat, attach, poses, skull
        )

    def final(self, st: _Leaned, shifts: dict, legs: dict, ground: float):
        """The repair pass's limbs and skull for the leaned body ``st`` standing on the legs
        ``legs`` (placement -> (attachment, pose)) shifted by ``shifts``: the body as it was
        posed for the unshifted legs, where the new ground leaves its tail, neck, free limbs
        and skull clear of the ground as the repair pass requires; ``None`` otherwise (the
        full pass decides). Arms, whose rest pose follows the trunk line and the ground, are
        posed again as the repair pass poses them."""
        if ground > st.ground:
            xy_f, s_f, region = sp.sample(st.flat)
            clear = ground + 0.02 * max(st.s[-1], 1.0)
            for reg in (2, 0):
                if (region == reg).any() and xy_f[region == reg, 1].min() < clear:
                    return None
            clear = ground + 0.01 * max(s_f[-1], 1.0)
            for i, p in st.poses.items():
                reach = 0.0
                if p.kind == "wing":
                    reach = wing_reach(st.spine, p_len(self.prev, i), st.attach[i][1][1] - ground)
                if p.points[1:, 1].min() < clear + reach:
                    return None
            shape = sk.get(st.skull.shape)
            c, sn = np.cos(st.skull.angle), np.sin(st.skull.angle)
            head = st.skull.origin[1]
            tip = head + st.skull.length * sn
            low = min(tip, head) - 0.5 * shape.height * st.skull.length * abs(c)
            if low < clear and st.skull.angle <= 60 * DEG:
                return None
        prev = self.prev
        places = placements(self.girdles, shifts, st.rl, st.s)
        attach = [legs[i][0] if i in legs else st.attach[i] for i in range(len(places))]
        lengths = [
            np.asarray(prev.lengths[i], float) if i in legs else np.array(p[2].lengths, float)
            for i, p in enumerate(places)
        ]
        poses = [legs[i][1] if i in legs else st.poses[i] for i in range(len(places))]
        arms = [i for i, p in enumerate(places) if p[2].kind == "arm"]
        if arms:
            xy_f, s_f, _ = sp.sample(st.flat)
            lean = _trunk_lean(places, attach)
            clear = 0.01 * max(s_f[-1], 1.0)
            for i in arms:
                base, L3 = attach[i][1], lengths[i]
                pose = _pose_free(st.spine, "arm", base, L3, None, lean, xy_f, ground + clear)
                poses[i] = lb.lift_clear(pose, base, L3, ground, clear)
        limbs = LimbsState(
            points=st.flat,
            ground=float(ground),
            places=places,
            attach=attach,
            lengths=lengths,
            poses=poses,
            shifts=dict(shifts),
        )
        return limbs, st.skull

    def _moved_part(self, i: int, attach, pose: lb.LimbPose) -> _Part:
        """The part of free limb ``i`` of ``prev`` moved rigidly to ``pose`` (the same
        angles): the cached part of its pose in ``prev``, translated."""
        prev = self.prev
        key = id(prev.poses[i])
        hit = self._parts.get(key)
        if hit is None or hit[0] is not prev.poses[i]:
            part = _limb_part(
                self.spine, prev.places[i], prev.attach[i], prev.poses[i], prev.lengths[i], None
            )
            hit = self._parts[key] = (prev.poses[i], part)
        part = hit[1]
        d = pose.points[0] - prev.poses[i].points[0]
        return _Part(
            part.vol,
            part.mom + part.vol * d[:2],
            part.xmin + d[0],
            part.xmax + d[0],
            part.patches,
        )

    def _attach(self, st: _Leaned, spine: SpineState, place, width: float):
        """:func:`steps._attach_all` for one leg placement (its arithmetic, fewer calls)."""
        at = place[3]
        h = max(st.s[-1] * 1e-3, 1e-9)
        q = sp.point_at(st.xy, st.s, np.array([at, at + h, at - h]))
        g = q[0]
        d = q[1] - q[2]
        nd = float(np.hypot(d[0], d[1]))
        t = d / nd if nd > 0 else d
        n = np.array([t[1], -t[0]])
        if n[1] < 0:
            n = -n
        hh, bb, _ = ms.profile(
            np.array([at]), st.rl, spine.girth, spine.cls, self.skull_h, spine.legs == 0
        )
        drop = _DROP[place[2].kind] * hh[0] * (0.75 if place[0] == "hip" else 1.0)
        half = 0.45 * bb[0] * (1.35 if spine.posture == "sprawling" else 1.0) * width
        a2 = g - drop * n
        return np.array([g[0], g[1], 0.0]), np.array([a2[0], a2[1], half])

    def unshifted(self, st: _Leaned, legs: _Part):
        """:meth:`stand` without a girdle shift, where the lean left the legs as they were:
        it turns the body about their attachment and the ground stays under their feet
        (``legs``: their part in ``prev``)."""
        prev = self.prev
        if prev.shifts or not len(legs.patches):
            return None
        g = carried_ground(st.spine, prev.places, prev.attach, prev, self.legs)
        tol = 1e-9 * max(abs(g), 1.0)
        if abs(st.ground - g) > tol:
            return None  # the trunk's underside lowered the ground: re-ground the legs
        # the girdle bones run from the leaned spine; the feet stood a little above the
        # ground they were posed for: their digits on g
        legs = _Part.join(
            [
                _limb_part(
                    st.spine, prev.places[i], st.attach[i], prev.poses[i], prev.lengths[i], g
                )
                for i in self.legs
            ]
        )
        stood = {i: (st.attach[i], prev.poses[i]) for i in self.legs}
        return _report(_Part.join([st.body, legs]), self.opts, g), legs, (stood, g)

    def stand(self, st: _Leaned, shifts: dict):
        """Balance of the leaned body with the legs at ``shifts``: ``(report, legs part,
        ({placement: (attachment, pose)}, ground))``; ``None`` where the re-grounding fails
        (the repair pass would pose that leg afresh) or an attachment lies below the
        ground."""
        prev, spine = self.prev, st.spine
        stood: dict = {}
        places = placements(self.girdles, shifts, st.rl, st.s)
        legs = self.legs
        w = shifts.get("width", 1.0)
        attach = {i: self._attach(st, spine, places[i], w) for i in legs}
        ground = min(carried_ground(spine, places, attach, prev, legs), st.lowest)
        parts = []
        for i in legs:
            if attach[i][1][1] <= ground:
                return None
            role = "hind" if places[i][0] == "hip" else "fore"
            plan = feet.digit_plan(
                "leg", role, spine.cls, spine.stance, spine.skull, spine.hoof_digits
            )
            L3 = prev.lengths[i]
            lift = feet.clearance(plan, float(L3[2]))
            pose = lb.reground(
                prev.poses[i], attach[i][1], L3, ground + lift, self.opts.descent, True
            )
            if pose is None:
                return None
            parts.append(_limb_part(spine, places[i], attach[i], pose, L3, ground))
            stood[i] = (attach[i], pose)
        lg = _Part.join(parts)
        return _report(_Part.join([st.body, lg]), self.opts, ground), lg, (stood, ground)

    def limbs(self, st: _Leaned, shifts: dict, repose: bool = False) -> LimbsState:
        """The real repair pass (:func:`step_limbs`) for ``st`` and ``shifts``."""
        return step_limbs(
            st.spine,
            self.girdles,
            self.opts,
            step_rng(self.opts.seed, "limbs", 100),
            shifts,
            ground=self.prev.ground,
            previous=self.prev,
            carry=True,
            repose=repose,
        )

    def rebase(self, st: _Leaned, shifts: dict, repose: bool = False):
        """The real pass at ``shifts`` — where re-grounding fails (or with ``repose``) it
        poses the legs afresh by the descent — becomes the pose the later steps re-ground
        from (once each per repair); returns :meth:`stand` there."""
        if self.reposed if repose else self.rebased:
            return None
        if repose:
            self.reposed = True
        else:
            self.rebased = True
        try:
            self.prev = self.limbs(st, shifts, repose)
        except ParameterError:
            return None
        return self.stand(st, shifts)

    def lean_angle(self, theta0: float, body: _Part, legs: _Part) -> float:
        """Total lean (:func:`pitch_body`'s rigid solution from the body leaned by
        ``theta0``, at most 40° more) that brings the centre of mass over the middle of the
        feet, inside the body plan's target trunk pitch (birds 21..49°, other bipeds 0..50°)."""
        mb, ml = body.vol, legs.vol
        if mb <= 0 or not len(legs.patches):
            return theta0
        xb = body.mom / mb
        xl = legs.mom[0] / max(ml, 1e-30)
        target = 0.5 * (legs.patches[:, 0].min() + legs.patches[:, 0].max())
        want = ((mb + ml) * target - ml * xl) / mb
        r = xb - self.pivot
        R = float(np.hypot(*r))
        if R < 1e-9:
            return theta0
        c = np.clip((want - self.pivot[0]) / R, -1.0, 1.0)
        phi = np.arctan2(r[1], r[0])
        cands = [
            (a + np.pi) % (2 * np.pi) - np.pi for a in (np.arccos(c) - phi, -np.arccos(c) - phi)
        ]
        lo, hi = TARGET[trunk_key(self.spine.cls, 2)]
        theta = theta0 + float(np.clip(min(cands, key=abs), -40 * DEG, 40 * DEG))
        lo_t, hi_t = min(lo * DEG - self.p0, 0.0), max(hi * DEG - self.p0, 0.0)
        return float(np.clip(theta, lo_t, hi_t))


def _repair_biped(spine, girdles, limbs, skull, opts, quick):
    """Girdle shift (and stance width) of an unstable biped chosen on the reduced model
    (:class:`_Reduced`) first, as it stands; only where that cannot balance it, a lean (the
    rigid solution, refined once, never past the bipeds' target trunk pitch,
    :data:`stance.TARGET`) and the girdle shift again. Returns ``(reduced model, leaned
    state, shifts, stood legs or None, repairs)``, or ``None`` where the reduced model cannot
    balance it inside that range (the iterative repair of :func:`finish` decides)."""
    report0, body0, legs0, parts = quick
    aim = opts.min_margin_fraction + _AIM
    need = opts.min_margin_fraction + _ACCEPT
    red = _Reduced(spine, girdles, limbs, skull, opts)
    red._parts = parts
    st0 = red.lean(0.0)
    best, repairs = _solve_shift(red, st0, (report0, legs0, None), need, aim, 0)
    if best[0].margin_fraction >= need:
        return red, st0, best[3], best[2][2], max(repairs, 1)
    red = _Reduced(spine, girdles, limbs, skull, opts)  # the legs as they were posed
    red._parts = parts
    cur = None
    theta0, body, legs, rep = 0.0, body0, legs0, report0
    for _ in range(2):  # lean
        theta = red.lean_angle(theta0, body, legs)
        if abs(theta - theta0) < 1e-4:
            break
        st2 = red.lean(theta)
        got2 = red.unshifted(st2, legs) or red.stand(st2, {}) or red.rebase(st2, {})
        if got2 is None or got2[0].margin < rep.margin - 0.05 * _body_px(rep):
            if red.rebased and got2 is not None:
                cur = (st2, got2)  # the legs were re-posed there: keep that lean
                repairs += 1
            break
        cur = (st2, got2)
        repairs += 1
        theta0, body, (rep, legs, _) = theta, st2.body, got2
        if rep.margin_fraction >= need:
            break
    if cur is None:
        return None
    st, got = cur
    best, repairs = _solve_shift(red, st, got, need, aim, repairs)
    if best[0].margin_fraction < need:
        return None
    return red, st, best[3], best[2][2], max(repairs, 1)


def _solve_shift(red: _Reduced, st: _Leaned, got0, need: float, aim: float, repairs: int):
    """Girdle shift of the leaned biped ``st`` on the reduced model until the margin reaches
    ``need`` (:func:`_search_shift`), then a wider stance where the lateral margin is short
    (× 1.35, at most three times); where the carried legs cannot balance it, they are posed
    afresh where they stood best and the search runs once more. Returns ``((report, legs
    part, stood, shifts), repairs)`` of the best state."""
    m = red.opts.min_margin_fraction
    best = (got0[0], got0[1], got0, {})

    def trial(shifts: dict):
        nonlocal best, repairs
        got = red.stand(st, shifts)
        if got is None:
            got = red.rebase(st, shifts)
            if got is None:
                return None
            best = (got[0], got[1], got, shifts)  # earlier states stood on the old legs
        repairs += 1
        if got[0].margin_fraction > best[0].margin_fraction:
            best = (got[0], got[1], got, shifts)
        return got[0].margin_fraction - aim

    for phase in range(2):
        _search_shift(red, st, best, trial, need, aim)
        for _ in range(3):  # the lateral margin: a wider stance
            rep, legs, _, shifts = best
            move = _shift_move(rep, legs, red.prev, shifts, m)
            if rep.margin_fraction >= need or move is None or move[0] != "width":
                break
            if trial(dict(shifts, width=shifts.get("width", 1.0) * 1.35)) is None:
                break
            if best[0].margin_fraction <= rep.margin_fraction:
                break
        if best[0].margin_fraction >= need or phase:
            break
        # the carried legs cannot balance it: pose them afresh where they stand best
        got = red.rebase(st, best[3], repose=True)
        if got is None:
            break
        repairs += 1
        best = (got[0], got[1], got, best[3])
    return best, repairs


def _search_shift(red: _Reduced, st: _Leaned, best, trial, need: float, aim: float) -> None:
    """Shift the leg girdle from the state ``best``: the first step 1.2 × the missing distance
    (:func:`_shift_move`), then secant steps on the margin towards ``aim`` until it reaches
    ``need``; a step that lowers the margin is halved back once, then the search stops
    (``trial(shifts)`` evaluates and keeps the best state)."""
    rep, legs, _, shifts = best
    move = _shift_move(rep, legs, red.prev, shifts, red.opts.min_margin_fraction)
    if move is None or move[0] == "width" or rep.margin_fraction >= need:
        return
    g, sign, delta = move
    s_prev, f_prev = shifts.get(g, 0.0), rep.margin_fraction - aim
    s_now, halved = s_prev + sign * 1.2 * delta, False
    for _ in range(_SHIFT_EVALS):
        f = trial(dict(shifts, **{g: s_now}))
        if f is None or f >= need - aim or halved:
            return
        if f > f_prev:  # secant on the margin
            d = s_now - s_prev
            step = float(np.clip(-f * d / (f - f_prev) * 1.05, -4 * abs(d), 4 * abs(d)))
            s_prev, f_prev, s_now = s_now, f, s_now + step
        else:  # past the best: back halfway, then stop
            s_now, halved = 0.5 * (s_prev + s_now), True


def _body_px(report) -> float:
    """The body length (px) a balance report measured its margin against."""
    f = report.margin_fraction
    return report.margin / f if abs(f) > 1e-15 else 0.0


def _shift_move(report, legs: _Part, limbs: LimbsState, shifts: dict, min_margin: float):
    """:func:`repair_shift`'s choice: ``(girdle, sign, missing distance)``, or ``("width", 0,
    0)`` to widen the stance, or ``None``."""
    com_x = report.com[0]
    x0, x1 = legs.patches[:, 0].min(), legs.patches[:, 0].max()
    span = max(x1 - x0, 1e-6)
    body = report.margin / report.margin_fraction if abs(report.margin_fraction) > 1e-15 else 0
    tm = min(0.45 * span, max(1.5 * min_margin * body, 0.08 * span))
    leg_girdles = sorted({p[0] for p in limbs.places if p[2].kind == "leg"})
    if com_x > x1 - tm:
        g = "shoulder" if "shoulder" in leg_girdles and len(leg_girdles) > 1 else leg_girdles[0]
        return g, -1.0, com_x - (x1 - tm)
    if com_x < x0 + tm:
        return ("hip" if "hip" in leg_girdles else leg_girdles[-1]), 1.0, (x0 + tm) - com_x
    if (
        report.margin < min_margin * body
        and shifts.get("width", 1.0) < 3.0
        and 0.5 * span >= _required(report, min_margin)
    ):
        return "width", 0.0, 0.0
    return None


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

    Repair (new beyond the seed): an unstable biped leans and shifts its leg girdle as
    chosen on the reduced model (:func:`_finish_biped`), then is posed and assembled once;
    other creatures (and a biped the reduced repair cannot help) shift the leg-bearing girdle
    on the failing side along the spine by the missing distance and re-ground its legs
    (:func:`_shift_loop`); the cheap re-check uses the fixed spine/skull masses plus the
    re-posed limbs.
    """
    leg_girdles = {p[0] for p in limbs.places if p[2].kind == "leg"}
    if len(leg_girdles) == 1:
        out = _finish_biped(spine, girdles, limbs, skull, opts, attempt_info)
        if out is not None:
            return out
    asm = assemble(spine, limbs, skull)
    report = balance_px(asm, opts)
    repairs = 0
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
    if report.applicable and not report.stable:
        limbs, asm, report, repairs = _shift_loop(
            spine, girdles, limbs, skull, asm, report, opts, repairs
        )
    return to_creature(asm, spine, girdles, limbs, skull, report, repairs, opts, attempt_info)


def _finish_biped(spine, girdles, limbs, skull, opts, attempt_info) -> Creature | None:
    """A biped: balance checked on the reduced model first; an unstable one is repaired
    there (:func:`_repair_biped`) and posed and assembled once. ``None`` leaves the creature
    to the iterative repair of :func:`finish` (stable on the reduced model — the full
    assembly then decides, as before — or nothing the reduced repair could do)."""
    quick = quick_report(spine, limbs, skull, opts)
    q = quick[0]
    if not q.applicable or q.margin_fraction > opts.min_margin_fraction - _EXACT_TOL:
        return None
    got = _repair_biped(spine, girdles, limbs, skull, opts, quick)
    if got is None:
        return None
    red, st, shifts, stood, repairs = got
    spine2 = st.spine
    out = None if stood is None else red.final(st, shifts, *stood)
    if out is not None:
        limbs2, skull2 = out
    else:
        try:
            limbs2 = red.limbs(st, shifts)
        except ParameterError:
            return None
        skull2 = step_skull(spine2, limbs2, opts, step_rng(opts.seed, "skull", 100))
    asm = assemble(spine2, limbs2, skull2)
    report = balance_px(asm, opts)
    if below_ground(asm):
        return None
    if not report.stable:  # the final pass moved the centre of mass: correct iteratively
        limbs2, asm, report, repairs = _shift_loop(
            spine2, girdles, limbs2, skull2, asm, report, opts, repairs, True
        )
    return to_creature(asm, spine2, girdles, limbs2, skull2, report, repairs, opts, attempt_info)


def _shift_loop(spine, girdles, limbs, skull, asm, report, opts, repairs, tol=False):
    """Girdle shifts (:func:`repair_shift`) re-checked cheaply (fixed spine/skull masses plus
    the re-posed limbs), then one assembly: ``(limbs, asm, report, repairs)``."""
    limbs0 = limbs
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
                carry=tol,
            )
        except ParameterError:
            break
        lvol, lmom, patches = limb_mass_and_patches(limbs, spine)
        com = (bmom + lmom) / max(bvol + lvol, 1e-30)
        report = bal.evaluate(
            com, bvol + lvol, patches, bl, opts.min_margin_fraction, float(com[1] - limbs.ground)
        )
        work = dict(work, patches=patches)
        repairs += 1
        if report.stable:
            break
    asm = assemble(spine, limbs, skull)
    return limbs, asm, balance_px(asm, opts), repairs
