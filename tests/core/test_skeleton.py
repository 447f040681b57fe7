"""JointSkeleton: world transforms against a naive per-joint reference, structure queries."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import InputError


@st.composite
def skeletons(draw, max_joints=12):
    n = draw(st.integers(1, max_joints))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    parent = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, n)])
    offset = rng.normal(size=(n, 3))
    rest = rng.normal(size=(n, 4))
    rest /= np.linalg.norm(rest, axis=1, keepdims=True)
    frames = draw(st.integers(1, 3))
    rot = rng.normal(size=(frames, n, 4))
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    root = rng.normal(size=(frames, 3))
    sk = JointSkeleton([f"j{i}" for i in range(n)], parent, offset, rest_rotation=rest)
    return sk, rot, root


def naive_world(sk, rot, root):
    """Reference: per joint, walk up to the root multiplying local matrices."""
    n = len(sk)
    out = np.empty((n, 4, 4))
    for j in range(n):
        chain = []
        k = j
        while k >= 0:
            chain.append(k)
            k = sk.parent[k]
        m = np.eye(4)
        for k in reversed(chain):
            t = root if sk.parent[k] < 0 else sk.offset[k]
            q = tf.quat_multiply(sk.rest_rotation[k], rot[k])
            m = m @ tf.make_transform(q, t)
        out[j] = m
    return out


@settings(max_examples=40, deadline=None)
@given(skeletons())
def test_world_matrices_match_naive_reference(data):
    sk, rot, root = data
    world = sk.world_matrices(sk.local_matrices(rot, root))
    assert world.shape == (rot.shape[0], len(sk), 4, 4)
    for f in range(rot.shape[0]):
        assert np.allclose(world[f], naive_world(sk, rot[f], root[f]), atol=1e-9)
    pos = sk.world_positions(rot, root)
    assert np.allclose(pos, world[..., :3, 3])


@settings(max_examples=40, deadline=None)
@given(skeletons())
def test_structure_queries_match_naive(data):
    sk = data[0]
    n = len(sk)
    depth = np.array([0 if sk.parent[i] < 0 else -1 for i in range(n)])
    for i in range(1, n):
        depth[i] = depth[sk.parent[i]] + 1
    assert np.array_equal(sk.depth, depth)
    levels = sk.levels
    assert sorted(np.concatenate(levels).tolist()) == list(range(n))
    for d, lev in enumerate(levels):
        assert np.all(depth[lev] == d)
    for j in range(n):
        kids = [i for i in range(n) if sk.parent[i] == j]
        assert sk.children(j).tolist() == kids
        desc = {j}
        for i in range(n):  # parents precede children
            if sk.parent[i] in desc:
                desc.add(i)
        assert sk.descendants(j).tolist() == sorted(desc)
        assert sk.descendants(sk.names[j], include_self=False).tolist() == sorted(desc - {j})
    segs = sk.bone_segments()
    assert segs.shape == (n - 1, 2, 3)


def test_rest_pose_positions_are_offset_sums():
    sk = JointSkeleton(
        ["hip", "knee", "ankle"], [-1, 0, 1], [[0, 1, 0], [0, -0.5, 0], [0, -0.4, 0.1]]
    )
    assert np.allclose(sk.world_positions(), [[0, 1, 0], [0, 0.5, 0], [0, 0.1, 0.1]])
    bent = tf.quat_identity((3,))
    bent[1] = tf.quat_from_axis_angle("x", np.pi / 2)
    pos = sk.world_positions(bent)
    # knee bent 90 deg about x: ankle offset (0,-0.4,0.1) -> (0,-0.1,-0.4)
    assert np.allclose(pos[2], [0, 0.4, -0.4])
    assert sk.index("knee") == 1


def test_invalid_skeletons_raise_input_error():
    with pytest.raises(InputError, match="parents must precede"):
        JointSkeleton(["a", "b"], [-1, 2], np.zeros((2, 3)))
    with pytest.raises(InputError, match="more than once"):
        JointSkeleton(["a", "a"], [-1, 0], np.zeros((2, 3)))
    with pytest.raises(InputError, match="no joints"):
        JointSkeleton([], [], np.zeros((0, 3)))
    with pytest.raises(InputError, match="offset"):
        JointSkeleton(["a", "b"], [-1, 0], np.zeros((3, 3)))
    sk = JointSkeleton(["a", "b"], [-1, 0], np.zeros((2, 3)))
    with pytest.raises(InputError, match="no joint named"):
        sk.index("zz")
    with pytest.raises(InputError, match="rotation has shape"):
        sk.local_matrices(np.zeros((3, 4)))


def test_skeleton_is_immutable_and_with_copies():
    sk = JointSkeleton(["a", "b"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError):
        sk.offset[0, 0] = 5.0
    sk2 = sk.with_(offset=[[0, 0, 0], [0, 2, 0]])
    assert sk.offset[1, 1] == 1.0 and sk2.offset[1, 1] == 2.0
