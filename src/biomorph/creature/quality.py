"""Quality measures of generated creatures (the issue's bars) and a diversity score."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.creature import spine as sp
from biomorph.creature.creature import Creature

CHECKS = ("ground_contact", "above_ground", "within_limits", "symmetric", "spine_c1",
          "stable", "monotone_leg_heights")


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
    out["ground_contact"] = bool(len(c.contacts) == 0 or np.all(np.abs(c.contacts[:, 1])
                                                                 <= contact_tol * h))
    low = min(c.joint_positions[:, 1].min(), c.bone_ends[:, 1].min())
    out["above_ground"] = bool(low >= -0.002 * h)
    lim = c.skeleton.limits
    a, al = c.anatomical_angles, c.anatomical_limits
    out["within_limits"] = bool(np.all(lim[..., 0] <= 1e-12) and np.all(lim[..., 1] >= -1e-12)
                                and np.all(a >= al[..., 0] - 1e-9)
                                and np.all(a <= al[..., 1] + 1e-9))
    m = c.mirror
    out["symmetric"] = bool(np.array_equal(c.joint_positions[m] * [1, 1, -1], c.joint_positions)
                            and np.array_equal(c.skeleton.rest_rotation[m] * [-1, -1, 1, 1],
                                               c.skeleton.rest_rotation))
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
