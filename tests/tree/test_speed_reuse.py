"""The cloud's k-d tree handed on through the pipeline (speed work): the radius stage's
cross-sections searched through a grid instead of ball queries, queries in the tree's
leaf order; every shortcut gives exactly the arrays of the code it replaces."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from biomorph.core.graph import BranchGraph
from biomorph.tree import metrics, neighbours, radius
from biomorph.tree.allometry import skeleton_distance
from biomorph.tree.metrics import segment_candidates
from biomorph.tree.neighbours import PointIndex, ball_lists, grid_query, query_ordered


def _stem_cloud(seed=0, n=6000):
    """A leaning stem (a noisy surface, points on a 1 mm grid as LAS stores them) with a
    few duplicates and a cloud of clutter around it."""
    rng = np.random.default_rng(seed)
    t = rng.random(n) * 2 * np.pi
    z = rng.random(n) * 2.0
    r = 0.08 - 0.02 * z
    stem = np.c_[r * np.cos(t) + 0.1 * z, r * np.sin(t), z]
    stem = np.round(stem + rng.normal(scale=0.002, size=stem.shape), 3)
    clutter = rng.normal(scale=0.3, size=(n // 10, 3)) + [0.1, 0.0, 1.0]
    xyz = np.concatenate([stem, clutter])
    xyz[5] = xyz[6]
    return xyz


def _reference_sections(pos, axes, xyz, rs, depth):
    """The cross-sections as first written: the bounding balls' points
    (``query_ball_point``, unsorted) that lie in each flat cylinder, projected."""
    t0, t1 = radius._tangents(axes)
    counts, idx = ball_lists(cKDTree(xyz), pos, np.sqrt(rs**2 + depth**2))
    node = np.repeat(np.arange(pos.shape[0]), counts)
    d = xyz[idx] - pos[node]
    hn = d[:, 0] * axes[node, 0] + d[:, 1] * axes[node, 1] + d[:, 2] * axes[node, 2]
    uu = d[:, 0] * t0[node, 0] + d[:, 1] * t0[node, 1] + d[:, 2] * t0[node, 2]
    ww = d[:, 0] * t1[node, 0] + d[:, 1] * t1[node, 1] + d[:, 2] * t1[node, 2]
    keep = (np.abs(hn) <= depth) & (uu * uu + ww * ww <= rs[node] ** 2)
    indptr = np.zeros(pos.shape[0] + 1, dtype=np.int64)
    np.cumsum(np.bincount(node[keep], minlength=pos.shape[0]), out=indptr[1:])
    return t0, t1, indptr, uu[keep], ww[keep]


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("plain", [False, True])
def test_cross_sections_equal_the_ball_query_sections(seed, plain):
    xyz = _stem_cloud(seed)
    rng = np.random.default_rng(seed + 10)
    m = 300
    pos = xyz[rng.choice(xyz.shape[0], m)] + rng.normal(scale=0.01, size=(m, 3))
    pos[:20] = [50.0, 50.0, 50.0]  # outside the cloud: nothing found
    axes = rng.normal(size=(m, 3))
    axes[20:60] = [0.0, 0.0, 1.0]  # upright: the tangents' special case
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    rs = rng.uniform(1e-4, 0.3, m)
    kd = cKDTree(xyz) if plain else PointIndex(xyz)
    for depth in (0.005, 0.02, 0.5):
        got = radius._cross_sections(pos, axes, xyz, kd, rs, depth)
        ref = _reference_sections(pos, axes, xyz, rs, depth)
        assert got[2][-1] > 0
        for a, b in zip(got, ref, strict=True):
            assert np.array_equal(a, b)


def test_point_index_is_the_cloud_kdtree():
    xyz = _stem_cloud(2)
    kd, pi = cKDTree(xyz), PointIndex(xyz)
    assert np.array_equal(kd.indices, pi.indices)
    q = xyz[::7] + 0.001
    for a, b in zip(kd.query(q, k=5), pi.query(q, k=5), strict=True):
        assert np.array_equal(a, b)
    lo, cell, dims, start, rank, pts = pi.grid()
    assert start[-1] == xyz.shape[0] and start.size - 1 <= 2 * xyz.shape[0] + 8
    assert np.array_equal(np.sort(rank), np.arange(xyz.shape[0]))
    assert np.array_equal(pts, xyz[pi.indices[rank]])
    assert pi.grid() is pi.grid()  # built once


def _chain_graph(xyz, n=40):
    z = np.linspace(0.0, 2.0, n)
    pos = np.c_[0.1 * z, np.zeros(n), z]
    parent = np.arange(-1, n - 1)
    side = np.c_[0.1 + 0.3 * np.linspace(0, 1, 8), np.zeros(8), 1.0 + 0.3 * np.linspace(0, 1, 8)]
    pos = np.concatenate([pos, side])
    parent = np.concatenate([parent, [n // 2] + list(range(n, n + 7))])
    return BranchGraph(pos, parent)


def _skeleton_distance_reference(points, parent, position):
    """``allometry.skeleton_distance`` as first written (one k-d tree query)."""
    from biomorph.tree.allometry import edge_length

    ch = np.flatnonzero(parent >= 0)
    el = edge_length(parent, position)[ch]
    step = max(float(np.median(el)) / 4, 1e-6)
    m = np.maximum(np.ceil(el / step).astype(np.int64), 1)
    eid = np.repeat(np.arange(ch.size), m + 1)
    start = np.repeat(np.cumsum(m + 1) - (m + 1), m + 1)
    t = (np.arange(eid.size) - start) / m[eid]
    a = position[parent[ch]][eid]
    samples = a + t[:, None] * (position[ch][eid] - a)
    node = np.where(t < 0.5, parent[ch][eid], ch[eid])
    d, j = cKDTree(samples).query(points)
    return d, node[j]


def test_queries_in_leaf_order_equal_the_direct_queries(monkeypatch):
    xyz = _stem_cloud(3)
    g = _chain_graph(xyz)
    order = PointIndex(xyz).indices
    ref = _skeleton_distance_reference(xyz, g.parent, g.position)
    for o in (None, order):
        got = skeleton_distance(xyz, g.parent, g.position, order=o)
        for a, b in zip(got, ref, strict=True):
            assert np.array_equal(a, b)
    a = segment_candidates(g, xyz)
    b = segment_candidates(g, xyz, order=order)
    monkeypatch.setattr(metrics, "GRID_K", 0)  # the k-d tree's query
    c = segment_candidates(g, xyz)
    for f in ("node", "par", "t", "d"):
        assert np.array_equal(getattr(a, f), getattr(c, f))
        assert np.array_equal(getattr(b, f), getattr(c, f))
    d, i = query_ordered(cKDTree(g.position), xyz, 3, order=order)
    d0, i0 = cKDTree(g.position).query(xyz, 3)
    assert np.array_equal(d, d0) and np.array_equal(i, i0)


def test_fit_radii_with_the_handed_kdtree_equals_its_own():
    xyz = _stem_cloud(4)
    g = _chain_graph(xyz)
    a_g, a_fit = radius.fit_radii(g, xyz, taper=True)
    b_g, b_fit = radius.fit_radii(g, xyz, taper=True, kdtree=PointIndex(xyz))
    assert np.array_equal(a_g.position, b_g.position)
    assert np.array_equal(a_g.radius, b_g.radius)
    assert np.array_equal(a_fit.radius, b_fit.radius)


def test_the_pipeline_builds_the_cloud_kdtree_once(monkeypatch):
    from biomorph.tree import skeletonize
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    built = []

    class Counted(PointIndex):
        def __init__(self, *args, **kwargs):
            built.append(1)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(neighbours, "PointIndex", Counted)
    monkeypatch.setattr(radius, "PointIndex", Counted)
    cl = simulate_scan(generate_tree("conifer", seed=0), n_points=8000, seed=0, noise=0.004)
    skel = skeletonize(cl, method="graph")
    assert skel.graph.n_nodes > 0 and skel.graph.radius is not None
    assert len(built) == 1


def _reference_fit_kernel():
    """The circle kernel before trials that cannot win were skipped (its RANSAC loop as
    first written), compiled here."""
    import numba

    circle3, lsq = radius._circle3, radius._lsq_circle

    @numba.njit
    def kernel(u, w, indptr, rmax, rmin, tr, ta, tm, trials, min_inliers, seed, ocx, ocy, orr):  # noqa: PLR0913
        np.random.seed(seed)  # noqa: NPY002
        for v in range(indptr.size - 1):
            a, b = indptr[v], indptr[v + 1]
            k = b - a
            orr[v] = -1.0
            if k < 3:
                continue
            x, y = u[a:b], w[a:b]
            best_n, best_res, bcx, bcy, br = 0, 1e300, 0.0, 0.0, -1.0
            for _ in range(trials):
                i1 = np.random.randint(k)  # noqa: NPY002
                i2 = np.random.randint(k)  # noqa: NPY002
                i3 = np.random.randint(k)  # noqa: NPY002
                if i1 == i2 or i2 == i3 or i1 == i3:
                    continue
                cx, cy, r = circle3(x[i1], y[i1], x[i2], y[i2], x[i3], y[i3])
                if r <= rmin[v] or r > rmax[v]:
                    continue
                tol = min(max(tr * r, ta), tm)
                cnt, res = 0, 0.0
                for i in range(k):
                    d = abs(np.sqrt((x[i] - cx) ** 2 + (y[i] - cy) ** 2) - r)
                    if d < tol:
                        cnt += 1
                        res += d
                if cnt > best_n or (cnt == best_n and res < best_res):
                    best_n, best_res, bcx, bcy, br = cnt, res, cx, cy, r
            if br <= 0 or best_n < min_inliers:
                continue
            tol = min(max(tr * br, ta), tm)
            sel = np.abs(np.sqrt((x - bcx) ** 2 + (y - bcy) ** 2) - br) < tol
            ocx[v], ocy[v], orr[v] = lsq(x[sel], y[sel], bcx, bcy, br, rmax[v])

    return kernel


def test_fit_kernel_skips_only_trials_that_cannot_win():
    rng = np.random.default_rng(7)
    counts = rng.integers(0, 40, 400)
    indptr = np.concatenate([[0], np.cumsum(counts)])
    t = rng.random(indptr[-1]) * 2 * np.pi
    rad = np.repeat(rng.uniform(0.005, 0.05, counts.size), counts)
    noise = rng.normal(scale=0.002, size=(2, t.size))
    out = rng.random(t.size) < 0.3  # clutter
    u = np.where(out, rng.normal(scale=0.05, size=t.size), rad * np.cos(t) + noise[0])
    w = np.where(out, rng.normal(scale=0.05, size=t.size), rad * np.sin(t) + noise[1])
    rmax, rmin = np.full(counts.size, 0.08), np.full(counts.size, 1e-4)
    ref = [np.zeros(counts.size) for _ in range(3)]
    _reference_fit_kernel()(u, w, indptr, rmax, rmin, 0.15, 0.003, 0.01, 64, 8, 3, *ref)
    got = [np.zeros(counts.size) for _ in range(3)] + [
        np.zeros(counts.size, np.int64),
        np.zeros(counts.size),
        np.zeros(counts.size),
        np.zeros(counts.size, np.int64),
    ]
    radius._fit_kernel(u, w, indptr, rmax, rmin, 0.15, 0.003, 0.01, 64, 8, 3, *got, 0.5)
    assert (got[2] > 0).sum() > 100
    for a, b in zip(got[:3], ref, strict=True):
        assert np.array_equal(a, b)


def _tie_cloud(seed=0):
    """Points on a 1 cm grid (many equal distances to other grid points), a duplicate
    data point and a few far away."""
    rng = np.random.default_rng(seed)
    return np.round(rng.normal(size=(3000, 3)) * [0.1, 0.1, 0.4], 2)


@pytest.mark.parametrize("k", [1, 2, 8, 32])
def test_grid_query_equals_the_kdtree_query(k):
    rng = np.random.default_rng(k)
    t = np.linspace(0, 1, 2000)
    line = np.c_[0.1 * np.sin(6 * t), 0.1 * np.cos(5 * t), 2 * t]  # a skeleton-like curve
    line[10] = line[11]  # a duplicate sample
    grid = _tie_cloud(k)
    far = rng.normal(scale=5.0, size=(50, 3))
    for data, pts in (
        (line, np.concatenate([line + rng.normal(scale=0.05, size=line.shape), far, line[:50]])),
        (grid, np.concatenate([_tie_cloud(k + 10), far, grid[:100]])),
        (np.c_[rng.random((500, 2)), np.zeros(500)], rng.random((800, 3)) - 0.5),  # flat
        (line[: k + 1], line[::7]),  # too few data points: the tree alone
    ):
        ref = cKDTree(data).query(pts, k)
        for order in (None, PointIndex(pts).indices):
            got = grid_query(data, pts, k, order=order)
            for a, b in zip(got, ref, strict=True):
                assert a.shape == b.shape and a.dtype == b.dtype
                assert np.array_equal(a, b)


def test_grid_query_with_many_duplicates_and_degenerate_data():
    rng = np.random.default_rng(11)
    data = np.concatenate([np.repeat([[0.1, 0.2, 0.3]], 20, axis=0), rng.random((300, 3))])
    pts = np.concatenate([data[:3], rng.random((200, 3)), [[0.1, 0.2, 0.3 + 1e-15]]])
    same = np.repeat([[1.0, 2.0, 3.0]], 30, axis=0)  # no extent at all
    for d in (data, same):
        for k in (1, 8):
            ref = cKDTree(d).query(pts, k)
            for a, b in zip(grid_query(d, pts, k), ref, strict=True):
                assert np.array_equal(a, b)
