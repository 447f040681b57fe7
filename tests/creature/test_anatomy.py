"""Per-joint anatomical labels (the contract with bone models / rigs)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.creature import generate
from biomorph.creature.anatomy import PARTS, vertebra_parts


def test_every_joint_has_a_known_part_and_mirrors_share_it():
    c = generate(3, legs=4)
    assert len(c.part) == len(c) and set(c.part) <= set(PARTS)
    assert all(c.part[j] == c.part[c.mirror[j]] for j in range(len(c)))
    for j, name in enumerate(c.names):
        if name.startswith("hip") and "_upper_" in name:
            assert c.part[j] == "femur"
        if name.startswith("shoulder") and "_upper_" in name:
            assert c.part[j] == "humerus"
    assert c.part[c.names.index("skull")] == "skull"
    assert c.digit is not None and np.all(
        c.digit[[p not in ("phalanx", "hoof", "claw", "nail") for p in c.part]] == 0
    )
    assert c.to_dict()["bones"][0]["part"] == c.part[0]


def test_back_splits_into_thoracic_lumbar_sacral_in_mammals_only():
    vreg = np.array([0] * 7 + [1] * 20 + [2] * 5)
    m = vertebra_parts(vreg, "mammal")
    assert m[:7] == ["cervical"] * 7 and m[-5:] == ["caudal"] * 5
    back = m[7:27]
    assert back.count("sacral") == 3 and back.count("lumbar") == 5
    assert back[-1] == "sacral" and back[0] == "thoracic"
    assert "lumbar" not in vertebra_parts(vreg, "reptile")


def _area(p) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def test_feet_are_digits_with_end_joints_and_carry_the_contacts():
    from biomorph.creature.balance import convex_hull

    for seed, kw in ((3, {"legs": 4}), (4, {"cls": "bird"}), (9, {"legs": 4, "weight": 600.0})):
        c = generate(seed, **kw)
        parts = set(c.part)
        assert "mandible" in parts and "phalanx" in parts
        assert parts & {"hoof", "claw", "nail"}
        jaw = c.part.index("mandible")
        assert c.part[c.skeleton.parent[jaw]] == "skull"
        # every contact is a digit joint / end-bone tip or a flat foot's ankle, on the ground
        for cp, j in zip(c.contacts, c.contact_joint, strict=True):
            assert c.part[j] in ("phalanx", "hoof", "claw", "nail", "metatarsal", "metacarpal")
            assert abs(cp[1]) <= 1e-6 * c.height
        # the balance report's support polygon is the hull of those contact points (the same
        # polygon: a contact on a straight edge may be kept or dropped as rounding decides)
        hull = convex_hull(c.contacts[:, [0, 2]])
        sup = np.array(c.balance.support)
        assert abs(_area(hull) - _area(sup)) <= 1e-9 * _area(hull) and c.balance.stable
        # end joints end their digit: no children
        ends = [j for j, p in enumerate(c.part) if p in ("hoof", "claw", "nail")]
        assert not set(ends) & set(c.skeleton.parent.tolist())


def test_digit_counts_follow_class_and_foot_posture():
    from biomorph.creature.feet import digit_plan

    assert len(digit_plan("leg", "hind", "mammal", "unguligrade")) == 2
    assert {d.end for d in digit_plan("leg", "hind", "mammal", "unguligrade")} == {"hoof"}
    assert len(digit_plan("leg", "fore", "mammal", "digitigrade")) == 4
    assert len(digit_plan("leg", "hind", "mammal", "plantigrade")) == 5
    bird = digit_plan("leg", "hind", "bird", "digitigrade")
    assert len(bird) == 4 and sum(d.backward for d in bird) == 1
    assert digit_plan("fin", "fore", "fish", "plantigrade") == ()
    assert {d.end for d in digit_plan("arm", "fore", "mammal", "plantigrade", "primate")} == {
        "nail"
    }


def test_stance_rules_hold_over_seeds():
    from biomorph.creature.quality import ANATOMY_CHECKS, anatomy_check

    fails = {k: [] for k in ANATOMY_CHECKS}
    for seed in range(30):
        c = generate(seed)
        for k, ok in anatomy_check(c).items():
            if not ok:
                fails[k].append(seed)
    # every rule on every seed (issue 14: 100 %)
    assert not any(fails.values()), fails


def test_a_600_kg_ungulate_stands_about_1_2_m_at_the_withers():
    from biomorph.creature.quality import standing_height

    for seed in range(3):
        c = generate(seed, legs=4, weight=600.0, cls="mammal")
        assert 1.1 <= standing_height(c) <= 1.3, standing_height(c)


def test_class_coherence_and_extrapolation():
    import pytest

    from biomorph.errors import ParameterError

    for seed in range(12):
        assert generate(seed, legs=4).params["class"] != "bird"
        assert generate(seed, legs=2).params["class"] != "fish"
    assert generate(1, cls="bird", legs=4).params["legs"] == 4  # asked for: allowed
    with pytest.raises(ParameterError, match="allow-extrapolation"):
        generate(0, weight=5e6)
    c = generate(0, weight=5e6, allow_extrapolation=True, legs=4)
    assert c.total_mass == pytest.approx(5e6, rel=1e-6)


def test_walk_plants_the_feet_and_stays_above_ground():
    from biomorph.creature.walk import phase_offsets, plan_walk, walk_cycle, walk_quality

    for seed, kw in ((3, {"legs": 4}), (2, {"legs": 2}), (5, {"legs": 6})):
        c = generate(seed, **kw)
        plan = plan_walk(c, frames=24, cycles=2, fps=24.0)
        mo = walk_cycle(c, frames=24, cycles=2, fps=24.0)
        assert mo.fps == 24.0 and mo.n_frames == 48 and plan.stride > 0
        q = walk_quality(c, mo, plan)
        assert q["slide_fraction"] <= 0.02, (seed, q)
        assert q["penetration_fraction"] <= 0.005, (seed, q)
        root = mo.world_positions()[:, 0, 0]
        assert root[-1] - root[0] == pytest.approx(plan.stride / plan.period * 47 / 24, rel=1e-9)
    legs = [{"tag": t, "side": s} for t in ("shoulder1", "hip1") for s in "lr"]
    offs, duty = phase_offsets(legs, "trot")
    assert offs == [0.5, 0.0, 0.0, 0.5] and duty == 0.5  # diagonal pairs together
    legs6 = [{"tag": t, "side": s} for t in ("shoulder1", "shoulder2", "hip1") for s in "lr"]
    offs6, _ = phase_offsets(legs6)
    assert sorted(offs6) == [0, 0, 0, 0.5, 0.5, 0.5]
    assert offs6[0] != offs6[1] and offs6[0] != offs6[2]  # tripod alternates
