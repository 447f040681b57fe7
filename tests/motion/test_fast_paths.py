"""Fast paths give the same bits as the paths they replace: the Motion type's NumPy FK and
slerp (small work, numba not loaded) against the compiled kernels, and each operator's fused
kernel against the reference it replaced (tests/motion/oracles.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from biomorph.core import motion as cm
from biomorph.core._motion_kernels import fk_positions, sample_slerp
from biomorph.io.bvh import read_bvh
from biomorph.motion.synthetic import walk
from tests.conftest import shared_file


def _clips():
    out = [walk(300, 120, n_joints=40, noise_deg=2.0, seed=3)]
    for name in ("ad_rokoko_jesse_dance.bvh", "ad_fair1_zombie_walk.bvh"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(read_bvh(shared_file("motion", name)))
    return out


@pytest.fixture(scope="module")
def clips():
    return _clips()


def test_numpy_fk_equals_the_compiled_fk(clips):
    for m in clips:
        rot = np.ascontiguousarray(m.rotation)
        tr = np.ascontiguousarray(m.local_translations())
        sk = m.skeleton
        p1, q1 = np.empty(tr.shape), np.empty(rot.shape)
        p2, q2 = np.empty(tr.shape), np.empty(rot.shape)
        fk_positions(cm.ro(sk.rest_rotation), cm.ro(rot), cm.ro(tr), cm.ro_int(sk.parent), p1, q1)
        cm.fk_numpy(sk.rest_rotation, rot, tr, sk.parent, p2, q2)
        assert np.array_equal(p1, p2) and np.array_equal(q1, q2)


def test_numpy_slerp_equals_the_compiled_slerp(clips):
    rng = np.random.default_rng(0)
    for m in clips:
        t = np.sort(rng.uniform(0, m.n_frames - 1, 2 * m.n_frames))
        t[::5] = np.floor(t[::5])  # exact frames
        t[-1] = m.n_frames - 1
        i0, frac, _, _ = cm.sample_linear(m, t)
        a = np.empty((t.size,) + m.rotation.shape[1:])
        b = np.empty_like(a)
        sample_slerp(cm.ro(m.rotation), cm.ro_int(i0), cm.ro(frac), a)
        cm.slerp_numpy(m.rotation, i0, frac, b)
        assert np.array_equal(a, b)


def test_store_flips_match_the_sequential_rule():
    """The compiled continuity step compares with the *stored* previous sample: a dot of
    exactly 0 resets the sign (``-0 < 0`` is false), which a plain parity count misses."""
    dots = np.array([[0.5], [-0.2], [0.0], [-0.3], [0.7], [-0.1], [np.nan], [0.4]])
    sign, want = 1.0, []
    for d in dots[:, 0]:
        sign = -1.0 if sign * d < 0 else 1.0
        want.append(sign < 0)
    assert cm._store_flips(dots)[:, 0].tolist() == want


def test_use_compiled_thresholds(monkeypatch):
    """NumPy below the threshold, compiled from it on — per call, and once the NumPy calls
    of the process add up to it (many small clips do not stay on the slower path)."""
    monkeypatch.delitem(__import__("sys").modules, "biomorph.core._motion_kernels")
    monkeypatch.setattr(cm, "_numpy_work", [0])
    assert cm.use_compiled(cm.COMPILED_MIN_WORK)
    half = cm.COMPILED_MIN_WORK // 2 + 1
    assert not cm.use_compiled(half) and not cm.use_compiled(half)
    assert cm.use_compiled(10)


def test_bvh_numpy_paths_add_up_to_the_kernels(monkeypatch, tmp_path):
    import biomorph.io.bvh as bvh
    from biomorph.io.bvh import read_bvh, write_bvh

    monkeypatch.delitem(__import__("sys").modules, "biomorph.io._bvh_kernels", raising=False)
    monkeypatch.setattr(bvh, "_numpy_values", [0])
    monkeypatch.setattr(bvh, "_COMPILED_MIN_VALUES", 5000)
    p = tmp_path / "w.bvh"
    mo = walk(30, 30, n_joints=20)
    write_bvh(p, mo)  # one write and two reads of 30 frames × n_ch values: all NumPy
    n_ch = sum(len(c) for c in mo.skeleton.channels)
    assert not bvh._compiled(10)
    for _ in range(2):
        read_bvh(p)
    assert bvh._numpy_values[0] == 3 * 30 * n_ch and bvh._compiled(10)


def _mirror_setup(m):
    from biomorph.motion import names as nm
    from biomorph.motion.retarget import _mirror_corrections, mirror

    out = mirror(m)
    a = "xyz".index(out.meta["history"][-1][-1])
    pairs = nm.left_right_pairs(m.names)
    other = np.arange(m.n_joints)
    for i, j in pairs:
        other[i], other[j] = j, i
    sign = -np.ones(4)
    sign[a] = sign[3] = 1.0
    corr, used = _mirror_corrections(m.skeleton, other, a, m.world_rotations()[0])
    return out, other, sign, corr if used else None


def test_mirror_kernel_equals_fk_gather_local_reference(clips):
    from tests.motion.oracles import mirror_rotations_reference

    for m in clips:
        out, other, sign, corr = _mirror_setup(m)
        want = mirror_rotations_reference(m, other, sign, corr)
        if corr is None:  # a symmetric rig: the kernel's bits
            assert np.array_equal(out.rotation, want)
        else:  # the Rokoko rig's frame corrections: quaternion products in another order
            assert np.abs(out.rotation - want).max() < 1e-12


def test_continuity_kernel_equals_quat_continuous():
    from biomorph.motion._kernels import continuous_inplace
    from tests.motion.oracles import continuous_reference

    rng = np.random.default_rng(4)
    q = rng.normal(size=(500, 7, 4))
    q[200:260] = q[199:200]  # repeated samples
    q[300, 2] = [1, 0, 0, 0]
    q[301, 2] = [0, 1, 0, 0]  # a dot of exactly 0
    got = np.array(q)
    continuous_inplace(got)
    assert np.array_equal(got, continuous_reference(q))


def test_root_motion_extract_equals_the_concatenate_reference(clips):
    """The extracted motion is built in place (no concatenation, one continuity pass);
    the arrays equal the concatenate-then-quat_continuous construction it replaced."""
    from biomorph.core import transforms as tf
    from biomorph.motion.rootmotion import extract_root_motion, ground_path

    for m in clips:
        out = extract_root_motion(m)
        path, yaw = ground_path(m)
        q = tf.quat_from_axis_angle([0.0, 1.0, 0.0], yaw)
        rest_h, inv = m.skeleton.rest_rotation[0], tf.quat_conjugate
        hips = tf.quat_multiply(
            inv(rest_h), tf.quat_multiply(inv(q), tf.quat_multiply(rest_h, m.rotation[:, 0]))
        )
        rot = np.concatenate([q[:, None], m.rotation], axis=1)
        rot[:, 1] = hips
        jt = np.concatenate([path[:, None], m.local_translations()], axis=1)
        jt[:, 1] = tf.quat_rotate(inv(q), m.root_position - path)
        assert np.array_equal(out.rotation, tf.quat_continuous(rot, axis=0))
        assert np.array_equal(out.joint_translation, jt)
        assert np.array_equal(out.root_position, path)


@pytest.mark.parametrize("boundary", ["edge", "reflect"])
def test_equalizer_vectorised_mean_log_path_equals_the_scalar_loop(boundary):
    """The mean-log path evaluates log and exp series over all frames at once (frames past
    the series' range redone exactly): the same bits as the frame-by-frame scalar loop, on
    a clip where many frames take each branch."""
    import biomorph.motion as bm
    from biomorph.core import transforms as tf
    from tests.motion.oracles import equalize_mean_log_reference

    m = walk(900, 120, n_joints=24, noise_deg=3.0, seed=7)
    rot = np.array(m.rotation)  # one joint swinging ±80°: both series' fallbacks are used
    rot[:, 5] = tf.quat_from_axis_angle([0.3, 0.0, 1.0], 1.4 * np.sin(np.arange(900) / 20))
    m = m.with_(rotation=rot)
    g = np.array([0.0, 0.5, 1.0, 1.3, 0.8])
    half = 0.5 * np.linalg.norm(tf.quat_to_rotvec(rot[:, 5]), axis=-1)
    assert (half > 0.5).mean() > 0.2 and (half < 0.05).mean() > 0.02
    got = bm.equalize(m, g, boundary=boundary).rotation
    ref = equalize_mean_log_reference(m.rotation, g, ["edge", "reflect"].index(boundary))
    assert np.array_equal(got, ref)


def test_pure_translation_of_the_root_shares_the_rotations(clips):
    """``transform_root`` with the identity rotation (blend's alignment step) keeps the pose
    rotations without the rest⁻¹·I·rest round trip: equal to the general formula, and the
    rotation array is shared, not copied."""
    from biomorph.core import transforms as tf
    from biomorph.core.motion import transform_root

    ident = np.array([0.0, 0.0, 0.0, 1.0])
    for m in clips:
        shift, pivot = np.array([0.3, 0.0, -1.2]), np.array([0.5, 0.0, 0.25])
        out = transform_root(m, ident, shift, pivot)
        pos = tf.quat_rotate(ident, m.root_position - pivot) + pivot + shift
        rest = m.skeleton.rest_rotation[0]
        turned = tf.quat_multiply(ident, tf.quat_multiply(rest, m.rotation[:, 0]))
        root = tf.quat_multiply(tf.quat_conjugate(rest), turned)
        assert np.array_equal(out.root_position, pos)
        assert np.array_equal(out.rotation[:, 0], tf.quat_continuous(root, axis=0))
        assert np.array_equal(out.rotation[:, 1:], m.rotation[:, 1:])
        assert out.rotation is m.rotation


def test_dtw_features_of_a_window_equal_the_sliced_clip_features(clips):
    """DTW alignment computes pose features of the matched windows only."""
    from biomorph.motion.align import pose_features

    for m in clips:
        k = m.n_frames // 3
        assert np.array_equal(pose_features(m[k:]), pose_features(m)[k:])
        assert np.array_equal(pose_features(m[:k]), pose_features(m)[:k])


def test_retarget_kernel_with_fused_source_fk_equals_the_reference(clips):
    """The retarget kernel computes the source's world rotations per frame itself (no
    ``(f, n, 4)`` FK array): equal to the reference fed with ``world_rotations()``."""
    from biomorph.core import transforms as tf
    from biomorph.motion.retarget import _retarget_kernel
    from tests.motion.oracles import retarget_rotations_reference

    rng = np.random.default_rng(2)
    for m in clips:
        sk = m.skeleton
        n = sk.n_joints + 3  # a target with a few extra (unmapped) joints
        parent = np.concatenate([sk.parent, [1, n - 3, 0]])
        src_of = np.concatenate([np.arange(sk.n_joints), [-1, -1, -1]])
        src_of[rng.choice(sk.n_joints, 3, replace=False)] = -1
        pre, post, rest_t = (tf.quat_normalize(rng.normal(size=(n, 4))) for _ in range(3))
        got = np.empty((m.n_frames, n, 4))
        _retarget_kernel(
            cm.ro(sk.rest_rotation),
            cm.ro(m.rotation),
            cm.ro_int(sk.parent),
            cm.ro_int(src_of),
            cm.ro(pre),
            cm.ro(post),
            cm.ro(rest_t),
            cm.ro(rest_t),  # unmapped joints composed with their own rest
            cm.ro_int(parent),
            got,
        )
        ref = retarget_rotations_reference(m.world_rotations(), src_of, pre, post, rest_t, parent)
        assert np.array_equal(got, ref)
