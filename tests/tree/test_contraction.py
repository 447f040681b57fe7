"""Contraction of the graph method (issue 13): level pieces that follow the wood.

With ``merge="overlap"`` or ``"adaptive"`` two twigs side by side in one geodesic level
stay two vertices (the default ``"adjacent"`` puts one centroid between them, > 10 cm from
the wood on real crowns); the reach bound keeps refined vertices on their points.
"""

from __future__ import annotations

import numpy as np

from biomorph.tree import livny
from biomorph.tree.allometry import skeleton_distance
from biomorph.tree.neighbours import (
    bridge_components,
    contract,
    neighbour_graph,
    shortest_path_forest,
)

from .test_livny import cylinder_points


def _twins(gap: float = 0.08, seed: int = 0):
    """A 5 cm stem forking into two parallel 1 cm twigs ``gap`` apart (axis to axis)."""
    rng = np.random.default_rng(seed)
    h = gap / 2
    parts = [
        ((0, 0, 0), (0, 0, 0.5), 0.05, 2500),
        ((0, 0, 0.5), (-h, 0, 0.6), 0.01, 120),
        ((0, 0, 0.5), (h, 0, 0.6), 0.01, 120),
        ((-h, 0, 0.6), (-h, 0, 1.6), 0.01, 900),
        ((h, 0, 0.6), (h, 0, 1.6), 0.01, 900),
    ]
    return np.vstack([cylinder_points(a, b, r, n, rng, 0.001) for a, b, r, n in parts])


def _levels(xyz, spacing, merge, point_spacing=None, cell=None):
    g, _ = bridge_components(xyz, neighbour_graph(xyz, k=10))
    roots = np.flatnonzero(xyz[:, 2] < 0.02)
    geo = g.copy()
    geo.data = np.sqrt(geo.data)
    plen, _ = shortest_path_forest(geo, roots)
    tree = np.where(np.isfinite(plen), 0, -1)
    return contract(
        xyz, g, plen, tree, spacing, merge=merge, point_spacing=point_spacing, cell=cell
    )


def test_twigs_side_by_side_stay_two_vertices():
    xyz = _twins()
    con = _levels(xyz, 0.03, "overlap")
    high = con.position[:, 2] > 0.9
    assert high.sum() >= 20  # both twigs reached
    # every vertex of the twin section sits on one twig (|x| ≈ 4 cm), none between them
    assert np.all(np.abs(np.abs(con.position[high, 0]) - 0.04) < 0.015)
    # the default joins every voxel-adjacent piece: centroids between the twigs
    merged = _levels(xyz, 0.03, "adjacent")
    hm = merged.position[:, 2] > 0.9
    assert np.median(np.abs(merged.position[hm, 0])) < 0.01


def test_reach_keeps_refined_twigs_on_their_points():
    xyz = _twins(gap=0.3)
    free = livny.skeletonize_graph(xyz, reach=None)
    bound = livny.skeletonize_graph(xyz)  # reach=REACH by default
    d_free, _ = skeleton_distance(xyz, free.graph.parent, free.graph.position)
    d_bound, _ = skeleton_distance(xyz, bound.graph.parent, bound.graph.position)
    twig = xyz[:, 2] > 0.7
    assert np.quantile(d_bound[twig], 0.95) < 0.03
    assert np.quantile(d_bound[twig], 0.95) <= np.quantile(d_free[twig], 0.95) + 1e-9
    c = livny.clamp_to_points(np.array([[3.0, 0, 0]]), np.zeros((1, 3)), np.array([0.5]))
    assert np.allclose(c, [[0.5, 0, 0]])


def test_adaptive_joins_arcs_of_one_thick_ring():
    """Two arcs of a 0.6 m stem ring behind an occlusion gap wider than their spreads:
    the overlap test keeps them apart, the adaptive rule joins them (both pieces are wider
    than the level width); two narrow twig pieces the same distance apart stay apart."""
    from biomorph.tree.neighbours import _merge_overlapping

    r = 0.3
    a = np.linspace(-0.2, 0.2, 40)  # two 12 cm arcs, 8 cm apart along the ring
    gap_angle = 0.2 + 0.08 / r
    arc1 = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)])
    b = a + 2 * gap_angle
    arc2 = np.column_stack([r * np.cos(b), r * np.sin(b), np.zeros_like(b)])
    xyz = np.vstack([arc1, arc2])
    lab = np.repeat([0, 1], 40)
    vr, vc = np.array([39]), np.array([40])  # the facing ends: the voxel link
    gap = np.linalg.norm(xyz[39] - xyz[40])
    spread = np.sqrt(np.mean(np.sum((arc1 - arc1.mean(0)) ** 2, axis=1)))
    assert gap > 2 * spread > 2 * 0.03
    assert np.unique(_merge_overlapping(xyz, lab, vr, vc, 0.01)).size == 2
    assert np.unique(_merge_overlapping(xyz, lab, vr, vc, 0.01, wide=0.03)).size == 1
    # twig pieces (1 cm across) as far apart: not wide, not joined
    rng = np.random.default_rng(0)
    t1 = rng.normal(0, 0.005, (40, 3))
    t2 = t1 + [gap + 0.02, 0, 0]
    tw = np.vstack([t1, t2])
    i, j = np.argmax(t1[:, 0]), 40 + np.argmin(t2[:, 0])
    out = _merge_overlapping(tw, lab, np.array([i]), np.array([j]), 0.01, wide=0.03)
    assert np.unique(out).size == 2


def test_adaptive_keeps_twigs_side_by_side_apart():
    xyz = _twins()
    con = _levels(xyz, 0.03, "adaptive")
    high = con.position[:, 2] > 0.9
    assert high.sum() >= 20
    assert np.all(np.abs(np.abs(con.position[high, 0]) - 0.04) < 0.015)


def test_adaptive_keeps_sparse_twig_pieces_in_their_levels():
    """Fragments join only pieces that hold a whole kNN neighbourhood (a stem's
    cross-section): every vertex of a sparse twig holds the points of one geodesic level
    (on 5 cm scans absorbing 1–2-point pieces into the next 3-point piece merged twigs)."""
    rng = np.random.default_rng(3)
    stem = cylinder_points((0, 0, 0), (0, 0, 1.0), 0.05, 3000, rng, 0.001)
    t = np.linspace(0, 0.6, 50)[:, None]  # a sparse twig: 2-3 points per 3 cm level
    twig = np.array([0.05, 0, 0.5]) + t * np.array([0.8, 0, 0.6])
    xyz = np.vstack([stem, twig + rng.normal(0, 0.002, twig.shape)])
    g, _ = bridge_components(xyz, neighbour_graph(xyz, k=10))
    roots = np.flatnonzero(xyz[:, 2] < 0.02)
    geo = g.copy()
    geo.data = np.sqrt(geo.data)
    plen, _ = shortest_path_forest(geo, roots)
    tree = np.where(np.isfinite(plen), 0, -1)
    con = contract(xyz, g, plen, tree, 0.03, merge="adaptive")
    level = np.floor(plen / 0.03).astype(int)
    ok = (con.label >= 0) & (xyz[:, 0] > 0.25)  # the twig past its base
    assert ok.sum() >= 12
    lo = np.full(con.count.size, 10**9)
    hi = np.full(con.count.size, -1)
    np.minimum.at(lo, con.label[ok], level[ok])
    np.maximum.at(hi, con.label[ok], level[ok])
    twig = np.unique(con.label[ok])
    assert np.array_equal(lo[twig], hi[twig])
    # the overlap merge's absorption (into any piece of 3 points) spans levels there
    old = contract(xyz, g, plen, tree, 0.03, merge="overlap")
    lo2 = np.full(old.count.size, 10**9)
    hi2 = np.full(old.count.size, -1)
    np.minimum.at(lo2, old.label[ok], level[ok])
    np.maximum.at(hi2, old.label[ok], level[ok])
    t2 = np.unique(old.label[ok])
    assert np.any(lo2[t2] != hi2[t2])


def test_two_scale_keeps_a_twiglet_beside_its_branch_apart():
    """Two 1 cm twigs 8 cm apart (6 cm of air between their surfaces): as far as voxels
    of the fine cell (3 point spacings of 1 cm) can reach, well within the 4.5 cm coarse
    cell's. The default of this function ("adjacent") puts vertices between them; the
    graph method's "two-scale" keeps every vertex on a twig."""
    xyz = _twins(gap=0.08)
    two = _levels(xyz, 0.03, "two-scale", point_spacing=0.01)
    high = two.position[:, 2] > 0.9
    assert high.sum() >= 20
    assert np.all(np.abs(np.abs(two.position[high, 0]) - 0.04) < 0.015)
    adj = _levels(xyz, 0.03, "adjacent", point_spacing=0.01)
    ha = adj.position[:, 2] > 0.9
    assert np.any(np.abs(adj.position[ha, 0]) < 0.02)


def test_two_scale_closes_an_occluded_stem_ring():
    """A 30 cm stem scanned from two sides: two 7 cm occlusion gaps in every ring, beyond
    the fine cell's reach (two 3 cm voxels), within the coarse cell's (8 cm here). The
    arcs are wider than their gap, so every level of the stem is one vertex on its axis,
    as with "adjacent"; joining at the fine scale alone leaves two arcs per level."""
    rng = np.random.default_rng(5)
    p = cylinder_points((0, 0, 0), (0, 0, 0.6), 0.3, 40000, rng, 0.001)
    ang = np.arctan2(p[:, 1], p[:, 0])
    half = 0.07 / 0.3 / 2  # half-angle of a 7 cm gap
    xyz = p[(np.abs(ang - np.pi / 2) > half) & (np.abs(ang + np.pi / 2) > half)]

    def off_axis(merge, cell):
        con = _levels(xyz, 0.03, merge, point_spacing=0.01, cell=cell)
        mid = (con.position[:, 2] > 0.1) & (con.position[:, 2] < 0.5)
        assert mid.sum() >= 10
        return np.hypot(con.position[mid, 0], con.position[mid, 1])

    assert np.all(off_axis("two-scale", 0.08) < 0.1)
    assert np.all(off_axis("adjacent", 0.08) < 0.1)
    assert np.median(off_axis("adjacent", 0.03)) > 0.15  # the fine scale alone


def test_graph_level_merge_option():
    xyz = _twins(gap=0.3)
    assert livny.LEVEL_MERGE_DEFAULT == "two-scale"
    assert livny.skeletonize_graph(xyz).info["level_merge"] == "two-scale"
    adj = livny.skeletonize_graph(xyz, level_merge="adjacent")
    assert adj.info["level_merge"] == "adjacent" and adj.graph.leaves.size >= 2
    res = livny.skeletonize_graph(xyz, level_merge="adaptive")
    assert res.info["level_merge"] == "adaptive" and res.graph.leaves.size >= 2


def test_segment_trees_gives_each_point_the_tree_of_the_root_it_hangs_from():
    from scipy import sparse

    from biomorph.tree.neighbours import segment_trees

    # a path 0-1-2-3-4 (squared lengths 1, 1, 5, 1) and a lone vertex 5
    r = np.array([0, 1, 2, 3])
    c = np.array([1, 2, 3, 4])
    g = sparse.csr_matrix((np.array([1.0, 1.0, 5.0, 1.0]), (r, c)), shape=(6, 6))
    g = g.maximum(g.T).tocsr()
    tree = segment_trees(g, np.array([0, 4]), np.array([7, 3]))
    assert tree.tolist() == [7, 7, 7, 3, 3, -1]


def test_contracted_graph_joins_no_two_trees():
    """Two stems 6 cm apart whose points touch: the points' segmentation gives each its
    tree, and Q has no edge between the trees' vertices (the spanning forest on Q and its
    re-weighting could otherwise hang one stem's upper part from the other)."""
    rng = np.random.default_rng(1)
    a = cylinder_points((0, 0, 0), (0, 0, 1.0), 0.02, 1500, rng)
    b = cylinder_points((0.06, 0, 0), (0.06, 0, 1.0), 0.02, 1500, rng)
    xyz = np.vstack([a, b])
    tree = np.r_[np.zeros(len(a), np.int64), np.ones(len(b), np.int64)]
    g = neighbour_graph(xyz, k=10)
    roots = np.array([int(np.argmin(a[:, 2])), len(a) + int(np.argmin(b[:, 2]))])
    geo = g.copy()
    geo.data = np.sqrt(geo.data)
    plen, _ = shortest_path_forest(geo, roots)
    # the points of both stems are neighbours: the kNN graph joins the trees
    coo = g.tocoo()
    assert np.any(tree[coo.row] != tree[coo.col])
    con = contract(xyz, g, plen, tree, 0.05, point_spacing=0.005, merge="two-scale")
    q = con.graph.tocoo()
    assert q.nnz > 0
    assert np.all(con.tree[q.row] == con.tree[q.col])
