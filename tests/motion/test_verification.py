"""Issue 15, animator's verification pass (second round): the defects found by driving every
operator over every shared capture, each pinned by a test on the file that showed it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from biomorph.io.bvh import read_bvh
from biomorph.motion.names import mirror_name
from biomorph.motion.quality import foot_skate
from biomorph.motion.retarget import mirror
from tests.conftest import shared_file


def _read(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_bvh(shared_file("motion", name))


@pytest.fixture(scope="module")
def rokoko():
    return _read("ad_rokoko_jesse_dance.bvh").frames(0, 300)


def test_mirror_rokoko_rig_reflects_positions(rokoko):
    # was: the rest pose (every bone along its local +x) gave y, the up axis, as the lateral
    # axis, and the two sides' identical offsets put each bone where the other side's was not
    # mirrored: skate 57 body scales/s, feet 1.2 hip heights below the floor
    m = rokoko
    out = mirror(m)
    assert out.meta["history"][-1] == "mirror axis=x"
    p0, p1 = m.world_positions(), out.world_positions()
    other = [m.names.index(mirror_name(n) or n) for n in m.names]
    want = p0[:, other].copy()
    want[..., 0] *= -1
    hip = float(np.median(p0[:, 0, 1]))
    assert np.abs(p1 - want).max() < 1e-3 * hip  # the rig's own 0.06-unit asymmetry
    assert p1[..., 1].min() > p0[..., 1].min() - 1e-3 * hip
    s0 = foot_skate(m)["skate_per_body_scale"]
    assert foot_skate(out)["skate_per_body_scale"] < s0 * 1.01
    assert np.abs(mirror(out).world_positions() - p0).max() < 1e-9 * hip
