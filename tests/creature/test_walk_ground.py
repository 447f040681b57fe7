"""The walk keeps every knee and elbow above the ground (sprawling legs included)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.creature.generator import Generator
from biomorph.creature.options import Options
from biomorph.creature.walk import _raise_knee, plan_walk, walk_cycle, walk_quality


# quadruped reptiles with long femurs over short shanks: their knees dipped 0.7-2.6 % of
# the height into the ground before the stride kept the knee clear (bench/creature.py)
@pytest.mark.parametrize("seed", [72, 250, 324])
def test_sprawling_knees_stay_above_the_ground(seed):
    c = Generator(Options(seed=seed)).run()
    assert c.params["legs"] > 0
    plan = plan_walk(c)
    mo = walk_cycle(c)
    q = walk_quality(c, mo, plan)
    assert q["penetration_fraction"] <= 0.005
    assert q["slide_fraction"] <= 0.02
    M = mo.world_matrices()
    for g in plan.legs:  # the knee joint itself, every frame
        assert M[:, g["lower"], 1, 3].min() >= -1e-9


def test_raise_knee_stays_on_the_chain_and_above_the_clearance():
    rng = np.random.default_rng(0)
    hip = np.tile([0.0, 0.37, 0.0], (200, 1))
    tgt = hip + rng.normal(size=(200, 3)) * [0.2, 0.05, 0.2] + [0.0, -0.3, 0.1]
    l1, l2 = 0.54, 0.19
    knee = _raise_knee(hip, tgt, l1, l2, np.array([1.0, -1.0, 0.3]) / 1.45, clear=0.01)
    assert np.allclose(np.linalg.norm(knee - hip, axis=1), l1)
    d = np.linalg.norm(tgt - hip, axis=1)
    reach = (d > abs(l1 - l2) * 1.001) & (d < (l1 + l2) * 0.999)
    assert np.allclose(np.linalg.norm(knee - tgt, axis=1)[reach], l2)
    # wherever a knee above the clearance exists, it is chosen
    from biomorph.creature.walk import _highest_knee

    possible = _highest_knee(hip, tgt, l1, l2) >= 0.01
    assert possible.any() and (knee[possible, 1] >= 0.01 - 1e-9).all()
