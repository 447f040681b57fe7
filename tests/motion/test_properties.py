"""The properties issue 4 asks the tests to check, one test each (plus real-data variants)."""

from __future__ import annotations

import numpy as np
import pytest

import biomorph.motion as bm
from biomorph.core import transforms as tf
from biomorph.io.bvh import read_bvh, write_bvh
from biomorph.motion.align import pose_features
from biomorph.motion.displacement import displacement_curve
from biomorph.motion.synthetic import spin, walk
from tests.conftest import shared_file


def _mean_acc(m: bm.Motion) -> float:
    w = m.world_positions()
    return float(np.linalg.norm(np.diff(w, 2, axis=0), axis=-1).mean())


# 1 ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "source", ["synthetic", "ad_fair1_zombie_walk.bvh", "ad_rokoko_jesse_dance.bvh"]
)
def test_unity_gains_reproduce_input(source):
    m = (
        walk(300, 60, noise_deg=1.0)
        if source == "synthetic"
        else read_bvh(shared_file("motion", source))
    )
    for gains in ([1, 1, 1, 1, 1], [1, 1, 1], np.ones(n_max := bm.n_bands(m.n_frames) + 1)):
        out = bm.equalize(m, gains)
        assert np.abs(out.rotation - m.rotation).max() < 1e-9, (gains, n_max)
        assert np.abs(out.root_position - m.root_position).max() < 1e-9


# 2 ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("source", ["synthetic", "cmu_01_01.bvh"])
def test_removing_high_bands_lowers_acceleration(source):
    m = (
        walk(400, 120, noise_deg=1.5)
        if source == "synthetic"
        else read_bvh(shared_file("motion", source))[100:700]
    )
    before = _mean_acc(m)
    after = _mean_acc(bm.equalize(m, [0, 0, 1, 1, 1]))
    assert after < 0.8 * before
    # and raising them adds jitter
    assert _mean_acc(bm.equalize(m, [2, 2, 1, 1, 1])) > before


# 3 ---------------------------------------------------------------------------------------
def test_spinning_joint_stays_continuous():
    m = spin(240, 60, turns=1.5)  # root turns 540°: Euler Y passes ±180° several times
    step_in = tf.quat_angle(m.rotation[1:, 0], m.rotation[:-1, 0])
    for gains in ([0, 0, 1, 1, 1], [1, 1, 2, 2, 1], [0.5, 1, 1, 1, 0.9]):
        out = bm.equalize(m, gains)
        step = tf.quat_angle(out.rotation[1:, 0], out.rotation[:-1, 0])
        assert step.max() < 2.0 * step_in.max(), gains
    # real data: the zombie's Hips Zrotation wraps ±180° 16 times in the file
    z = read_bvh(shared_file("motion", "ad_fair1_zombie_walk.bvh"))
    out = bm.equalize(z, [0, 0, 1, 1, 1])
    hips_in = tf.quat_angle(z.rotation[1:, 0], z.rotation[:-1, 0])
    hips = tf.quat_angle(out.rotation[1:, 0], out.rotation[:-1, 0])
    assert hips.max() <= hips_in.max() + 1e-9
    e = out.euler(0, degrees=True)
    assert np.abs(np.diff(e, axis=0)).max() < 30  # unwrapped view: no ±360 spikes


# 4 ---------------------------------------------------------------------------------------
def test_blend_constant_curve_gives_a_or_b_exactly():
    a = walk(200, 60, seed=1, noise_deg=0.5)
    b = walk(200, 60, stride_hz=1.3, speed=2.0, seed=2, noise_deg=0.5)
    out0 = bm.blend([a, b], offsets=[0, 0], curve=0.0)
    assert np.array_equal(out0.rotation, a.rotation)
    assert np.array_equal(out0.root_position, a.root_position)
    out1 = bm.blend([a, b], offsets=[0, 0], curve=1.0, align_root=False)
    assert np.array_equal(out1.rotation, b.rotation)
    assert np.array_equal(out1.root_position, b.root_position)
    # with root alignment B's local (non-root) rotations are still B's exactly
    out1a = bm.blend([a, b], offsets=[0, 0], curve=1.0)
    assert np.array_equal(out1a.rotation[:, 1:], b.rotation[:, 1:])


# 5 ---------------------------------------------------------------------------------------
def test_displacement_hits_keys_and_is_zero_outside_support():
    keys = {60: [0.1, -0.2, 0.3], 75: [0.0, 0.4, 0.0], 90: [-0.3, 0.0, 0.1]}
    d = displacement_curve(keys, 200, fade=20)
    for f, v in keys.items():
        assert np.allclose(d[f], v, atol=0, rtol=0) or np.abs(d[f] - v).max() < 1e-12
    assert not d[:40].any() and not d[111:].any()
    assert np.abs(d[41:110]).max() > 0
    m = walk(200, 60, noise_deg=0.5)
    out = bm.displace(m, "LeftArm", keys, fade=20)
    j = m.skeleton.index("LeftArm")
    for f, v in keys.items():
        got = tf.quat_to_rotvec(
            tf.quat_multiply(tf.quat_conjugate(m.rotation[f, j]), out.rotation[f, j])
        )
        assert np.abs(got - v).max() < 1e-9
    same = np.r_[0:40, 111:200]
    assert np.array_equal(out.rotation[same], m.rotation[same])
    others = [i for i in range(m.n_joints) if i != j]
    assert np.array_equal(out.rotation[:, others], m.rotation[:, others])
    # high-frequency detail is kept: the change is smooth (its second difference is tiny;
    # auto-clamped keys are C1, the former C2 spline reached 0.0096 here, these 0.0139)
    diff = tf.quat_to_rotvec(
        tf.quat_multiply(tf.quat_conjugate(m.rotation[:, j]), out.rotation[:, j])
    )
    assert np.abs(np.diff(diff, 2, axis=0)).max() < 0.015


# 6 ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [120, 121, 327])
def test_speed_one_is_identity_and_two_halves(n):
    m = walk(n, 120, noise_deg=0.3)
    same = bm.change_speed(m, 1.0)
    assert same.n_frames == m.n_frames
    assert np.array_equal(same.rotation, m.rotation)
    assert np.array_equal(same.root_position, m.root_position)
    fast = bm.change_speed(m, 2.0)
    assert abs(fast.n_frames - n / 2) <= 1
    assert np.allclose(fast.rotation[1], tf.quat_slerp(m.rotation[2], m.rotation[2], 0.0))
    slow = bm.change_speed(m, {0: 0.5, n - 1: 0.5})
    assert abs(slow.n_frames - 2 * n) <= 2


# 7 ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("source", ["synthetic", "xia_neutral_01_000_walk.bvh"])
def test_cycle_seam_is_no_worse_than_the_clip(source):
    m = walk(600, 60) if source == "synthetic" else read_bvh(shared_file("motion", source))
    s, e, _ = bm.best_loop(m, 60, None, transition=20)
    out = bm.make_cycle(m, s, e, 20, cycles=2)
    p = out.meta["cycle"]["period"]
    assert out.n_frames == 2 * p
    x = pose_features(out)
    xs = pose_features(m)
    median_acc = np.median(np.linalg.norm(np.diff(xs, 2, axis=0), axis=1))
    median_step = np.median(np.linalg.norm(np.diff(xs, axis=0), axis=1))
    acc = np.linalg.norm(np.diff(x, 2, axis=0), axis=1)
    # velocity jump across the seam (second difference at the frames around it): no more
    # than the clip's median, or than the clip's own at the frames the seam joins onto
    # (a seam cannot be smoother than the motion there)
    clip_acc = np.linalg.norm(np.diff(xs, 2, axis=0), axis=1)
    assert acc[p - 2] <= max(median_acc, clip_acc[s - 2] + 1e-12)
    assert acc[p - 1] <= max(median_acc, clip_acc[s - 1] + 1e-12)
    # pose jump: the seam step differs from the step before it by less than a median step
    steps = np.linalg.norm(np.diff(x, axis=0), axis=1)
    assert abs(steps[p - 1] - steps[p - 2]) <= median_step
    # root keeps travelling (cycle with offset): the step over the seam is a normal step
    rs = np.linalg.norm(np.diff(out.root_position, axis=0), axis=1)
    assert rs[p - 1] <= 2 * np.median(rs) + 1e-12


# 8 ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta", [0.3, -2.0, np.pi])
def test_reorient_rotates_root_positions_and_keeps_local_rotations(theta):
    m = read_bvh(shared_file("motion", "xia_neutral_01_000_walk.bvh"))
    out = bm.reorient(m, theta, pivot=(0, 0, 0))
    r = tf.quat_from_axis_angle("y", theta)
    assert np.allclose(out.root_position, tf.quat_rotate(r, m.root_position), atol=1e-9)
    assert np.array_equal(out.rotation[:, 1:], m.rotation[:, 1:])
    # the root orientation turned by theta about Y: heading changed by theta
    from biomorph.motion.align import heading

    dh = heading(out) - heading(m)
    wrapped = (dh - theta + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(wrapped).max() < 1e-6


# 9 ---------------------------------------------------------------------------------------
def _ops():
    return {
        "equalize": lambda m: bm.equalize(m, [0, 1, 1.2, 1, 1]),
        "displace": lambda m: bm.displace(m, m.names[2], {m.n_frames // 2: [0, 0.2, 0]}),
        "reorient": lambda m: bm.reorient(m, 0.7, translate=(1, 0, 2)),
        "layers": lambda m: bm.apply_layers(m, [bm.Layer.make("a", m.names[1], {5: [0.1, 0, 0]})]),
        "blend": lambda m: bm.blend([m, m[10:]], transition=10),
        "speed": lambda m: bm.change_speed(m, {0: 1, m.n_frames - 1: 2}),
        "cycle": lambda m: bm.make_cycle(m, 0, m.n_frames, 10, cycles=2),
        "resample": lambda m: m.resample(24),
    }


@pytest.mark.parametrize("op", list(_ops()))
@pytest.mark.parametrize("source", ["ad_cmu1_jumping_jacks.bvh", "fairmotion_sinusoidal.bvh"])
def test_operations_keep_names_channels_frame_time_through_bvh(tmp_path, op, source):
    m = read_bvh(shared_file("motion", source))
    out = _ops()[op](m)
    path = write_bvh(tmp_path / f"{op}.bvh", out)
    back = read_bvh(path)
    assert back.names == m.names
    assert back.skeleton.channels == m.skeleton.channels
    assert back.rotation_orders == m.rotation_orders
    expected_ft = 1 / 24 if op == "resample" else m.frame_time
    assert back.frame_time == pytest.approx(expected_ft, rel=1e-12)
    assert np.max(tf.quat_angle(back.rotation, out.rotation)) < 1e-6
