"""Procedural bone models: every joint dressed, models inside their boxes, closed outward
meshes, regional variation along the spine, rib cage, skull with mandible, LODs, GLB."""

from __future__ import annotations

import numpy as np
import pygltflib
import pytest

import biomorph.creature as bc
from biomorph.creature.bones import LODS, geometry, joint_meshes, world_mesh
from biomorph.creature.bones import appendicular as ap
from biomorph.creature.bones import axial as ax
from biomorph.creature.bones import skull as sk
from biomorph.creature.bones.fit import parts_of
from biomorph.creature.exporters import export
from biomorph.errors import ParameterError


def signed_volume(v, f):
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float((a * np.cross(b, c)).sum() / 6)


@pytest.fixture(scope="module", params=[0, 3])
def creature(request):
    return bc.generate(seed=request.param)


def test_every_bone_dressed_with_closed_outward_meshes(creature):
    meshes = joint_meshes(creature)
    with_bone = set(np.flatnonzero(creature.bone_length > 1e-9).tolist())
    assert set(meshes) == with_bone
    for j, m in meshes.items():
        assert signed_volume(m.vertices, m.faces) > 0, creature.names[j]
        assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0)
    w = world_mesh(creature)
    assert signed_volume(w.vertices, w.faces) > 0
    assert w.vertices[:, 1].min() > -0.02 * creature.height  # nothing sinks into the ground


def test_limb_and_vertebra_models_fit_their_boxes(creature):
    meshes = joint_meshes(creature)
    parts = parts_of(creature)
    for j, m in meshes.items():
        if parts[j] in ("thoracic", "scapula", "pelvis", "mandible"):
            continue  # ribs/blade/clavicle/pubis reach out; the coronoid rises into the skull
        L = creature.bone_length[j]
        half = np.array([creature.box_size[j, 0], 0, creature.box_size[j, 2]]) / 2
        tol = 0.08 * max(L, half.max())
        v = m.vertices
        assert np.all(np.abs(v[:, [0, 2]]) <= half[[0, 2]] * 1.05 + tol), creature.names[j]
        assert v[:, 1].min() >= -tol and v[:, 1].max() <= L + tol, creature.names[j]


def test_vertebrae_vary_by_region():
    def spine_top(region, t):
        v, _, _ = ax.vertebra(region, t, 1)
        return v[:, 0].max()

    def span(region, t):
        v, _, _ = ax.vertebra(region, t, 1)
        return np.ptp(v[:, 2])

    assert spine_top("thoracic", 0) > spine_top("cervical", 0) + 0.1
    assert spine_top("thoracic", 0) > spine_top("thoracic", ax.BINS - 1)  # withers tallest
    assert span("lumbar", 2) > span("thoracic", 2)  # long processes
    assert spine_top("caudal", ax.BINS - 1) < spine_top("caudal", 0)  # fading out
    # the caudal vertebrae carry chevrons below the centrum near the tail base
    assert ax.vertebra("caudal", 0, 1)[0][:, 0].min() < ax.vertebra("lumbar", 0, 1)[0][:, 0].min()


def test_rib_cage_wraps_the_trunk(creature):
    parts = parts_of(creature)
    meshes = joint_meshes(creature)
    thor = [j for j in range(len(creature)) if parts[j] == "thoracic" and j in meshes]
    assert thor
    for j in thor[:3]:
        v = meshes[j].vertices
        width = creature.mass_size[j, 2]
        assert np.ptp(v[:, 2]) > 0.7 * max(width, creature.box_size[j, 2])  # ribs span it
    fish_ribs = ax.rib_pair(1.0, True, 1)[0]
    tetra_ribs = ax.rib_pair(1.0, False, 1)[0]
    assert tetra_ribs[:, 0].min() < fish_ribs[:, 0].min()  # ribs reach the sternum, fish don't


def test_skull_has_orbits_and_a_separate_mandible():
    with_jaw = sk.skull("mammal", 1, True)
    without = sk.skull("mammal", 1, False)
    jaw = sk.mandible("mammal", 1)
    assert len(with_jaw[0]) == len(without[0]) + len(jaw[0])
    placed = with_jaw[0][len(without[0]) :]
    assert placed[:, 0].min() < without[0][:, 0].min() + 0.05  # the jaw at the skull's base


def _profile(v, y0, y1):
    """(height, width) of a unit skull's vertices with y in [y0, y1]."""
    sel = v[(v[:, 1] >= y0) & (v[:, 1] <= y1)]
    return np.ptp(sel[:, 0]), np.ptp(sel[:, 2])


def test_skull_shapes_per_class():
    mammal, bird, croc = (sk.skull(p, 1, False)[0] for p in ("mammal", "bird", "reptile_long"))
    # a bird's beak closes to a point; a mammal's muzzle keeps a blunt end
    assert _profile(bird, 0.93, 1.0)[0] < 0.5 * _profile(mammal, 0.93, 1.0)[0]
    # facial part: crocodylian snout longer than a dog's muzzle, a primate's shortest
    assert sk.PLANS["reptile_long"].snout > sk.PLANS["mammal"].snout > sk.PLANS["primate"].snout
    # a crocodylian skull is flat: its snout wider than deep, a dog's deeper than a croc's
    h_c, w_c = _profile(croc, 0.6, 0.9)
    assert w_c > h_c
    assert _profile(mammal, 0.6, 0.9)[0] > h_c
    # birds' orbits are the largest openings (share of the skull height)
    assert sk.PLANS["bird"].orbit[2] > sk.PLANS["mammal"].orbit[2]
    # plans by skull type, falling back to the class
    assert sk.plan_for("mammal_long", "mammal") == "mammal"
    assert sk.plan_for("unknown", "bird") == "bird"


def test_autopods_have_digits_per_class():
    def tips(vf):
        v = vf[0]
        return v[v[:, 1] > 0.97 * v[:, 1].max()]

    five = ap.autopod(5, 0.4, "claw", 1, 0.62)
    two = ap.autopod(2, 0.2, "hoof", 1, 0.62)
    assert len(five[0]) > 2 * len(two[0])
    assert np.ptp(tips(five)[:, 2]) > 0


def test_levels_of_detail_and_box_shape(creature):
    counts = [len(geometry(creature, "bone", lod)[3]) for lod in LODS]
    assert counts[0] < counts[1] < counts[2]
    box = joint_meshes(creature, "box")
    assert all(m.n_vertices == 8 for j, m in box.items() if creature.kind[j] != "skull")
    with pytest.raises(ParameterError, match="level of detail"):
        geometry(creature, "bone", 3)
    with pytest.raises(ParameterError, match="bone shape"):
        geometry(creature, "blob")


def test_glb_with_bone_models_and_skin_is_valid(creature, tmp_path):
    from tests.gltf_validator import assert_valid_glb

    p = export(creature, tmp_path / "c.glb", skin=True)
    assert_valid_glb(p)
    doc = pygltflib.GLTF2().load(str(p))
    names = [m.name for m in doc.meshes]
    assert names == ["creature_bones", "creature_skin_mesh"]
    assert all(n.skin == 0 for n in doc.nodes if n.mesh is not None)


def test_hooved_foot_without_digit_joints_follows_hoof_digits():
    """A metapodial without digit joints of its own gets an autopod with the creature's
    hoof count: one centred hoof for a horse, a cloven pair otherwise."""
    from types import SimpleNamespace

    from biomorph.creature.bones import fit

    def model(hoof_digits):
        c = SimpleNamespace(skeleton=SimpleNamespace(parent=np.array([-1])), kind=("leg",))
        ctx = SimpleNamespace(
            c=c, lod=1, cls="mammal", stance="unguligrade", hoof_digits=hoof_digits
        )
        return fit._limb_model(ctx, 0, "metatarsal")

    horse, cattle = model(1), model(2)
    assert horse is ap.autopod(1, 0.0, "hoof", 1, 0.62)
    assert cattle is ap.autopod(2, 0.18, "hoof", 1, 0.62)
    # one hoof on the midline vs two side by side
    assert np.ptp(horse[0][:, 2]) < np.ptp(cattle[0][:, 2])
    assert ap.ungulate(1) == (1, 0.0, "hoof") and ap.ungulate(2)[0] == 2
