"""``biomorph motion …`` in-process: happy paths on real files, every bad-input case of the
issue (one clear line, exit 2, nothing written)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.io.bvh import read_bvh, write_bvh
from biomorph.motion.synthetic import walk
from tests.conftest import shared_file


@pytest.fixture
def walk_bvh(tmp_path):
    return write_bvh(tmp_path / "walk.bvh", walk(240, 60, noise_deg=0.5))


def _json(capsys):
    out = capsys.readouterr().out
    return json.loads(out[out.index("{") :])


def test_info_json_real_and_skate_pair(capsys):
    raw = shared_file("motion", "dme_comp_3d_2_raw.bvh")
    fixed = shared_file("motion", "dme_comp_3d_2_fixed.bvh")
    assert run(["motion", "info", str(raw), "--json"]) == 0
    r = _json(capsys)
    assert run(["motion", "info", str(fixed), "--json"]) == 0
    f = _json(capsys)
    assert r["frames"] == 64 and r["joints"] == 31
    # the cleaned file of the raw/cleaned pair skates less
    assert f["foot_skate"]["skate_speed"] < r["foot_skate"]["skate_speed"]
    z = shared_file("motion", "ad_fair1_zombie_walk.bvh")
    assert run(["motion", "info", str(z), "--json"]) == 0
    zr = _json(capsys)
    assert zr["up_guess"] == "z" and zr["euler_wraps_in_file"] == 16
    assert zr["foot_skate"]["up"] == "z"
    assert not zr["first_frame_is_calibration_pose"]
    cmu = shared_file("motion", "cmu_01_01.bvh")  # frame 0 is a T-pose
    assert run(["motion", "info", str(cmu), "--json"]) == 0
    cr = _json(capsys)
    assert cr["first_frame_is_calibration_pose"] and cr["first_frame_jump_deg"] > 100


def test_every_command_writes(tmp_path, walk_bvh, capsys):
    o = tmp_path / "out"
    cmds = [
        ["equalize", str(walk_bvh), "-o", str(o / "eq.bvh"), "--gains", "0,0,1,1,1"],
        [
            "equalize",
            str(walk_bvh),
            "-o",
            str(o / "eq2.bvh"),
            "--joint",
            "LeftUpLeg",
            "--below",
            "--channels",
            "rotation",
        ],
        [
            "edit",
            str(walk_bvh),
            "-o",
            str(o / "ed.bvh"),
            "--joint",
            "RightArm",
            "--key",
            "100:0/0/30;140:0/20/0",
            "--fade",
            "15",
        ],
        ["reorient", str(walk_bvh), "-o", str(o / "ro.bvh"), "--angle", "90", "--move", "1,0,0"],
        [
            "blend",
            str(walk_bvh),
            str(walk_bvh),
            "-o",
            str(o / "bl.bvh"),
            "--transition",
            "20",
            "--align",
            "peaks",
            "--align-joint",
            "LeftUpLeg",
        ],
        [
            "blend",
            str(walk_bvh),
            str(walk_bvh),
            "-o",
            str(o / "bl2.bvh"),
            "--offsets",
            "0,100",
            "--curve",
            "110:0,130:1",
        ],
        ["speed", str(walk_bvh), "-o", str(o / "sp.bvh"), "--speed", "0:1,120:2,239:1"],
        [
            "cycle",
            str(walk_bvh),
            "-o",
            str(o / "cy.bvh"),
            "--auto",
            "--transition",
            "10",
            "--cycles",
            "3",
        ],
        ["convert", str(walk_bvh), "-o", str(o / "cv.bvh"), "--fps", "30"],
        [
            "plot",
            str(walk_bvh),
            "-o",
            str(o / "p.png"),
            "--joint",
            "LeftUpLeg",
            "--gains",
            "0,0,1,1,1",
        ],
        ["plot", str(walk_bvh), "-o", str(o / "q.png"), "--kind", "poses"],
    ]
    for c in cmds:
        assert run(["motion", *c, "--json"]) == 0, c
        summary = _json(capsys)
        out = o / c[c.index("-o") + 1].split("/")[-1]
        assert out.exists() and summary["output"] == str(out)
    assert read_bvh(o / "cv.bvh").fps == pytest.approx(30)
    sp = read_bvh(o / "sp.bvh")
    assert sp.n_frames < 240


def test_convert_htr_and_asf(tmp_path, capsys):
    htr = shared_file("motion", "animal3d_egnaro_skel_anim.htr")
    asf = shared_file("motion", "cmu_11.asf")
    assert run(["motion", "convert", str(htr), "-o", str(tmp_path / "h.bvh")]) == 0
    assert read_bvh(tmp_path / "h.bvh").n_joints == 89
    assert run(["motion", "convert", str(asf), "-o", str(tmp_path / "a.bvh"), "--json"]) == 0
    assert _json(capsys)["frames"] == 597
    z = shared_file("motion", "ad_fair1_zombie_walk.bvh")
    assert run(["motion", "convert", str(z), "-o", str(tmp_path / "z.bvh"), "--up", "z"]) == 0
    assert read_bvh(tmp_path / "z.bvh").meta["up_guess"] == "y"


def _bad(tmp_path, capsys, args, needle):
    out = tmp_path / "never.bvh"
    argv = ["motion", *args]
    argv = [a.replace("OUT", str(out)) for a in argv]
    code = run(argv)
    err = capsys.readouterr().err
    assert code == 2, (args, err)
    assert needle.lower() in err.lower(), err
    assert len(err.strip().splitlines()) <= 2, err  # one message (may wrap once)
    assert not out.exists()
    assert not list(tmp_path.glob(".never.bvh*"))


def test_bad_inputs_exit_2_and_write_nothing(tmp_path, walk_bvh, capsys):
    good = walk_bvh.read_text()
    trunc = tmp_path / "trunc.bvh"
    trunc.write_text(good[: len(good) // 2])
    notnum = tmp_path / "nan.bvh"
    lines = good.splitlines()
    lines[-3] = lines[-3].replace(" ", " x", 1)
    notnum.write_text("\n".join(lines) + "\n")
    badhtr = tmp_path / "bad.htr"
    badhtr.write_text("[Header]\nNumSegments 1\n")
    other = write_bvh(tmp_path / "other.bvh", walk(100, 60, n_joints=30))
    w = str(walk_bvh)
    cases = [
        (["equalize", str(trunc), "-o", "OUT", "--strict"], "truncated"),
        (["info", str(notnum)], "not a number"),
        (["convert", str(badhtr), "-o", "OUT"], "missing section"),
        (["blend", w, str(other), "-o", "OUT"], "do not share a skeleton"),
        (["cycle", w, "-o", "OUT", "--start", "50", "--stop", "50"], "empty"),
        (
            ["cycle", w, "-o", "OUT", "--start", "0", "--stop", "40", "--transition", "60"],
            "transition",
        ),
        (["blend", w, w, "-o", "OUT", "--transition", "500"], "longer than"),
        (["speed", w, "-o", "OUT", "--speed", "0"], "speed"),
        (["speed", w, "-o", "OUT", "--speed", "0:1,100:-1"], "speed"),
        (["edit", w, "-o", "OUT", "--joint", "LeftArm", "--key", "900:0/0/10"], "outside the clip"),
        (["speed", w, "-o", "OUT", "--speed", "0:1,5000:2"], "outside the clip"),
        (["edit", w, "-o", "OUT", "--joint", "Tail", "--key", "10:0/0/10"], "no joint"),
        (["equalize", w, "-o", "OUT", "--gains", "1,a"], "gains"),
        (["equalize", w, "-o", "OUT", "--gains", ",".join(["1"] * 12)], "supports at most"),
        (["equalize", w, "-o", str(tmp_path / "x.obj")], "cannot write"),
        (["info", str(tmp_path / "missing.bvh")], "does not exist"),
    ]
    for args, needle in cases:
        _bad(tmp_path, capsys, args, needle)


def test_glb_output_if_available(tmp_path, walk_bvh):
    pytest.importorskip("biomorph.io.gltf")
    out = tmp_path / "w.glb"
    assert run(["motion", "equalize", str(walk_bvh), "-o", str(out), "--gains", "0,1,1,1,1"]) == 0
    assert out.stat().st_size > 1000
    assert np.frombuffer(out.read_bytes()[:4], np.uint8).tobytes() == b"glTF"
