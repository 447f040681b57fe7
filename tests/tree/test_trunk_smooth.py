"""The trunk's axis smoothed once the trunk is chosen (order.smooth_trunk,
resample.smooth_branches): the skeleton's node-to-node wiggle made a straight 16.7 m spruce's
trunk 21.7 m long."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.tree.order import smooth_trunk
from biomorph.tree.resample import smooth_branches


def _chain(pos: np.ndarray) -> BranchGraph:
    return BranchGraph(pos, np.arange(-1, len(pos) - 1))


def _length(pos: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())


def test_a_straight_unevenly_spaced_branch_is_left_where_it_is():
    z = np.cumsum(np.random.default_rng(0).uniform(0.02, 0.08, 60))
    pos = np.stack([0.3 * z, np.zeros_like(z), z], axis=1)
    out = smooth_branches(_chain(pos), np.ones(len(z), bool), 20.0)
    assert np.allclose(out.position, pos, atol=1e-9)


def test_a_zigzag_loses_its_wiggle_but_not_its_ends():
    n = 200
    z = np.arange(n) * 0.05
    x = 0.03 * (-1.0) ** np.arange(n)  # ±3 cm node to node on 5 cm edges
    pos = np.stack([x, np.zeros(n), z], axis=1)
    out = smooth_branches(_chain(pos), np.ones(n, bool), 20.0).position
    assert _length(pos) > 1.5 * z[-1]
    assert _length(out) < 1.02 * z[-1]
    assert abs(out[0, 2] - z[0]) < 0.01 and abs(out[-1, 2] - z[-1]) < 0.01
    assert np.abs(out[20:-20, 0]).max() < 0.003


def test_a_smooth_bend_keeps_its_shape():
    th = np.linspace(0, np.pi / 2, 80)  # a quarter circle of 2 m, 4 cm edges
    pos = np.stack([2 * np.cos(th), np.zeros_like(th), 2 * np.sin(th)], axis=1)
    out = smooth_branches(_chain(pos), np.ones(len(th), bool), 20.0).position
    r = np.linalg.norm(out[:, [0, 2]], axis=1)
    assert np.abs(r - 2).max() < 0.01
    assert _length(out) == pytest.approx(_length(pos), rel=0.01)


def _wiggly_tree(seed: int = 0):
    """A vertical 10 m trunk of 5 cm edges wiggling ±3 cm, with one side branch."""
    rng = np.random.default_rng(seed)
    n = 201
    z = np.arange(n) * 0.05
    pos = np.stack([rng.normal(0, 0.03, n), rng.normal(0, 0.03, n), z], axis=1)
    parent = np.arange(-1, n - 1)
    side = np.array([[0.1 * k, 0.0, 5.0 + 0.05 * k] for k in range(1, 21)])
    side_parent = np.concatenate([[100], n + np.arange(19)])
    depth = np.concatenate([np.zeros(n, int), np.ones(20, int)])
    g = BranchGraph(
        np.vstack([pos, side]),
        np.concatenate([parent, side_parent]),
        radius=np.full(n + 20, 0.05),
        depth=depth,
    )
    segment = np.concatenate([np.zeros(n, int), np.ones(20, int)])
    return g, segment, n


def test_smooth_trunk_straightens_the_trunk_and_leaves_the_branches():
    g, segment, n = _wiggly_tree()
    out = smooth_trunk(g, segment)
    before, after = _length(g.position[:n]), _length(out.position[:n])
    assert before > 1.3 * 10.0
    assert after < 1.05 * 10.0
    assert np.array_equal(out.position[n:], g.position[n:])  # the side branch stays
    assert np.array_equal(out.parent, g.parent) and np.array_equal(out.radius, g.radius)


def test_the_spruce_trunk_is_about_as_long_as_the_tree_is_tall():
    from biomorph.io import read_points
    from biomorph.tree import skeletonize
    from tests.conftest import shared_file

    cloud = read_points(shared_file("trees", "treels_spruce.laz"))
    # the detours taken out of the trunk (test_trunk_detours) or not: the wiggle alone
    # (and the run cylinders off: they put the upper trunk's nodes on their fitted axes)
    on = skeletonize(cloud, method="graph", detours=False, run_cylinders=False)
    off = skeletonize(cloud, method="graph", trunk_smooth=False, detours=False, run_cylinders=False)
    t_on, t_off = on.metrics["trees"][0], off.metrics["trees"][0]
    assert on.params["trunk_smooth"] is True and off.params["trunk_smooth"] is False
    assert t_off["trunk_length"] > 1.2 * t_off["height"]
    # the wiggle gone (21.7 -> 18.6 m); the detours beside the stem stay (clamped moves)
    assert t_on["height"] <= t_on["trunk_length"] < 0.9 * t_off["trunk_length"]
    assert t_on["trunk_volume"] < t_off["trunk_volume"]


def test_no_trunk_smooth_reaches_the_summary(tmp_path, capsys):
    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz
    from tests.tree.test_livny import make_cloud

    xyz = _write_xyz(tmp_path / "tree.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(xyz), "--no-ground", "--json"]
    assert run([*args, "--no-trunk-smooth", "--out", str(tmp_path / "off")]) == 0
    off = json.loads(capsys.readouterr().out)
    assert off["params"]["trunk_smooth"] is False


def test_smooth_trunk_moves_no_node_farther_than_its_radius_or_an_edge():
    # a 0.5 m bump in the trunk's route (through a crown's branches): the wiggle on it goes,
    # the route stays, no node moving more than max(radius, median edge)
    g, segment, n = _wiggly_tree(seed=1)
    pos = g.position.copy()
    z = pos[:n, 2]
    pos[:n, 0] += 0.5 * np.exp(-(((z - 7.0) / 0.3) ** 2))
    g = g.with_(position=pos)
    out = smooth_trunk(g, segment)
    move = np.linalg.norm(out.position - g.position, axis=1)
    limit = max(0.05, float(np.median(g.edge_length[1:n])))  # radius 5 cm, edges ~7 cm
    assert 0.03 < move.max() <= limit + 1e-9
    assert out.position[:n, 0].max() > 0.4  # the bump is still there


def test_taper_trunk_makes_the_trunk_radii_non_increasing_and_caps_its_branches():
    from biomorph.tree.order import taper_trunk

    g, segment, n = _wiggly_tree()
    r = np.linspace(0.12, 0.02, n)
    r[100] = 0.2  # a whorl's circle fit, swollen by its branch bases
    radius = np.concatenate([r, np.full(20, 0.05)])
    radius[n] = 0.08  # the side branch's first node: thicker than its parent will be
    g = g.with_(radius=radius)
    out = taper_trunk(g, segment)
    assert np.all(np.diff(out.radius[:n]) <= 1e-12)
    assert out.radius[100] < 0.13  # the swelling pooled with its neighbours
    assert out.radius[0] == pytest.approx(0.12, abs=0.01)  # the base kept
    assert out.radius[n] <= out.radius[100] + 1e-12
    assert np.all(out.radius[n + 1 :] <= 1.1 * out.radius[n : n + 19] + 1e-12)


def test_the_tube_rings_follow_their_own_branch_not_the_whorl():
    from biomorph.tree.export import tube_mesh

    # a vertical stem with two branches leaving one node horizontally
    stem = np.array([[0, 0, z] for z in np.arange(0, 2.01, 0.1)])
    n = len(stem)
    side = np.array(
        [[0.1 * k, 0, 1.0] for k in range(1, 6)] + [[0, 0.1 * k, 1.0] for k in range(1, 6)]
    )
    parent = np.concatenate(
        [np.arange(-1, n - 1), [10, n, n + 1, n + 2, n + 3, 10, n + 5, n + 6, n + 7, n + 8]]
    )
    g = BranchGraph(np.vstack([stem, side]), parent, radius=np.full(n + 10, 0.05))
    mesh = tube_mesh(g, sides=8)
    ring = mesh.vertices[10 * 8 : 11 * 8]  # the fork node's own ring
    assert np.ptp(ring[:, 2]) < 1e-9  # perpendicular to the stem, not tilted to the branches
