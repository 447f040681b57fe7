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
        np.linalg.norm(off[m.names.index("rtibia")]), rel=0.05)
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
