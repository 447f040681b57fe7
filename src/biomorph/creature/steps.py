"""The generator's first four steps: spine, girdles, limbs and skull (seed §3.4, §5).

Each step is a pure function of the options, the earlier steps' states and its own random
stream; the states are the typed dataclasses of :mod:`biomorph.creature.states`. Units: the
seed's frame px (1000-px annotation frame); ``step_limbs`` and ``step_skull`` work in creature
coordinates (x forward, y up, z right).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.curves import bezier_eval
from biomorph.creature import feet
from biomorph.creature import girdles as gd
from biomorph.creature import limbs as lb
from biomorph.creature import mass as ms
from biomorph.creature import pca as pc
from biomorph.creature import skulls as sk
from biomorph.creature import spine as sp
from biomorph.creature import vertebrae as vt
from biomorph.creature.model import species_model
from biomorph.creature.options import Options
from biomorph.creature.stance import TARGET, allometric_height, trunk_key
from biomorph.creature.states import LimbsState, SkullState, SpineState
from biomorph.errors import ParameterError

DEG = np.pi / 180.0


def to_creature_px(points_px: NDArray) -> NDArray:
    """Frame px (head on the left, y up) → creature px coordinates (x forward, y up)."""
    p = np.array(points_px, float)
    p[..., 0] = 500.0 - p[..., 0]
    return p


# --------------------------------------------------------------------------- step: spine
def step_spine(opts: Options, rng: np.random.Generator, attempt: int = 0) -> SpineState:
    """Sample the PCA (conditioned on the options), read the discrete values as
    probabilities, inherit class/stance/skull/counts from the nearest species, C1-fix."""
    if opts.hoof_digits is not None and opts.legs is None:
        opts = replace(opts, legs=4)  # hoofed mammals stand on four legs
    m = species_model(opts.dataset)
    model: pc.PCA = m.pca
    table = m.table
    fixed: dict[int, float] = {}
    scores: dict[int, float] = {}
    class_pick: dict[str, Any] = {}
    if opts.legs is not None:
        fixed[pc.DIM["legs"]] = min(opts.legs, 4) / 4.0 / pc.SMALL
    if opts.wings is not None:
        fixed[pc.DIM["wings"]] = (1.0 if opts.wings else 0.0) / pc.SMALL
    if opts.weight is not None:
        fixed[pc.DIM["weight"]] = pc.weight_to_feature(opts.weight)
    if opts.neck_length is not None:
        d = m.neck_dir * opts.neck_length
        fixed[pc.NECK_OFFSET[0]], fixed[pc.NECK_OFFSET[1]] = float(d[0]), float(d[1])
    if opts.tail_length is not None:
        d = m.tail_dir * opts.tail_length
        fixed[pc.TAIL_OFFSET[0]], fixed[pc.TAIL_OFFSET[1]] = float(d[0]), float(d[1])
    if opts.cls is not None:
        members = m.cls_scores[opts.cls]
        if len(members):
            # condition on a point between the class centre and a random member, and on that
            # member's wings / legs unless the user fixed them
            centre = members.mean(axis=0)
            j = int(rng.integers(len(members)))
            target = centre + 0.6 * (members[j] - centre)
            ncomp = 3 if opts.k is None else min(3, opts.k)
            scores = {i: float(target[i]) for i in range(ncomp)}
            row = [i for i, c in enumerate(table.cls) if c == opts.cls][j]
            if opts.wings is None:
                fixed[pc.DIM["wings"]] = float(table.wings[row]) / pc.SMALL
                class_pick["wings"] = bool(table.wings[row])
            if opts.legs is None:
                fixed[pc.DIM["legs"]] = float(table.legs[row]) / 4.0 / pc.SMALL
                class_pick["legs"] = int(table.legs[row])
    user = {
        int(i): float(v) * float(np.sqrt(model.eigenvalues[int(i)]))
        for i, v in (opts.scores or {}).items()
    }
    if fixed or scores:
        scores.update(user)  # the user's component scores win over the class target
        x = model.sample_conditional(rng, fixed, scores, opts.k, opts.temperature, opts.jitter)
    else:
        x = model.sample(rng, 1, opts.k, opts.temperature)[0]
        if user:  # same draw as without scores; only the fixed components are replaced
            z = model.project(x[None], opts.k)[0]
            for i, v in user.items():
                z[i] = v
            x = model.reconstruct(z)
    raw = pc.decode(x, reparam=True)
    pts = raw["points"][0]
    lengths = np.clip(raw["lengths"][0], 0.0, None)
    weight = float(opts.weight if opts.weight is not None else raw["weight"][0])
    if opts.weight is None:  # sampled weights stay inside the data's range (no 1-cm animals)
        weight = float(np.clip(weight, table.weight.min(), table.weight.max()))
    feat = np.asarray(x, float)
    idx, w = _neighbours(model, x, table, opts)
    if opts.cls is not None:
        cls = opts.cls
    else:
        votes: dict[str, float] = {}
        for i, wi in zip(idx, w, strict=True):
            votes[table.cls[i]] = votes.get(table.cls[i], 0.0) + wi
        cls = max(votes, key=votes.get)
    # discrete values read as probabilities where they fall between the data's values
    wings_v = float(raw["wings"][0])
    legs_v = float(raw["legs"][0])
    if opts.wings is not None or "wings" in class_pick:
        wings = bool(opts.wings if opts.wings is not None else class_pick["wings"])
    else:
        wings = bool(rng.random() < np.clip(wings_v, 0.0, 1.0)) and cls != "fish"
    if opts.legs is not None or "legs" in class_pick:
        legs = int(opts.legs if opts.legs is not None else class_pick["legs"])
    else:
        lv = float(np.clip(legs_v, 0.0, 4.0))
        legs = (
            (2 if rng.random() < lv / 2 else 0)
            if lv <= 2
            else (4 if rng.random() < (lv - 2) / 2 else 2)
        )
    if opts.legs is None and "legs" not in class_pick:
        legs = CLASS_LEGS.get(cls, legs)  # class coherence: birds stand on two, fish swim
    if cls == "fish":  # fish: the shoulder girdle sits right behind the head (no neck)
        pts[0:3] = pts[3]
    pts = sp.c1_fix(level_trunk(pts, legs, cls))
    xy, s, region = sp.sample(pts)
    rl = sp.region_lengths(s, region)
    if opts.centaur and rl[0] < gd.CENTAUR_MIN_NECK * rl[1]:
        # rule propagation: a centaur girdle needs a long neck -> lengthen it
        pts = _scale_neck(pts, 1.05 * gd.CENTAUR_MIN_NECK * rl[1] / max(rl[0], 1e-6))
        pts = sp.c1_fix(pts)
        xy, s, region = sp.sample(pts)
        rl = sp.region_lengths(s, region)
    # inherited attributes (nearest species, inverse-distance weights)
    near = [table.name[i] for i in idx]
    pick = idx[int(np.argmax(w))]
    same = [i for i in idx if table.cls[i] == cls] or list(idx)
    ws = np.array([w[list(idx).index(i)] for i in same])
    ws = ws / ws.sum()
    stance = table.stance[same[0]] if cls != "bird" else "digitigrade"
    hooves = int(table.hoof_digits[same[0]]) if stance == "unguligrade" else 0
    if opts.hoof_digits is not None and cls == "mammal":
        stance, hooves = "unguligrade", int(opts.hoof_digits)
    posture = table.posture[same[0]]
    skull_name = table.skull[same[0]] if table.cls[same[0]] == cls else sk.CLASS_SKULL[cls]
    back_chord = float(np.linalg.norm(pts[6] - pts[3]))
    ratio = float(
        ws
        @ (
            table.skull_length[same]
            / np.maximum(np.linalg.norm(table.points[same, 6] - table.points[same, 3], axis=1), 1.0)
        )
    )
    girth = float(ws @ table.girth[same])
    counts = vt.region_counts(cls, table.counts[same], ws, rl, m.region_len[same])
    return SpineState(
        points=pts,
        lengths=lengths,
        weight=weight,
        wings=wings,
        legs=legs,
        cls=cls,
        stance=stance,
        posture=posture,
        skull=skull_name,
        skull_length=max(ratio * max(back_chord, 0.05 * s[-1]), 0.03 * s[-1]),
        girth=girth,
        counts=counts,
        neighbours=near,
        features=feat,
        wings_value=wings_v,
        legs_value=legs_v,
        nearest=table.name[pick],
        hoof_digits=hooves,
    )


#: Leg counts a class always has when the user does not ask for others.
CLASS_LEGS = {"bird": 2, "fish": 0}


def _compatible(cls: str, opts: Options) -> bool:
    """May a sample of class ``cls`` carry the requested legs / wings (class coherence: no
    four-legged birds, no legged or winged fish unless the class is asked for)?"""
    if opts.hoof_digits is not None and cls != "mammal":
        return False  # hooves: an ungulate mammal
    if opts.legs is not None:
        if opts.legs >= 2 and cls == "fish":
            return False
        if opts.legs != 2 and cls == "bird":
            return False
    return not (opts.wings and cls == "fish")


def _neighbours(
    model: pc.PCA, x: NDArray, table, opts: Options
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The three nearest species (inverse-distance weights) among those whose class is
    compatible with the request; with ``--class`` the nearest of any class (the class is
    fixed, only stance/skull/counts are inherited from them)."""
    idx, w = model.nearest(x, n_neighbours=len(table.name))
    keep = [
        k for k, i in enumerate(idx) if opts.cls is not None or _compatible(table.cls[i], opts)
    ][:3] or [0, 1, 2]
    ww = w[keep] / w[keep].sum()
    return idx[keep], ww


def trunk_pitch(points: NDArray) -> float:
    """Back chord (hip p6 → shoulder p3) above the horizontal, frame px (head on the left),
    radians, + = shoulders higher."""
    d = np.asarray(points, float)[3] - np.asarray(points, float)[6]
    return float(np.arctan2(d[1], -d[0]))


def level_trunk(points: NDArray, legs: int, cls: str | None = None) -> NDArray:
    """Rotate the spine rigidly about the hip (p6) so the trunk pitch lies in the standing
    range of the body plan (:data:`biomorph.creature.stance.TARGET`, :func:`stance.trunk_key`:
    birds on two legs, other bipeds, quadrupeds; a bird's sampled pitch is mapped linearly
    from the bipeds' range onto the birds'); legless bodies keep the sampled curve. Rigid
    rotation keeps the C1 joins."""
    if legs == 0:
        return points
    key = trunk_key(cls, legs)
    lo, hi = TARGET[key]
    a = trunk_pitch(points)
    if key == "trunk_pitch_bird":
        # the sampled back's place in the bipeds' range mapped onto the birds' (a clamp
        # would stand half of them at its lower end): the PCA's spread is kept
        b0, b1 = TARGET["trunk_pitch_biped"]
        u = float(np.clip((a / DEG - b0) / (b1 - b0), 0.0, 1.0))
        want = (lo + u * (hi - lo)) * DEG
    else:
        want = float(np.clip(a, lo * DEG, hi * DEG))
    if abs(want - a) < 1e-12:
        return points
    phi = a - want  # CCW rotation in the frame (head on the left) lowers the front
    c, s_ = np.cos(phi), np.sin(phi)
    p = np.asarray(points, float)
    q = p - p[6]
    return p[6] + np.stack([c * q[:, 0] - s_ * q[:, 1], s_ * q[:, 0] + c * q[:, 1]], axis=1)


def _scale_neck(points: NDArray, factor: float) -> NDArray:
    p = np.array(points, float)
    p[0:3] = p[3] + (p[0:3] - p[3]) * factor
    return p


# --------------------------------------------------------------------------- step: girdles
def step_girdles(
    spine: SpineState, opts: Options, rng: np.random.Generator
) -> tuple[gd.Girdle, ...]:
    """Girdles and limb pairs from the discrete choices (rules in :mod:`girdles`)."""
    xy, s, region = sp.sample(spine.points)
    rl = sp.region_lengths(s, region)
    L = np.asarray(spine.lengths, float)
    back = max(rl[1], 0.05 * s[-1])
    fore, hind = L[:3].copy(), L[3:].copy()
    legs = spine.legs
    wings = spine.wings
    # sampled (not requested) wings yield when the shoulder girdle is already full
    shoulder = (
        (1 if legs >= 4 else 0)
        + (1 if legs == 6 else 0)
        + (1 if opts.arms and not opts.centaur else 0)
    )
    if wings and opts.wings is None and shoulder >= gd.MAX_PAIRS:
        wings = False
    # a limb that must carry the body gets at least a minimal length per segment
    if legs >= 2:
        hind = np.maximum(hind, 0.08 * back)
    if legs >= 4 or wings or opts.arms or opts.centaur:
        fore = np.maximum(fore, 0.08 * back)
    return gd.plan(spine.cls, legs, wings, opts.arms, opts.centaur, fore, hind, rl)


# --------------------------------------------------------------------------- step: limbs
def _frame_at(xy: NDArray, s: NDArray, at: float) -> tuple[NDArray, NDArray, NDArray]:
    """Point, tail-ward tangent and dorsal normal of the spine (creature px) at arc ``at``."""
    g = sp.point_at(xy, s, at)
    t = sp.tangent_at(xy, s, at)
    n = np.array([t[1], -t[0]])
    if n[1] < 0:
        n = -n
    return g, t, n


def _attach(
    xy,
    s,
    rl,
    girth,
    cls,
    skull_h,
    legless,
    girdle: str,
    at: float,
    kind: str,
    posture: str,
    width: float = 1.0,
) -> tuple[NDArray, NDArray]:
    """Spine point (3,) and limb attachment point (3,) of the right limb of a pair."""
    g, t, n = _frame_at(xy, s, at)
    h, b, _ = ms.profile(np.array([at]), rl, girth, cls, skull_h, legless)
    drop = {"leg": 0.35, "arm": 0.3, "wing": 0.12, "fin": 0.3}[kind] * h[0]
    if girdle == "hip":
        drop *= 0.75
    half = 0.45 * b[0] * (1.35 if posture == "sprawling" else 1.0) * width
    a2 = g - drop * n
    return np.array([g[0], g[1], 0.0]), np.array([a2[0], a2[1], half])


_DROP = {"leg": 0.35, "arm": 0.3, "wing": 0.12, "fin": 0.3}


def _attach_all(xy, s, rl, spine, skull_h, legless, places, width: float) -> list:
    """:func:`_attach` for every placement at once (the same arithmetic: the spine's points
    and profile as arrays, the few per-placement products as plain floats — IEEE doubles
    like NumPy's element-wise ones, without its per-call cost on arrays of two to six)."""
    if not places:
        return []
    at = np.array([p[3] for p in places], float)
    k = len(at)
    # point_at and tangent_at (central differences) in one interpolation
    h = max(s[-1] * 1e-3, 1e-9)
    q = sp.point_at(xy, s, np.concatenate([at, at + h, at - h])).tolist()
    hh, b, _ = ms.profile(at, rl, spine.girth, spine.cls, skull_h, legless)
    hh, b = hh.tolist(), b.tolist()
    sprawl = 1.35 if spine.posture == "sprawling" else 1.0
    out = []
    for i, p in enumerate(places):
        gx, gy = q[i]
        dx, dy = q[k + i][0] - q[2 * k + i][0], q[k + i][1] - q[2 * k + i][1]
        nd = math.sqrt(dx * dx + dy * dy)  # np.linalg.norm's sum of squares and sqrt
        if nd > 0:
            dx, dy = dx / nd, dy / nd
        nx, ny = dy, -dx  # the normal, turned upwards
        if ny < 0:
            nx, ny = -nx, -ny
        drop = _DROP[p[2].kind] * hh[i]
        if p[0] == "hip":
            drop = drop * 0.75
        half = 0.45 * b[i] * sprawl
        half = half * (width if p[2].kind == "leg" else 1.0)
        out.append((np.array([gx, gy, 0.0]), np.array([gx - drop * nx, gy - drop * ny, half])))
    return out


#: The Bernstein basis at 17 samples (``bezier_eval(seg, np.linspace(0, 1, 17))`` is
#: ``einsum(basis, seg)``; the basis is computed once).
_BASIS17 = bezier_eval(np.eye(4), np.linspace(0, 1, 17))


def _flatten(points: NDArray, which: str, floor: float) -> NDArray:
    """Raise a drooping tail (or neck) above ``floor`` keeping the join's tangent (C1)."""
    base, inner, outer = (6, 7, (8, 9)) if which == "tail" else (3, 2, (1, 0))
    p = np.array(points, float)
    for alpha in (0.7, 0.45, 0.25, 0.1, 0.0):
        q = p.copy()
        for k in outer:
            q[k, 1] = p[base, 1] + alpha * (p[k, 1] - p[base, 1])
        q[inner] = p[base] + max(alpha, 0.25) * (p[inner] - p[base])
        seg = q[6:10] if which == "tail" else q[0:4]
        if np.einsum("mk,...kd->...md", _BASIS17, seg)[:, 1].min() >= floor:
            return q
        p_last = q
    return p_last


def _allometric_ground(
    spine: SpineState, places, attach, lengths, legs, s, rl, skull_h, stand_fraction: float
) -> float | None:
    """Ground height (creature px) at which the withers (quadrupeds) or hip (bipeds) stand at
    the allometric height of :mod:`biomorph.creature.stance`, or ``None`` where none applies.

    The metres-per-px scale is the one ``finish`` will use, ``(w / (ρ V))^(1/3)``, and the
    volume ``V`` grows with the legs, which are resized so that each stands at
    ``stand_fraction`` of its reach above the ground: ``V(y) = V_body + Σ V_leg,i · g_i(y)³``
    with ``g_i = (a_i − y) / (f · reach_i)``. The standing height ``(top − y) · scale(y)`` is
    solved for ``y`` by bisection (the smallest legs that reach it); where heavy legs keep the
    height below the target at every size (their volume grows as fast as their length), the
    tallest attainable stance is taken."""
    cls = spine.cls
    h_m = allometric_height(cls, spine.posture, spine.weight)
    if h_m is None:
        return None
    girdle = "shoulder" if spine.legs >= 4 else "hip"
    top = [attach[i][0][1] for i in legs if places[i][0] == girdle]
    if not top:
        return None
    h, b, _ = ms.profile(s, rl, spine.girth, cls, skull_h, spine.legs == 0)
    body = float(ms.slice_volumes(s, h, b).sum()) + ms.ellipsoid_volume(
        sk.box_size(sk.get(spine.skull), spine.skull_length)
    )
    body += sum(
        2 * float(ms.limb_volume(lengths[i], p[2].kind).sum())
        for i, p in enumerate(places)
        if i not in legs
    )
    a = np.array([attach[i][1][1] for i in legs], float)
    reach = np.array(
        [stand_fraction * lb.max_reach(lengths[i], spine.stance, spine.posture) for i in legs]
    )
    v1 = np.array([2 * float(ms.limb_volume(lengths[i], "leg").sum()) for i in legs])
    k = (spine.weight / ms.density(cls)) ** (1.0 / 3.0)
    top0 = float(top[0])

    legs_av = [
        (float(ai), max(float(ri), 1e-12), float(vi))
        for ai, ri, vi in zip(a, reach, v1, strict=True)
    ]

    def excess(y: float) -> float:  # standing height (m) minus the allometric height
        vol = 0.0  # Σ v1_i · g_i³ in order (plain floats: the same IEEE operations)
        for q, (ai, ri, vi) in enumerate(legs_av):
            term = vi * (max(ai - y, 1e-9) / ri) ** 3.0
            vol = term if q == 0 else vol + term
        return (top0 - y) * k / (body + vol) ** (1.0 / 3.0) - h_m

    # the height grows from 0 (legs of no length, ground at the lowest attachment) and
    # approaches a limit as the legs grow; scan outwards for the first crossing
    hi = float(a.min())  # ground at the attachment: no height
    span = max(float(np.max(reach)), float(s[-1]), 1.0)
    lo, best, f_best = hi, hi, -np.inf
    for _ in range(40):
        hi, lo = lo, lo - span
        f_lo = excess(lo)
        if f_lo > f_best:
            best, f_best = lo, f_lo
        if f_lo >= 0:
            break
        span *= 1.6
    else:
        return best  # the legs' own weight keeps it below the target: tallest stance found
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if excess(mid) >= 0:
            lo = mid
        else:
            hi = mid
    return float(lo)


def _girdle_rise(spine: SpineState, places, attach, previous: LimbsState) -> float:
    """Height change (px) of the withers (quadrupeds: shoulder) or hip (bipeds) spine point
    between ``previous`` and the new placement — the girdle
    :func:`biomorph.creature.quality.standing_height` measures."""
    girdle = "shoulder" if spine.legs >= 4 else "hip"
    for i, p in enumerate(places):
        if p[0] == girdle and p[1] == 0 and p[2].kind == "leg":
            return float(attach[i][0][1] - previous.attach[i][0][1])
    return 0.0


def placements(girdles, shifts: dict[str, float], rl: NDArray, s: NDArray) -> list:
    """Limb placements ``(girdle name, pair index, spec, arc position)``: each girdle's
    position plus its balance-repair shift; a second pair a little apart, towards the body
    centre; clamped to the spine."""
    places = []
    for g in girdles:
        for k, spec in enumerate(g.pairs):
            at = g.at + shifts.get(g.name, 0.0)
            if k == 1:  # second pair a little apart, towards the body centre
                step = 0.18 * max(rl[1], 1e-6)
                at = at + step if g.name in ("shoulder", "centaur") else at - step
            at = min(max(float(at), 0.0), float(s[-1]))  # np.clip on a float
            places.append((g.name, k, spec, at))
    return places


def carried_ground(spine: SpineState, places, attach, previous: LimbsState, legs) -> float:
    """Ground height (creature px) under legs that keep their joint angles and move with their
    attachments (``attach`` indexable by place): the lowest foot's contact less the height
    its digits need (:func:`feet.clearance`)."""
    out = np.inf
    for i in legs:
        role = "hind" if places[i][0] == "hip" else "fore"
        plan = feet.digit_plan("leg", role, spine.cls, spine.stance, spine.skull, spine.hoof_digits)
        L3 = previous.lengths[i]
        pose = previous.poses[i]
        _, p = lb.forward(attach[i][1], L3, pose.angles)
        out = min(out, float(p[2 if pose.foot_flat else 3, 1]) - feet.clearance(plan, float(L3[2])))
    return out


def step_limbs(
    spine: SpineState,
    girdles: tuple[gd.Girdle, ...],
    opts: Options,
    rng: np.random.Generator,
    shifts: dict[str, float] | None = None,
    ground: float | None = None,
    previous: LimbsState | None = None,
    carry: bool = False,
    repose: bool = False,
) -> LimbsState:
    """Ground height, grounded legs by the seed's descent, free limbs by rule (frame px).

    With ``previous`` (balance repair) the legs keep their poses and are re-grounded at the
    new attachments; the ground follows the girdle the standing height is measured at
    (``ground`` + its rise) or, with ``carry`` (the bipeds' repair), lies under the feet of
    the legs carried rigidly with their attachments (:func:`carried_ground`; re-grounding
    then :func:`limbs.reground`'s continuous one) and wings keep their angles; ``repose``
    poses the legs afresh there by the descent instead of re-grounding them."""
    pts = to_creature_px(spine.points)
    cls, posture, stance = spine.cls, spine.posture, spine.stance
    legless = spine.legs == 0
    xy, s, region = sp.sample(pts)
    rl = sp.region_lengths(s, region)
    skull_h = sk.get(spine.skull).height * spine.skull_length
    shifts = shifts or {}
    places = placements(girdles, shifts, rl, s)
    attach = _attach_all(xy, s, rl, spine, skull_h, legless, places, shifts.get("width", 1.0))
    legs = [i for i, p in enumerate(places) if p[2].kind == "leg"]
    lengths = [np.array(p[2].lengths, float) for p in places]
    if previous is not None and ground is not None and len(previous.places) == len(places):
        # balance repair: the legs keep the lengths they were sized to (allometric height),
        # and the ground follows the girdle the standing height is measured at, so a girdle
        # moved along a pitched spine carries its legs instead of stretching them
        for i in legs:
            lengths[i] = np.array(previous.lengths[i], float)
        if carry:
            ground = carried_ground(spine, places, attach, previous, legs)
        else:
            ground = ground + _girdle_rise(spine, places, attach, previous)
    h_all, _, off_all = ms.profile(s, rl, spine.girth, cls, skull_h, legless)
    body_bottom = xy[:, 1] - np.where(region == 1, 0.35, 0.2) * h_all
    if legs:
        reach = [lb.max_reach(lengths[i], stance, posture) for i in legs]
        if ground is None:
            target = _allometric_ground(
                spine, places, attach, lengths, legs, s, rl, skull_h, opts.stand_fraction
            )
            if target is not None:  # legs sized so the body stands at its allometric height
                for i, r in zip(legs, reach, strict=True):
                    lengths[i] = (
                        lengths[i] * max(attach[i][1][1] - target, 1e-6) / (opts.stand_fraction * r)
                    )
                reach = [lb.max_reach(lengths[i], stance, posture) for i in legs]
            ground = max(
                attach[i][1][1] - opts.stand_fraction * r for i, r in zip(legs, reach, strict=True)
            )
            # every leg must reach down at least a quarter of its length (a low hip under a
            # high shoulder): lower the ground; the legs that then fall short are stretched
            ground = min(
                [ground] + [attach[i][1][1] - 0.25 * r for i, r in zip(legs, reach, strict=True)]
            )
        trunk = region == 1
        lowest_trunk = float(body_bottom[trunk].min()) if trunk.any() else ground
        if lowest_trunk < ground:
            ground = lowest_trunk  # legs too short for this body: lower the ground ...
        for i, r in zip(legs, reach, strict=True):  # ... and stretch legs that cannot reach
            need = (attach[i][1][1] - ground) / opts.stand_fraction
            if need > r:
                lengths[i] = lengths[i] * (need / r)
            # a leg far too long for its height would start (fully bent) below the ground:
            # shorten it until its start pose clears the ground (rule propagation)
            role = "hind" if places[i][0] == "hip" else "fore"
            start = lb.start_pose(role, posture, opts.descent.plausible)
            for _ in range(30):
                _, p0 = lb.forward(attach[i][1], lengths[i], start)
                if p0[1:, 1].min() >= ground:
                    break
                lengths[i] = lengths[i] * 0.9
        # neck and tail must stay above the ground (bones), keeping C1 at the joins
        clear = ground + 0.02 * max(s[-1], 1.0)
        for which, reg in (("tail", 2), ("neck", 0)):
            if (region == reg).any() and xy[region == reg, 1].min() < clear:
                pts = _flatten(pts, which, clear)
        xy, s, region = sp.sample(pts)
    else:
        ground = None
    if legs and any(attach[i][1][1] <= ground for i in legs):
        raise ParameterError("a leg attachment lies below the ground")  # repair path only
    lean = _trunk_lean(places, attach)
    poses = []
    for i, (gname, _k, spec, _at) in enumerate(places):
        base = attach[i][1]
        if spec.kind == "leg":
            role = "hind" if gname == "hip" else "fore"
            plan = feet.digit_plan("leg", role, cls, stance, spine.skull, spine.hoof_digits)
            pose = None
            if previous is not None and not repose:  # repair: keep the pose, re-ground
                prev = previous.poses[i]
                lift = feet.clearance(plan, float(previous.lengths[i][2]))
                pose = lb.reground(
                    prev, base, previous.lengths[i], ground + lift, opts.descent, carry
                )
                if pose is not None:
                    lengths[i] = previous.lengths[i]
            if pose is None:
                pose = _pose_leg(spine, opts, rng, base, lengths[i], ground, role, plan)
            lengths[i] = pose.lengths
        elif carry and spec.kind == "wing":  # the bipeds' repair: wings keep their angles
            pose = carried_wing(spine, previous.poses[i], base, lengths[i], ground, s, rng)
        else:
            floor = None if ground is None else ground + 0.01 * max(s[-1], 1.0)
            pose = _pose_free(spine, spec.kind, base, lengths[i], rng, lean, xy, floor)
        poses.append(pose)
    _knees_behind_elbows(spine, opts, rng, places, attach, lengths, poses, ground)
    if ground is None:
        lows = [xy[:, 1].min() - 0.5 * float(h_all.min())]
        lows += [p.points[:, 1].min() for p in poses]
        ground = float(min(lows))
    else:
        clear = 0.01 * max(s[-1], 1.0)  # lift_clear's clearance is above ``ground``
        poses = [
            lb.lift_clear(
                p,
                attach[i][1],
                lengths[i],
                ground,
                clear
                + (
                    wing_reach(spine, lengths[i], attach[i][1][1] - ground)
                    if carry and p.kind == "wing"
                    else 0.0
                ),
            )
            if p.kind != "leg"
            else p
            for i, p in enumerate(poses)
        ]
    return LimbsState(
        points=pts,
        ground=float(ground),
        places=places,
        attach=attach,
        lengths=lengths,
        poses=poses,
        shifts=dict(shifts),
    )


def carried_wing(spine, pose, base, lengths, ground: float, s: NDArray, rng) -> lb.LimbPose:
    """A wing in the bipeds' repair: its angles at the new attachment, folded
    (:func:`limbs.lift_clear`) until it and its digits clear the ground by
    :func:`wing_reach`; drawn again from the repair's stream where folding cannot."""
    lift = 0.01 * max(s[-1], 1.0) + wing_reach(spine, lengths, base[1] - ground)
    out = lb.moved(pose, base, lengths)
    if np.all(out.points[1:, 1] >= ground + lift):
        return out
    out = lb.lift_clear(out, base, lengths, ground, lift)
    if np.all(out.points[1:, 1] >= ground + lift):
        return out
    return lb.pose_free("wing", base, lengths, rng, cls=spine.cls)


def wing_reach(spine: SpineState, lengths: NDArray, height: float) -> float:
    """Clearance (px) a wing kept in its pose during the bipeds' repair keeps above the ground
    besides the free limbs' own: how far its digits reach beyond its hand, plus 5 % of its
    attachment's ``height`` above the ground (a walk lowers the body by up to 4 % of the hip
    height, :mod:`biomorph.creature.walk`)."""
    plan = feet.digit_plan("wing", "fore", spine.cls, spine.stance, spine.skull)
    reach = max((sum(d.fractions) for d in plan), default=0.0) * float(lengths[2])
    return reach + 0.05 * max(float(height), 0.0)


def _pose_free(spine, kind, base, lengths, rng, lean, xy, floor) -> lb.LimbPose:
    """A free limb; an arm keeps its fingertips behind the head's front: the atlas plus the
    skull at its steepest allowed pitch (``TARGET['head_pitch']``); with the head behind the
    shoulder, as far back as the arm folds."""
    if kind != "arm":
        return lb.pose_free(kind, base, lengths, rng, cls=spine.cls)
    pitch = max(abs(v) for v in TARGET["head_pitch"]) * np.pi / 180.0
    front = float(xy[0, 0]) + float(spine.skull_length) * np.cos(pitch)
    plan = feet.digit_plan("arm", "fore", spine.cls, spine.stance, spine.skull)
    share = max((sum(d.fractions) for d in plan), default=0.0)
    return lb.pose_free(
        kind,
        base,
        lengths,
        rng,
        cls=spine.cls,
        trunk_lean=lean,
        front=front,
        finger_share=share,
        floor=floor,
    )


def _trunk_lean(places, attach) -> float:
    """Forward lean (rad) of the trunk line from the hip girdle to the first shoulder girdle
    (0 upright, π/2 horizontal with the head ahead); π/2 without both girdles."""
    hip = [attach[i][0] for i, p in enumerate(places) if p[0] == "hip"]
    sho = [attach[i][0] for i, p in enumerate(places) if p[0] == "shoulder"]
    if not hip or not sho:
        return float(np.pi / 2)
    d = np.asarray(sho[0], float) - np.asarray(hip[0], float)
    return float(np.arctan2(d[0], d[1]))


def _pose_leg(spine, opts, rng, base, lengths, ground, role, plan, lean_max=None):
    return lb.pose_leg(
        base,
        lengths,
        ground,
        role,
        spine.stance,
        spine.posture,
        rng,
        opts.descent,
        feet.clearance(plan, float(lengths[2])),
        None if spine.cls == "bird" else TARGET["femur_max"],
        lean_max,
        TARGET["femur_min_bird"] if spine.cls == "bird" else None,
    )


#: Gap kept between the hind knees and the front elbows when they would overlap, as a
#: fraction of the distance between the hip and shoulder attachments.
KNEE_GAP = 0.05


def _knees_behind_elbows(spine, opts, rng, places, attach, lengths, poses, ground) -> None:
    """Quadrupeds: every hind knee stands behind every front elbow (the femur leans
    forward, the humerus back). Where the posed legs overlap, the femur's forward and the
    humerus' backward lean are capped so each upper bone stays on its side of a split
    point between the attachments (shared in proportion to the bones' lengths), and those
    legs are posed again (in place, ``poses`` and ``lengths`` updated)."""
    hind = [i for i, p in enumerate(places) if p[2].kind == "leg" and p[0] == "hip"]
    fore = [i for i, p in enumerate(places) if p[2].kind == "leg" and p[0] != "hip"]
    if not hind or not fore:
        return
    knee = max(poses[i].points[1, 0] for i in hind)
    elbow = min(poses[i].points[1, 0] for i in fore)
    if knee < elbow:
        return
    xh = max(attach[i][1][0] for i in hind)
    xf = min(attach[i][1][0] for i in fore)
    gap = xf - xh
    if gap <= 0:
        return  # hips ahead of the shoulders: nothing to split (balance repair resamples)
    lh = max(float(lengths[i][0]) for i in hind)
    lf = max(float(lengths[i][0]) for i in fore)
    usable = (1.0 - KNEE_GAP) * gap
    split = xh + usable * lh / max(lh + lf, 1e-12)
    for idx, end, L in ((hind, split, lh), (fore, split + KNEE_GAP * gap, lf)):
        for i in idx:
            reach = abs(end - attach[i][1][0]) if i in hind else abs(attach[i][1][0] - end)
            cap = float(np.degrees(np.arcsin(np.clip(reach / max(L, 1e-12), 0.0, 1.0))))
            if (i in hind and poses[i].points[1, 0] < end) or (
                i in fore and poses[i].points[1, 0] > end
            ):
                continue  # this leg already clears the split point
            role = "hind" if i in hind else "fore"
            plan = feet.digit_plan(
                "leg", role, spine.cls, spine.stance, spine.skull, spine.hoof_digits
            )
            pose = _pose_leg(
                spine, opts, rng, attach[i][1], lengths[i], ground, role, plan, lean_max=cap
            )
            poses[i] = pose
            lengths[i] = pose.lengths


# --------------------------------------------------------------------------- step: skull
def step_skull(
    spine: SpineState, limbs: LimbsState, opts: Options, rng: np.random.Generator
) -> SkullState:
    """Pick the skull from the library, size and orient it, keep it above the ground."""
    shape = sk.get(spine.skull)
    length = float(spine.skull_length)
    pts = limbs.points
    xy, s, _ = sp.sample(pts)
    head = np.array([xy[0, 0], xy[0, 1]])
    fwd = -sp.tangent_at(xy, s, 0.0)
    if shape.follow_spine or np.linalg.norm(pts[0] - pts[3]) < 1e-6:
        ang = float(np.arctan2(fwd[1], fwd[0]))
    else:
        ang = -(shape.pitch_deg + rng.uniform(-6.0, 6.0)) * DEG
    floor = limbs.ground + 0.01 * max(s[-1], 1.0)
    for _ in range(12):
        d = np.array([np.cos(ang), np.sin(ang)])
        tip = head + length * d
        low = min(tip[1], head[1]) - 0.5 * shape.height * length * abs(np.cos(ang))
        if low >= floor or ang > 60 * DEG:
            break
        ang += 10 * DEG
    lo, hi = TARGET["head_pitch"]
    ang = float(np.clip(ang, lo * DEG, hi * DEG))
    return SkullState(shape=shape.name, length=length, angle=float(ang), origin=head)
