"""Skeleton metrics: NOB, TBL, MSE, F1 against truth, DBH, volume."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError
from biomorph.tree.metrics import (
    compare_to_truth,
    dbh,
    point_to_skeleton_distance,
    skeleton_metrics,
    volume,
)
from biomorph.tree.synthetic import generate_tree


def _fork():
    # stem 0-(0,0,2), two branches
    pos = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 3], [-1, 0, 3]]
    return BranchGraph(pos, [-1, 0, 1, 2, 2], radius=[0.2, 0.15, 0.1, 0.05, 0.05])


def test_nob_tbl_mse():
    g = _fork()
    pts = np.array([[0.1, 0, 0.5], [0, 0.3, 1.5], [1, 0, 3.2]])
    m = skeleton_metrics(g, PointCloud(pts))
    assert m["nob"] == 2 and m["n_trees"] == 1
    assert m["tbl"] == pytest.approx(2 + 2 * np.sqrt(2))
    assert m["mse"] == pytest.approx((0.01 + 0.09 + 0.04) / 3)
    assert skeleton_metrics(g)["mse"] is None


def test_point_segment_distance_exact():
    g = BranchGraph([[0, 0, 0], [10, 0, 0]], [-1, 0])
    d = point_to_skeleton_distance(g, np.array([[5, 3, 4], [-3, 4, 0], [12, 0, 0]]))
    np.testing.assert_allclose(d, [5, 5, 2])


def test_per_tree_metrics():
    a = _fork()
    b = BranchGraph(
        np.r_[a.position, a.position + [5, 0, 0]],
        np.r_[a.parent, np.where(a.parent >= 0, a.parent + 5, -1)],
    )
    m = skeleton_metrics(b, np.array([[5, 0, 0.5]]))
    assert m["n_trees"] == 2 and [t["nob"] for t in m["trees"]] == [2, 2]
    assert m["trees"][1]["n_points"] == 1 and m["trees"][0]["mse"] is None


def test_dbh_and_volume():
    g = _fork()
    assert dbh(g) == pytest.approx(2 * (0.15 + 0.3 * (0.1 - 0.15)))
    cyl = BranchGraph([[0, 0, 0], [0, 0, 2]], [-1, 0], radius=[0.1, 0.1])
    assert volume(cyl) == pytest.approx(np.pi * 0.01 * 2)
    cone = BranchGraph([[0, 0, 0], [0, 0, 3]], [-1, 0], radius=[1.0, 0.0])
    assert volume(cone) == pytest.approx(np.pi)
    assert np.isnan(dbh(BranchGraph([[0, 0, 0], [0, 0, 1]], [-1, 0], radius=[1, 1])))


def test_compare_identity_and_shifted():
    t = generate_tree("aspen", seed=0)
    m = compare_to_truth(t, t)
    assert m["f1"] == 1 and m["nob_ratio"] == 1 and m["tbl_ratio"] == pytest.approx(1)
    assert m["radius_error"] == 0 and m["dbh_error"] == 0 and m["volume_error"] == 0
    shifted = t.with_(position=t.position + [0.3, 0.3, 0])
    m2 = compare_to_truth(shifted, t, tolerance=0.1)
    assert m2["f1"] < 0.2
    # missing half the branches: recall drops, precision stays
    keep = t.depth == 0
    m3 = compare_to_truth(t.subgraph(keep), t, tolerance=0.05)
    assert m3["precision"] == 1 and m3["recall"] < 0.3
    fat = t.with_(radius=t.radius * 1.2)
    assert compare_to_truth(fat, t)["radius_error"] == pytest.approx(0.2)
    with pytest.raises(InputError):
        compare_to_truth(BranchGraph(np.zeros((0, 3)), []), t)


def test_observed_truth_measures_leave_out_unscanned_branches():
    """A scan that saw the stem and one branch only: 3.41 of 4.83 m of truth is observed;
    a skeleton of exactly that part has TBL ratio 0.71 but observed TBL ratio 1 and
    observed recall 1. Leaf and ground points do not count as observations."""
    t = _fork()
    rng = np.random.default_rng(0)
    s = rng.uniform(0, 1, 600)
    r = 0.2 - 0.1 * s  # the stem's true radius
    stem = np.column_stack([r * np.cos(9 * s), r * np.sin(9 * s), 2 * s])
    s2 = rng.uniform(0, 1, 300)
    branch = np.array([0, 0, 2.0]) + s2[:, None] * np.array([1.0, 0, 1]) + [0, 0.05, 0]
    leaves = np.array([-1, 0, 3.0]) + rng.normal(0, 0.01, (50, 3))  # on the other tip
    xyz = np.vstack([stem, branch, leaves])
    is_leaf = np.r_[np.zeros(900, bool), np.ones(50, bool)]
    cloud = PointCloud(xyz, attributes={"is_leaf": is_leaf})
    seen_part = t.subgraph(np.array([True, True, True, True, False]))
    m = compare_to_truth(seen_part, t, tolerance=0.05, cloud=cloud)
    frac = (2 + np.sqrt(2)) / (2 + 2 * np.sqrt(2))
    # (the unseen branch's first few cm lie next to the seen points at the fork)
    assert m["observed_fraction"] == pytest.approx(frac, abs=0.04)
    assert m["tbl_ratio"] == pytest.approx(frac, abs=1e-9)
    assert m["tbl_ratio_observed"] == pytest.approx(1.0, abs=0.06)
    assert m["recall_observed"] == pytest.approx(1.0, abs=0.04)
    assert "observed_fraction" not in compare_to_truth(seen_part, t, tolerance=0.05)
    # the leaf points alone observe nothing of the wood
    with pytest.raises(InputError, match="no wood points"):
        compare_to_truth(
            seen_part, t, cloud=PointCloud(leaves, attributes={"is_leaf": is_leaf[900:]})
        )
