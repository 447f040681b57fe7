"""TreeQSM's model of the rTwig cloud read from its ``.mat`` and compared with our skeleton
(issue 13; skipped without ../shared/data)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from biomorph.errors import FormatError
from biomorph.io import read_points
from biomorph.tree.metrics import tree_attributes
from biomorph.tree.pipeline import skeletonize
from biomorph.tree.reference import compare_to_reference, read_reference, read_treeqsm_mat
from tests.conftest import shared_file


def test_treeqsm_mat_reads_as_its_cylinders():
    g = read_treeqsm_mat(shared_file("trees", "rtwig_QSM_treeqsm.mat"))
    assert g.n_nodes == 1136 + 1  # cylinder ends + one base node
    vol = np.pi * g.radius[g.parent >= 0] ** 2 * g.edge_length[g.parent >= 0]
    # OptQSM.treedata.TotalVolume 21.57 L; node-to-node edges differ from the cylinders by 2 %
    assert 1000 * vol.sum() == pytest.approx(21.57, rel=0.03)
    assert read_reference(shared_file("trees", "rtwig_QSM_treeqsm.mat")).n_nodes == g.n_nodes


def test_a_mat_without_a_qsm_is_refused(tmp_path):
    p = tmp_path / "other.mat"
    scipy.io.savemat(p, {"x": np.arange(3)})
    with pytest.raises(FormatError, match="OptQSM"):
        read_treeqsm_mat(p)


def test_rtwig_skeleton_against_treeqsm():
    cloud = read_points(shared_file("trees", "rtwig_cloud.txt"))
    skel = skeletonize(cloud)
    ref = read_treeqsm_mat(shared_file("trees", "rtwig_QSM_treeqsm.mat"))
    c = compare_to_reference(skel.world_graph(), ref, tolerance=0.05)
    assert c["f1"] >= 0.85
    assert c["radius_profile_error"] < 0.25  # 0.16 measured (e = 2 pipe taper)
    vol = tree_attributes(skel.graph)[0]["total_volume"]
    # TreeQSM 21.6 L, SimpleForest 30.0 L (both uncorrected QSMs); ours 16.0 L: guard it
    assert 0.65 * 0.02157 <= vol <= 1.4 * 0.02157, vol
