"""Muscles and body envelope: attachments on the bones, closed envelope round the bones,
smooth skin weights."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import biomorph.creature as bc
from biomorph.creature.muscles import attachment, muscles
from biomorph.creature.skin import body


@pytest.fixture(scope="module")
def creature():
    return bc.generate(seed=0)


@pytest.fixture(scope="module")
def dressed(creature):
    return body(creature, lod=0)


def test_muscles_run_between_attachments_on_bones(creature, dressed):
    ms = dressed.muscle_list
    limbs = {
        m.name.rsplit("_", 1)[0] for m in ms if not m.name.startswith(("back", "neck", "tail"))
    }
    assert len(limbs) >= 4  # four legs, each with its muscles
    for m in ms:
        assert np.allclose(m.path[0], m.origin) and np.allclose(m.path[-1], m.insertion)
        sheet = m.name.startswith(("back", "neck", "tail")) or "_spinati" in m.name
        if m.origin_joint != m.insertion_joint and not sheet:
            assert m.radius.max() > 3 * m.radius[0]  # tendons thin, belly thick
    # an attachment given on the unit model lies within the bone's box
    j = next(i for i in range(len(creature)) if creature.kind[i] == "leg")
    p = attachment(creature, j, (0.5, 0.5, 0.0))
    local = creature.world[j, :3, :3].T @ (p - creature.world[j, :3, 3])
    assert local[0] == pytest.approx(0.5 * creature.box_size[j, 0])
    assert muscles(creature, 0)[0].name == ms[0].name


def test_envelope_is_closed_and_wraps_the_trunk(creature, dressed):
    env = dressed.envelope
    tm = trimesh.Trimesh(env.vertices, env.faces, process=False)
    assert tm.volume > 0
    back = [j for j in range(len(creature)) if creature.region[j] == "back"]
    inside = tm.contains(creature.joint_positions[back])
    assert inside.mean() > 0.9
    # normals point outwards: moving along them leaves the body
    probe = env.vertices[::50] + env.normals[::50] * 0.05 * creature.height
    assert tm.contains(probe).mean() < 0.1


def test_skin_weights_are_smooth_and_normalised(creature, dressed):
    w, j = dressed.weights, dressed.joints
    assert w.shape == j.shape == (dressed.envelope.n_vertices, 4)
    assert np.allclose(w.sum(axis=1), 1.0)
    assert (w > 0.02).sum(axis=1).mean() > 1.5  # most vertices blend several bones
    assert np.all(creature.bone_length[j[w > 0]] > 0)


def test_obj_with_skin_has_an_envelope_group(creature, tmp_path):
    from biomorph.creature.exporters import export

    plain = export(creature, tmp_path / "a.obj", lod=0).read_text()
    dressed = export(creature, tmp_path / "b.obj", lod=0, skin=True).read_text()
    groups = [ln for ln in dressed.splitlines() if ln.startswith("g ")]
    assert len(groups) == sum(ln.startswith("g ") for ln in plain.splitlines()) + 1
