"""BVH reader/writer: real dialects, round trip, written edge cases, precise errors."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core import transforms as tf
from biomorph.errors import FormatError
from biomorph.io.bvh import read_bvh, write_bvh
from tests.conftest import shared_file

# file, frames, joints, fps, euler wraps (±180° jumps between frames in the file)
REAL = [
    ("cmu_01_01.bvh", 2752, 31, 120.0, 0),
    ("fairmotion_sinusoidal.bvh", 120, 4, 60.0, 0),
    ("ad_fair1_zombie_walk.bvh", 779, 27, 30.0, 16),
    ("ad_fair1_jumping.bvh", 654, 27, 1 / 0.008342, None),
    ("ad_cmu1_jumping_jacks.bvh", 125, 31, None, None),
    ("ad_rokoko_jesse_dance.bvh", 1007, 60, 100.0, 18),
    ("dme_comp_3d_2_raw.bvh", 64, 31, None, None),
    ("dme_comp_3d_2_fixed.bvh", 64, 31, None, None),
    ("xia_neutral_01_000_walk.bvh", 327, 31, None, None),
    ("xia_angry_13_000_run.bvh", 140, 31, None, None),
]


@pytest.mark.parametrize("name,frames,joints,fps,wraps", REAL)
def test_real_file_reads_and_round_trips(tmp_path, name, frames, joints, fps, wraps):
    mo = read_bvh(shared_file("motion", name))
    assert mo.n_frames == frames and mo.n_joints == joints
    if fps is not None:
        assert mo.fps == pytest.approx(fps, rel=1e-4)
    if wraps is not None:
        assert mo.meta["euler_wraps_in_file"] == wraps
    # unit, hemisphere-continuous quaternions
    assert np.allclose(np.linalg.norm(mo.rotation, axis=-1), 1.0, atol=1e-12)
    assert (np.sum(mo.rotation[1:] * mo.rotation[:-1], axis=-1) >= 0).all()
    out = write_bvh(tmp_path / "rt.bvh", mo, euler="continuous")
    back = read_bvh(out)
    assert back.names == mo.names
    assert back.skeleton.channels == mo.skeleton.channels
    assert back.frame_time == mo.frame_time
    assert np.allclose(back.root_position, mo.root_position, atol=1e-6)
    assert np.max(tf.quat_angle(back.rotation, mo.rotation)) < 1e-6
    # euler="continuous": written Euler curves have no ±360 jumps
    assert back.meta["euler_wraps_in_file"] == 0
    # writing again is idempotent to the last digit
    again = write_bvh(tmp_path / "rt2.bvh", back, euler="continuous")
    assert again.read_bytes() == out.read_bytes()
    # the default writes principal values: every angle within ±180°, same rotations
    wrapped = write_bvh(tmp_path / "wrap.bvh", mo)
    data = np.loadtxt(
        wrapped.read_text().split("Frame Time:")[1].split("\n", 1)[1].splitlines(), ndmin=2
    )
    rot_cols = [
        i
        for i, c in enumerate(c for j in _dfs(mo) for c in mo.skeleton.channels[j])
        if c.endswith("rotation")
    ]
    assert np.abs(data[:, rot_cols]).max() <= 180.0 + 1e-6
    w = read_bvh(wrapped)
    assert np.max(tf.quat_angle(w.rotation, mo.rotation)) < 1e-6


def _dfs(mo):
    from biomorph.core.motion import dfs_preorder

    return dfs_preorder(mo.skeleton.parent)


def test_mixed_orders_and_z_up():
    mo = read_bvh(shared_file("motion", "ad_cmu1_jumping_jacks.bvh"))
    assert {"ZYX", "ZXY"} <= set(mo.rotation_orders)
    zombie = read_bvh(shared_file("motion", "ad_fair1_zombie_walk.bvh"))
    assert {"XYZ", "YXZ"} <= set(zombie.rotation_orders)
    assert zombie.meta["up_guess"] == "z"
    yup = read_bvh(shared_file("motion", "ad_fair1_zombie_walk.bvh"), up="z")
    # root height (file Z ≈ 23–25) is now on Y
    assert 20 < yup.root_position[:, 1].mean() < 27
    assert np.allclose(yup.root_position[:, 1], zombie.root_position[:, 2])


def test_sinusoidal_values_round_trip_to_6_decimals(tmp_path):
    src = shared_file("motion", "fairmotion_sinusoidal.bvh")
    out = write_bvh(tmp_path / "s.bvh", read_bvh(src))

    def values(p):
        text = p.read_text()
        body = text.split("Frame Time:")[1].split("\n", 1)[1]
        return np.array(body.split(), float)

    assert np.allclose(values(src), values(out), atol=1.5e-6)


HAND = """HIERARCHY\r
ROOT\troot\r
{\r
  OFFSET 1 2 3\r
  CHANNELS 6 Zrotation Xposition Yrotation Yposition Xrotation Zposition\r
  JOINT   mid {\r
    OFFSET 0 1.5e1 0\r
    CHANNELS 5 Xposition Yrotation  Xrotation Zrotation Zposition\r
    JOINT tip\r
    {\r
      OFFSET 0 2 0\r
      CHANNELS 3 Yrotation Zrotation Xrotation\r
      End Site\r
      {\r
        OFFSET 0 1E0 0\r
      }\r
    }\r
  }\r
}\r
MOTION\r
Frames:\t3\r
Frame Time: 0.0333333\r
10 0.5 20 1 30 -2  0.1 40 50 60 0.2  70 80 90\r
-10 0.6 -20 1 -30 -2 0.2 -40 -50 -60 0.3 -70 -80 -90\r
1e1 7.5e-1 2.0E+1 1 3e1 -2 0 0 0 0 0 179.5 -179.5 0\r
"""


def test_hand_written_dialect(tmp_path):
    p = tmp_path / "hand.bvh"
    p.write_bytes(HAND.encode())
    mo = read_bvh(p)
    assert mo.names == ("root", "mid", "tip")
    assert mo.skeleton.channels[0] == (
        "Zrotation",
        "Xposition",
        "Yrotation",
        "Yposition",
        "Xrotation",
        "Zposition",
    )
    assert mo.rotation_orders == ("ZYX", "YXZ", "YZX")
    assert np.allclose(mo.skeleton.offset[1], [0, 15, 0])
    assert np.allclose(mo.skeleton.end_site[2], [0, 1, 0])
    assert np.isnan(mo.skeleton.end_site[0]).all()
    assert np.allclose(mo.root_position[0], [0.5, 1, -2])
    assert np.allclose(mo.root_position[2], [0.75, 1, -2])
    # position channels on an inner joint: Xposition/Zposition given, Y from OFFSET
    assert mo.joint_translation is not None
    assert np.allclose(mo.joint_translation[0, 1], [0.1, 15, 0.2])
    # R = Rz · Ry · Rx for channel order Zrotation Yrotation Xrotation (root)
    expect = tf.euler_to_quat([10, 20, 30], "ZYX", degrees=True)
    assert tf.quat_angle(mo.rotation[0, 0], expect) < 1e-7
    # world positions: vectorised FK agrees with a hand computation for frame 0
    w = mo.world_positions()
    r = tf.quat_to_matrix(expect)
    assert np.allclose(w[0, 1], mo.root_position[0] + r @ [0.1, 15, 0.2])
    out = write_bvh(tmp_path / "out.bvh", mo)
    back = read_bvh(out)
    assert back.skeleton.channels == mo.skeleton.channels
    assert np.allclose(back.joint_translation, mo.joint_translation, atol=1e-6)
    assert np.max(tf.quat_angle(back.rotation, mo.rotation)) < 1e-6


def _broken(tmp_path, text: str):
    p = tmp_path / "bad.bvh"
    p.write_text(text)
    with pytest.raises(FormatError) as info:
        read_bvh(p, strict=True)
    return info.value


GOOD = HAND.replace("\r", "")


@pytest.mark.parametrize(
    "mutate,line,needle",
    [
        (lambda s: s.rsplit("\n", 2)[0] + "\n", None, "truncated"),  # last frame missing
        (lambda s: s.replace("0.1 40 50 60", "0.1 40 50"), 23, "expected 14"),  # short line
        (lambda s: s.replace("-30 -2", "-30 abc"), 24, "'abc' is not a number"),
        (lambda s: s.replace("Frames:\t3\n", ""), 21, "Frames"),
        (lambda s: s.replace("Frame Time: 0.0333333\n", ""), 22, "Frame Time"),
        (lambda s: s.replace("Frames:\t3", "Frames: 2"), 25, "more data"),
        (lambda s: s.replace("CHANNELS 5", "CHANNELS 4"), 8, "Zposition"),
        (lambda s: s.replace("OFFSET 0 2 0", "OFFSET 0 x 0"), 11, "not a number"),
        (lambda s: s.split("MOTION")[0].rsplit("}", 2)[0], None, "file ends"),
        (lambda s: s.replace("Frame Time: 0.0333333", "Frame Time: 0"), 22, "Frame Time"),
    ],
)
def test_malformed_files_name_the_line(tmp_path, mutate, line, needle):
    err = _broken(tmp_path, mutate(GOOD))
    assert needle in str(err)
    if line is not None:
        assert err.line == line, str(err)
    assert "bad.bvh" in str(err)


@pytest.mark.parametrize(
    "mutate,frames,needle",
    [
        (lambda s: s.replace("Frames:\t3", "Frames: 2"), 3, "'Frames: 2' but 3 complete"),
        (lambda s: s.replace("Frames:\t3", "Frames: 7"), 3, "'Frames: 7' but 3 complete"),
        (lambda s: s.rsplit("\n", 2)[0] + "\n", 2, "'Frames: 3' but 2 complete"),
        (lambda s: s.rstrip("\n").rsplit(" ", 3)[0] + "\n", 2, "cut-off last line"),
    ],
)
def test_frame_count_mismatch_is_tolerated_with_a_warning(tmp_path, mutate, frames, needle):
    from biomorph.core.motion import MotionInputWarning

    p = tmp_path / "odd.bvh"
    p.write_text(mutate(GOOD))
    with pytest.warns(MotionInputWarning, match="odd.bvh"):
        mo = read_bvh(p)
    assert mo.n_frames == frames
    assert any(needle in t for t in mo.meta["tolerated"]), mo.meta["tolerated"]
    good = read_bvh(_write(tmp_path, GOOD))
    assert np.array_equal(mo.rotation, good.rotation[:frames])
    with pytest.raises(FormatError):
        read_bvh(p, strict=True)


def _write(tmp_path, text):
    p = tmp_path / "good.bvh"
    p.write_text(text)
    return p


def test_empty_and_non_bvh(tmp_path):
    assert "empty" in str(_broken(tmp_path, ""))
    assert "HIERARCHY" in str(_broken(tmp_path, "hello world\nMOTION\n"))


@pytest.mark.parametrize(
    "mutate,line,needle",
    [
        # the file ends inside an End Site block (was an IndexError on the End Site marker)
        (lambda s: s.split("OFFSET 0 1E0 0")[0], None, "file ends inside joint 'tip'"),
        (
            lambda s: s.replace("      }\n    }\n  }\n}\nMOTION", "MOTION"),
            16,
            "MOTION inside joint 'tip'",
        ),
        # overflowing and non-finite numbers (were accepted as inf / nan)
        (lambda s: s.replace("-30 -2", "-30 1e999"), 24, "overflows"),
        (lambda s: s.replace("-30 -2", "-30 -2e400"), 24, "overflows"),
        (lambda s: s.replace("OFFSET 0 2 0", "OFFSET 0 nan 0"), 11, "finite"),
        (lambda s: s.replace("OFFSET 0 2 0", "OFFSET 0 1e999 0"), 11, "finite"),
    ],
)
def test_damaged_files_raise_format_errors(tmp_path, mutate, line, needle):
    err = _broken(tmp_path, mutate(GOOD))
    assert needle in str(err), str(err)
    if line is not None:
        assert err.line == line, str(err)
    assert "bad.bvh" in str(err)


def test_large_exponent_that_stays_finite_reads(tmp_path):
    p = tmp_path / "ok.bvh"
    p.write_text(GOOD.replace("-30 -2", "-30 -2e-300"))
    assert read_bvh(p).root_position[1, 2] == pytest.approx(-2e-300, rel=1e-15, abs=0)


def test_long_take_euler_blocks_equal_sequential_reference(tmp_path):
    """The Euler→quaternion kernel works on blocks of 4,096 frames in parallel and chains
    the blocks' signs afterwards; on a 9,000-frame take whose joints spin (hemisphere flips
    everywhere, also across block boundaries) it equals the sequential reference
    (euler_to_quat per frame + quat_continuous) to 1e-12."""
    from biomorph.io._bvh_kernels import _EULER_CHUNK

    f = 2 * _EULER_CHUNK + 808
    t = np.arange(f)
    rng = np.random.default_rng(5)
    root = np.column_stack(
        [
            np.sin(t / 50),
            np.cos(t / 70),
            0.01 * t,
            (7.3 * t) % 360 - 180,
            40 * np.sin(t / 30),
            (3.1 * t) % 360 - 180,
        ]
    )
    mid = np.column_stack([(11.7 * t) % 360 - 180, 80 * np.sin(t / 9), rng.normal(0, 20, f)])
    data = np.column_stack([root, mid])
    text = (
        "HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Xrotation Yrotation\n JOINT m\n {\n  OFFSET 0 1 0\n  CHANNELS 3 "
        "Yrotation Zrotation Xrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\n"
        f"MOTION\nFrames: {f}\nFrame Time: 0.01\n"
    )
    p = tmp_path / "long.bvh"
    p.write_text(text + "\n".join(" ".join(f"{v:.9f}" for v in row) for row in data) + "\n")
    mo = read_bvh(p)
    vals = np.loadtxt(p, skiprows=text.count("\n"))
    ref = np.stack(
        [
            tf.euler_to_quat(vals[:, 3:6], "ZXY", degrees=True),
            tf.euler_to_quat(vals[:, 6:9], "YZX", degrees=True),
        ],
        axis=1,
    )
    ref = tf.quat_continuous(ref, axis=0)
    ref *= np.sign(np.sum(ref[:1] * mo.rotation[:1], axis=-1))[..., None]
    assert np.abs(mo.rotation - ref).max() < 1e-12
    assert np.array_equal(mo.root_position, vals[:, :3])


def test_scanner_values_equal_python_float(tmp_path):
    """The compiled MOTION scanner (power-of-ten table) reads what Python's float() reads,
    to 1e-15 relative, over mixed decimal/exponent spellings."""
    rng = np.random.default_rng(11)
    mags = 10.0 ** rng.integers(-25, 25, 600) * rng.uniform(-10, 10, 600)
    toks = []
    for k, v in enumerate(mags):
        fmt = ("{:.17g}", "{:.6f}", "{:.3e}", "{:.12E}", "{:+.9g}")[k % 5]
        toks.append(fmt.format(v))
    rows = [toks[i : i + 6] for i in range(0, 600, 6)]
    text = (
        "HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Xrotation Yrotation\n End Site\n {\n  OFFSET 0 1 0\n }\n}\n"
        f"MOTION\nFrames: {len(rows)}\nFrame Time: 0.01\n"
        + "\n".join(" ".join(r) for r in rows)
        + "\n"
    )
    p = tmp_path / "nums.bvh"
    p.write_text(text)
    mo = read_bvh(p)
    expect = np.array([[float(x) for x in r[:3]] for r in rows])
    assert np.allclose(mo.root_position, expect, rtol=1e-15, atol=0)


def test_huge_page_buffers_give_the_same_motion(monkeypatch):
    """Big reads allocate their buffers from a huge-page mapping; forced on for a small file
    the result equals the ordinary path and stays valid after the reader returns."""
    import gc

    import biomorph.io.bvh as bvh

    p = shared_file("motion", "cmu_01_01.bvh")
    plain = read_bvh(p)
    monkeypatch.setattr(bvh, "_HUGE_MIN_BYTES", 0)
    huge = read_bvh(p)
    gc.collect()
    assert not huge.rotation.flags.writeable
    assert np.array_equal(huge.rotation, plain.rotation)
    assert np.array_equal(huge.root_position, plain.root_position)
    assert bvh._empty((3, 2)).shape == (3, 2)


@pytest.fixture
def parallel_scan(monkeypatch):
    """Every MOTION section goes through the parallel chunked scan (normally >= 8 MB)."""
    import biomorph.io.bvh as bvh_module

    monkeypatch.setattr(bvh_module, "_PARALLEL_MIN_BYTES", 1)
    monkeypatch.setattr(bvh_module, "_COMPILED_MIN_VALUES", 0)  # not the small-file path


def test_parallel_scan_equals_the_sequential_one(tmp_path, parallel_scan):
    import biomorph.io._bvh_kernels as kernels
    import biomorph.io.bvh as bvh_module
    from biomorph.motion.synthetic import walk

    p = tmp_path / "walk.bvh"
    write_bvh(p, walk(400, 60, n_joints=20, noise_deg=1.0))
    raw = p.read_bytes()
    buf = np.frombuffer(raw, dtype=np.uint8)
    start = raw.index(b"\n", raw.index(b"Frame Time")) + 1
    n_ch = len(raw[start : raw.index(b"\n", start)].split())
    a = np.empty(400 * n_ch)
    b = np.empty(400 * n_ch)
    assert bvh_module._scan_floats_parallel(buf, start, a, n_ch)[:2] == (a.size, 0)
    assert kernels._scan_floats(buf, start, b, n_ch)[:2] == (b.size, 0)
    assert np.array_equal(a, b)
    # the chunked kernel itself succeeds on a clean split (no silent fallback)
    mid = raw.index(b"\n", (start + len(raw)) // 2) + 1
    c = np.empty(400 * n_ch)
    cuts = np.array([start, mid, len(raw)], dtype=np.int64)
    assert kernels._scan_floats_chunks(buf, cuts, c, n_ch)
    assert np.array_equal(c, b)
    mo = read_bvh(p)
    assert mo.n_frames == 400


# damage that the parallel and the streamed MOTION readers must report like the one-piece one
MOTION_DAMAGE = [
    (lambda s: s.rsplit("\n", 2)[0] + "\n", None, "truncated"),
    (lambda s: s.replace("0.1 40 50 60", "0.1 40 50"), 23, "expected 14"),
    (lambda s: s.replace("-30 -2", "-30 abc"), 24, "'abc' is not a number"),
    (lambda s: s.replace("Frames:\t3", "Frames: 2"), 25, "more data"),
]


@pytest.mark.parametrize("mutate,line,needle", MOTION_DAMAGE)
def test_parallel_scan_keeps_the_exact_diagnostics(tmp_path, parallel_scan, mutate, line, needle):
    err = _broken(tmp_path, mutate(GOOD))
    assert needle in str(err)
    if line is not None:
        assert err.line == line, str(err)


@pytest.mark.parametrize(
    "name", ["ad_fair1_zombie_walk.bvh", "ad_rokoko_jesse_dance.bvh", "cmu_01_01.bvh"]
)
def test_streamed_read_equals_the_whole_read(monkeypatch, name):
    """Big MOTION sections are read in blocks through one buffer: rotations (with
    hemisphere continuity across blocks), root positions, joint translations and the
    Euler wrap count equal the one-piece read exactly (blocks of 7 frames here)."""
    import biomorph.io.bvh as bvh_module

    path = shared_file("motion", name)
    whole = read_bvh(path)
    monkeypatch.setattr(bvh_module, "_STREAM_MIN_BYTES", 1)
    monkeypatch.setattr(bvh_module, "_STREAM_FRAMES", 7)
    calls = []
    real = bvh_module._stream_motion
    monkeypatch.setattr(bvh_module, "_stream_motion", lambda *a: calls.append(1) or real(*a))
    part = read_bvh(path)
    assert calls and np.array_equal(part.rotation, whole.rotation)
    assert np.array_equal(part.root_position, whole.root_position)
    if whole.joint_translation is not None:
        assert np.array_equal(part.joint_translation, whole.joint_translation)
    assert part.meta["euler_wraps_in_file"] == whole.meta["euler_wraps_in_file"]


@pytest.mark.parametrize("mutate,line,needle", MOTION_DAMAGE)
def test_streamed_read_keeps_the_exact_diagnostics(tmp_path, monkeypatch, mutate, line, needle):
    import biomorph.io.bvh as bvh_module

    monkeypatch.setattr(bvh_module, "_STREAM_MIN_BYTES", 1)
    monkeypatch.setattr(bvh_module, "_STREAM_FRAMES", 1)
    err = _broken(tmp_path, mutate(GOOD))
    assert needle in str(err)
    if line is not None:
        assert err.line == line, str(err)
