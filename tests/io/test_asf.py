"""ASF/AMC reader: the CMU take, sibling lookup, written files, errors."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from biomorph.errors import FormatError
from biomorph.io import read_motion
from biomorph.io.asf import read_motion as read_asf_amc
from biomorph.io.bvh import read_bvh, write_bvh
from tests.conftest import shared_file


def test_cmu_asf_amc(tmp_path):
    asf = shared_file("motion", "cmu_11.asf")
    shared_file("motion", "cmu_11_01.amc")
    m = read_motion(asf)  # finds cmu_11_01.amc beside it
    assert m.n_frames == 597 and m.n_joints == 31 and m.fps == 120
    w = m.world_positions()
    height = w[0, m.names.index("head"), 1] - w[0, m.names.index("lfoot"), 1]
    assert 1.2 < height < 1.8  # metres (length unit 0.45 -> inches -> m)
    assert m.meta["up_guess"] == "y"
    # from the .amc side too
    m2 = read_motion(shared_file("motion", "cmu_11_01.amc"))
    assert np.array_equal(m2.rotation, m.rotation)
    # left/right femur lengths agree (bone lengths in metres)
    off = m.skeleton.offset
    assert np.linalg.norm(off[m.names.index("ltibia")]) == pytest.approx(
        np.linalg.norm(off[m.names.index("rtibia")]), rel=0.05
    )
    back = read_bvh(write_bvh(tmp_path / "k.bvh", m))
    assert back.names == m.names
    assert np.abs(back.world_positions() - w).max() < 1e-5


def test_missing_partner_and_bad_values(tmp_path):
    asf = shared_file("motion", "cmu_11.asf")
    amc = shared_file("motion", "cmu_11_01.amc")
    lone = tmp_path / "solo.asf"
    shutil.copy(asf, lone)
    with pytest.raises(FormatError, match="no motion beside"):
        read_motion(lone)
    text = amc.read_text()
    bad = tmp_path / "solo_01.amc"
    bad.write_text(text.replace("lfemur", "lfemur 1", 1))
    with pytest.raises(FormatError, match="lfemur has 4 values") as info:
        read_asf_amc(bad)
    assert info.value.line is not None
    bad.write_text(text.replace("\nltibia ", "\nltibia x", 1))
    with pytest.raises(FormatError, match="non-numeric"):
        read_asf_amc(bad, asf=lone)
    cut = tmp_path / "cut.asf"
    cut.write_text(asf.read_text().split(":hierarchy")[0][:-200])
    with pytest.raises(FormatError):
        read_asf_amc(cut, amc=amc)


def _line_no(text: str, needle: str) -> int:
    return next(i for i, s in enumerate(text.splitlines(), start=1) if needle in s)


@pytest.mark.parametrize(
    "old,new,needle",
    [
        # axis letters and angle counts disagree (was a bare ValueError from zip(strict=True))
        ("axis 0 0 20  XYZ", "axis 0 0 20  XY", "axis order 'XY' for 3 angle(s)"),
        ("axis 0 0 20  XYZ", "axis 0 20", "axis has 2 value(s); expected 3"),
        ("axis 0 0 20  XYZ", "axis 0 0 20  XXZ", "distinct letters"),
        ("axis 0 0 20  XYZ", "axis 0 0 20  XQZ", "expected 3 distinct letters"),
        ("direction 0.34202 -0.939693 0  ", "direction 0.34202", "direction has 1 value(s)"),
        ("length 7.33161  ", "length", "length has 0 value(s)"),
        ("length 7.33161  ", "length 1e999", "non-finite"),
        ("name lfemur", "name", "bone name without a value"),
        ("name lfemur", "name lhipjoint", "defined twice"),
        ("dof rx ry rz", "dof rx rx rz", "repeats a rotation"),
        ("order TX TY TZ RX RY RZ", "order TX TY TZ RX RQ RZ", "root order"),
        ("axis XYZ", "axis XY", "root axis order 'XY'"),
        ("axis XYZ", "axis", "root axis without a value"),
        ("orientation 0 0 0", "orientation 0 0", "root orientation has 2 value(s)"),
        ("angle deg", "angle", "units angle without a value"),
        ("angle deg", "angle grad", "expected 'deg' or 'rad'"),
        ("length 0.45", "length 0", "expected a positive"),
        ("lfemur ltibia", "lfemurr ltibia", "unknown parent bone 'lfemurr'"),
        ("lfemur ltibia", "lfemur ltibiaa", "unknown bone 'ltibiaa'"),
    ],
)
def test_malformed_asf_names_file_and_line(tmp_path, old, new, needle):
    asf = shared_file("motion", "cmu_11.asf").read_text().replace("\r\n", "\n")
    amc = shared_file("motion", "cmu_11_01.amc")
    assert old in asf
    bad = asf.replace(old, new, 1)
    p = tmp_path / "bad.asf"
    p.write_text(bad)
    with pytest.raises(FormatError) as info:
        read_asf_amc(p, amc=amc)
    assert needle in str(info.value) and "bad.asf" in str(info.value)
    assert info.value.line == _line_no(asf, old.strip()), str(info.value)


def test_rot_checks_angle_count():
    from biomorph.io.asf import _rot

    with pytest.raises(FormatError, match=r"x.asf:7: axis line holds 2 angle\(s\) for the 3"):
        _rot([0.0, 1.0], "XYZ", True, "x.asf", 7)


def test_malformed_amc_names_file_and_line(tmp_path):
    asf = shared_file("motion", "cmu_11.asf")
    text = shared_file("motion", "cmu_11_01.amc").read_text().replace("\r\n", "\n")
    lines = text.splitlines()
    k = next(i for i, s in enumerate(lines) if s.startswith("lfemur "))
    bad = tmp_path / "dup.amc"
    bad.write_text("\n".join(lines[: k + 1] + [lines[k]] + lines[k + 1 :]) + "\n")
    with pytest.raises(FormatError, match="listed twice") as info:
        read_asf_amc(bad, asf=asf)
    assert info.value.line == k + 2
    bad.write_text("\n".join(lines[:k] + lines[k + 1 :]) + "\n")
    with pytest.raises(FormatError, match="lacks bone 'lfemur'") as info:
        read_asf_amc(bad, asf=asf)
    assert info.value.line is not None
    bad.write_text(text.replace(lines[k], "lfemur 1e999 0 0", 1))
    with pytest.raises(FormatError, match="non-finite") as info:
        read_asf_amc(bad, asf=asf)
    assert info.value.line == k + 1
