"""Issue 15: tolerant reading, root-aware equalizer, root motion and cycle modes, foot
contacts with two-bone IK, auto-clamped tangents, partial-body operators, Euler wrap."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import biomorph.motion as bm
from biomorph.cli import run
from biomorph.core import transforms as tf
from biomorph.errors import ParameterError
from biomorph.io.bvh import read_bvh
from biomorph.motion.contact import ContactWarning, detect_contacts, lock_feet, two_bone_ik
from biomorph.motion.displacement import displacement_curve
from biomorph.motion.partial import merge_below
from biomorph.motion.quality import foot_skate
from biomorph.motion.rootmotion import apply_root_motion, extract_root_motion, in_place
from tests.conftest import shared_file


def _read(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_bvh(shared_file("motion", name))


@pytest.fixture(scope="module")
def zombie():
    return _read("ad_fair1_zombie_walk.bvh")


@pytest.fixture(scope="module")
def xia():
    return _read("xia_neutral_01_000_walk.bvh")


def test_equalizer_last_gain_keeps_the_path_and_the_floor(zombie):
    # issue: last gain 0.8 dropped the hips from 33.5 to 26.8 and the feet through the floor
    up = 2  # the fair1 captures are Z-up
    floor = zombie.world_positions()[..., up].min()
    for g in (0.8, 0.5, 1.5):
        out = bm.equalize(zombie, [1, 1, 1, 1, g])
        assert np.allclose(out.root_position.mean(0), zombie.root_position.mean(0), atol=1e-6)
        if g < 1:  # (a gain above 1 also exaggerates the leg poses themselves)
            # was 7-21 units through the floor; the leg rotations' own last band may still
            # move a foot by a few percent of the hip height
            assert out.world_positions()[..., up].min() > floor - 0.05 * 24.0
    old = bm.equalize(zombie, [1, 1, 1, 1, 0.8], root="world")
    assert old.root_position[:, up].mean() < 0.85 * zombie.root_position[:, up].mean()
    start = bm.equalize(zombie, [1, 1, 1, 1, 0.5], root="start")
    assert np.allclose(start.root_position[0], zombie.root_position[0], atol=0.5)
    with pytest.raises(ParameterError):
        bm.equalize(zombie, [1, 1, 1, 1, 0.5], root="up")


def test_root_motion_extract_apply_round_trip(xia, tmp_path):
    e = extract_root_motion(xia)
    assert e.names[0] == "root" and e.n_joints == xia.n_joints + 1
    assert np.allclose(e.root_position[:, 1], 0.0)  # ground level
    assert np.abs(e.world_positions()[:, 1:] - xia.world_positions()).max() < 1e-9
    back = apply_root_motion(e)
    assert back.names == xia.names
    assert np.abs(back.world_positions() - xia.world_positions()).max() < 1e-9
    ip = in_place(xia)
    assert np.allclose(ip.root_position[:, [0, 2]], xia.root_position[0, [0, 2]])
    assert np.allclose(ip.root_position[:, 1], xia.root_position[:, 1])


@pytest.mark.parametrize("mode", ["world", "in-place", "root-motion"])
def test_cycle_modes_never_teleport(xia, mode):
    s, e, _ = bm.best_loop(xia, 60, None, 12)
    out = bm.make_cycle(xia, s, e, 12, cycles=3, mode=mode)
    w = out.world_positions()[:, -xia.n_joints:]
    step = np.linalg.norm(np.diff(w[:, 0], axis=0), axis=1)
    assert step.max() < 4 * np.median(step) + 1e-3 * np.ptp(w[..., 1])
    if mode == "in-place":
        assert np.linalg.norm(w[-1, 0, [0, 2]] - w[0, 0, [0, 2]]) < 2.0
    else:
        assert np.linalg.norm(w[-1, 0, [0, 2]] - w[0, 0, [0, 2]]) > 20.0


def test_cycle_shorter_than_two_frames_is_refused(xia):
    with pytest.raises(ParameterError, match="at least 2"):
        bm.make_cycle(xia, 5, 6, 1)


def test_two_bone_ik_reaches_and_clamps_without_nan():
    f = 50
    hip = np.zeros((f, 3))
    knee = np.tile([0.0, -1.0, 0.1], (f, 1))
    ankle = np.tile([0.0, -2.0, 0.0], (f, 1))
    tgt = np.column_stack([np.linspace(-0.5, 0.5, f), np.full(f, -1.6), np.zeros(f)])
    r1, r2, c = two_bone_ik(hip, knee, ankle, tgt)
    new_knee = tf.quat_rotate(r1, knee - hip) + hip
    new_ankle = new_knee + tf.quat_rotate(r2, tf.quat_rotate(r1, ankle - knee))
    assert c == 0 and np.abs(new_ankle - tgt).max() < 1e-9
    assert (new_knee[:, 2] > 0).all()  # knee kept on its side
    far = np.tile([0.0, -5.0, 0.0], (f, 1))
    r1, r2, c = two_bone_ik(hip, knee, ankle, far)
    assert c == f and np.isfinite(r1).all() and np.isfinite(r2).all()


def test_contacts_are_found_on_a_walk(xia):
    c = detect_contacts(xia)
    feet = {xia.names[j] for j in c}
    assert {"LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase"} <= feet
    frac = np.mean([v.mean() for v in c.values()])
    assert 0.2 < frac < 0.9


@pytest.mark.parametrize("name", ["dme_comp_3d_2_raw.bvh", "xia_angry_13_000_run.bvh",
                                  "cmu_01_01.bvh", "ad_rokoko_jesse_dance.bvh"])
def test_locking_lowers_foot_skate(name):
    m = _read(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContactWarning)
        locked = lock_feet(m)
    assert foot_skate(locked)["skate_per_body_scale"] < foot_skate(m)["skate_per_body_scale"]
    # planted points barely move while planted
    c = detect_contacts(m)
    w0, w1 = m.world_positions(), locked.world_positions()
    v0, v1 = [], []
    for j, on in c.items():
        idx = np.flatnonzero(on[1:] & on[:-1])
        v0.append(np.linalg.norm(np.diff(w0[:, j], axis=0)[idx][:, [0, 2]], axis=1).mean())
        v1.append(np.linalg.norm(np.diff(w1[:, j], axis=0)[idx][:, [0, 2]], axis=1).mean())
    assert np.mean(v1) < 0.7 * np.mean(v0)


def test_root_edit_keeps_the_feet_on_the_ground(xia):
    # lowering the hips (a crouch) pushed the planted feet through the floor
    lifted = bm.displace(xia, 0, {160: [0.0, -1.5, 0.0]}, kind="position", fade=60)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContactWarning)
        fixed = lock_feet(lifted, xia)
    c = detect_contacts(xia)
    j = xia.skeleton.index("LeftFoot")
    frames = np.flatnonzero(c[j][130:190]) + 130
    y0 = xia.world_positions()[frames, j, 1]
    err_lifted = np.abs(lifted.world_positions()[frames, j, 1] - y0)
    err_fixed = np.abs(fixed.world_positions()[frames, j, 1] - y0)
    assert err_fixed.max() < 0.5 * err_lifted.max()


def test_auto_clamped_tangents_never_overshoot():
    keys = [(30, [30.0, 0, 0]), (40, [10.0, 0, 0]), (50, [30.0, 0, 0])]
    auto = displacement_curve(keys, 100, 20)[:, 0]
    assert auto.max() <= 30.0 + 1e-9 and auto.min() >= 0.0 - 1e-9
    spline = displacement_curve(keys, 100, 20, tangent="spline")[:, 0]
    assert spline.max() > 30.5  # the former behaviour overshoots
    lin = displacement_curve(keys, 100, 20, tangent="linear")[:, 0]
    assert lin[35] == pytest.approx(20.0)
    with pytest.raises(ParameterError):
        displacement_curve(keys, 100, 20, tangent="bezier")


def test_partial_body_speed_keeps_the_rest(xia):
    fast = bm.change_speed(xia, 2.0)
    out = merge_below(xia, fast, "LeftUpLeg")
    assert out.n_frames == xia.n_frames
    legs = xia.skeleton.descendants(xia.skeleton.index("LeftUpLeg"))
    rest = np.setdiff1d(np.arange(xia.n_joints), legs)
    assert np.array_equal(out.rotation[:, rest], xia.rotation[:, rest])
    assert np.allclose(out.rotation[:20, legs], fast.rotation[:20, legs])


def test_cli_tolerant_read_and_strict(tmp_path, capsys):
    src = shared_file("motion", "dme_comp_3d_2_fixed.bvh").read_text()
    odd = tmp_path / "odd.bvh"
    odd.write_text(src.replace("Frames: 64", "Frames: 63"))
    assert run(["motion", "info", str(odd), "--json"]) == 0
    cap = capsys.readouterr()
    rep = json.loads(cap.out)
    assert rep["frames"] == 64 and "64 complete data rows" in rep["tolerated"][0]
    assert cap.err.count("warning:") == 1
    assert run(["motion", "info", str(odd), "--strict"]) == 2
    assert "more data" in capsys.readouterr().err


def test_cli_new_commands(tmp_path, capsys):
    walk = str(shared_file("motion", "xia_neutral_01_000_walk.bvh"))
    o = tmp_path
    for args in (["cycle", walk, "-o", str(o / "c.bvh"), "--auto", "--transition", "12",
                  "--cycles", "2", "--mode", "in-place"],
                 ["root", walk, "-o", str(o / "r.bvh")],
                 ["trim", walk, "-o", str(o / "t.bvh"), "--start", "10", "--stop", "50"],
                 ["speed", walk, "-o", str(o / "s.bvh"), "--speed", "1.5", "--joint",
                  "LeftUpLeg"],
                 ["equalize", walk, "-o", str(o / "e.bvh"), "--gains", "1,1,1,1,0.5",
                  "--euler", "continuous", "--no-lock-feet"]):
        assert run(["motion", *args, "--json"]) == 0, args
        capsys.readouterr()
    assert read_bvh(o / "r.bvh").names[0] == "root"
    assert read_bvh(o / "t.bvh").n_frames == 40
    assert read_bvh(o / "s.bvh").n_frames == 327


@pytest.mark.parametrize("args,needle", [
    (["cycle", "W", "-o", "OUT", "--start", "3", "--stop", "4", "--transition", "1"],
     "at least 2"),
    (["cycle", "W", "-o", "OUT", "--mode", "spiral"], "cycle mode"),
    (["equalize", "W", "-o", "OUT", "--root", "up"], "root"),
    (["edit", "W", "-o", "OUT", "--joint", "Hips", "--key", "10:0/0/1", "--tangent", "x"],
     "tangent"),
    (["convert", "W", "-o", "OUT", "--fps", "nan"], "--fps"),
    (["cycle", "W", "-o", "OUT", "--cycles", "0"], "--cycles"),
    (["trim", "W", "-o", "OUT", "--start", "400"], "frame range"),
    (["root", "W", "-o", "OUT", "--action", "apply"], "exactly one child"),
    (["equalize", "W", "-o", "OUT", "--euler", "deg"], "--euler"),
])
def test_cli_bad_input_exit_2_no_file(tmp_path, capsys, args, needle):
    walk = str(shared_file("motion", "xia_neutral_01_000_walk.bvh"))
    out = tmp_path / "never.bvh"
    argv = ["motion", *[walk if a == "W" else str(out) if a == "OUT" else a for a in args]]
    assert run(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) <= 2, err
    assert not out.exists()
