"""Operators beyond the headline properties: N-clip blends, auto-alignment, layers, Motion
slicing/resampling, joint selection, filter-bank details, API errors."""

from __future__ import annotations

import numpy as np
import pytest

import biomorph.motion as bm
from biomorph.core import transforms as tf
from biomorph.errors import InputError, ParameterError
from biomorph.io.bvh import read_bvh
from biomorph.motion.align import dtw_path, local_maxima, peak_offset
from biomorph.motion.blending import plan
from biomorph.motion.equalizer import KERNEL, bands, equalize_signal
from biomorph.motion.keys import parse_keys
from biomorph.motion.synthetic import spin, walk
from tests.conftest import shared_file


def test_filter_bank_is_the_seeds():
    assert np.allclose(KERNEL, [1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
    x = np.random.default_rng(0).normal(size=64)
    b = bands(x, 3)
    assert np.allclose(b.sum(axis=0), x, atol=1e-12)
    # G1 at an interior frame is the plain 5-tap convolution, G2 skips every other frame
    g1 = x - b[0]
    assert np.isclose(g1[10], np.dot(KERNEL, x[8:13]))
    g2 = g1 - b[1]
    assert np.isclose(g2[20], np.dot(KERNEL, g1[16:25:2]))
    # edge boundary: index clamped to the end value
    assert np.isclose(g1[0], np.dot(KERNEL, x[[0, 0, 0, 1, 2]]))
    # a constant is all low-pass; a gain on the last band scales it
    assert np.allclose(equalize_signal(np.full(40, 3.0), [0, 0, 2]), 6.0)
    assert bm.n_bands(2752) == 11 and bm.n_bands(16) == 4


def test_equalize_joint_selection_and_channels():
    m = walk(200, 60, noise_deg=1.0)
    out = bm.equalize(m, [0, 0, 1, 1, 1], joints="LeftUpLeg", hierarchy_below=True)
    below = set(m.skeleton.descendants("LeftUpLeg").tolist())
    for j in range(m.n_joints):
        same = np.array_equal(out.rotation[:, j], m.rotation[:, j])
        assert same == (j not in below), m.names[j]
    assert np.array_equal(out.root_position, m.root_position)  # root not selected
    rot_only = bm.equalize(m, [0, 0, 1, 1, 1], channels="rotation")
    assert np.array_equal(rot_only.root_position, m.root_position)
    pos_only = bm.equalize(m, [0, 0, 1, 1, 1], channels="position")
    assert np.array_equal(pos_only.rotation, m.rotation)
    assert not np.array_equal(pos_only.root_position, m.root_position)
    with pytest.raises(ParameterError):
        bm.equalize(m, [1] * 9)  # 200 frames support 7 bands
    with pytest.raises(ParameterError):
        bm.equalize(m, [1, 1], boundary="zero")


def test_blend_three_clips_weights_and_continuity():
    a = walk(200, 60, seed=1)
    b = walk(200, 60, stride_hz=1.2, seed=2)
    c = walk(200, 60, stride_hz=1.5, seed=3)
    p = plan([a, b, c], transition=40)
    assert np.allclose(p.weights.sum(axis=1), 1.0)
    assert p.n_frames == 3 * 200 - 2 * 40 - 2
    out = bm.blend([a, b, c], transition=40)
    assert out.n_frames == p.n_frames
    step = tf.quat_angle(out.rotation[1:], out.rotation[:-1]).max()
    assert step < 0.3
    # the middle of clip B is B exactly (weight 1), local joints untouched by root alignment
    mid = int(p.offsets[1]) + 100
    assert np.array_equal(out.rotation[mid, 1:], b.rotation[100, 1:])
    # root continues: no jump at the transitions
    rs = np.linalg.norm(np.diff(out.root_position, axis=0), axis=1)
    assert rs.max() < 4 * np.median(rs)


def test_blend_scales_offsets_and_alignment():
    a = read_bvh(shared_file("motion", "xia_neutral_01_000_walk.bvh"))
    b = read_bvh(shared_file("motion", "xia_angry_13_000_run.bvh"))
    pa, pb = peak_offset(a, b, "LeftUpLeg")
    assert (
        pa
        in local_maxima(
            np.convolve(
                np.pad(a.channel("LeftUpLeg", "Xrotation"), 2, mode="edge"),
                [1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16],
                "valid",
            )
        )
        or pa
    )
    out = bm.blend([a, b], transition=30, align="peaks", align_joint="LeftUpLeg")
    off = out.meta["blend"]["offsets"][1]
    assert off == pytest.approx(pa - pb)
    dtw = bm.blend([a, b], transition=30, align="dtw")
    assert 0 < dtw.meta["blend"]["offsets"][1] < a.n_frames
    slow = bm.blend([a, b], offsets=[0, 300], scales=[1, 2], transition=20)
    assert slow.n_frames == 300 + 2 * (b.n_frames - 1) + 1
    # walk -> run: heading and position continue at the transition start
    rs = np.linalg.norm(np.diff(out.root_position[:, [0, 2]], axis=0), axis=1)
    assert rs.max() < 3 * np.percentile(rs, 95)
    with pytest.raises(InputError):
        bm.blend([a, walk(100, 60)])
    half = b.resample(60)  # another frame rate: resampled onto A's timeline
    mixed = bm.blend([a, half], transition=30)
    assert mixed.frame_time == a.frame_time
    assert mixed.n_frames > a.n_frames
    with pytest.raises(ParameterError):
        bm.blend([a, b], align="peaks")  # needs a joint


def test_dtw_path_recovers_a_shift():
    t = np.linspace(0, 1, 80)
    x = np.sin(6 * t)
    y = np.sin(6 * t**1.5)  # the same signal, time-warped
    path, cost = dtw_path(np.abs(x[:, None] - y[None, :]))
    assert tuple(path[0]) == (0, 0) and tuple(path[-1]) == (79, 79)
    assert np.all(np.diff(path, axis=0) >= 0)
    # matched samples have similar values
    assert np.abs(x[path[:, 0]] - y[path[:, 1]]).mean() < 0.05


def test_layers_sum_and_remove():
    m = walk(200, 60)
    l1 = bm.Layer.make("lift", "LeftArm", {100: [0, 0, 0.4]}, fade=30)
    l2 = bm.Layer.make("twist", "LeftArm", {100: [0, 0.2, 0]}, weight=0.5, fade=30)
    l3 = bm.Layer.make("bob", "Hips", {50: [0, 0.1, 0]}, kind="position", fade=10)
    out = bm.apply_layers(m, [l1, l2, l3])
    j = m.skeleton.index("LeftArm")
    d = tf.quat_to_rotvec(
        tf.quat_multiply(tf.quat_conjugate(m.rotation[100, j]), out.rotation[100, j])
    )
    assert np.allclose(d, [0, 0.1, 0.4], atol=1e-9)
    assert np.allclose(out.root_position[50] - m.root_position[50], [0, 0.1, 0])
    stack = bm.remove_layer([l1, l2, l3], "bob")
    again = bm.apply_layers(m, stack)
    assert np.array_equal(again.root_position, m.root_position)
    muted = bm.apply_layers(m, [bm.Layer.make("x", "LeftArm", {100: [1, 0, 0]}, weight=0.0)])
    assert np.array_equal(muted.rotation, m.rotation)
    with pytest.raises(ParameterError):
        bm.remove_layer(stack, "bob")


def test_motion_slicing_resample_concatenate_euler():
    m = read_bvh(shared_file("motion", "ad_fair1_jumping.bvh"))  # 119.88 fps
    assert m.fps == pytest.approx(1 / 0.008342)
    r = m.resample(30)
    assert r.fps == 30 and abs(r.duration - m.duration) < 1 / 30
    assert np.array_equal(r.rotation[0], m.rotation[0])
    part = m[100:200]
    assert part.n_frames == 100
    joined = bm.concatenate([m[:100], m[100:]])
    assert np.array_equal(np.abs(joined.rotation), np.abs(m.rotation))
    e = m.euler("Hips", degrees=True)
    assert e.shape == (m.n_frames, 3)
    assert np.abs(np.diff(e, axis=0)).max() < 90  # unwrapped
    q = tf.euler_to_quat(e, m.rotation_orders[0], degrees=True)
    assert np.max(tf.quat_angle(q, m.rotation[:, 0])) < 1e-6
    with pytest.raises(InputError):
        m[5:5]
    with pytest.raises(ParameterError):
        m.resample(0)
    pos, seg = bm.preview_positions(m, 10)
    assert pos.shape == (m.n_joints, 3) and seg.shape == (m.n_joints - 1, 2, 3)


def test_cycle_errors_and_offsets():
    m = walk(300, 60)
    loop = bm.make_cycle(m, 0, 200, 20, cycles=2)
    period = loop.meta["cycle"]["period"]
    assert period == 180 and loop.n_frames == 360
    # the root keeps travelling forward (cycle with offset), in place without offset
    assert loop.root_position[-1, 2] > loop.root_position[period - 1, 2] > 0
    flat = bm.make_cycle(m, 0, 200, 20, cycles=2, offset=False)
    assert abs(flat.root_position[-1, 2] - flat.root_position[period - 1, 2]) < 1.0
    for bad in [(0, 0, 5), (0, 50, 50), (0, 50, 0), (250, 400, 5)]:
        with pytest.raises(ParameterError):
            bm.make_cycle(m, *bad)


def test_keys_parsing(tmp_path):
    assert [f for f, _ in parse_keys("10:1,0:2")] == [0, 10]
    k = parse_keys("5:1/2/3;9:4/5/6", dim=3)
    assert np.allclose(k[1][1], [4, 5, 6])
    jf = tmp_path / "k.json"
    jf.write_text("[[0, 1], [50, 2]]")
    assert len(parse_keys(str(jf))) == 2
    for bad in ["", "10", "a:1", "1:1,1:2"]:
        with pytest.raises(ParameterError):
            parse_keys(bad)
    with pytest.raises(ParameterError):
        parse_keys("1:1/2", dim=3)


def test_every_real_file_through_every_operator():
    """Each real capture survives the whole chain with finite, unit quaternions."""
    names = [
        "cmu_01_01.bvh",
        "ad_fair1_zombie_walk.bvh",
        "ad_rokoko_jesse_dance.bvh",
        "animal3d_egnaro_skel_anim.htr",
        "cmu_11.asf",
    ]
    from biomorph.io import read_motion

    for name in names:
        m = read_motion(shared_file("motion", name))
        m = m[: min(m.n_frames, 400)]
        n = m.n_frames
        out = bm.equalize(m, [0.5, 1, 1.2, 1, 1])
        out = bm.displace(out, 1, {n // 2: [0.1, 0, 0]})
        out = bm.change_speed(out, {0: 1.0, n - 1: 1.5})
        out = bm.make_cycle(out, 0, out.n_frames, max(2, out.n_frames // 5))
        out = bm.blend([out, out], transition=out.n_frames // 4)
        assert np.all(np.isfinite(out.rotation)), name
        assert np.allclose(np.linalg.norm(out.rotation, axis=-1), 1.0), name
        assert bm.quality_report(out)["frames"] == out.n_frames


def _unwrap_rotvec(u: np.ndarray) -> np.ndarray:
    """Per joint, replace u[t] by u[t] + 2πk·û[t] (k in -2..2) nearest u[t-1] (NumPy)."""
    out = u.copy()
    for t in range(1, len(u)):
        ang = np.linalg.norm(u[t], axis=-1, keepdims=True)
        axis = u[t] / np.where(ang > 1e-9, ang, 1.0)
        cand = u[t][None] + 2 * np.pi * np.arange(-2, 3)[:, None, None] * axis[None]
        best = np.argmin(((cand - out[t - 1][None]) ** 2).sum(-1), axis=0)
        out[t] = np.where(ang > 1e-9, cand[best, np.arange(u.shape[1])], u[t])
    return out


def _numpy_equalize(q: np.ndarray, gains: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """The documented rotation path written with NumPy; returns (rotations, mean_log mask).

    Per joint: mean M of the continuous quaternions; if every frame is within 90° of M,
    x = log(M⁻¹q) with all gains and q' = M·exp(x'). Otherwise the smooth reference R,
    x = log(R⁻¹q) filtered, R' = M·exp(g_K·unwrap(log(M⁻¹R))) with M the mean of R,
    q' = R'·exp(x')."""
    from biomorph.motion.equalizer import smooth_reference

    f, n = q.shape[:2]
    s = q.sum(axis=0)
    norm = np.linalg.norm(s, axis=-1)
    mean = s / norm[:, None]
    mean_log = (norm > 0.5 * f) & (
        np.abs(np.einsum("fji,ji->fj", q, mean)).min(axis=0) >= np.cos(np.pi / 4)
    )
    out = np.empty_like(q)
    m = mean_log
    x = tf.quat_to_rotvec(tf.quat_multiply(tf.quat_conjugate(mean[m])[None], q[:, m]))
    x2 = equalize_signal(x.reshape(f, -1), gains).reshape(x.shape)
    out[:, m] = tf.quat_multiply(mean[m][None], tf.quat_from_rotvec(x2))
    r = ~mean_log
    ref = smooth_reference(q[:, r], len(gains) - 1)
    x = tf.quat_to_rotvec(tf.quat_multiply(tf.quat_conjugate(ref), q[:, r]))
    x2 = equalize_signal(x.reshape(f, -1), gains).reshape(x.shape)
    if gains[-1] != 1:
        mr = ref.sum(axis=0)
        mr /= np.linalg.norm(mr, axis=-1, keepdims=True)
        u = _unwrap_rotvec(tf.quat_to_rotvec(tf.quat_multiply(tf.quat_conjugate(mr)[None], ref)))
        ref = tf.quat_multiply(mr[None], tf.quat_from_rotvec(gains[-1] * u))
    out[:, r] = tf.quat_multiply(ref, tf.quat_from_rotvec(x2))
    return out, mean_log


@pytest.mark.parametrize("glast", [1.0, 0.8, 1.6])
def test_equalizer_kernel_matches_numpy_reference(glast):
    """The compiled rotation path equals the documented algorithm written with NumPy, on a
    walk (every joint within 90° of its mean: the mean-log path) plus a joint spinning 1.5
    turns (the smooth-reference path, whose log map about the mean passes 180°, so with a
    last gain ≠ 1 the unwrap matters)."""
    m = walk(300, 60, n_joints=8, noise_deg=2.0)
    q = np.array(m.rotation)
    q[:, 3] = spin(300, 60, turns=1.5).rotation[:, 0]
    m = m.with_(rotation=q)
    gains = [0.2, 0.7, 1.3, 1.1, glast]
    expect, mean_log = _numpy_equalize(q, gains)
    assert not mean_log[3] and mean_log[[0, 1, 2, 4, 5, 6, 7]].all()
    got = bm.equalize(m, gains, channels="rotation").rotation
    err = np.minimum(np.abs(got - expect).max(axis=-1), np.abs(got + expect).max(axis=-1))
    assert err.max() < 1e-10


@pytest.mark.parametrize("scales", [(1.0, 1.0, 1.0), (1.3, 0.7, 2.1)])
def test_fused_blend_average_equals_reference(scales):
    """The fused sample-and-average kernel of N-clip blends equals sampling every clip on the
    whole timeline, stacking and averaging (the earlier path), to 1e-12."""
    from biomorph.motion.blending import average_rotations
    from tests.motion.oracles import average_rotations_reference

    a = walk(300, 60, n_joints=12, noise_deg=2.0, seed=1)
    b = walk(260, 60, n_joints=12, speed=2.5, noise_deg=2.0, seed=2)
    c = bm.reorient(walk(200, 60, n_joints=12, noise_deg=2.0, seed=3), 2.5)  # other heading
    clips = [a, b, c]
    p = plan(clips, None, np.asarray(scales), 40, None)
    t = np.arange(p.n_frames, dtype=float)
    us = [
        np.clip((t - p.offsets[i]) / p.scales[i], 0.0, m.n_frames - 1) for i, m in enumerate(clips)
    ]
    fast = average_rotations(clips, us, p.weights)
    ref = average_rotations_reference(clips, us, p.weights)
    assert np.abs(fast - ref).max() < 1e-12
    # and through blend(): four clips, with root alignment
    out = bm.blend([a, b, c, a], transition=30)
    assert np.all(np.isfinite(out.rotation))


def test_kernels_compile_once_for_read_only_and_writable_input():
    """Every kernel input goes through a read-only view: one compiled version per kernel
    (a cold numba cache otherwise compiles the parallel equalizer kernel twice)."""
    from biomorph.motion import _kernels as k

    m = walk(120, 60, n_joints=8)
    ro_rot = m.rotation.copy()
    ro_rot.setflags(write=False)
    for rot in (m.rotation.copy(), ro_rot):
        mm = m.with_(rotation=rot)
        bm.equalize(mm, [0, 1, 1, 1])
        mm.world_positions()
        bm.blend([mm, mm], transition=10)
        bm.blend([mm, mm, mm], transition=10)
    for kern in (
        k.equalize_rotations,
        k.fk_positions,
        k.blend_slerp,
        k.sample_slerp,
        k.blend_average_sampled,
        k.lowpass_into,
    ):
        assert len(kern.signatures) == 1, (kern, kern.signatures)


@pytest.mark.parametrize("f", [1, 3, 7, 16, 33, 200])
@pytest.mark.parametrize("mode", [0, 1])
def test_lowpass_kernel_equals_per_index_reference(f, mode):
    """The vectorised à-trous level (shifted views) equals the per-index formula with the
    boundary index map, to 1e-12 (in fact bit for bit: same expression, same order)."""
    from biomorph.motion._kernels import lowpass_into

    def idx(j):
        if f == 1:
            return 0
        if mode == 0:
            return min(max(j, 0), f - 1)
        period = 2 * (f - 1)
        j = abs(j) % period
        return period - j if j > f - 1 else j

    x = np.random.default_rng(f).normal(size=f)
    for step in (1, 2, 4, 8, 16):
        got = np.empty(f)
        lowpass_into(x, got, step, mode)
        ref = np.array(
            [
                0.375 * x[i]
                + 0.25 * (x[idx(i - step)] + x[idx(i + step)])
                + 0.0625 * (x[idx(i - 2 * step)] + x[idx(i + 2 * step)])
                for i in range(f)
            ]
        )
        assert np.abs(got - ref).max() <= 1e-12
        assert np.array_equal(got, ref)


@pytest.mark.parametrize("f,r", [(1, 0), (1, 3), (5, 8), (40, 0), (40, 2), (300, 16)])
def test_box_filter_four_columns_equals_per_column_reference(f, r):
    """The equalizer reference's fused 4-column box filter equals the former one-column
    running sum (edge hold) applied per column, to 1e-12 (bit for bit)."""
    from biomorph.motion._kernels import _box_edge4

    def box1(src):
        dst = np.empty(f)
        if r == 0:
            return src.copy()
        acc = 0.0
        for m in range(-r, r + 1):
            acc += src[min(max(m, 0), f - 1)]
        inv = 1.0 / (2 * r + 1)
        for i in range(f):
            dst[i] = acc * inv
            acc += src[min(i + r + 1, f - 1)] - src[max(i - r, 0)]
        return dst

    x = np.random.default_rng(r).normal(size=(f, 4))
    got = np.empty_like(x)
    _box_edge4(x, got, r)
    ref = np.stack([box1(x[:, c]) for c in range(4)], axis=1)
    assert np.abs(got - ref).max() <= 1e-12
    assert np.array_equal(got, ref)
