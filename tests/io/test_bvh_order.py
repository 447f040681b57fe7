"""BVH write of a skeleton whose joints are not stored depth-first (regression)."""

from __future__ import annotations

import numpy as np

import biomorph as bm
from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.motion.motion import Motion


def test_breadth_first_skeleton_round_trips(tmp_path) -> None:
    names = ["root", "a", "b", "a1", "b1", "a2"]
    parent = [-1, 0, 0, 1, 2, 3]  # breadth-first: the file lists root a a1 a2 b b1
    offset = np.array([[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, 1, 0], [0, 0, 1]], float)
    skeleton = JointSkeleton(names, parent, offset)
    rng = np.random.default_rng(3)
    rotation = tf.quat_from_rotvec(rng.normal(size=(5, 6, 3)) * 0.6)
    motion = Motion(skeleton, rotation, rng.normal(size=(5, 3)), 1 / 30)
    path = bm.io.write_bvh(tmp_path / "bfs.bvh", motion)
    back = bm.io.read_bvh(path)
    index = [back.skeleton.index(name) for name in names]
    assert np.allclose(back.world_positions()[:, index], motion.world_positions(), atol=1e-5)
