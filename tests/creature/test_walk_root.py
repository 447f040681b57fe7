"""Root motion on the ground-level root bone: exact, on the ground, in the GLB."""

from __future__ import annotations

import numpy as np
import pygltflib

import biomorph.creature as bc
from biomorph.creature.exporters import ground_point, with_ground_root, write_glb
from biomorph.creature.walk import plan_walk, walk_cycle


def test_ground_root_carries_the_walk_exactly():
    c = bc.generate(seed=11, legs=4, wings=False, cls="mammal")
    mo = walk_cycle(c)
    sk, mo2 = with_ground_root(c.skeleton, mo, ground_point(c))
    assert sk.names[0] == "root" and sk.parent[1] == 0 and (sk.parent[2:] >= 1).all()
    a, b = mo.world_matrices(), mo2.world_matrices()
    assert np.abs(a - b[:, 1:]).max() < 1e-12  # every joint where it was
    root = b[:, 0, :3, 3]
    assert np.abs(root[:, 1]).max() == 0.0  # on the ground in every frame
    plan = plan_walk(c)
    speed = np.diff(root[:, 0]) * plan.fps
    assert np.allclose(speed, plan.stride / plan.period)  # the body's travel rides on it
    assert np.allclose(root[0], ground_point(c))
    # rest: the root under the centre of mass, its +Y aimed at the old root
    w = sk.world_matrices()
    aim = c.skeleton.offset[0] - ground_point(c)
    assert np.allclose(w[0, :3, 1], aim / np.linalg.norm(aim))


def test_glb_root_translation_keys_stay_on_the_ground(tmp_path):
    c = bc.generate(seed=4, legs=2, wings=False, cls="reptile")
    p = write_glb(c, tmp_path / "w.glb", walk=True)
    doc = pygltflib.GLTF2().load(str(p))
    root = next(i for i, n in enumerate(doc.nodes) if n.name == "root")
    assert doc.skins[0].joints[0] == root
    ch = [
        x
        for x in doc.animations[0].channels
        if x.target.node == root and x.target.path == "translation"
    ]
    assert len(ch) == 1
    acc = doc.accessors[doc.animations[0].samplers[ch[0].sampler].output]
    view = doc.bufferViews[acc.bufferView]
    data = doc.binary_blob()[view.byteOffset + (acc.byteOffset or 0) :][: acc.count * 12]
    keys = np.frombuffer(data, np.float32).reshape(-1, 3)
    assert np.abs(keys[:, 1]).max() == 0.0 and np.ptp(keys[:, 2]) > 0  # glTF: Y up, +Z forward
