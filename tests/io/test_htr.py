"""HTR reader: the real Motion Analysis file, written files, conventions, errors."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core import transforms as tf
from biomorph.errors import FormatError
from biomorph.io import read_motion
from biomorph.io.bvh import read_bvh, write_bvh
from biomorph.io.htr import read_htr
from tests.conftest import shared_file

SMALL = """# Motion Analysis HTR\r
[Header]\r
FileType htr\r
DataType HTRS\r
FileVersion 1\r
NumSegments 3\r
NumFrames 2\r
DataFrameRate 30\r
EulerRotationOrder ZYX\r
CalibrationUnits cm\r
RotationUnits Degrees\r
GlobalAxisofGravity Y\r
BoneLengthAxis Y\r
ScaleFactor 1.0\r
[SegmentNames&Hierarchy]\r
# child parent\r
arm\tbody\r
body\tGLOBAL\r
hand\tarm\r
[BasePosition]\r
body\t0\t100\t0\t0\t0\t0\t50\r
arm\t0\t50\t0\t0\t0\t90\t30\r
hand\t0\t30\t0\t0\t0\t0\t10\r
[body]\r
0\t0\t0\t0\t0\t0\t0\t1\r
1\t10\t0\t0\t0\t45\t0\t1\r
[arm]\r
0\t0\t0\t0\t0\t0\t0\t1\r
1\t0\t0\t0\t30\t0\t0\t1\r
[hand]\r
0\t0\t0\t0\t0\t0\t0\t1\r
1\t0\t0\t0\t0\t0\t0\t1\r
[EndOfFile]\r
"""


def test_real_htr_file(tmp_path):
    m = read_motion(shared_file("motion", "animal3d_egnaro_skel_anim.htr"))
    assert m.n_frames == 81 and m.n_joints == 89 and m.fps == pytest.approx(24)
    assert m.names[0] == "main" and m.meta["htr_units"] == "mm"
    # base pose (frame 0 is all zeros): left and right limbs mirror each other in X
    w = m.world_positions()
    left = [i for i, s in enumerate(m.names) if s.startswith("L_")]
    right = [m.names.index("R_" + m.names[i][2:]) for i in left]
    for fr in (0, 40):
        rel = w[fr] - w[fr, 0]
        mirrored = rel[right] * [-1, 1, 1]
        assert np.abs(rel[left] - mirrored).max() < 2e-5  # file precision: 6 decimals
    # round trip through BVH keeps the pose (rest rotations baked into the Euler channels)
    back = read_bvh(write_bvh(tmp_path / "e.bvh", m))
    assert back.names == m.names
    assert np.abs(back.world_positions() - w).max() < 1e-5


def test_small_written_htr(tmp_path):
    p = tmp_path / "s.htr"
    p.write_bytes(SMALL.encode())
    m = read_htr(p)
    assert m.names == ("body", "arm", "hand")  # parents first although listed later
    assert np.allclose(m.skeleton.offset[1], [0, 0.5, 0])  # cm -> m
    assert np.allclose(m.root_position[1], [0.1, 1.0, 0])  # base + frame translation
    # arm base rotation Rz(90): rest; frame 1 pose Rx(30) (R = Rz Ry Rx)
    assert (
        tf.quat_angle(
            m.skeleton.rest_rotation[1], tf.euler_to_quat([90, 0, 0], "ZYX", degrees=True)
        )
        < 1e-12
    )
    assert tf.quat_angle(m.rotation[1, 1], tf.quat_from_axis_angle("x", np.radians(30))) < 1e-9
    assert np.allclose(m.skeleton.end_site[2], [0, 0.1, 0])
    w = m.world_positions()
    assert np.allclose(w[0, 2], [-0.3, 1.5, 0])  # arm bone along rotated Y = -X


@pytest.mark.parametrize(
    "mutate,needle",
    [
        (lambda s: s.replace("[EndOfFile]\r\n", ""), "EndOfFile"),
        (lambda s: s.replace("1\t0\t0\t0\t30\t0\t0\t1\r\n", ""), "has 1 frames"),
        (lambda s: s.replace("1\t0\t0\t0\t30", "1\t0\t0\t0\tabc"), "'abc' is not a number"),
        (lambda s: s.replace("hand\tarm", "hand\tfoot"), "unknown parent"),
        (lambda s: s.replace("[BasePosition]", "[Base]"), "BasePosition"),
        (lambda s: s.replace("EulerRotationOrder ZYX", "EulerRotationOrder ABC"), "ABC"),
        (lambda s: "", "empty"),
    ],
)
def test_bad_htr(tmp_path, mutate, needle):
    p = tmp_path / "bad.htr"
    p.write_bytes(mutate(SMALL).encode())
    with pytest.raises(FormatError) as info:
        read_htr(p, strict=True)
    assert needle in str(info.value) and "bad.htr" in str(info.value)


@pytest.mark.parametrize(
    "mutate,needle",
    [
        (lambda s: s.replace("1\t0\t0\t0\t30", "1\t0\t0\t0\t1e999"), "non-finite"),
        (lambda s: s.replace("1\t0\t0\t0\t30", "1\t0\t0\t0\tnan"), "non-finite"),
        (lambda s: s.replace("arm\t0\t50\t0", "arm\t0\tinf\t0"), "non-finite"),
        (lambda s: s.replace("ScaleFactor 1.0", "ScaleFactor nan"), "ScaleFactor"),
        (lambda s: s.replace("DataFrameRate 30", "DataFrameRate nan"), "DataFrameRate"),
        # a damaged NumFrames is reported, not allocated
        (lambda s: s.replace("NumFrames 2", "NumFrames 2000000000000"), "NumFrames says"),
    ],
)
def test_damaged_htr_values(tmp_path, mutate, needle):
    p = tmp_path / "bad.htr"
    p.write_bytes(mutate(SMALL).encode())
    with pytest.raises(FormatError) as info:
        read_htr(p, strict=True)
    assert needle in str(info.value) and "bad.htr" in str(info.value)


@pytest.mark.parametrize(
    "mutate,frames,needle",
    [
        (lambda s: s.replace("[EndOfFile]\r\n", ""), 2, "no [EndOfFile]"),
        (lambda s: s.replace("1\t0\t0\t0\t30\t0\t0\t1\r\n", ""), 1, "read the 1 frames"),
        (
            lambda s: s.replace("NumFrames 2", "NumFrames 2000000000000"),
            2,
            "NumFrames 2000000000000",
        ),
    ],
)
def test_tolerated_htr_reads_with_a_warning(tmp_path, mutate, frames, needle):
    from biomorph.core.motion import MotionInputWarning

    p = tmp_path / "odd.htr"
    p.write_bytes(mutate(SMALL).encode())
    with pytest.warns(MotionInputWarning, match="odd.htr"):
        m = read_htr(p)
    assert m.n_frames == frames
    assert any(needle in t for t in m.meta["tolerated"]), m.meta["tolerated"]
