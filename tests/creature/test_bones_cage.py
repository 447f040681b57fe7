"""Rib cage round the trunk's sections, inside the skin; scapula on the cage's side."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

import biomorph.creature as bc
from biomorph.creature.bones import cage
from biomorph.creature.bones.appendicular import scapula
from biomorph.creature.bones.fit import parts_of
from biomorph.creature.muscles import muscles
from biomorph.creature.skin import envelope_field

CASES = [
    (11, dict(legs=4, wings=False, cls="mammal")),
    (1, dict(legs=2, cls="reptile")),  # has massless trunk vertebrae
    (6, dict(cls="bird")),
    (2, dict(legs=0, cls="fish")),
    (3, dict(legs=4, centaur=True, wings=False)),
    (16, {}),
]


def thoracic(c):
    p = parts_of(c)
    return [j for j in range(len(c)) if p[j] == "thoracic"]


@pytest.fixture(scope="module", params=CASES, ids=[f"seed{s}" for s, _ in CASES])
def creature(request):
    seed, kw = request.param
    return bc.generate(seed=seed, **kw)


@pytest.mark.parametrize("lod", [0, 1])
def test_no_rib_vertex_outside_the_skin(creature, lod):
    pieces = cage.rib_cage(creature, thoracic(creature), lod, creature.params["class"] == "fish")
    assert pieces
    v = np.concatenate([p[0][p[2]] for p in pieces.values()])
    grid, lo, h = envelope_field(creature, muscles(creature, lod), lod)
    inside = map_coordinates(grid, ((v - lo) / h).T, order=1)  # field > 0 inside the skin
    assert (inside <= 0).sum() == 0, f"{(inside <= 0).sum()} of {len(v)} rib vertices outside"


@pytest.mark.parametrize("lod", [0, 1])
def test_no_scapula_vertex_outside_the_skin(creature, lod):
    parts = parts_of(creature)
    blades = [
        cage.scapula_blade(creature, j, scapula(lod), creature.params["class"])
        for j in range(len(creature))
        if parts[j] == "scapula"
    ]
    blades = [b for b in blades if b is not None]
    if not blades:
        pytest.skip("no shoulder blade (fish)")
    v = np.concatenate([b[0] for b in blades])
    grid, lo, h = envelope_field(creature, muscles(creature, lod), lod)
    inside = map_coordinates(grid, ((v - lo) / h).T, order=1)
    assert (inside <= 0).sum() == 0, f"{(inside <= 0).sum()} of {len(v)} blade vertices outside"


def test_ribs_arch_round_the_trunk_to_the_sternum():
    c = bc.generate(seed=11, legs=4, wings=False, cls="mammal")
    th = thoracic(c)
    pieces = cage.rib_cage(c, th, 1)
    idx, centre, radius = cage.trunk_sections(c)
    sec = {int(j): (centre[k], radius[k]) for k, j in enumerate(idx)}
    deep = 0
    for j in th:
        v, _, rib = pieces[j]
        cen, r = sec[j]
        ribs = v[rib]
        # ribs arch out to both sides (a barrel, not rods hanging below the spine)
        assert ribs[:, 2].max() > 0.6 * r and ribs[:, 2].min() < -0.6 * r
        # and their depth follows the trunk's: down to near its bottom, never below it
        assert ribs[:, 1].min() > (centre[:, 1] - radius).min()
        deep += ribs[:, 1].min() < cen[1] - 0.4 * r
        if (~rib).any():  # true ribs: a sternebra on the ventral midline under the centre
            st = v[~rib]
            assert abs(st[:, 2].mean()) < 1e-9 and st[:, 1].mean() < cen[1] - 0.6 * r
    assert deep == len(th)


def test_scapula_glenoid_at_the_shoulder_on_the_cage_side():
    c = bc.generate(seed=11, legs=4, wings=False, cls="mammal")
    parts = parts_of(c)
    idx, centre, radius = cage.trunk_sections(c)
    for j in [j for j in range(len(c)) if parts[j] == "scapula"]:
        v, f = cage.scapula_blade(c, j, scapula(1), "mammal")
        glen = c.bone_ends[j]  # the shoulder joint
        assert np.linalg.norm(v - glen, axis=1).min() < 0.1 * np.linalg.norm(np.ptp(v, axis=0))
        top = v[v[:, 1].argmax()]
        assert top[1] > glen[1] + 0.3 * c.bone_length[j] and top[0] < glen[0]  # up and back
        # the blade lies on the cage, not in it: no vertex deep inside a trunk section
        d = np.linalg.norm(v[:, None, :] - centre[None], axis=2) - radius[None]
        assert d.min(axis=1).min() > -0.25 * radius.max()
        assert np.sign(v[:, 2].mean()) == np.sign(glen[2])
