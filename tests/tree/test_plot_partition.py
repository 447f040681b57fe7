"""A plot's crown partition against synthetic truth (issue 13): a stand of conifers whose
neighbours occlude each other's upper stems (:func:`generate_stand`), scanned once."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from biomorph.errors import ParameterError
from biomorph.tree.pipeline import skeletonize
from biomorph.tree.synthetic import generate_stand, simulate_scan


def test_generate_stand_places_trees_apart_with_their_ids():
    g = generate_stand("conifer", 5, spacing=2.5, seed=4)
    assert sorted(np.unique(g.tree_id).tolist()) == [0, 1, 2, 3, 4]
    assert g.roots.size == 5
    base = g.position[g.roots, :2]
    d = np.hypot(*(base[:, None] - base[None]).transpose(2, 0, 1))
    assert d[np.triu_indices(5, 1)].min() >= 0.4 * 2.5 - 1e-9
    assert np.allclose(base[g.tree_id[g.roots] == 0], 0.0)
    # every node is in the tree of its root; heights drawn in 0.6-1.15 of 14 m
    for r in g.roots:
        t = g.tree_id[r]
        top = g.position[g.tree_id == t, 2].max()
        assert 0.6 * 14.0 - 0.5 <= top <= 1.15 * 14.0 + 0.5
    assert np.array_equal(g.tree_id[g.parent[g.parent >= 0]], g.tree_id[g.parent >= 0])


@pytest.mark.parametrize(
    "kw", [{"n_trees": 0}, {"spacing": 0.0}, {"preset": "oak"}, {"height_range": (1.0, 0.5)}]
)
def test_generate_stand_refuses_bad_parameters(kw):
    with pytest.raises(ParameterError):
        generate_stand(**kw)


def test_each_stem_keeps_its_upper_stem_and_top():
    """Seed 2: before the contracted graph kept to one tree per edge, one tree's stem from
    5 m up hung from its neighbour (a 6 m height error, trunk/height 0.48-1.25, 95.4 % of
    the points on the right tree); now 99 %+ and every height within 0.5 m."""
    truth = generate_stand("conifer", 5, seed=2)
    cloud = simulate_scan(truth, n_points=100_000, seed=2, noise=0.008, occlusion=True, scanners=3)
    node = cloud.attributes["node"]
    t_true = np.where(node >= 0, truth.tree_id[np.maximum(node, 0)], -1)
    s = skeletonize(cloud)
    g = s.world_graph()
    base = truth.position[truth.roots]
    d, j = cKDTree(base[:, :2]).query(g.position[g.roots, :2])
    assert np.all(d < 0.3) and np.unique(j).size == 5  # every stem found, once
    match = dict(
        zip(g.tree_id[g.roots].tolist(), truth.tree_id[truth.roots][j].tolist(), strict=True)
    )
    _, near = cKDTree(g.position).query(cloud.xyz)
    label = np.array([match.get(int(t), -1) for t in g.tree_id])[near]
    wood = t_true >= 0
    assert np.mean(label[wood] == t_true[wood]) > 0.98
    trees = s.metrics["trees"]
    for r in g.roots:
        t = int(g.tree_id[r])
        scanned_top = cloud.xyz[t_true == match[t], 2].max()
        height = g.position[g.tree_id == t, 2].max() - g.position[r, 2]
        assert abs(height - scanned_top) < 0.6
        assert 0.9 < trees[t]["trunk_length"] / scanned_top < 1.1


def _ring(rng, centre, z0, z1, r, n):
    z = rng.uniform(z0, z1, n)
    a = rng.uniform(0, 2 * np.pi, n)
    c = np.asarray(centre, float)
    return np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a), z]


def test_track_stems_follows_a_leaning_stem_across_a_short_gap():
    from biomorph.tree.crowns import track_stems

    rng = np.random.default_rng(0)
    lean = np.tan(np.radians(8.0))  # 14 cm per metre
    pts = _ring(rng, (0, 0), 0.0, 8.0, 0.08, 6000)
    pts = pts[(pts[:, 2] < 5.0) | (pts[:, 2] > 5.2)]  # a 20 cm occlusion gap
    pts[:, 0] += lean * pts[:, 2]
    whorl = _ring(rng, (0.4 + lean * 3.0, 0), 2.95, 3.05, 0.3, 300)  # branch wood at 3 m
    other = _ring(rng, (2.0, 0), 0.0, 4.0, 0.08, 3000)
    xyz = np.vstack([pts, whorl, other])
    roots = np.r_[
        np.flatnonzero(pts[:, 2] < 0.1), len(pts) + len(whorl) + np.flatnonzero(other[:, 2] < 0.1)
    ]
    root_tree = np.r_[
        np.zeros((pts[:, 2] < 0.1).sum(), int), np.ones((other[:, 2] < 0.1).sum(), int)
    ]
    axes = track_stems(xyz, roots, root_tree, 2, step=0.15, max_gap=0.3)
    assert axes.ok.all()
    assert axes.top[0, 2] > 7.8 and axes.top[1, 2] > 3.8 and axes.top[1, 2] <= 4.0
    # the top stands over the leaning axis, not over the branch
    assert abs(axes.top[0, 0] - lean * axes.top[0, 2]) < 0.12
    # the base: the centre of the lowest metre (half a metre up a leaning stem)
    assert abs(axes.base[0, 0] - 0.5 * lean) < 0.03 and abs(axes.base[0, 1]) < 0.03


def test_a_top_behind_a_gap_goes_to_the_stem_below_it():
    """Stem B (x = 1.5 m) is scanned to 6 m and again from 7.6 m (its top); stem A's
    branch ends half a metre beside B's top. Livny's shortest-path forest hangs B's top
    from A (the branch's gap is shorter than the one in B's stem); the partition gives it
    back to B and returns the bridge that joins it to B."""
    from biomorph.tree.crowns import partition_trees
    from biomorph.tree.neighbours import neighbour_graph, segment_trees

    rng = np.random.default_rng(1)
    a = _ring(rng, (0, 0), 0.0, 10.0, 0.1, 8000)
    branch = np.c_[rng.uniform(0.1, 1.0, 600), rng.normal(0, 0.02, 600), np.full(600, 7.3)]
    branch[:, 2] += 0.15 * branch[:, 0]  # rising towards B's top
    b_low = _ring(rng, (1.5, 0), 0.0, 6.0, 0.08, 4000)
    b_top = _ring(rng, (1.5, 0), 7.6, 9.0, 0.04, 600)
    xyz = np.vstack([a, branch, b_low, b_top])
    na, nb = len(a) + len(branch), len(b_low)
    top = np.arange(na + nb, len(xyz))
    roots = np.r_[np.flatnonzero(a[:, 2] < 0.1), na + np.flatnonzero(b_low[:, 2] < 0.1)]
    root_tree = np.r_[np.zeros((a[:, 2] < 0.1).sum(), int), np.ones((b_low[:, 2] < 0.1).sum(), int)]
    g = neighbour_graph(xyz, k=10)
    from biomorph.tree.neighbours import bridge_components

    g, _ = bridge_components(xyz, g)
    assert np.mean(segment_trees(g, roots, root_tree)[top] == 0) > 0.9  # annexed by A
    tree, br, bc = partition_trees(xyz, g, roots, root_tree, gap=0.3)
    assert np.all(tree[top] == 1)
    assert np.all(tree[na : na + nb] == 1) and np.all(tree[: len(a)] == 0)
    assert np.mean(tree[len(a) : na] == 0) > 0.9  # A's branch stays A's
    # one bridge joins the top to the rest of B
    assert br.size >= 1
    in_top = np.isin(br, top) != np.isin(bc, top)
    assert np.any(in_top & (tree[br] == 1) & (tree[bc] == 1))


def _sparse_stand(**kw):
    """4 conifers, 50 k points: points on their true tree and every tree's height error
    against its highest scanned point."""
    truth = generate_stand("conifer", 4, seed=0)
    cloud = simulate_scan(truth, n_points=50_000, seed=0, noise=0.002, occlusion=True, scanners=4)
    node = cloud.attributes["node"]
    t_true = np.where(node >= 0, truth.tree_id[np.maximum(node, 0)], -1)
    s = skeletonize(cloud, **kw)
    g = s.world_graph()
    base = truth.position[truth.roots]
    d, j = cKDTree(base[:, :2]).query(g.position[g.roots, :2])
    assert np.all(d < 0.3) and np.unique(j).size == 4
    match = dict(
        zip(g.tree_id[g.roots].tolist(), truth.tree_id[truth.roots][j].tolist(), strict=True)
    )
    _, near = cKDTree(g.position).query(cloud.xyz)
    label = np.array([match.get(int(t), -1) for t in g.tree_id])[near]
    wood = t_true >= 0
    dh = [
        abs(
            g.position[g.tree_id == g.tree_id[r], 2].max()
            - g.position[r, 2]
            - cloud.xyz[t_true == match[int(g.tree_id[r])], 2].max()
        )
        for r in g.roots
    ]
    return float(np.mean(label[wood] == t_true[wood])), float(max(dh)), s


def test_sparse_stand_tops_go_to_their_own_stems():
    """The upper stems and tops are sparse and broken. Livny's segmentation alone
    (``crown_partition=False``) puts 91 % of the points on their true tree and leaves one
    tree 5.7 m short; the crown partition over 95 % and every height within 4 m. (In the
    order the simulator writes the points, tree by tree, ties broke towards the true tree:
    97.5 % and 2.1 m; every shuffled order gives 94.6-95.7 % and 3.8-4.0 m, and the
    pipeline's canonical order, session 33, 95.7 % and 3.8 m.)"""
    acc, worst, s = _sparse_stand()
    assert acc > 0.95 and worst < 4.0
    assert s.params["crown_partition"] is True
    acc0, worst0, s0 = _sparse_stand(crown_partition=False)
    assert acc0 < 0.93 and worst0 > 5.0
    assert s0.params["crown_partition"] is False


def test_a_top_no_root_reaches_goes_to_the_stem_it_continues():
    """The same stand without bridging: B's top is a piece of its own (the bridging rule
    refused it, as it refuses sparse tops above a long occlusion gap). It continues B's
    measured stem and stands over it, so it joins B instead of dropping out."""
    from biomorph.tree.crowns import partition_trees
    from biomorph.tree.neighbours import neighbour_graph

    rng = np.random.default_rng(1)
    a = _ring(rng, (0, 0), 0.0, 10.0, 0.1, 8000)
    b_low = _ring(rng, (1.5, 0), 0.0, 6.0, 0.08, 4000)
    b_top = _ring(rng, (1.5, 0), 7.6, 9.0, 0.04, 600)
    far = _ring(rng, (6.0, 6.0), 3.0, 3.5, 0.05, 200)  # a piece over no stem
    xyz = np.vstack([a, b_low, b_top, far])
    top = np.arange(len(a) + len(b_low), len(a) + len(b_low) + len(b_top))
    roots = np.r_[np.flatnonzero(a[:, 2] < 0.1), len(a) + np.flatnonzero(b_low[:, 2] < 0.1)]
    root_tree = np.r_[np.zeros((a[:, 2] < 0.1).sum(), int), np.ones((b_low[:, 2] < 0.1).sum(), int)]
    g = neighbour_graph(xyz, k=10)
    tree, br, bc = partition_trees(xyz, g, roots, root_tree, gap=0.3)
    assert np.all(tree[top] == 1)
    assert np.all(tree[-len(far) :] == -1)  # stays out
    assert br.size == 1 and np.isin(br, top).sum() + np.isin(bc, top).sum() == 1
