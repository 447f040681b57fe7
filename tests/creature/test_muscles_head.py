"""Jaw closers (temporalis, masseter) and digital flexors in the muscle set."""

from __future__ import annotations

import numpy as np

import biomorph.creature as bc
from biomorph.creature.muscles import muscles


def test_jaw_closers_run_from_the_skull_down_to_the_mandible():
    c = bc.generate(seed=11, legs=4, wings=False, cls="mammal")
    s, j = c.kind.index("skull"), c.names.index("jaw")
    ms = {m.name: m for m in muscles(c, 1)}
    dorsal = -c.world[s, :3, 0]  # the skull frame's local X is ventral (it points headward)
    right = np.array([0.0, 0.0, 1.0])
    for side, sign in (("r", 1.0), ("l", -1.0)):
        t, m = ms[f"temporalis_{side}"], ms[f"masseter_{side}"]
        for mu in (t, m):
            assert (mu.origin_joint, mu.insertion_joint) == (s, j)
            assert (mu.origin - mu.insertion) @ dorsal > 0  # origin above the insertion
            assert sign * (mu.path[len(mu.path) // 2] - c.joint_positions[s]) @ right > 0
            assert mu.radius.max() < 0.5 * c.box_size[s].max()
        # the temporalis starts on the crown, higher than the masseter's arch
        assert (t.origin - m.origin) @ dorsal > 0


def test_no_jaw_muscles_without_a_jaw_and_flexors_on_standing_legs():
    c = bc.generate(seed=11, legs=4, wings=False, cls="mammal")
    names = [m.name for m in muscles(c, 1)]
    assert sum(n.endswith("_flexor") for n in names) == 4
    fish = bc.generate(seed=2, legs=0, cls="fish")
    fnames = [m.name for m in muscles(fish, 1)]
    assert not any(n.endswith("_flexor") for n in fnames)
    if "jaw" not in fish.names:
        assert not any(n.startswith(("temporalis", "masseter")) for n in fnames)
