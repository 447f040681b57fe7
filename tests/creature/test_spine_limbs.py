"""Spine C1 fix, vertebrae, and the seed's ground-contact descent."""

from __future__ import annotations

import numpy as np

from biomorph.creature import limbs as lb
from biomorph.creature import spine as sp
from biomorph.creature import vertebrae as vt


def test_c1_fix_makes_joins_smooth_and_keeps_distances():
    rng = np.random.default_rng(0)
    for _ in range(50):
        p = rng.uniform(0, 1000, (10, 2))
        q = sp.c1_fix(p)
        assert np.all(np.degrees(sp.join_angles(q)) < 1e-6)
        for before, join, after in ((2, 3, 4), (5, 6, 7)):
            assert np.isclose(
                np.linalg.norm(q[before] - q[join]), np.linalg.norm(p[before] - p[join])
            )
            assert np.isclose(
                np.linalg.norm(q[after] - q[join]), np.linalg.norm(p[after] - p[join])
            )
        # equal and opposite: the bisector of the two original tangents is kept
        untouched = [0, 1, 3, 6, 8, 9]
        assert np.array_equal(q[untouched], p[untouched])


def test_c1_fix_leaves_a_missing_neck_alone():
    p = np.random.default_rng(1).uniform(0, 1000, (10, 2))
    p[:3] = p[3]
    q = sp.c1_fix(p)
    assert np.array_equal(q[:4], p[:4])


def test_vertebrae_cover_the_spine_by_arc_length():
    edges, reg = vt.boundaries([100.0, 300.0, 200.0], [7, 20, 10])
    assert len(reg) == 37 and edges[0] == 0 and np.isclose(edges[-1], 600)
    assert np.allclose(np.diff(edges[:8]), 100 / 7)
    edges, reg = vt.boundaries([50.0, 300.0, 0.0], [0, 10, 0])  # no neck vertebrae
    assert np.isclose(edges[0], 0) and np.isclose(edges[-1], 350) and set(reg) == {1}


def test_descent_reaches_ground_without_going_below():
    rng = np.random.default_rng(3)
    params = lb.DescentParams()
    for _ in range(40):
        L = rng.uniform(50, 300, 3)
        base = np.array([0.0, 0.0, 20.0])
        role = rng.choice(["hind", "fore"])
        stance = rng.choice(["plantigrade", "digitigrade", "unguligrade"])
        posture = rng.choice(["erect", "sprawling", "crouched"])
        ground = -0.8 * lb.max_reach(L, stance, posture)
        pose = lb.pose_leg(base, L, ground, role, stance, posture, rng, params)
        assert abs(pose.residual) <= 0.01 * L.sum()
        assert np.all(pose.points[1:, 1] >= ground - 1e-6 * L.sum())
        lo, hi = pose.limits[..., 0], pose.limits[..., 1]
        assert np.all(pose.angles >= lo - 1e-12) and np.all(pose.angles <= hi + 1e-12)


def test_descent_poses_plausible_standing_legs():
    """Hip above knee above ankle above contact, bones lean to their anatomical side (hind
    femur forward, shank back, metatarsus forward; fore humerus back), knee and hock flex in
    their own direction only, and the relaxation never adds flexion."""
    rng = np.random.default_rng(11)
    params = lb.DescentParams()
    for _ in range(60):
        L = rng.uniform(50, 300, 3)
        base = np.array([0.0, 0.0, 20.0])
        role = str(rng.choice(["hind", "fore"]))
        stance = str(rng.choice(["digitigrade", "unguligrade", "plantigrade"]))
        ground = -0.8 * lb.max_reach(L, stance, "erect")
        pose = lb.pose_leg(base, L, ground, role, stance, "erect", rng, params)
        n = 2 if pose.foot_flat else 3
        y = pose.points[: n + 1, 1]
        assert np.all(np.diff(y) <= 1e-6 * L.sum()), (role, stance, y)
        assert lb.implausibility(pose.points, pose.lengths, n, role, params) <= 0.002 * L.sum()
        dx = np.diff(pose.points[:, 0])
        assert lb.LEAN_SIDE[role][0] * dx[0] >= -np.sin(15 * lb.DEG) * L[0] - 1e-9
        box = lb.STAND_LIMITS_DEG[role] * lb.DEG
        assert np.all(pose.angles[:n, 0] >= box[:n, 0, 0] - 1e-9)
        assert np.all(pose.angles[:n, 0] <= box[:n, 0, 1] + 1e-9)
        if role == "hind":
            assert pose.angles[1, 0] <= 0 and (n == 2 or pose.angles[2, 0] >= 0)
        relaxed = lb.pose_leg(
            base,
            L,
            ground,
            role,
            stance,
            "erect",
            np.random.default_rng(5),
            lb.DescentParams(relax=(0.5, 0.25)),
        )
        plain = lb.pose_leg(
            base, L, ground, role, stance, "erect", np.random.default_rng(5), params
        )
        assert (
            lb.flexion_from_neutral(relaxed.angles, role, n)
            <= lb.flexion_from_neutral(plain.angles, role, n) + 1e-9
        )


def test_descent_constants_are_parameters():
    p = lb.DescentParams()
    assert (p.step_deg, p.shrink, p.stall) == (30.0, 0.8, 0.1)
    assert p.p_abduct < p.p_flex
