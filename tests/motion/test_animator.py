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
    w = out.world_positions()[:, -xia.n_joints :]
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


@pytest.mark.parametrize(
    "name",
    [
        "dme_comp_3d_2_raw.bvh",
        "xia_angry_13_000_run.bvh",
        "cmu_01_01.bvh",
        "ad_rokoko_jesse_dance.bvh",
    ],
)
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
    y = xia.world_positions()[:, j, 1]
    frames = np.flatnonzero(c[j])
    moved = np.abs(lifted.world_positions()[:, j, 1] - y) > 0.3
    flat = frames[(np.abs(y[frames] - np.median(y[frames])) < 0.1) & moved[frames]]
    assert flat.size >= 10  # heel down (not rolling) where the edit moved the foot
    err_lifted = np.abs(lifted.world_positions()[flat, j, 1] - y[flat])
    err_fixed = np.abs(fixed.world_positions()[flat, j, 1] - y[flat])
    assert err_fixed.max() < 0.2 * err_lifted.max()


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
    for args in (
        [
            "cycle",
            walk,
            "-o",
            str(o / "c.bvh"),
            "--auto",
            "--transition",
            "12",
            "--cycles",
            "2",
            "--mode",
            "in-place",
        ],
        ["root", walk, "-o", str(o / "r.bvh")],
        ["trim", walk, "-o", str(o / "t.bvh"), "--start", "10", "--stop", "50"],
        ["speed", walk, "-o", str(o / "s.bvh"), "--speed", "1.5", "--joint", "LeftUpLeg"],
        [
            "equalize",
            walk,
            "-o",
            str(o / "e.bvh"),
            "--gains",
            "1,1,1,1,0.5",
            "--euler",
            "continuous",
            "--no-lock-feet",
        ],
    ):
        assert run(["motion", *args, "--json"]) == 0, args
        capsys.readouterr()
    assert read_bvh(o / "r.bvh").names[0] == "root"
    assert read_bvh(o / "t.bvh").n_frames == 40
    assert read_bvh(o / "s.bvh").n_frames == 327


@pytest.mark.parametrize(
    "args,needle",
    [
        (
            ["cycle", "W", "-o", "OUT", "--start", "3", "--stop", "4", "--transition", "1"],
            "at least 2",
        ),
        (["cycle", "W", "-o", "OUT", "--mode", "spiral"], "cycle mode"),
        (["equalize", "W", "-o", "OUT", "--root", "up"], "root"),
        (
            ["edit", "W", "-o", "OUT", "--joint", "Hips", "--key", "10:0/0/1", "--tangent", "x"],
            "tangent",
        ),
        (["convert", "W", "-o", "OUT", "--fps", "nan"], "--fps"),
        (["cycle", "W", "-o", "OUT", "--cycles", "0"], "--cycles"),
        (["trim", "W", "-o", "OUT", "--start", "400"], "frame range"),
        (["root", "W", "-o", "OUT", "--action", "apply"], "exactly one child"),
        (["equalize", "W", "-o", "OUT", "--euler", "deg"], "--euler"),
        (["equalize", "W", "-o", "OUT", "--gains", "1,nan,1"], "--gains"),
        (["blend", "W", "W", "-o", "OUT", "--offsets", "0,1e308"], "--offsets"),
        (["speed", "W", "-o", "OUT", "--speed", "0"], "--speed"),
        (
            ["edit", "W", "-o", "OUT", "--joint", "Hips", "--key", "10:0/0/1", "--fade", "inf"],
            "--fade",
        ),
    ],
)
def test_cli_bad_input_exit_2_no_file(tmp_path, capsys, args, needle):
    walk = str(shared_file("motion", "xia_neutral_01_000_walk.bvh"))
    out = tmp_path / "never.bvh"
    argv = ["motion", *[walk if a == "W" else str(out) if a == "OUT" else a for a in args]]
    assert run(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) <= 2, err
    assert not out.exists()


def test_mirror_twice_is_identity_and_reflects_positions(xia):
    from biomorph.motion.names import left_right_pairs, mirror_name
    from biomorph.motion.retarget import mirror

    once = mirror(xia)
    assert np.abs(mirror(once).world_positions() - xia.world_positions()).max() < 1e-9
    assert mirror_name("LeftArm") == "RightArm" and mirror_name("thigh.L") == "thigh.R"
    assert mirror_name("hand_r") == "hand_l" and mirror_name("LThumb") == "RThumb"
    assert len(left_right_pairs(xia.names)) >= 10
    w, wm = xia.world_positions(), once.world_positions()
    other = [
        xia.names.index(mirror_name(n) or n) if (mirror_name(n) or n) in xia.names else i
        for i, n in enumerate(xia.names)
    ]
    ref = w[:, other].copy()
    ref[..., 0] *= -1  # the CMU skeleton's lateral axis is x
    # the captured skeleton is not exactly symmetric (offsets differ by up to 0.26 units)
    assert np.abs(wm - ref).max() < 0.05 * np.ptp(w[..., 1])


def _renamed(m, prefix, scale):
    from biomorph.core.skeleton import JointSkeleton

    sk = m.skeleton
    return JointSkeleton(
        [prefix + n for n in sk.names],
        sk.parent,
        sk.offset * scale,
        sk.rest_rotation,
        sk.limits,
        sk.channels,
        sk.end_site * scale,
    )


def test_retarget_onto_a_mixamo_named_smaller_skeleton(xia):
    from biomorph.motion.retarget import retarget

    target = _renamed(xia, "mixamorig:", 0.5)
    out = retarget(xia, target, feet=False)
    assert out.names == target.names
    from biomorph.motion.contact import foot_floor

    want = 0.5 * xia.world_positions()
    want[..., 1] -= 0.5 * foot_floor(xia)  # the source's lowest foot onto the target's 0
    assert np.abs(out.world_positions() - want).max() < 1e-9
    assert out.meta["retarget"]["leg_scale"] == pytest.approx(0.5)


def test_retarget_cmu_walk_onto_the_rokoko_mixamo_rig(xia):
    from biomorph.motion.retarget import retarget

    dance = _read("ad_rokoko_jesse_dance.bvh")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContactWarning)
        out = retarget(xia, dance.skeleton)
    w = out.world_positions()
    assert np.isfinite(w).all() and out.n_frames == xia.n_frames
    # hips at the target's own height (leg-length scaled), feet on its ground
    hips_rest = dance.skeleton.offset[0, 1]
    assert 0.7 * hips_rest < w[:, 0, 1].mean() < 1.3 * hips_rest
    feet = [dance.names.index(n) for n in ("LeftFoot", "RightFoot")]
    travel = np.linalg.norm(w[-1, 0, [0, 2]] - w[0, 0, [0, 2]])
    src_travel = np.linalg.norm(xia.root_position[-1, [0, 2]] - xia.root_position[0, [0, 2]])
    assert travel == pytest.approx(src_travel * out.meta["retarget"]["leg_scale"], rel=0.05)
    assert w[:, feet, 1].min() > -0.1 * hips_rest


def test_retarget_and_mirror_bad_input(xia, tmp_path):
    from biomorph.errors import FormatError, InputError
    from biomorph.motion.retarget import mirror, retarget

    sine = _read("fairmotion_sinusoidal.bvh")
    with pytest.raises(InputError, match="mirror needs left/right"):
        mirror(sine)
    with pytest.raises(InputError, match="preset"):
        retarget(xia, sine.skeleton)
    legless = _renamed(xia, "", 1.0)
    names = list(legless.names)
    names[names.index("LeftLeg")] = "LeftKnee"
    from biomorph.core.skeleton import JointSkeleton

    legless = JointSkeleton(names, legless.parent, legless.offset)
    with pytest.raises(InputError, match="required joint 'l_shin'"):
        retarget(xia, legless)
    bad = tmp_path / "map.csv"
    bad.write_text("source,target\nHips,Hips\nLeftUpLeg,NoSuchJoint\n")
    with pytest.raises(InputError, match="NoSuchJoint"):
        retarget(xia, xia.skeleton, csv_map=bad)
    bad.write_text("Hips;Hips\n")
    with pytest.raises(FormatError, match="expected source,target"):
        retarget(xia, xia.skeleton, csv_map=bad)


def test_cli_retarget_and_mirror(tmp_path, capsys):
    walk = str(shared_file("motion", "xia_neutral_01_000_walk.bvh"))
    dance = str(shared_file("motion", "ad_rokoko_jesse_dance.bvh"))
    sine = str(shared_file("motion", "fairmotion_sinusoidal.bvh"))
    out = tmp_path / "rt.bvh"
    assert run(["motion", "retarget", walk, "--to", dance, "-o", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["mapped"] >= 20
    assert read_bvh(out).n_joints == 60
    assert run(["motion", "mirror", walk, "-o", str(tmp_path / "m.bvh")]) == 0
    never = tmp_path / "never.bvh"
    for argv in (
        ["retarget", walk, "--to", sine, "-o", str(never)],
        ["mirror", sine, "-o", str(never)],
    ):
        assert run(["motion", *argv]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) <= 2
        assert not never.exists()


def test_batch_applies_a_chain_and_reports_failures(tmp_path, capsys):
    walk = shared_file("motion", "xia_neutral_01_000_walk.bvh")
    raw = shared_file("motion", "dme_comp_3d_2_raw.bvh")
    broken = tmp_path / "broken.bvh"
    broken.write_text("HIERARCHY\nROOT a\n{\n")
    out = tmp_path / "out"
    argv = [
        "motion",
        "batch",
        str(walk),
        str(raw),
        str(broken),
        "--op",
        "equalize:gains=0/0/1/1/1",
        "--op",
        "trim:start=2,stop=40",
        "--out",
        str(out),
        "--workers",
        "0",
        "--json",
    ]
    assert run(argv) == 1  # one input failed, the others were written
    rep = json.loads(capsys.readouterr().out)
    assert len(rep["ok"]) == 2 and len(rep["failed"]) == 1
    assert read_bvh(out / "xia_neutral_01_000_walk.bvh").n_frames == 38
    assert not (out / "broken.bvh").exists()
    assert run(["motion", "batch", str(walk), "--op", "explode", "--out", str(out)]) == 2
    assert "unknown operator" in capsys.readouterr().err


def test_chain_matches_single_operators(xia):
    from biomorph.motion.chain import Step, apply_chain

    steps = [Step.parse("equalize:gains=0/0/1/1/1"), Step.parse("mirror")]
    out = apply_chain(xia, steps, lock_feet=False)
    from biomorph.motion.retarget import mirror

    ref = mirror(bm.equalize(xia, [0, 0, 1, 1, 1]))
    assert np.array_equal(out.rotation, ref.rotation)
    with pytest.raises(ParameterError, match="gains"):
        apply_chain(xia, [Step.parse("equalize:gains=a/b")])
    with pytest.raises(ParameterError, match="speed"):
        apply_chain(xia, [Step.parse("speed:speed=inf")])


def test_preview_gif(tmp_path, capsys):
    from PIL import Image

    from biomorph.motion.preview import render_preview

    walk = str(shared_file("motion", "dme_comp_3d_2_fixed.bvh"))
    gif = render_preview(
        _read("dme_comp_3d_2_fixed.bvh"), tmp_path / "clip.gif", max_frames=8, size_px=96
    )
    im = Image.open(gif)
    assert im.n_frames == 8 and im.size == (96, 96)
    frames = set()
    for k in range(im.n_frames):  # the skeleton moves: frames differ
        im.seek(k)
        frames.add(im.convert("L").tobytes())
    assert len(frames) == 8
    never = tmp_path / "never.bvh"
    assert (
        run(["motion", "convert", walk, "-o", str(never), "--preview", str(tmp_path / "x.png")])
        == 2
    )
    assert "--preview" in capsys.readouterr().err and not never.exists()


def test_retarget_a_cmu_walk_onto_a_biomorph_creature_biped(xia):
    from biomorph.creature.generator import generate
    from biomorph.motion.names import detect_preset
    from biomorph.motion.retarget import retarget

    biped = generate(3, legs=2, arms=True).skeleton
    assert detect_preset(biped.names) == "creature"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContactWarning)
        out = retarget(xia, biped)
    w = out.world_positions()
    assert np.isfinite(w).all() and out.names == biped.names
    feet = [biped.index("hip1_distal_l"), biped.index("hip1_distal_r")]
    # the feet alternate (a walk, not a glide): their forward order swaps during the clip
    gap = w[:, feet[0], 0] - w[:, feet[1], 0]
    assert gap.max() > 0.02 and gap.min() < -0.02
    assert out.meta["retarget"]["joints"] >= 15


# --------------------------------------------------------------------------- verification pass
@pytest.mark.parametrize(
    ("name", "preset", "pairs"),
    [("cmu_11.asf", "cmu_asf", 12), ("ad_cmu1_jumping_jacks.bvh", "cmu_max", 12)],
)
def test_cmu_dialects_retarget_and_mirror(name, preset, pairs, xia):
    # the verification pass found CMU's own ASF names (lfemur, ltibia, lfoot) and the
    # 3ds-Max dialect (LeftHip, LeftKnee, LeftAnkle) refused by retarget ("misses 'hips'")
    # and the ASF refused by mirror ("no left/right names")
    from biomorph.io import read_motion
    from biomorph.motion import names as nm
    from biomorph.motion.retarget import mirror, retarget

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = read_motion(shared_file("motion", name))[:40]
        assert nm.detect_preset(m.names) == preset
        assert len(nm.left_right_pairs(m.names)) >= pairs
        assert np.isfinite(mirror(m).rotation).all()
        out = retarget(m, xia.skeleton)
    assert out.names == xia.names and np.isfinite(out.rotation).all()


def test_root_motion_on_a_skeleton_with_a_root_joint():
    # CMU ASF's pelvis is called "root": cycle --mode root-motion refused it
    from biomorph.io import read_motion

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = read_motion(shared_file("motion", "cmu_11.asf"))[:60]
    e = extract_root_motion(m)
    assert e.names[:2] == ("root_motion", "root")
    assert np.abs(e.world_positions()[:, 1:] - m.world_positions()).max() < 1e-9
    with pytest.raises(Exception, match="already has a joint named 'root'"):
        extract_root_motion(m, name="root")


def test_a_creature_biped_has_legs_for_contact_locking():
    from biomorph.motion.contact import find_legs

    sk_names = ("back_02", "back_01", "hip1_girdle_l", "hip1_upper_l", "hip1_lower_l",
                "hip1_distal_l", "hip1_digit3_1_l")  # fmt: skip
    parent = np.array([-1, 0, 1, 2, 3, 4, 5])
    from biomorph.core.motion import Motion
    from biomorph.core.skeleton import JointSkeleton

    off = np.zeros((7, 3))
    off[1:, 1] = [-0.1, -0.05, -0.3, -0.3, -0.1, 0.0]
    off[6, 2] = 0.1
    sk = JointSkeleton(names=sk_names, parent=parent, offset=off)
    rot = np.zeros((3, 7, 4))
    rot[..., 3] = 1
    root = np.tile([0, 1.0, 0], (3, 1))
    m = Motion(skeleton=sk, rotation=rot, root_position=root, frame_time=1 / 30)
    legs = find_legs(m)
    assert foot_skate(m)["feet"] == ["hip1_distal_l", "hip1_digit3_1_l"]  # not every leaf
    assert [(m.names[lg.hip], m.names[lg.ankle], m.names[lg.toe]) for lg in legs] == [
        ("hip1_upper_l", "hip1_distal_l", "hip1_digit3_1_l")
    ]
