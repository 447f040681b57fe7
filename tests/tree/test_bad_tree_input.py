"""Clouds with no tree model to give (issue 13 "Bad input"): foliage only, no trunk, two
trees touching in a one-tree run. Each raises InputError from the skeleton stage (one
line, exit 2 at the CLI, nothing written); real trees pass the same checks."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.errors import InputError
from biomorph.tree.foliage import SCATTER_LEAVES, check_not_only_leaves, scatter_ratio
from biomorph.tree.livny import skeletonize_graph
from biomorph.tree.roots import check_single_tree, check_trunk_reaches_ground, stem_bases
from tests.tree.test_livny import Y_TREE, make_cloud


def _leaf_ball(n=6000, seed=0):
    """Scattered returns filling a 1.5 m crown 2-5 m above the origin (no wood)."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v *= (1.5 * rng.random(n) ** (1 / 3) / np.linalg.norm(v, axis=1))[:, None]
    return v + [0.0, 0.0, 3.5]


def _two_trees(gap=1.6, n=6000):
    """Two Y trees whose crowns touch: stems ``gap`` m apart, the second mirrored."""
    a = make_cloud(n=n, seed=1)
    b = make_cloud(n=n, seed=2) * [-1, 1, 1] + [gap, 0, 0]
    return np.vstack([a, b])


def _write(path, pts):
    np.savetxt(path, pts, fmt="%.5f")
    return path


def test_scatter_separates_wood_from_foliage():
    wood = scatter_ratio(make_cloud(n=6000, noise=0.003))
    leaves = scatter_ratio(_leaf_ball())
    assert wood < 0.5 * SCATTER_LEAVES < SCATTER_LEAVES < leaves
    assert check_not_only_leaves(make_cloud(n=3000)) < SCATTER_LEAVES
    with pytest.raises(InputError, match="foliage only"):
        check_not_only_leaves(_leaf_ball(), "crown.xyz")


def test_only_leaves_raises_from_both_methods():
    with pytest.raises(InputError, match="foliage only"):
        skeletonize_graph(_leaf_ball())
    from biomorph.core.pointcloud import PointCloud
    from biomorph.tree.voxel import skeletonize_voxel

    with pytest.raises(InputError, match="foliage only"):
        skeletonize_voxel(PointCloud(_leaf_ball()))


def test_trunk_must_reach_a_found_ground():
    check_trunk_reaches_ground(None)  # no ground: nothing to check
    check_trunk_reaches_ground(np.array([0.05, 2.0, 9.0]))
    with pytest.raises(InputError, match=r"no trunk found .* 2\.40 m high"):
        check_trunk_reaches_ground(np.array([2.4, 3.0, 7.0]), source="crown.laz")
    pts = make_cloud(n=3000)
    with pytest.raises(InputError, match="no trunk found"):
        skeletonize_graph(pts, height=pts[:, 2] + 1.5)  # the cloud floats 1.5 m up


def test_two_stems_in_a_one_tree_run():
    pts = _two_trees()
    bases = stem_bases(pts)
    assert bases.shape == (2, 2)
    assert np.allclose(np.sort(bases[:, 0]), [0.0, 1.6], atol=0.1)
    with pytest.raises(InputError, match=r"2 stems found .*\(1\.6\d m apart\)"):
        check_single_tree(pts, source="pair.xyz")
    with pytest.raises(InputError, match="n_trees=1"):
        skeletonize_graph(pts, n_trees=1)
    assert skeletonize_graph(pts).info["trees"] == 2  # the automatic count splits them


def test_single_trees_pass_the_one_tree_check():
    check_single_tree(make_cloud(n=6000, seed=3))
    # a Y tree with a low side branch whose tip hangs into the root slice
    low = [*Y_TREE, ((0, 0, 0.9), (0.9, 0, 0.2), 0.02)]
    check_single_tree(make_cloud(segments=low, n=6000, seed=4))
    res = skeletonize_graph(make_cloud(n=3000, seed=5), n_trees=1)
    assert res.info["trees"] == 1


@pytest.mark.parametrize("method", ["graph", "voxel"])
@pytest.mark.parametrize("case", ["leaves", "pair"])
def test_cli_exits_2_with_one_line(case, method, tmp_path, capsys):
    """Both methods refuse the same clouds, naming the file (the voxel method made one
    tree of two touching stems in a one-tree run until session 14)."""
    pts = _leaf_ball() if case == "leaves" else _two_trees()
    path = _write(tmp_path / f"{case}.xyz", pts)
    out = tmp_path / "out"
    args = ["tree", "skeletonize", str(path), "--out", str(out), "--method", method]
    if case == "pair":
        args += ["--n-trees", "1"]
    code = run(args)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.startswith("error:") and len(err.splitlines()) == 1, err
    assert str(path.name) in err
    assert "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())
