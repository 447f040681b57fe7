"""MJCF contact scaled to the creature's size (issue 14): a 7-cm creature on 0.3-mm foot
pads stands in MuJoCo instead of sinking through the floor and flipping."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.creature.generator import generate
from biomorph.io.mjcf import CONTACT_TIMECONST, TIMESTEP, contact_scale, creature_to_mjcf


def test_contact_scales_with_size():
    big, tiny = generate(0), generate(38)
    assert max(big.height, big.length) >= 1.0
    assert max(tiny.height, tiny.length) < 0.1  # the defect's creature: 10 g, 7 cm
    b, t = contact_scale(big), contact_scale(tiny)
    assert b["timeconst"] == CONTACT_TIMECONST and b["timestep"] == TIMESTEP
    size = max(tiny.height, tiny.length)
    assert t["timeconst"] == pytest.approx(CONTACT_TIMECONST * np.sqrt(size))
    assert t["width"] == pytest.approx(1e-3 * size)
    assert t["timeconst"] >= 2 * t["timestep"]  # MuJoCo's stability bound
    xml = creature_to_mjcf(tiny, rigid=True)
    assert f'solref="{t["timeconst"]:.9g} 1"' in xml


def test_tiny_creature_settles_upright():
    pytest.importorskip("mujoco")
    from biomorph.io.mjcf import settle

    c = generate(38)
    assert c.balance.applicable and max(c.height, c.length) < 0.1
    r = settle(c)
    assert r["upright"], r
    # it rests on its pads: the root sank by less than 2 % of the creature's height
    assert r["root_height_m"] > c.skeleton.offset[0, 1] - 0.02 * c.height, r
