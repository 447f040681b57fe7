"""Quality measures of generated creatures (the issue's bars) and a diversity score."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.creature import spine as sp
from biomorph.creature.creature import Creature
from biomorph.creature.stance import RANGES, trunk_key
from biomorph.creature.stance import allometric_height as _allometric

CHECKS = (
    "ground_contact",
    "above_ground",
    "within_limits",
    "symmetric",
    "spine_c1",
    "stable",
    "monotone_leg_heights",
)


def leg_height_steps(c: Creature) -> list[NDArray[np.float64]]:
    """Per ground contact the height drops ``y[k] - y[k+1]`` along the leg's joints from the
    hip/shoulder (femur/humerus joint) through knee/elbow, ankle/wrist and the digit's
    phalanges to the contact point (metres; all ≥ 0 for a plausible standing leg)."""
    parents = c.skeleton.parent
    p = c.joint_positions
    out = []
    for cp, j in zip(c.contacts, c.contact_joint, strict=True):
        chain = [int(j)]
        while parents[chain[-1]] >= 0 and c.kind[parents[chain[-1]]] == "leg":
            chain.append(int(parents[chain[-1]]))
        ys = [p[k, 1] for k in chain[::-1]]
        if np.linalg.norm(p[j] - cp) > 1e-9 * max(c.height, 1e-12):
            ys.append(cp[1])
        out.append(-np.diff(np.array(ys)))
    return out


def monotone_leg_heights(c: Creature, tol: float = 0.005) -> bool:
    """True if on every grounded leg no distal joint lies higher than its proximal one (hip
    above knee above ankle above the contact), within ``tol`` × body height."""
    h = max(c.height, 1e-12)
    return all(bool(np.all(d >= -tol * h)) for d in leg_height_steps(c))


def check(c: Creature, contact_tol: float = 0.01, c1_deg: float = 1.0) -> dict[str, bool]:
    """Each quality bar for one creature.

    ground_contact: every contact within ``contact_tol`` × body height of the ground;
    above_ground: no joint or bone end below the ground (0.2 % of height for the bone's
    rounding at a grounded tip); within_limits: rest pose inside every stored range and limb
    angles inside their anatomical limits; symmetric: mirrored joints bit-identical;
    spine_c1: tangent angle ≤ ``c1_deg`` at both joins; stable: statically stable (or no
    legs on the ground); monotone_leg_heights: see :func:`monotone_leg_heights`.
    """
    h = max(c.height, 1e-12)
    out = {}
    out["ground_contact"] = bool(
        len(c.contacts) == 0 or np.all(np.abs(c.contacts[:, 1]) <= contact_tol * h)
    )
    low = min(c.joint_positions[:, 1].min(), c.bone_ends[:, 1].min())
    out["above_ground"] = bool(low >= -0.002 * h)
    lim = c.skeleton.limits
    a, al = c.anatomical_angles, c.anatomical_limits
    out["within_limits"] = bool(
        np.all(lim[..., 0] <= 1e-12)
        and np.all(lim[..., 1] >= -1e-12)
        and np.all(a >= al[..., 0] - 1e-9)
        and np.all(a <= al[..., 1] + 1e-9)
    )
    m = c.mirror
    out["symmetric"] = bool(
        np.array_equal(c.joint_positions[m] * [1, 1, -1], c.joint_positions)
        and np.array_equal(c.skeleton.rest_rotation[m] * [-1, -1, 1, 1], c.skeleton.rest_rotation)
    )
    ang = np.degrees(sp.join_angles(c.spine_points))
    out["spine_c1"] = bool(np.all(np.nan_to_num(ang) <= c1_deg))
    b = c.balance
    out["stable"] = bool(b is None or not b.applicable or b.stable)
    out["monotone_leg_heights"] = monotone_leg_heights(c)
    return out


def vendi_score(features: ArrayLike) -> float:
    """Vendi score (Friedman & Dieng 2023): ``exp`` of the Shannon entropy of the eigenvalues
    of ``K / n`` with an RBF similarity on standardised features (bandwidth: median distance).
    1 = all identical, n = all completely different."""
    x = np.asarray(features, float)
    x = (x - x.mean(axis=0)) / np.where(x.std(axis=0) > 0, x.std(axis=0), 1.0)
    d2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(-1)
    med = np.median(d2[np.triu_indices(len(x), 1)])
    k = np.exp(-d2 / max(med, 1e-12))
    ev = np.linalg.eigvalsh(k / len(x))
    ev = ev[ev > 1e-12]
    return float(np.exp(-(ev * np.log(ev)).sum()))


# --------------------------------------------------------------------------- anatomy checks
def _joint(c: Creature, name: str) -> int | None:
    try:
        return c.names.index(name)
    except ValueError:
        return None


def trunk_pitch_deg(c: Creature) -> float:
    """Back line (the spine curve's hip point p6 → shoulder point p3, ``Creature.spine_points``)
    above the horizontal (deg, + = shoulders higher)."""
    p = np.asarray(c.spine_points, float)
    d = p[3] - p[6]
    return float(np.degrees(np.arctan2(d[1], d[0])))


def head_pitch_deg(c: Creature) -> float:
    """Skull axis above the horizontal (deg, + = snout up)."""
    j = _joint(c, "skull")
    return 0.0 if j is None else float(np.degrees(np.arcsin(np.clip(c.world[j, 1, 1], -1, 1))))


def femur_angles_deg(c: Creature) -> list[float]:
    """Each standing hind leg's femur from the vertical (deg)."""
    return femur_angles_of(c.kind, c.part, c.side, c.world[:, :3, 1])


def femur_angles_of(kind, part, side, bone_y: NDArray) -> list[float]:
    """:func:`femur_angles_deg` on joint arrays (``bone_y (n, 3)``: each bone's world +Y)."""
    out = []
    for j in range(len(kind)):
        if kind[j] == "leg" and part and part[j] == "femur" and side[j] > 0:
            out.append(float(np.degrees(np.arccos(np.clip(-bone_y[j, 1], -1, 1)))))
    return out


def knee_behind_elbow(c: Creature) -> bool:
    """Quadrupeds: every hind knee lies behind (−x of) every front elbow."""
    return knee_behind_elbow_of(c.kind, c.part, c.joint_positions[:, 0])


def knee_behind_elbow_of(kind, part, x: NDArray) -> bool:
    """:func:`knee_behind_elbow` on joint arrays (``x``: joint positions along +x)."""
    knees = [j for j, p in enumerate(part) if p == "tibia" and kind[j] == "leg"]
    elbows = [j for j, p in enumerate(part) if p == "radius" and kind[j] == "leg"]
    if not knees or not elbows:
        return True
    return bool(x[knees].max() < x[elbows].min())


def standing_joint(names, legs: int) -> int | None:
    """Index of the joint :func:`standing_height` measures (withers / hip girdle)."""
    name = "shoulder1_girdle_r" if legs >= 4 else "hip1_girdle_r" if legs == 2 else None
    if name is None:
        return None
    try:
        return list(names).index(name)
    except ValueError:
        return None


def standing_height(c: Creature) -> float | None:
    """Withers (shoulder girdle on the spine) of a quadruped, hip of a biped (m)."""
    j = standing_joint(c.names, c.params.get("legs", 0))
    return None if j is None else float(c.joint_positions[j, 1])


def rules_hold(
    names, kind, part, side, bone_y, pos, cls: str, posture: str, legs: int, mass: float
) -> bool:
    """The femur, knee/elbow and withers rules of :func:`anatomy_check` on joint arrays in
    metres (``pos (n, 3)`` with the ground at y = 0) — what the generator checks before it
    returns a creature, without building the skeleton's world transforms."""
    fr = RANGES["femur_from_vertical_bird" if cls == "bird" else "femur_from_vertical"]
    if not all(fr[0] <= a <= fr[1] for a in femur_angles_of(kind, part, side, bone_y)):
        return False
    if not knee_behind_elbow_of(kind, part, pos[:, 0]):
        return False
    j = standing_joint(names, legs)
    pred = _allometric(cls, posture, mass)
    if j is None or not pred:
        return True
    lo, hi = RANGES["withers_ratio"]
    return bool(lo <= float(pos[j, 1]) / pred <= hi)


def allometric_height(c: Creature) -> float | None:
    """Predicted withers / hip height (m) for the creature's class, posture and mass."""
    return _allometric(c.params.get("class", ""), c.params.get("posture", ""), c.total_mass)


def anatomy_measures(c: Creature) -> dict[str, float | bool | None]:
    """The measured values behind :func:`anatomy_check`."""
    h, pred = standing_height(c), allometric_height(c)
    return {
        "trunk_pitch_deg": trunk_pitch_deg(c),
        "head_pitch_deg": head_pitch_deg(c),
        "femur_deg": femur_angles_deg(c),
        "knee_behind_elbow": knee_behind_elbow(c),
        "height_m": h,
        "allometric_m": pred,
        "withers_ratio": None if (h is None or not pred) else h / pred,
    }


ANATOMY_CHECKS = (
    "trunk_pitch",
    "head_pitch",
    "femur_angle",
    "knee_behind_elbow",
    "withers_height",
    "class_legs",
    "weight_in_range",
    "feet_have_digits",
)


def anatomy_check(c: Creature, m: dict | None = None) -> dict[str, bool]:
    """Each anatomical rule of issue 14 (ranges :data:`RANGES`) for one creature."""
    m = anatomy_measures(c) if m is None else m
    legs = c.params.get("legs", 0)
    cls = c.params.get("class")
    opts = c.params.get("options", {})
    inside = lambda v, r: r[0] <= v <= r[1]  # noqa: E731
    out = {}
    tp = RANGES[trunk_key(cls, legs)]  # birds on two legs 20..50°, other bipeds, quadrupeds
    out["trunk_pitch"] = legs == 0 or inside(m["trunk_pitch_deg"], tp)
    out["head_pitch"] = inside(m["head_pitch_deg"], RANGES["head_pitch"])
    fr = RANGES["femur_from_vertical_bird" if cls == "bird" else "femur_from_vertical"]
    out["femur_angle"] = all(inside(a, fr) for a in m["femur_deg"])
    out["knee_behind_elbow"] = bool(m["knee_behind_elbow"])
    out["withers_height"] = m["withers_ratio"] is None or inside(
        m["withers_ratio"], RANGES["withers_ratio"]
    )
    asked = opts.get("legs") is not None or opts.get("cls") is not None
    out["class_legs"] = asked or not ((cls == "bird" and legs != 2) or (cls == "fish" and legs))
    out["weight_in_range"] = opts.get("weight") is not None or 0.01 * (
        1 - 1e-9
    ) <= c.total_mass <= 120000.0 * (1 + 1e-9)
    grounded = set(int(j) for j in c.contact_joint)
    out["feet_have_digits"] = all(
        c.part[j] in ("phalanx", "hoof", "claw", "nail", "metatarsal", "metacarpal")
        for j in grounded
    ) and (not grounded or any(c.part[j] in ("hoof", "claw", "nail", "phalanx") for j in grounded))
    return out
