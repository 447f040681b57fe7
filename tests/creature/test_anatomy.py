"""Per-joint anatomical labels (the contract with bone models / rigs)."""

from __future__ import annotations

import numpy as np

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
    assert c.digit is not None and np.all(c.digit[[p not in ("phalanx", "hoof", "claw", "nail")
                                                   for p in c.part]] == 0)
    assert c.to_dict()["bones"][0]["part"] == c.part[0]


def test_back_splits_into_thoracic_lumbar_sacral_in_mammals_only():
    vreg = np.array([0] * 7 + [1] * 20 + [2] * 5)
    m = vertebra_parts(vreg, "mammal")
    assert m[:7] == ["cervical"] * 7 and m[-5:] == ["caudal"] * 5
    back = m[7:27]
    assert back.count("sacral") == 3 and back.count("lumbar") == 5
    assert back[-1] == "sacral" and back[0] == "thoracic"
    assert "lumbar" not in vertebra_parts(vreg, "reptile")
