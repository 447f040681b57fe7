"""Rigify metarig structure (no Blender needed): chains, connect flags, bend axes, exact
walk retargeting, GLB extras and the rigify-setup command."""

from __future__ import annotations

import numpy as np
import pygltflib
import pytest

import biomorph.creature as bc
from biomorph.core.transforms import quat_to_matrix
from biomorph.creature.exporters import TO_GLTF, export, floor_bone_lengths, ground_point
from biomorph.creature.rigify import build_metarig, retarget
from biomorph.creature.walk import walk_cycle


@pytest.fixture(scope="module", params=[0, 3, 7])
def creature(request):
    return bc.generate(seed=request.param)


def test_spine_chain_runs_pelvis_to_head(creature):
    rig = build_metarig(creature)
    sk, names = rig.skeleton, rig.skeleton.names
    assert names[0] == "spine" and sk.parent[0] == -1
    # walk from the head back to the root: every step is a connected spine/neck bone
    j = names.index("head")
    seen = []
    while j > 0:
        seen.append(names[j])
        assert rig.connect[j] or names[j] == "neck", names[j]
        j = int(sk.parent[j])
    assert seen[-1].startswith("spine")
    world = sk.world_matrices()
    skull = creature.kind.index("skull")
    assert np.allclose(world[names.index("head"), :3, 3], creature.joint_positions[skull])
    assert rig.rigify_type[0] in ("spines.basic_spine", "basic.copy_chain")
    # heads of connected bones sit on their parent's tail
    tails = world[:, :3, 3] + world[:, :3, 1] * rig.length[:, None]
    inner = np.flatnonzero(rig.connect)
    assert np.abs(world[inner, :3, 3] - tails[sk.parent[inner]]).max() < 1e-9


def test_legs_have_toe_heel_and_bend_about_x(creature):
    rig = build_metarig(creature)
    names = rig.skeleton.names
    world = rig.skeleton.world_matrices()
    legs = [i for i, t in enumerate(rig.rigify_type) if t == "limbs.leg"]
    girdles = [
        j
        for j in range(len(creature))
        if creature.kind[j] == "girdle"
        and creature.kind[int(np.flatnonzero(creature.skeleton.parent == j)[0])] == "leg"
    ]
    assert len(legs) == len(girdles) > 0
    for i in legs:
        chain = [i]
        for _ in range(3):
            kids = [k for k in np.flatnonzero(rig.skeleton.parent == chain[-1]) if rig.connect[k]]
            assert len(kids) == 1
            chain.append(int(kids[0]))
        heel = [k for k in np.flatnonzero(rig.skeleton.parent == chain[2]) if not rig.connect[k]]
        assert heel and "_heel." in names[heel[0]]
        assert "_toe." in names[chain[3]]
        for k in chain[:2]:
            x = world[k, :3, 0]
            # local X is the flexion axis: lateral, pointing to the creature's left (-z)
            assert x[2] < -0.5, (names[k], x)


def test_walk_is_carried_over_exactly(creature):
    rig = build_metarig(creature)
    mo = walk_cycle(creature, frames=8, cycles=1)
    rm = retarget(mo, rig)
    want = mo.world_matrices()[:, rig.owner] @ rig.carry[None]
    assert np.abs(rm.world_matrices() - want).max() < 1e-9


def test_rigify_glb_carries_rig_types_and_blender_frame(creature, tmp_path):
    p = export(creature, tmp_path / "r.glb", rigify=True, walk=True)
    doc = pygltflib.GLTF2().load(str(p))
    rig = build_metarig(creature)
    nodes = {n.name: n for n in doc.nodes}
    assert all(
        nodes[n].extras.get("rigify_type", "") == t
        for n, t in zip(rig.skeleton.names, rig.rigify_type, strict=True)
    )
    # heads in Blender's frame: creature (x, y, z) -> glTF TO_GLTF -> Blender (x, -z, y)
    skull = creature.joint_positions[creature.kind.index("skull")] @ TO_GLTF.T
    want = [skull[0], -skull[2], skull[1]]
    assert np.allclose(nodes["head"].extras["biomorph_head"], want, atol=1e-6)
    assert len(doc.animations) == 1


def test_glb_axes_and_bone_floor(tmp_path):
    c = bc.generate(seed=5, weight=0.002)
    sk, changed = floor_bone_lengths(c.skeleton)
    assert changed > 0
    d = np.linalg.norm(sk.offset[1:], axis=1)
    assert d[d > 1e-12].min() >= 0.0045 - 1e-12
    p = export(c, tmp_path / "t.glb")
    doc = pygltflib.GLTF2().load(str(p))
    # the ground-level root bone under the centre of mass carries the old root
    ground = next(n for n in doc.nodes if n.name == "root")
    assert np.allclose(ground.translation, ground_point(c) @ TO_GLTF.T)
    assert ground.translation[1] == 0.0
    hips = next(n for n in doc.nodes if n.name == c.names[0])
    assert doc.nodes.index(hips) in ground.children
    world = np.asarray(ground.translation) + quat_to_matrix(ground.rotation) @ hips.translation
    assert np.allclose(world, c.skeleton.offset[0] @ TO_GLTF.T)
    assert np.allclose(TO_GLTF @ [1, 0, 0], [0, 0, 1])  # forward -> +Z
    assert np.allclose(TO_GLTF @ [0, 0, -1], [1, 0, 0])  # the creature's left -> +X


def test_rigify_setup_command(tmp_path, capsys):
    from biomorph.cli import run

    assert run(["creature", "rigify-setup"]) == 0
    text = capsys.readouterr().out
    assert "rigify_generate" in text
    compile(text, "setup.py", "exec")
    out = tmp_path / "s.py"
    assert run(["creature", "rigify-setup", "-o", str(out)]) == 0
    assert out.read_text().startswith("# biomorph rigify-setup")
    assert run(["creature", "rigify-setup", "-o", str(tmp_path / "s.txt")]) == 2
    assert "expected one of .py" in capsys.readouterr().err
    assert not (tmp_path / "s.txt").exists()
