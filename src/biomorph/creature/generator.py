"""Stepwise creature generation: spine → girdles → limbs → skull → finish (seed §3.4, §5).

:class:`Generator` runs the steps one at a time; every step can be undone, re-rolled with
another seed or edited, and later steps are re-run so rules propagate (a changed leg is
grounded again; a centaur girdle lengthens a short neck; impossible edits raise
:class:`~biomorph.errors.ParameterError` naming the reason). Each step draws from its own
random stream derived from ``(seed, step, re-roll count)``, so the same seed and options give
the identical creature, and re-rolling one step leaves the others' randomness unchanged.

Units: the first four steps work in the seed's frame units (px of the 1000-px annotation
frame, creature coordinates: x forward, y up, z right); ``finish`` sizes the creature from its
weight (:mod:`biomorph.creature.mass`) and returns metres with the ground at ``y = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.creature import anatomy as an
from biomorph.creature import balance as bal
from biomorph.creature import girdles as gd
from biomorph.creature import limbs as lb
from biomorph.creature import mass as ms
from biomorph.creature import pca as pc
from biomorph.creature import skulls as sk
from biomorph.creature import spine as sp
from biomorph.creature import vertebrae as vt
from biomorph.creature.creature import Creature
from biomorph.creature.dataset import CLASSES, load_species
from biomorph.errors import InputError, ParameterError

STEPS = ("spine", "girdles", "limbs", "skull", "finish")
LEG_COUNTS = (0, 2, 4, 6)
DEG = np.pi / 180.0
_M = np.diag([1.0, 1.0, -1.0])

#: Relative joint ranges (degrees, about local x, y, z) for spine/skull/girdle bones.
SPINE_RANGE = {"neck": (20, 15, 30), "back": (5, 5, 8), "tail": (15, 12, 20),
               "head": (25, 20, 40), "girdle": (5, 5, 10)}


#: Largest |score| (standard deviations) accepted in :attr:`Options.scores`.
MAX_SCORE = 4.0


@dataclass(frozen=True)
class Options:
    """What the user asks for. ``None`` means "sample it".

    legs : legs with ground contact, 0/2/4/6. wings / arms / centaur : limb choices.
    weight : kg. neck_length / tail_length : neck / tail chord in frame units (1.0 = the
    1000-px frame, i.e. the largest extent of the skeleton). cls : animal class.
    k : PCA components to sample from (None = all 29). temperature : variance scale.
    jitter : scale of the jitter interval on conditioned values.
    scores : fixed PCA component scores ``{component index (0-based): score}`` in standard
    deviations of that component (units of ``sqrt(eigenvalue)``, independent of the
    temperature), |score| <= 4; the other components are sampled as without them.
    stand_fraction : the shortest leg stands at this fraction of its straightened reach.
    require_stable : repair or resample until statically stable.
    """

    seed: int = 0
    legs: int | None = None
    wings: bool | None = None
    arms: bool = False
    centaur: bool = False
    weight: float | None = None
    neck_length: float | None = None
    tail_length: float | None = None
    cls: str | None = None
    k: int | None = None
    temperature: float = 1.0
    jitter: float = 1.0
    descent: lb.DescentParams = field(default_factory=lb.DescentParams)
    stand_fraction: float = 0.8
    require_stable: bool = True
    min_margin_fraction: float = 0.02
    max_resamples: int = 25
    dataset: str | None = None
    scores: dict[int, float] | None = None

    def __post_init__(self) -> None:
        # own copy: later changes to the caller's dict do not leak into the options
        if self.scores is not None:
            object.__setattr__(self, "scores", dict(self.scores))

    def validate(self) -> Options:
        """Raise :class:`ParameterError` for impossible requests; return self."""
        if self.scores is not None:
            n = pc.N_DIMS if self.k is None else int(self.k)
            for idx, val in self.scores.items():
                if isinstance(idx, bool) or not isinstance(idx, (int, np.integer)) \
                        or not 0 <= idx < n:
                    raise ParameterError(f"PCA component {idx!r}: expected an index 0..{n - 1} "
                                         f"(the model's {n} sampled components)")
                try:
                    v = float(val)
                except (TypeError, ValueError):
                    v = float("nan")
                if not (np.isfinite(v) and abs(v) <= MAX_SCORE):
                    raise ParameterError(f"PCA component {idx} score {val!r}: expected a finite "
                                         f"score in -{MAX_SCORE:g}..{MAX_SCORE:g} standard "
                                         "deviations")
        if self.legs is not None and self.legs not in LEG_COUNTS:
            raise ParameterError(f"legs={self.legs}: legs come in pairs with ground contact; "
                                 "expected 0, 2, 4 or 6")
        if self.weight is not None and not (np.isfinite(self.weight) and self.weight > 0):
            raise ParameterError(f"weight={self.weight} kg: expected a positive weight in kg")
        if self.cls is not None and self.cls not in CLASSES:
            raise ParameterError(f"class {self.cls!r} unknown; expected one of "
                                 f"{', '.join(CLASSES)}")
        for name in ("neck_length", "tail_length"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and 0 <= v <= 1.5):
                raise ParameterError(f"{name.replace('_', '-')}={v}: expected 0..1.5 frame "
                                     "units (1 = the skeleton's largest extent)")
        if self.cls == "fish":
            if self.wings:
                raise ParameterError("wings need a shoulder joint (scapula with a wing socket); "
                                     "class fish has only fin girdles")
            if self.legs:
                raise ParameterError(f"legs={self.legs} with class fish: fish have fins, no "
                                     "legs with ground contact")
            if self.arms or self.centaur:
                raise ParameterError("arms/centaur need a tetrapod shoulder; class fish has "
                                     "only fin girdles")
        if self.legs == 6 and self.wings and self.arms:
            raise ParameterError("six legs, wings and arms need three shoulder limb pairs; a "
                                 "girdle holds at most two")
        if self.legs == 6 and (self.wings or self.arms) and not self.centaur:
            raise ParameterError("six legs fill the shoulder girdle (two leg pairs); wings or "
                                 "arms need a free shoulder slot (use --centaur for arms)")
        if not 0 < self.stand_fraction <= 1:
            raise ParameterError(f"stand_fraction={self.stand_fraction}: expected 0 < f <= 1")
        if self.temperature < 0 or self.jitter < 0:
            raise ParameterError("temperature and jitter must be >= 0")
        return self


# --------------------------------------------------------------------------- model cache
@lru_cache(maxsize=8)
def _model(dataset: str | None):
    table = load_species(dataset)
    model = pc.fit_dataset(table, reparam=True)
    feats = pc.encode(table.points, table.lengths, table.wings, table.legs, table.weight)
    region_len = np.array([sp.region_lengths(*sp.sample(p, 16)[1:]) for p in table.points])
    off_n = table.points[:, 0] - table.points[:, 3]
    off_t = table.points[:, 9] - table.points[:, 6]

    def mean_dir(off):
        n = np.linalg.norm(off, axis=1)
        keep = n > 20
        d = (off[keep] / n[keep, None]).mean(axis=0)
        return d / np.linalg.norm(d)

    cls_scores = {c: model.scores[[i for i, x in enumerate(table.cls) if x == c], :3]
                  for c in CLASSES}
    return dict(table=table, pca=model, feats=feats, region_len=region_len,
                neck_dir=mean_dir(off_n), tail_dir=mean_dir(off_t), cls_scores=cls_scores)


def _rng(seed: int, step: str, roll: int) -> np.random.Generator:
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, STEPS.index(step), int(roll)])


def _to_creature(points_px: NDArray) -> NDArray:
    """Frame px (head on the left, y up) → creature px coordinates (x forward, y up)."""
    p = np.array(points_px, float)
    p[..., 0] = 500.0 - p[..., 0]
    return p


# --------------------------------------------------------------------------- step: spine
def step_spine(opts: Options, rng: np.random.Generator, attempt: int = 0) -> dict[str, Any]:
    """Sample the PCA (conditioned on the options), read the discrete values as
    probabilities, inherit class/stance/skull/counts from the nearest species, C1-fix."""
    m = _model(opts.dataset)
    model: pc.PCA = m["pca"]
    table = m["table"]
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
        d = m["neck_dir"] * opts.neck_length
        fixed[pc.NECK_OFFSET[0]], fixed[pc.NECK_OFFSET[1]] = float(d[0]), float(d[1])
    if opts.tail_length is not None:
        d = m["tail_dir"] * opts.tail_length
        fixed[pc.TAIL_OFFSET[0]], fixed[pc.TAIL_OFFSET[1]] = float(d[0]), float(d[1])
    if opts.cls is not None:
        members = m["cls_scores"][opts.cls]
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
    user = {int(i): float(v) * float(np.sqrt(model.eigenvalues[int(i)]))
            for i, v in (opts.scores or {}).items()}
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
    weight = max(weight, 0.005)
    feat = np.asarray(x, float)
    idx, w = model.nearest(model.mean + (x - model.mean), n_neighbours=3)
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
        legs = (2 if rng.random() < lv / 2 else 0) if lv <= 2 else (
            4 if rng.random() < (lv - 2) / 2 else 2)
        if cls == "fish":
            legs = 0
    if cls == "fish":  # fish: the shoulder girdle sits right behind the head (no neck)
        pts[0:3] = pts[3]
    pts = sp.c1_fix(pts)
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
    posture = table.posture[same[0]]
    skull_name = table.skull[same[0]] if table.cls[same[0]] == cls else sk.CLASS_SKULL[cls]
    back_chord = float(np.linalg.norm(pts[6] - pts[3]))
    ratio = float(ws @ (table.skull_length[same] / np.maximum(
        np.linalg.norm(table.points[same, 6] - table.points[same, 3], axis=1), 1.0)))
    girth = float(ws @ table.girth[same])
    counts = vt.region_counts(cls, table.counts[same], ws, rl, m["region_len"][same])
    return dict(points=pts, lengths=lengths, weight=weight, wings=wings, legs=legs, cls=cls,
                stance=stance, posture=posture, skull=skull_name,
                skull_length=max(ratio * max(back_chord, 0.05 * s[-1]), 0.03 * s[-1]),
                girth=girth, counts=counts, neighbours=near, features=feat,
                wings_value=wings_v, legs_value=legs_v, nearest=table.name[pick])


def _scale_neck(points: NDArray, factor: float) -> NDArray:
    p = np.array(points, float)
    p[0:3] = p[3] + (p[0:3] - p[3]) * factor
    return p


# --------------------------------------------------------------------------- step: girdles
def step_girdles(spine: dict, opts: Options, rng: np.random.Generator) -> tuple[gd.Girdle, ...]:
    """Girdles and limb pairs from the discrete choices (rules in :mod:`girdles`)."""
    xy, s, region = sp.sample(spine["points"])
    rl = sp.region_lengths(s, region)
    L = np.asarray(spine["lengths"], float)
    back = max(rl[1], 0.05 * s[-1])
    fore, hind = L[:3].copy(), L[3:].copy()
    legs = spine["legs"]
    wings = spine["wings"]
    # sampled (not requested) wings yield when the shoulder girdle is already full
    shoulder = (1 if legs >= 4 else 0) + (1 if legs == 6 else 0) + \
        (1 if opts.arms and not opts.centaur else 0)
    if wings and opts.wings is None and shoulder >= gd.MAX_PAIRS:
        wings = False
    # a limb that must carry the body gets at least a minimal length per segment
    if legs >= 2:
        hind = np.maximum(hind, 0.08 * back)
    if legs >= 4 or wings or opts.arms or opts.centaur:
        fore = np.maximum(fore, 0.08 * back)
    return gd.plan(spine["cls"], legs, wings, opts.arms, opts.centaur, fore, hind, rl)


# --------------------------------------------------------------------------- step: limbs
def _frame_at(xy: NDArray, s: NDArray, at: float) -> tuple[NDArray, NDArray, NDArray]:
    """Point, tail-ward tangent and dorsal normal of the spine (creature px) at arc ``at``."""
    g = sp.point_at(xy, s, at)
    t = sp.tangent_at(xy, s, at)
    n = np.array([t[1], -t[0]])
    if n[1] < 0:
        n = -n
    return g, t, n


def _attach(xy, s, rl, girth, cls, skull_h, legless, girdle: str, at: float, kind: str,
            posture: str, width: float = 1.0) -> tuple[NDArray, NDArray]:
    """Spine point (3,) and limb attachment point (3,) of the right limb of a pair."""
    g, t, n = _frame_at(xy, s, at)
    h, b, _ = ms.profile(np.array([at]), rl, girth, cls, skull_h, legless)
    drop = {"leg": 0.35, "arm": 0.3, "wing": 0.12, "fin": 0.3}[kind] * h[0]
    if girdle == "hip":
        drop *= 0.75
    half = 0.45 * b[0] * (1.35 if posture == "sprawling" else 1.0) * width
    a2 = g - drop * n
    return np.array([g[0], g[1], 0.0]), np.array([a2[0], a2[1], half])


def _flatten(points: NDArray, which: str, floor: float) -> NDArray:
    """Raise a drooping tail (or neck) above ``floor`` keeping the join's tangent (C1)."""
    base, inner, outer = (6, 7, (8, 9)) if which == "tail" else (3, 2, (1, 0))
    p = np.array(points, float)
    for alpha in (0.7, 0.45, 0.25, 0.1, 0.0):
        q = p.copy()
        for k in outer:
            q[k, 1] = p[base, 1] + alpha * (p[k, 1] - p[base, 1])
        q[inner] = p[base] + max(alpha, 0.25) * (p[inner] - p[base])
        from biomorph.core.curves import bezier_eval
        seg = q[6:10] if which == "tail" else q[0:4]
        if bezier_eval(seg, np.linspace(0, 1, 17))[:, 1].min() >= floor:
            return q
        p_last = q
    return p_last


def step_limbs(spine: dict, girdles: tuple[gd.Girdle, ...], opts: Options,
               rng: np.random.Generator, shifts: dict[str, float] | None = None,
               ground: float | None = None, previous: dict | None = None) -> dict[str, Any]:
    """Ground height, grounded legs by the seed's descent, free limbs by rule (frame px)."""
    pts = _to_creature(spine["points"])
    cls, posture, stance = spine["cls"], spine["posture"], spine["stance"]
    legless = spine["legs"] == 0
    xy, s, region = sp.sample(pts)
    rl = sp.region_lengths(s, region)
    skull_h = sk.get(spine["skull"]).height * spine["skull_length"]
    shifts = shifts or {}
    # placements: (girdle name, pair index, spec, arc position)
    places = []
    for g in girdles:
        for k, spec in enumerate(g.pairs):
            at = g.at + shifts.get(g.name, 0.0)
            if k == 1:  # second pair a little apart, towards the body centre
                step = 0.18 * max(rl[1], 1e-6)
                at = at + step if g.name in ("shoulder", "centaur") else at - step
            at = float(np.clip(at, 0.0, s[-1]))
            places.append((g.name, k, spec, at))
    attach = [_attach(xy, s, rl, spine["girth"], cls, skull_h, legless, gname, at, spec.kind,
                      posture, shifts.get("width", 1.0) if spec.kind == "leg" else 1.0)
              for gname, k, spec, at in places]
    legs = [i for i, p in enumerate(places) if p[2].kind == "leg"]
    lengths = [np.array(p[2].lengths, float) for p in places]
    h_all, _, off_all = ms.profile(s, rl, spine["girth"], cls, skull_h, legless)
    body_bottom = xy[:, 1] - np.where(region == 1, 0.35, 0.2) * h_all
    if legs:
        reach = [lb.max_reach(lengths[i], stance, posture) for i in legs]
        if ground is None:
            ground = max(attach[i][1][1] - opts.stand_fraction * r
                         for i, r in zip(legs, reach, strict=True))
            # every leg must reach down at least a quarter of its length (a low hip under a
            # high shoulder): lower the ground; the legs that then fall short are stretched
            ground = min([ground] + [attach[i][1][1] - 0.25 * r
                                     for i, r in zip(legs, reach, strict=True)])
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
    poses = []
    for i, (gname, _k, spec, _at) in enumerate(places):
        base = attach[i][1]
        if spec.kind == "leg":
            role = "hind" if gname == "hip" else "fore"
            pose = None
            if previous is not None:  # balance repair: keep the pose, re-ground continuously
                prev = previous["poses"][i]
                pose = lb.reground(prev, base, previous["lengths"][i], ground, opts.descent)
                if pose is not None:
                    lengths[i] = previous["lengths"][i]
            if pose is None:
                pose = lb.pose_leg(base, lengths[i], ground, role, stance, posture, rng,
                                   opts.descent)
            lengths[i] = pose.lengths
        else:
            pose = lb.pose_free(spec.kind, base, lengths[i], rng)
        poses.append(pose)
    if ground is None:
        lows = [xy[:, 1].min() - 0.5 * float(h_all.min())]
        lows += [p.points[:, 1].min() for p in poses]
        ground = float(min(lows))
    else:
        clear = ground + 0.01 * max(s[-1], 1.0)
        poses = [lb.lift_clear(p, attach[i][1], lengths[i], ground, clear)
                 if p.kind != "leg" else p for i, p in enumerate(poses)]
    return dict(points=pts, ground=float(ground), places=places, attach=attach,
                lengths=lengths, poses=poses, shifts=dict(shifts))


# --------------------------------------------------------------------------- step: skull
def step_skull(spine: dict, limbs: dict, opts: Options, rng: np.random.Generator
               ) -> dict[str, Any]:
    """Pick the skull from the library, size and orient it, keep it above the ground."""
    shape = sk.get(spine["skull"])
    length = float(spine["skull_length"])
    pts = limbs["points"]
    xy, s, _ = sp.sample(pts)
    head = np.array([xy[0, 0], xy[0, 1]])
    fwd = -sp.tangent_at(xy, s, 0.0)
    if shape.follow_spine or np.linalg.norm(pts[0] - pts[3]) < 1e-6:
        ang = float(np.arctan2(fwd[1], fwd[0]))
    else:
        ang = -(shape.pitch_deg + rng.uniform(-6.0, 6.0)) * DEG
    floor = limbs["ground"] + 0.01 * max(s[-1], 1.0)
    for _ in range(12):
        d = np.array([np.cos(ang), np.sin(ang)])
        tip = head + length * d
        low = min(tip[1], head[1]) - 0.5 * shape.height * length * abs(np.cos(ang))
        if low >= floor or ang > 60 * DEG:
            break
        ang += 10 * DEG
    return dict(shape=shape.name, length=length, angle=float(ang), origin=head)


# --------------------------------------------------------------------------- step: finish
def _frames_from_dirs(d: NDArray) -> NDArray:
    """World rotations ``(m, 3, 3)`` with +Y along each sagittal direction and Z = +z."""
    d = np.asarray(d, float)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    y = np.where(n > 1e-12, d / np.where(n > 1e-12, n, 1.0), [[-1.0, 0.0, 0.0]])
    z = np.zeros_like(y)
    z[:, 2] = 1.0
    z = z - (y[:, 2:3]) * y
    z = z / np.linalg.norm(z, axis=1, keepdims=True)
    x = np.stack([y[:, 1] * z[:, 2] - y[:, 2] * z[:, 1], y[:, 2] * z[:, 0] - y[:, 0] * z[:, 2],
                  y[:, 0] * z[:, 1] - y[:, 1] * z[:, 0]], axis=1)
    return np.stack([x, y, z], axis=2)


def _frame_from_dir(d: NDArray) -> NDArray:
    """World rotation with +Y along ``d`` (in the sagittal plane) and Z lateral (+z)."""
    return _frames_from_dirs(np.asarray(d, float)[None])[0]


_RZ_PI = np.diag([-1.0, -1.0, 1.0])
_RANGES = {k: np.stack([-np.radians(v), np.radians(v)], axis=1) for k, v in SPINE_RANGE.items()}


def _assemble(spine: dict, limbs: dict, skull: dict, opts: Options) -> dict[str, Any]:
    """Joint arrays in creature px (world rotations, positions, masses, contacts).

    Vertebrae and skull are built as whole arrays; limbs per pair (right side, then the
    exact mirror image for the left)."""
    cls = spine["cls"]
    legless = spine["legs"] == 0
    pts = limbs["points"]
    xy, s, region = sp.sample(pts)
    rl = sp.region_lengths(s, region)
    shape = sk.get(skull["shape"])
    skull_h = shape.height * skull["length"]
    edges, vreg = vt.boundaries(rl, spine["counts"])
    P = sp.point_at(xy, s, edges)
    m = len(vreg)
    back_idx = np.flatnonzero(vreg == 1)
    root = int(back_idx[min(int(round(0.65 * (len(back_idx) - 1))), len(back_idx) - 1)])
    order = np.concatenate([[root], np.arange(root - 1, -1, -1), np.arange(root + 1, m)])
    slot = np.empty(m, np.int64)
    slot[order] = np.arange(m)           # joint index of vertebra i
    rname = ("neck", "back", "tail")
    within = np.zeros(m, np.int64)
    for r in range(3):
        sel = vreg == r
        within[sel] = np.arange(1, sel.sum() + 1)
    vnames = [f"{rname[vreg[i]]}_{within[i]:02d}" for i in order]
    vparts = an.vertebra_parts(vreg, cls)
    # body slices (volume, centre, owning vertebra)
    h, b, off = ms.profile(s, rl, spine["girth"], cls, skull_h, legless)
    vol = ms.slice_volumes(s, h, b)
    smid = 0.5 * (s[1:] + s[:-1])
    t = np.diff(xy, axis=0)
    t = t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    nrm = np.stack([t[:, 1], -t[:, 0]], axis=1)
    nrm = np.where(nrm[:, 1:2] < 0, -nrm, nrm)
    cen2 = 0.5 * (xy[1:] + xy[:-1]) - nrm * 0.5 * (off[1:] + off[:-1])[:, None]
    owner = np.clip(np.searchsorted(edges, smid, side="right") - 1, 0, m - 1)
    vmass = np.bincount(owner, weights=vol, minlength=m)
    vcen = np.stack([np.bincount(owner, weights=vol * cen2[:, k], minlength=m)
                     for k in range(2)], axis=1) / np.maximum(vmass, 1e-30)[:, None]
    emid = 0.5 * (edges[1:] + edges[:-1])
    vh = np.interp(emid, s, h)
    vb = np.interp(emid, s, b)
    # vertebra i: joint at the end nearer the root, bone towards the other end
    ant = order < root
    vi = order
    a = np.where(ant[:, None], P[vi + 1], P[vi])
    e = np.where(ant[:, None], P[vi], P[vi + 1])
    par_v = np.where(vi == root, -1, np.where(ant, slot[np.minimum(vi + 1, m - 1)],
                                              slot[np.maximum(vi - 1, 0)]))
    d3 = np.concatenate([e - a, np.zeros((m, 1))], axis=1)
    Lv = np.linalg.norm(d3, axis=1)
    blocks = {
        "names": vnames, "parent": [par_v], "kind": ["spine"] * m,
        "part": [vparts[i] for i in vi], "digit": [np.zeros(m, np.int64)],
        "region": [rname[r] for r in vreg[vi]], "side": [np.zeros(m, np.int64)],
        "W": [_frames_from_dirs(d3)], "pos": [np.concatenate([a, np.zeros((m, 1))], axis=1)],
        "blen": [Lv], "box": [np.stack([0.35 * vh[vi], Lv, 0.3 * vb[vi]], axis=1)],
        "vol": [vmass[vi]], "mass_c": [np.concatenate([vcen[vi], np.zeros((m, 1))], axis=1)],
        "mass_sz": [np.stack([vh[vi], np.maximum(Lv, 1e-9), vb[vi]], axis=1)],
        "lim": [np.stack([_RANGES[rname[r]] for r in vreg[vi]])],
        "anat_a": [np.zeros((m, 3))], "anat_l": [np.zeros((m, 3, 2))]}

    def put(names, parent, kind, region, side, W, pos, blen, box, volv, mc, msz, lim, aa, al,
            part):
        blocks["names"] += names
        blocks["kind"] += kind
        blocks["region"] += region
        blocks["part"] += list(part)
        blocks["digit"].append(np.zeros(len(names), np.int64))
        for key, val in (("parent", parent), ("side", side), ("W", W), ("pos", pos),
                         ("blen", blen), ("box", box), ("vol", volv), ("mass_c", mc),
                         ("mass_sz", msz), ("lim", lim), ("anat_a", aa), ("anat_l", al)):
            blocks[key].append(np.asarray(val, float) if key not in ("parent", "side")
                               else np.asarray(val, np.int64))

    # skull
    ang = skull["angle"]
    d = np.array([np.cos(ang), np.sin(ang), 0.0])
    org = np.array([skull["origin"][0], skull["origin"][1], 0.0])
    sbox = sk.box_size(shape, skull["length"])
    put(["skull"], [slot[0]], ["skull"], ["head"], [0], _frames_from_dirs(d[None]), [org],
        [skull["length"]], [sbox], [ms.ellipsoid_volume(sbox)],
        [org + d * skull["length"] / 2], [sbox], [_RANGES["head"]], np.zeros((1, 3)),
        np.zeros((1, 3, 2)), ["skull"])
    n_now = m + 1
    contacts, contact_joint, patches = [], [], []
    seg_names = ("girdle", "upper", "lower", "distal")
    for (gname, k, spec, at), (gpt, apt), pose, L3 in zip(
            limbs["places"], limbs["attach"], limbs["poses"], limbs["lengths"], strict=True):
        vidx = int(np.clip(np.searchsorted(edges, at, side="right") - 1, 0, m - 1))
        tag = f"{gname}{k + 1}"
        gvec = apt - gpt
        gl = float(np.linalg.norm(gvec))
        radius = ms.LIMB_RADIUS[spec.kind] * L3
        rb = ms.BONE_FRACTION * radius
        vols = ms.limb_volume(L3, spec.kind)
        # right side (4 joints: girdle, upper, lower, distal)
        Wr = np.concatenate([_frames_from_dirs(gvec[None]) if gl > 1e-9 else np.eye(3)[None],
                             pose.rotations @ _RZ_PI])
        pr = np.concatenate([gpt[None], pose.points[:3]])
        bl = np.concatenate([[gl], L3])
        bx = np.concatenate([[[0.3 * gl, gl, 0.06 * gl]],
                             np.stack([2 * rb, L3, 2 * rb], axis=1)])
        vv = np.concatenate([[0.0], vols])
        mc = np.concatenate([[0.5 * (gpt + apt)], 0.5 * (pose.points[:3] + pose.points[1:])])
        msz = np.concatenate([[[0.3 * gl, max(gl, 1e-9), 0.06 * gl]],
                              np.stack([2 * radius, np.maximum(L3, 1e-9), 2 * radius], axis=1)])
        lim = np.stack([_RANGES["girdle"]] * 4)
        aa = np.concatenate([np.zeros((1, 3)), pose.angles])
        al = np.concatenate([np.zeros((1, 3, 2)), pose.limits])
        kinds = ["girdle"] + [spec.kind] * 3
        for sd, sgn in (("r", 1), ("l", -1)):
            base = n_now
            par = [slot[vidx], base, base + 1, base + 2]
            if sgn > 0:
                Ws, ps, mcs, aas, als = Wr, pr, mc, aa, al
            else:
                Ws = _M @ Wr @ _M
                ps, mcs = pr * [1, 1, -1], mc * [1, 1, -1]
                aas = aa * [1, -1, -1]
                als = al.copy()
                als[:, 1:] = -al[:, 1:, ::-1]
            put([f"{tag}_{sn}_{sd}" for sn in seg_names], par, kinds, [gname] * 4,
                [sgn] * 4, Ws, ps, bl, bx, vv, mcs, msz, lim, aas, als,
                an.limb_parts(spec.kind, gname))
            n_now += 4
            if pose.contact is not None:
                M = np.array([1.0, 1.0, float(sgn)])
                contacts.append(pose.contact * M)
                contact_joint.append(n_now - 1)
                patches += _pad(pose, L3, float(sgn))
    names = blocks["names"]
    side = np.concatenate(blocks["side"])
    idx_of = {nm: i for i, nm in enumerate(names)}
    mirror = np.array([idx_of[nm[:-1] + ("l" if nm.endswith("r") else "r")] if side[i] != 0
                       else i for i, nm in enumerate(names)], dtype=np.int64)
    cat = {k: np.concatenate(blocks[k]) for k in ("parent", "W", "pos", "blen", "box", "vol",
                                                   "mass_c", "mass_sz", "lim", "anat_a",
                                                   "anat_l")}
    return dict(names=names, parent=cat["parent"], kind=blocks["kind"],
                region=blocks["region"], part=blocks["part"],
                digit=np.concatenate(blocks["digit"]), side=side, W=cat["W"], pos=cat["pos"],
                blen=cat["blen"], box=cat["box"], vol=cat["vol"], mass_c=cat["mass_c"],
                mass_sz=cat["mass_sz"], lim=cat["lim"], anat_a=cat["anat_a"],
                anat_l=cat["anat_l"], mirror=mirror, n=len(names),
                contacts=np.array(contacts).reshape(-1, 3),
                contact_joint=np.array(contact_joint, dtype=np.int64),
                patches=np.array(patches).reshape(-1, 2), density=ms.density(cls),
                ground=limbs["ground"])


def _balance_px(asm: dict, opts: Options) -> bal.BalanceReport:
    vol = asm["vol"]
    com = (vol[:, None] * asm["mass_c"]).sum(axis=0) / max(vol.sum(), 1e-30)
    p = np.concatenate([asm["pos"], asm["pos"] + asm["W"][:, :, 1] * asm["blen"][:, None]])
    return bal.evaluate(com, float(vol.sum()), asm["patches"], float(np.ptp(p[:, 0])),
                        opts.min_margin_fraction)


def _repair_shift(asm: dict, report: bal.BalanceReport, limbs: dict,
                  min_margin: float = 0.02) -> dict[str, float] | None:
    """Girdle shifts (arc length, px) that move the feet under the centre of mass."""
    if not report.applicable:
        return None
    com_x = report.com[0]
    patches = asm["patches"]
    x0, x1 = patches[:, 0].min(), patches[:, 0].max()
    span = max(x1 - x0, 1e-6)
    body = float(np.ptp(asm["pos"][:, 0]))
    target_margin = min(0.45 * span, max(1.5 * min_margin * body, 0.08 * span))
    leg_girdles = sorted({p[0] for p in limbs["places"] if p[2].kind == "leg"})
    shifts = dict(limbs["shifts"])
    if com_x > x1 - target_margin:      # too far forward: move the front-most legs forward
        delta = com_x - (x1 - target_margin)
        g = "shoulder" if "shoulder" in leg_girdles and len(leg_girdles) > 1 else leg_girdles[0]
        shifts[g] = shifts.get(g, 0.0) - 1.2 * delta   # arc length grows tailwards
    elif com_x < x0 + target_margin:    # too far back: move the hind-most legs back
        delta = (x0 + target_margin) - com_x
        g = "hip" if "hip" in leg_girdles else leg_girdles[-1]
        shifts[g] = shifts.get(g, 0.0) + 1.2 * delta
    elif report.margin < min_margin * body and shifts.get("width", 1.0) < 3.0:
        shifts["width"] = shifts.get("width", 1.0) * 1.35  # lateral margin: widen the stance
    else:
        return None
    return shifts


#: Toe pad of a digitigrade/unguligrade foot: forward and backward reach from the contact
#: point as fractions of the distal segment (toes/hoof are not modelled as bones).
TOE_PAD = (0.45, 0.2)


def _pad(pose: lb.LimbPose, L3: NDArray, sgn: float) -> list[NDArray]:
    """Four (x, z) corners of one foot's contact patch (creature px)."""
    rb = ms.BONE_FRACTION * ms.LIMB_RADIUS["leg"] * L3
    wdt = max(1.5 * rb[2], 0.02 * L3.sum())
    tip, ank = pose.points[3], pose.points[2]
    if pose.foot_flat:
        dh = np.array([tip[0] - ank[0], sgn * (tip[2] - ank[2])])
        nd = np.linalg.norm(dh)
        dh = dh / nd if nd > 1e-9 else np.array([1.0, 0.0])
        q0, q1 = np.array([ank[0], sgn * ank[2]]), np.array([tip[0], sgn * tip[2]])
    else:
        dh = np.array([1.0, 0.0])
        c = np.array([tip[0], sgn * tip[2]])
        q0, q1 = c - TOE_PAD[1] * L3[2] * dh, c + TOE_PAD[0] * L3[2] * dh
    perp = np.array([-dh[1], dh[0]])
    return [q0 + wdt * perp, q0 - wdt * perp, q1 + wdt * perp, q1 - wdt * perp]


def _depth_first(asm: dict) -> dict:
    """Reorder joints depth-first (children after their parent, subtrees contiguous) — the
    order BVH files and most DCC tools use — remapping parent, mirror and contact indices."""
    par = asm["parent"]
    n = asm["n"]
    kids: list[list[int]] = [[] for _ in range(n)]
    for j in range(n):
        if par[j] >= 0:
            kids[par[j]].append(j)
    order: list[int] = []
    stack = [j for j in range(n) if par[j] < 0][::-1]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(kids[j][::-1])
    perm = np.array(order)
    inv = np.empty(n, np.int64)
    inv[perm] = np.arange(n)
    out = dict(asm)
    for k in ("W", "pos", "blen", "box", "vol", "mass_c", "mass_sz", "lim", "anat_a", "anat_l",
              "side", "digit"):
        out[k] = asm[k][perm]
    for k in ("names", "kind", "region", "part"):
        out[k] = [asm[k][i] for i in perm]
    p = par[perm]
    out["parent"] = np.where(p >= 0, inv[np.maximum(p, 0)], -1)
    out["mirror"] = inv[asm["mirror"][perm]]
    out["contact_joint"] = inv[asm["contact_joint"]] if len(asm["contact_joint"]) else \
        asm["contact_joint"]
    return out


#: Lean iterations for bipeds (the rotation is solved analytically; re-posed free limbs and
#: a raised tail make a second pass worthwhile).
PITCH_ITERATIONS = 3


def _below_ground(asm: dict) -> bool:
    """True if a joint or bone end lies below the ground (beyond 0.2 % of the extent)."""
    ends = asm["pos"] + asm["W"][:, :, 1] * asm["blen"][:, None]
    low = min(asm["pos"][:, 1].min(), ends[:, 1].min())
    ext = float(np.ptp(np.concatenate([asm["pos"], ends])[:, 1]))
    return bool(low < asm["ground"] - 0.002 * ext)


def _pitch_body(spine: dict, limbs: dict, asm: dict, report: bal.BalanceReport,
                max_deg: float = 40.0) -> dict | None:
    """Spine rotated rigidly (sagittal plane) about the leg attachment so that the centre of
    mass moves over the middle of the feet; ``None`` if no rotation within ``max_deg`` helps.
    Rigid rotation keeps the C1 joins; legs keep their attachment (the pivot)."""
    legs = [i for i, p in enumerate(limbs["places"]) if p[2].kind == "leg"]
    if not legs:
        return None
    pivot = limbs["attach"][legs[0]][1][:2]
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
    want = ((mb + ml) * target - ml * xl) / mb        # body COM x needed
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
    if abs(theta) < 1e-4:
        return None
    ct, st = np.cos(theta), np.sin(theta)
    pc_ = _to_creature(spine["points"]) - pivot
    rot = np.stack([ct * pc_[:, 0] - st * pc_[:, 1], st * pc_[:, 0] + ct * pc_[:, 1]], axis=1)
    return dict(spine, points=_to_creature(rot + pivot))


def _limb_mass_and_patches(limbs: dict) -> tuple[float, NDArray, NDArray]:
    """Volume, volume-weighted centre sum and contact patches (x, z) of all limbs (both
    sides) straight from the poses — the cheap part of a balance re-check."""
    vol, mom, patches = 0.0, np.zeros(3), []
    for (_g, _k, spec, _at), pose, L3 in zip(limbs["places"], limbs["poses"], limbs["lengths"],
                                             strict=True):
        v = ms.limb_volume(L3, spec.kind)
        mid = 0.5 * (pose.points[:3] + pose.points[1:])
        vol += 2 * v.sum()
        mom += 2 * (v[:, None] * mid * [1, 1, 0]).sum(axis=0)
        if pose.contact is not None:
            patches += _pad(pose, L3, 1.0) + _pad(pose, L3, -1.0)
    return vol, mom, np.array(patches).reshape(-1, 2)


def finish(spine: dict, girdles, limbs: dict, skull: dict, opts: Options,
           rng: np.random.Generator, attempt_info: dict | None = None) -> Creature:
    """Assemble bones, repair balance, size from weight and return a :class:`Creature`.

    Repair (new beyond the seed): while the centre of mass is not inside the support polygon
    with the required margin, the leg-bearing girdle on the failing side is shifted along the
    spine by the missing distance and its legs are grounded again (up to 6 times); the
    cheap re-check uses the fixed spine/skull masses plus the re-posed limbs.
    """
    asm = _assemble(spine, limbs, skull, opts)
    report = _balance_px(asm, opts)
    repairs = 0
    leg_girdles = {p[0] for p in limbs["places"] if p[2].kind == "leg"}
    if report.applicable and not report.stable and len(leg_girdles) == 1:
        # bipeds (legs on one girdle): lean the body about the leg attachment (posture)
        for _ in range(PITCH_ITERATIONS):
            spine2 = _pitch_body(spine, limbs, asm, report)
            if spine2 is None:
                break
            limbs2 = step_limbs(spine2, girdles, opts, _rng(opts.seed, "limbs", 100),
                                ground=limbs["ground"], previous=limbs)
            skull2 = step_skull(spine2, limbs2, opts, _rng(opts.seed, "skull", 100))
            asm2 = _assemble(spine2, limbs2, skull2, opts)
            rep2 = _balance_px(asm2, opts)
            repairs += 1
            if rep2.margin_fraction < report.margin_fraction - 0.05 or _below_ground(asm2):
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
        while repairs < 10:
            shifts = _repair_shift(work, report, limbs, opts.min_margin_fraction)
            if shifts is None:
                break
            try:
                limbs = step_limbs(spine, girdles, opts, _rng(opts.seed, "limbs", 100),
                                   shifts, ground=limbs0["ground"], previous=limbs0)
            except ParameterError:
                break
            lvol, lmom, patches = _limb_mass_and_patches(limbs)
            com = (bmom + lmom) / max(bvol + lvol, 1e-30)
            report = bal.evaluate(com, bvol + lvol, patches, bl, opts.min_margin_fraction)
            work = dict(work, patches=patches)
            repairs += 1
            if report.stable:
                break
        asm = _assemble(spine, limbs, skull, opts)
        report = _balance_px(asm, opts)
    asm = _depth_first(asm)
    below = _below_ground(asm)
    # size from weight: metres per px
    vol_px = float(asm["vol"].sum())
    scale = ms.size_scale(spine["weight"], vol_px, spine["cls"])
    shift = np.array([0.0, asm["ground"], 0.0])
    pos = (asm["pos"] - shift) * scale
    W = asm["W"]
    par = asm["parent"]
    x0 = pos[0, 0]
    pos[:, 0] -= x0
    shift_m = np.array([x0, 0.0, 0.0])
    # local rest transforms from world frames
    pw = np.where(par[:, None, None] >= 0, W[np.maximum(par, 0)], np.eye(3)[None])
    pp = np.where(par[:, None] >= 0, pos[np.maximum(par, 0)], 0.0)
    local_r = np.einsum("nji,njk->nik", pw, W)
    offset = np.einsum("nji,nj->ni", pw, pos - pp)
    quat = tf.matrix_to_quat(local_r)
    # stored limits: anatomical range minus the rest angle, in the joint's local axes
    lim = asm["lim"].copy()
    limb = np.isin(np.array(asm["kind"]), ("leg", "arm", "wing", "fin"))
    rel = asm["anat_l"] - asm["anat_a"][:, :, None]   # (n, 3[z,x,y], 2)
    # limb frame -> joint frame flips x and y (rotation by pi about z)
    lz, lx, ly = rel[:, 0], -rel[:, 1, ::-1], -rel[:, 2, ::-1]
    lim[limb] = np.stack([lx, ly, lz], axis=1)[limb]
    end_site = np.full((asm["n"], 3), np.nan)
    leaf = np.setdiff1d(np.arange(asm["n"]), par[par >= 0])
    end_site[leaf] = np.array([[0.0, 1.0, 0.0]]) * (asm["blen"][leaf, None] * scale)
    skel = JointSkeleton(asm["names"], par, offset, quat, lim, end_site=end_site)
    dens = asm["density"]
    mass = asm["vol"] * dens * scale ** 3
    mass_c = (asm["mass_c"] - shift) * scale - shift_m
    contacts = (asm["contacts"] - shift) * scale - shift_m
    rep = report
    # the balance report in metres is the px report scaled (mass ∝ volume, lengths ∝ s)
    com = (np.asarray(rep.com) - shift) * scale - shift_m
    total = float(mass.sum())
    final = replace(rep, margin=rep.margin * scale, sagittal_margin=rep.sagittal_margin * scale,
                    tipping_torque=total * bal.G * rep.margin * scale,
                    com=tuple(float(v) for v in com), mass=total,
                    support=tuple((float(a * scale - x0), float(b * scale))
                                  for a, b in rep.support))
    info = attempt_info or {}
    final = replace(final, repairs=repairs, resamples=int(info.get("resamples", 0)))
    if not rep.applicable:
        final = replace(final, reason="no legs with ground contact: swims or rests on its body")
    pts_m = (limbs["points"] - np.array([0.0, asm["ground"]])) * scale - np.array([x0, 0.0])
    params = dict(seed=opts.seed, options=_options_dict(opts), **{"class": spine["cls"]},
                  legs=spine["legs"], wings="wing" in asm["kind"], weight_kg=spine["weight"],
                  stance=spine["stance"], posture=spine["posture"], skull=skull["shape"],
                  vertebrae=spine["counts"].tolist(), nearest_species=spine["neighbours"],
                  metres_per_px=scale, wings_value=spine["wings_value"],
                  legs_value=spine["legs_value"], features=spine["features"].tolist(),
                  girdles=[{"name": g.name, "pairs": [p.kind for p in g.pairs]}
                           for g in girdles],
                  descent_residual_px=[float(p.residual) for p in limbs["poses"]
                                       if p.kind == "leg"], below_ground=below)
    return Creature(skeleton=skel, kind=tuple(asm["kind"]), region=tuple(asm["region"]),
                    side=asm["side"].astype(np.int64), mirror=asm["mirror"].astype(np.int64),
                    bone_length=asm["blen"] * scale, box_size=asm["box"] * scale, mass=mass,
                    mass_center=mass_c, mass_size=asm["mass_sz"] * scale,
                    anatomical_angles=asm["anat_a"], anatomical_limits=asm["anat_l"],
                    contacts=contacts.reshape(-1, 3), contact_joint=asm["contact_joint"],
                    spine_points=pts_m, params=params, balance=final,
                    part=tuple(asm["part"]), digit=asm["digit"].astype(np.int64))


def _options_dict(opts: Options) -> dict[str, Any]:
    d = {k: getattr(opts, k) for k in ("legs", "wings", "arms", "centaur", "weight",
                                       "neck_length", "tail_length", "cls", "k", "temperature",
                                       "jitter", "stand_fraction", "require_stable")}
    if opts.scores is not None:
        d["scores"] = {str(i): float(v) for i, v in sorted(opts.scores.items())}
    d["descent"] = dict(vars(opts.descent))
    return d


# --------------------------------------------------------------------------- Generator
class Generator:
    """Step-by-step creature generation with undo, re-roll, edits and rule propagation.

    Example
    -------
    >>> g = Generator(Options(seed=3, legs=4))
    >>> g.step()
    'spine'
    >>> g.step()
    'girdles'
    >>> g.set_limb("hip", 0, "fin")   # doctest: +SKIP
    >>> c = g.run()                   # remaining steps -> Creature
    """

    def __init__(self, options: Options | None = None, **kwargs: Any) -> None:
        opts = options if options is not None else Options(**kwargs)
        if options is not None and kwargs:
            opts = replace(opts, **kwargs)
        self.options = opts.validate()
        self._states: dict[str, Any] = {}
        self._rolls = {s: 0 for s in STEPS}
        self._history: list[tuple[dict, dict]] = []
        self._attempt = 0
        self._edits: dict[str, Any] = {}

    # ------------------------------------------------------------ introspection
    @property
    def done(self) -> tuple[str, ...]:
        return tuple(s for s in STEPS if s in self._states)

    @property
    def next_step(self) -> str | None:
        for s in STEPS:
            if s not in self._states:
                return s
        return None

    def state(self, step: str) -> Any:
        if step not in self._states:
            raise ParameterError(f"step {step!r} has not run yet; done: {', '.join(self.done)}")
        return self._states[step]

    @property
    def creature(self) -> Creature:
        return self.state("finish")

    # ------------------------------------------------------------ running
    def _seed_rng(self, step: str) -> np.random.Generator:
        return _rng(self.options.seed + 7919 * self._attempt, step, self._rolls[step])

    def _run(self, step: str) -> None:
        o = self.options
        st = self._states
        if step == "spine":
            spine = step_spine(o, self._seed_rng("spine"))
            for k, v in self._edits.get("spine", {}).items():
                spine = _apply_spine_edit(spine, k, v)
            st["spine"] = spine
        elif step == "girdles":
            g = step_girdles(st["spine"], o, self._seed_rng("girdles"))
            for edit in self._edits.get("girdles", []):
                g = _apply_girdle_edit(g, edit, st["spine"])
            st["girdles"] = g
        elif step == "limbs":
            st["limbs"] = step_limbs(st["spine"], st["girdles"], o, self._seed_rng("limbs"))
        elif step == "skull":
            st["skull"] = step_skull(st["spine"], st["limbs"], o, self._seed_rng("skull"))
        else:
            st["finish"] = finish(st["spine"], st["girdles"], st["limbs"], st["skull"], o,
                                  self._seed_rng("finish"), {"resamples": self._attempt})

    def _snapshot(self) -> None:
        self._history.append((dict(self._states), {"rolls": dict(self._rolls),
                                                   "edits": _copy_edits(self._edits),
                                                   "attempt": self._attempt}))

    def step(self) -> str:
        """Run the next step; return its name."""
        s = self.next_step
        if s is None:
            raise ParameterError("all steps have run; undo or edit first")
        self._snapshot()
        self._run(s)
        return s

    def run(self) -> Creature:
        """Run all remaining steps; with ``require_stable`` resample until balanced."""
        while self.next_step is not None:
            self.step()
        c = self.creature
        o = self.options
        while (o.require_stable and self._attempt < o.max_resamples
               and (c.params.get("below_ground") or (c.balance is not None
                                                     and c.balance.applicable
                                                     and not c.balance.stable))):
            self._attempt += 1
            self._states.clear()
            while self.next_step is not None:
                self._run(self.next_step)
            c = self.creature
        if o.require_stable and c.balance is not None and c.balance.applicable \
                and not c.balance.stable:
            raise InputError(f"no statically stable creature found for seed {o.seed} after "
                             f"{o.max_resamples} resamples; relax the conditions or pass "
                             "require_stable=False")
        return c

    def undo(self) -> str:
        """Undo the last step or edit; return what is now the next step."""
        if not self._history:
            raise ParameterError("nothing to undo")
        states, meta = self._history.pop()
        self._states = states
        self._rolls = meta["rolls"]
        self._edits = meta["edits"]
        self._attempt = meta["attempt"]
        return self.next_step or "done"

    def _invalidate_from(self, step: str) -> list[str]:
        i = STEPS.index(step)
        redo = [s for s in STEPS[i:] if s in self._states]
        for s in STEPS[i:]:
            self._states.pop(s, None)
        return redo

    def _rerun(self, steps: list[str]) -> None:
        for s in STEPS:
            if s in steps:
                self._run(s)

    def reroll(self, step: str, seed: int | None = None) -> None:
        """Re-run ``step`` with fresh randomness (or the stream of ``seed``), then re-run the
        later steps that had already run (rule propagation)."""
        if step not in STEPS:
            raise ParameterError(f"step {step!r} unknown; expected one of {', '.join(STEPS)}")
        if step not in self._states:
            raise ParameterError(f"step {step!r} has not run yet")
        self._snapshot()
        self._rolls[step] = (self._rolls[step] + 1) if seed is None else 1000 + int(seed)
        self._rerun(self._invalidate_from(step))

    # ------------------------------------------------------------ edits
    def _edit(self, step: str, record) -> None:
        if step not in self._states:
            raise ParameterError(f"run the {step} step before editing it")
        self._snapshot()
        try:
            record()
            self._rerun(self._invalidate_from(step))
        except Exception:
            self.undo()
            raise

    def set_limb(self, girdle: str, pair: int, kind: str) -> None:
        """Change the type of limb pair ``pair`` (0-based) at ``girdle``."""
        self._check_girdle_pair(girdle, pair)
        gd.check_pair(girdle, kind, pair + 1)
        if kind == "leg" and girdle == "shoulder" and not any(
                p.kind == "leg" for g in self.state("girdles") if g.name == "hip"
                for p in g.pairs):
            raise ParameterError("legs at the shoulder need legs at the hip too: a creature "
                                 "cannot stand on its front legs alone")
        self._edit("girdles", lambda: self._edits.setdefault("girdles", []).append(
            ("set", girdle, pair, kind)))

    def add_limb_pair(self, girdle: str, kind: str) -> None:
        """Add a limb pair of ``kind`` at ``girdle`` (at most two pairs per girdle)."""
        if girdle == "centaur":
            sp_ = self.state("spine")
            xy, s, region = sp.sample(sp_["points"])
            rl = sp.region_lengths(s, region)
            if rl[0] < gd.CENTAUR_MIN_NECK * rl[1]:
                raise ParameterError(f"a centaur girdle needs a neck of at least "
                                     f"{gd.CENTAUR_MIN_NECK:.2f} × the back; lengthen the neck "
                                     "first (set_neck_length)")
        existing = [g for g in self.state("girdles") if g.name == girdle]
        n = len(existing[0].pairs) if existing else 0
        gd.check_pair(girdle, kind, n + 1)
        self._edit("girdles", lambda: self._edits.setdefault("girdles", []).append(
            ("add", girdle, None, kind)))

    def set_neck_length(self, factor: float) -> None:
        """Scale the neck chord by ``factor`` (0 < factor <= 4); later steps re-run."""
        if not (np.isfinite(factor) and 0 < factor <= 4):
            raise ParameterError(f"neck factor {factor}: expected 0 < factor <= 4")
        self._edit("spine", lambda: self._edits.setdefault("spine", {}).__setitem__(
            "neck", self._edits.get("spine", {}).get("neck", 1.0) * factor))

    def set_tail_length(self, factor: float) -> None:
        """Scale the tail chord by ``factor`` (0 < factor <= 4)."""
        if not (np.isfinite(factor) and 0 < factor <= 4):
            raise ParameterError(f"tail factor {factor}: expected 0 < factor <= 4")
        self._edit("spine", lambda: self._edits.setdefault("spine", {}).__setitem__(
            "tail", self._edits.get("spine", {}).get("tail", 1.0) * factor))

    def _check_girdle_pair(self, girdle: str, pair: int) -> None:
        gs = {g.name: g for g in self.state("girdles")}
        if girdle not in gs:
            raise ParameterError(f"no {girdle} girdle on this creature; girdles: "
                                 f"{', '.join(gs)}")
        if not 0 <= pair < len(gs[girdle].pairs):
            raise ParameterError(f"the {girdle} girdle has {len(gs[girdle].pairs)} limb "
                                 f"pair(s); pair {pair} does not exist")


def _copy_edits(e: dict) -> dict:
    return {k: (list(v) if isinstance(v, list) else dict(v)) for k, v in e.items()}


def _apply_spine_edit(spine: dict, key: str, factor: float) -> dict:
    pts = np.array(spine["points"], float)
    if key == "neck":
        pts[0:3] = pts[3] + (pts[0:3] - pts[3]) * factor
    else:
        pts[7:10] = pts[6] + (pts[7:10] - pts[6]) * factor
    return dict(spine, points=sp.c1_fix(pts))


def _apply_girdle_edit(girdles, edit, spine) -> tuple:
    op, name, pair, kind = edit
    out = list(girdles)
    names = [g.name for g in out]
    if op == "set":
        g = out[names.index(name)]
        old = g.pairs[pair]
        pairs = list(g.pairs)
        pairs[pair] = gd.LimbSpec(kind, old.lengths)
        out[names.index(name)] = replace(g, pairs=tuple(pairs))
    else:
        xy, s, region = sp.sample(spine["points"])
        rl = sp.region_lengths(s, region)
        L = np.asarray(spine["lengths"], float)
        back = max(rl[1], 0.05 * s[-1])
        base = L[:3] if name in ("shoulder", "centaur") else L[3:]
        lengths = tuple(float(v) for v in np.maximum(base, 0.08 * back))
        if name in names:
            out[names.index(name)] = out[names.index(name)].with_pair(gd.LimbSpec(kind, lengths))
        else:
            at = {"shoulder": rl[0], "hip": rl[0] + rl[1], "centaur": 0.22 * rl[0]}[name]
            out.append(gd.Girdle(name, at, (gd.LimbSpec(kind, lengths),)))
    return tuple(out)


def generate(seed: int = 0, **kwargs: Any) -> Creature:
    """Generate one creature (all steps). Keyword arguments are :class:`Options` fields;
    ``cls`` may also be given as ``class_``."""
    if "class_" in kwargs:
        kwargs["cls"] = kwargs.pop("class_")
    return Generator(Options(seed=seed, **kwargs)).run()
