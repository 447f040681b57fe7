"""Shared neighbour queries of the graph pipeline (speed work): every shortcut gives
exactly the arrays of the query it replaces."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from biomorph.core.graph import BranchGraph
from biomorph.tree import foliage
from biomorph.tree.neighbours import (
    NeighbourCache,
    ball_lists,
    estimate_spacing,
    spatial_order,
)


def _grid_cloud(n=4000, seed=5):
    """Points on a 1 mm grid (as LAS stores them): many equal distances, and duplicates."""
    rng = np.random.default_rng(seed)
    xyz = np.round(rng.normal(size=(n, 3)) * [0.05, 0.05, 0.5], 3)
    xyz[7] = xyz[8]
    return xyz


def _leafy_cloud(seed=0):
    """A thin stem (a surface) with a ball of scattered 'leaves' around its top."""
    rng = np.random.default_rng(seed)
    t = rng.random(6000) * 2 * np.pi
    z = rng.random(6000) * 3.0
    stem = np.c_[0.1 * np.cos(t), 0.1 * np.sin(t), z] + rng.normal(scale=0.002, size=(6000, 3))
    leaves = rng.normal(scale=0.4, size=(600, 3)) + [0.0, 0.0, 3.0]
    return np.concatenate([stem, leaves])


CLOUDS = [_grid_cloud, lambda: np.random.default_rng(1).random((3000, 3)), _leafy_cloud]


def _morton_numpy(xyz):
    """The Morton order as first written with numpy (the reference of the numba kernel)."""
    lo = xyz.min(axis=0)
    span = max(float(np.max(xyz.max(axis=0) - lo)), 1e-300)
    q = np.clip((xyz - lo) * ((2**21 - 1) / span), 0, 2**21 - 1).astype(np.uint64)
    code = np.zeros(xyz.shape[0], dtype=np.uint64)
    for axis in range(3):
        v = q[:, axis]
        v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
        v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
        v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
        v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
        v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
        code |= v << np.uint64(axis)
    return np.argsort(code, kind="stable")


@pytest.mark.parametrize("make", CLOUDS)
def test_spatial_order_equals_the_numpy_morton_order(make):
    xyz = make()
    assert np.array_equal(spatial_order(xyz), _morton_numpy(xyz))
    far = xyz * 1e3 + [6.5e5, 5.1e6, 300.0]  # georeferenced-sized
    assert np.array_equal(spatial_order(far), _morton_numpy(far))
    assert np.array_equal(spatial_order(xyz[:1]), [0])


def test_ball_lists_equal_the_lists():
    xyz = _grid_cloud()
    tree = cKDTree(xyz)
    centres = xyz[::37] + 0.001
    lists = tree.query_ball_point(centres, 0.03, return_sorted=False)
    counts, idx = ball_lists(tree, centres, 0.03)
    assert np.array_equal(counts, [len(x) for x in lists])
    assert np.array_equal(idx, np.concatenate([np.asarray(x, dtype=np.int64) for x in lists]))
    counts, idx = ball_lists(tree, centres + 100.0, 0.03)  # nothing found
    assert not counts.any() and idx.size == 0


@pytest.mark.parametrize("make", CLOUDS)
def test_neighbour_cache_blocks_equal_fresh_query(make):
    xyz = make()
    cache = NeighbourCache.from_query(cKDTree(xyz), 17)
    keep = np.random.default_rng(2).random(xyz.shape[0]) > 0.1
    sub, c = xyz[keep], cache.select(keep)
    tree = cKDTree(sub)
    d0, i0 = tree.query(sub, k=12)
    for start, stop in ((0, None), (0, 500), (500, 1234), (sub.shape[0] - 3, None)):
        d, i = c.query(12, tree, sub, start, stop)
        assert np.array_equal(d, d0[start:stop]) and np.array_equal(i, i0[start:stop])


def test_estimate_spacing_is_the_median_nearest_neighbour():
    xyz = _grid_cloud(3000)
    first = estimate_spacing(xyz, sample=500)
    assert estimate_spacing(xyz, sample=500, kdtree=cKDTree(xyz)) == first
    idx = np.random.default_rng(0).choice(xyz.shape[0], size=500, replace=False)
    d, _ = cKDTree(xyz).query(xyz[idx], k=2)
    assert first == float(np.median(d[:, 1][d[:, 1] > 0]))
    assert estimate_spacing(xyz * 2.0, sample=500) == pytest.approx(2 * first)


@pytest.mark.parametrize("make", CLOUDS)
def test_foliage_from_the_neighbour_cache_equals_the_query(make):
    xyz = make()
    cache = NeighbourCache.from_query(cKDTree(xyz), 17)
    th0 = foliage.neighbourhood_thickness(xyz, 12)
    assert np.array_equal(foliage.neighbourhood_thickness(xyz, 12, neighbours=cache), th0)
    assert np.array_equal(foliage.neighbourhood_thickness(xyz, 12, kdtree=cKDTree(xyz)), th0)
    for detect in (False, True):
        a = foliage.separate_foliage(xyz, detect=detect)
        b = foliage.separate_foliage(xyz, detect=detect, neighbours=cache)
        assert np.array_equal(a.wood, b.wood) and np.array_equal(a.thickness, b.thickness)
        assert a.threshold == b.threshold and a.foliage_share == b.foliage_share
        assert b.kdtree is not None and b.kdtree.data is not None
        assert np.array_equal(b.kdtree.data, xyz)


def test_separate_foliage_two_passes_with_cache_removes_the_leaves():
    xyz = _leafy_cloud()
    cache = NeighbourCache.from_query(cKDTree(xyz), 17)
    split = foliage.separate_foliage(xyz, passes=2, neighbours=cache)
    assert len(split.threshold) == 2  # the second pass ran on the remaining points
    assert (~split.wood[6000:]).mean() > 0.5 and split.wood[:6000].mean() > 0.9


def test_surface_refinement_reuses_the_samples():
    from biomorph.tree.metrics import segment_candidates, surface_distance

    rng = np.random.default_rng(0)
    pos = np.c_[np.zeros(30), np.zeros(30), np.linspace(0, 3, 30)]
    side = np.c_[np.linspace(0.1, 1.0, 10), np.zeros(10), np.full(10, 1.5)]
    parent = np.r_[-1, np.arange(29), 15, np.arange(30, 39)]
    graph = BranchGraph(np.r_[pos, side], parent, radius=np.full(40, 0.05))
    xyz = rng.normal(scale=0.3, size=(2000, 3)) + [0.0, 0.0, 1.5]
    c = segment_candidates(graph, xyz)
    assert c.samples is not None
    far = np.arange(0, 2000, 3)
    wide = segment_candidates(graph, xyz[far], 32, _samples=c.samples)
    fresh = segment_candidates(graph, xyz[far], 32)
    for name in ("node", "par", "t", "d"):
        assert np.array_equal(getattr(wide, name), getattr(fresh, name))
    sd, rd, near = surface_distance(graph, xyz, refine=0.01)
    sd0, rd0, near0 = surface_distance(graph, xyz, candidates=c, refine=0.01)
    assert np.array_equal(sd, sd0) and np.array_equal(rd, rd0) and np.array_equal(near, near0)


def test_segment_candidates_do_not_depend_on_radii():
    from biomorph.tree import metrics

    pos = np.c_[np.zeros(20), np.zeros(20), np.linspace(0, 2, 20)]
    graph = BranchGraph(pos, np.r_[-1, np.arange(19)], radius=np.full(20, 0.05))
    xyz = np.random.default_rng(1).normal(scale=0.2, size=(500, 3)) + [0.0, 0.0, 1.0]
    a = metrics.segment_candidates(graph, xyz)
    b = metrics.segment_candidates(graph.with_(radius=np.full(20, 0.08)), xyz)
    for name in ("node", "par", "t", "d"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    moved = metrics.segment_candidates(graph, xyz + 0.01)
    assert not np.array_equal(moved.d, a.d)
    bent = BranchGraph(pos + [0.01, 0.0, 0.0], graph.parent)
    assert not np.array_equal(metrics.segment_candidates(bent, xyz).d, a.d)


def test_the_metrics_reuse_the_twig_phase_candidates(monkeypatch):
    from biomorph.tree import metrics
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    cloud = simulate_scan(generate_tree("aspen", seed=0), n_points=8000, seed=0)
    searches = []
    real = metrics.segment_candidates

    def counting(graph, xyz, k=8, **kw):
        if "_samples" not in kw:  # a fresh search (not a refinement on known samples)
            searches.append((graph.position.copy(), xyz.shape[0]))
        return real(graph, xyz, k, **kw)

    monkeypatch.setattr(metrics, "segment_candidates", counting)
    skel = skeletonize(cloud, method="graph")
    assert skel.info["twig_offset"]
    # of the finished skeleton, one search of the whole cloud: the twig phase's, which the
    # metrics reuse (the residual stage searched the skeleton before it grew)
    final = [n for pos, n in searches if np.array_equal(pos, skel.graph.position)]
    assert final == [skel.cloud.n_points]
    monkeypatch.setattr(metrics, "segment_candidates", real)
    fresh = metrics.qsm_report(skel.graph, skel.cloud)["fit"]
    assert fresh == skel.metrics["fit"]


def test_collapse_round_equals_the_python_loop():
    from biomorph.tree.cleanup import _merge_round

    rng = np.random.default_rng(7)
    n = 400
    par = np.r_[-1, rng.integers(0, np.arange(1, n))]
    m = 300
    keep, drop = rng.integers(0, n, m), rng.integers(1, n, m)
    dist = rng.random(m)
    pos0, rad0, c = rng.normal(size=(n, 3)), rng.random(n), rng.random(n) + 1e-9
    pos, rad = pos0.copy(), rad0.copy()
    used = np.zeros(n, dtype=bool)
    removed0 = np.zeros(n, dtype=bool)
    redirect0 = np.arange(n)
    for i in np.argsort(dist, kind="stable"):
        a, b = keep[i], drop[i]
        ids = (a, b, par[a], par[b])
        if any(x >= 0 and used[x] for x in ids):
            continue
        for x in ids:
            if x >= 0:
                used[x] = True
        ca, cb = c[a], c[b]
        pos[a] = (ca * pos[a] + cb * pos[b]) / (ca + cb)
        rad[a] = (ca * rad[a] + cb * rad[b]) / (ca + cb)
        removed0[b] = True
        redirect0[b] = a
    pos1, rad1 = pos0.copy(), rad0.copy()
    removed1 = np.zeros(n, dtype=bool)
    redirect1 = np.arange(n)
    order = np.argsort(dist, kind="stable")
    _merge_round(keep, drop, order, par, pos1, rad1, c, removed1, redirect1)
    assert removed0.any()
    assert np.array_equal(pos1, pos) and np.array_equal(rad1, rad)
    assert np.array_equal(removed1, removed0) and np.array_equal(redirect1, redirect0)


def test_nearest_surface_equals_the_array_expressions():
    from biomorph.tree.metrics import _nearest_surface

    rng = np.random.default_rng(11)
    n, k, nodes = 3000, 8, 50
    node = rng.integers(0, nodes, (n, k))
    par = np.where(rng.random((n, k)) < 0.1, -1, rng.integers(0, nodes, (n, k)))
    t = np.round(rng.random((n, k)), 1)  # many equal parameters, 0.5 among them
    d = np.round(rng.random((n, k)) * 0.1, 2)  # and equal distances: ties in |s|
    r = np.round(rng.random(nodes) * 0.05, 2)
    r[3] = np.nan  # a NaN radius: argmin takes the first NaN
    rp = np.where(par >= 0, r[np.maximum(par, 0)], r[node])
    rad = rp + (r[node] - rp) * t
    s = d - rad
    best = np.argmin(np.abs(s), axis=1)
    rows = np.arange(n)
    bp, bt, bn = par[rows, best], t[rows, best], node[rows, best]
    near0 = np.where((bp >= 0) & (bt < 0.5), bp, bn)
    sd, rd, near = _nearest_surface(node, par, t, d, r)
    assert np.array_equal(sd, s[rows, best], equal_nan=True)
    assert np.array_equal(rd, rad[rows, best], equal_nan=True)
    assert np.array_equal(near, near0)


def _ball(n=5000, seed=4):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1)[:, None] * rng.random((n, 1)) ** (1 / 3)


def test_require_wood_gives_the_verdict_of_the_full_check():
    from biomorph.errors import InputError

    stem = _leafy_cloud()[:6000]
    assert foliage.check_not_only_leaves(stem) < foliage.SCATTER_LEAVES
    foliage.require_wood(stem)  # wood: no error (stops early)
    with pytest.raises(InputError) as full:
        foliage.check_not_only_leaves(_ball(), "crown.xyz")
    with pytest.raises(InputError) as fast:
        foliage.require_wood(_ball(), "crown.xyz")
    assert str(fast.value) == str(full.value)  # the same median in the message
    # rows of 12-fold duplicates have no ratio: the early stop is never reached, the
    # median of the others decides (as in the full check)
    dup = np.repeat(_ball(200) * 5.0 + 10.0, 13, axis=0)
    mixed = np.concatenate([stem[:1500], dup])
    assert foliage.check_not_only_leaves(mixed) < foliage.SCATTER_LEAVES
    foliage.require_wood(mixed)
    foliage.require_wood(stem[:5])  # too few points: nothing to judge
