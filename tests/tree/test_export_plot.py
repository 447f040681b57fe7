"""Plot outputs: per-tree folders and the LAS ``tree_id`` point label (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.io import read_graph, read_points
from biomorph.tree.export import export_skeleton
from biomorph.tree.pipeline import skeletonize
from tests.tree.test_livny import make_cloud


@pytest.fixture(scope="module")
def plot():
    a = make_cloud(n=3000, seed=3)
    b = make_cloud(n=3000, seed=4) + [4.0, 0.0, 0.0]
    return skeletonize(PointCloud(np.vstack([a, b]) + [500.0, 800.0, 20.0]), ground=None)


def test_points_carry_their_tree_and_each_tree_has_a_folder(plot, tmp_path):
    assert plot.metrics["n_trees"] == 2
    files = export_skeleton(plot, tmp_path, formats=("las", "trees", "png"))
    pts = read_points(files["las"])
    assert "tree_id" in pts.attributes
    lab = np.asarray(pts.attributes["tree_id"])
    x = pts.world_xyz[:, 0]
    # the trees stand 4 m apart: every point left of the gap has one label, right the other
    left, right = lab[x < 502.0], lab[x > 502.0]
    assert np.unique(left).size == 1 and np.unique(right).size == 1 and left[0] != right[0]
    for t in (0, 1):
        d = tmp_path / f"tree_{t}"
        g = read_graph(d / "skeleton.ply")
        assert np.unique(g.trees).size == 1
        assert (d / "cylinders.csv").is_file() and (d / "treedata.csv").is_file()
        sub = read_points(d / "points.laz")
        assert (np.asarray(sub.attributes["tree_id"]) == t).all()
        assert sub.n_points == int((lab == t).sum())
    assert files["png"].stat().st_size > 0


def test_a_single_tree_gets_no_tree_folders(tmp_path):
    skel = skeletonize(make_cloud(n=3000, seed=5), ground=None)
    files = export_skeleton(skel, tmp_path, formats=("trees",))
    assert files == {} and not list(tmp_path.glob("tree_*"))
