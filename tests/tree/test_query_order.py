"""The speed helpers of step ii (issue 13): ordered k-d tree queries and union-find
components give exactly the arrays of the plain scipy calls they replace."""

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from biomorph.tree.neighbours import (
    components,
    neighbour_graph,
    query_blocks,
    query_ordered,
    shortest_path_forest,
    spatial_order,
)


@pytest.fixture
def cloud():
    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(6000, 3)) * [1.0, 1.0, 4.0] + 6.5e5  # georeferenced-sized
    xyz[100] = xyz[101]  # a duplicate point
    return xyz


def test_spatial_order_is_a_permutation(cloud):
    p = spatial_order(cloud)
    assert np.array_equal(np.sort(p), np.arange(cloud.shape[0]))
    assert spatial_order(np.zeros((0, 3))).size == 0
    assert np.array_equal(spatial_order(np.ones((3, 3))), [0, 1, 2])  # no extent


@pytest.mark.parametrize("k", [1, 2, 9])
def test_query_ordered_equals_direct_query(cloud, k):
    tree = cKDTree(cloud)
    d0, i0 = tree.query(cloud, k=k)
    for pts in (None, cloud):
        d, i = query_ordered(tree, pts, k, block=1000)
        assert np.array_equal(d, d0) and np.array_equal(i, i0)
    other = cloud[::7] + 0.01
    d0, i0 = tree.query(other, k=k, distance_upper_bound=0.5)
    d, i = query_ordered(tree, other, k, distance_upper_bound=0.5, index_dtype=np.int32)
    assert i.dtype == np.int32
    assert np.array_equal(d, d0) and np.array_equal(i, i0)


def test_query_blocks_cover_every_row_once(cloud):
    tree = cKDTree(cloud)
    seen = np.concatenate([rows for rows, _, _ in query_blocks(tree, None, 3, block=777)])
    assert np.array_equal(np.sort(seen), np.arange(cloud.shape[0]))


def test_components_equal_scipy():
    rng = np.random.default_rng(0)
    n = 3000
    r, c = rng.integers(0, n, 2000), rng.integers(0, n, 2000)
    r2, c2 = rng.integers(0, n, 500), rng.integers(0, n, 500)
    a = sparse.csr_matrix((np.ones(r.size), (r, c)), shape=(n, n))
    b = sparse.csr_matrix((np.ones(r2.size), (r2, c2)), shape=(n, n))
    k0, lab0 = connected_components(a + b, directed=False)
    for got in (components(n, ((r2, c2),), graph=a), components(n, ((r, c), (r2, c2)))):
        assert got[0] == k0 and np.array_equal(got[1], lab0)
    assert components(4)[0] == 4


def test_shortest_path_forest_matches_coo_build(cloud):
    from scipy.sparse.csgraph import dijkstra

    xyz = cloud - cloud.min(axis=0)
    g = neighbour_graph(xyz, k=8)
    src = np.array([5, 3, 3])
    dist, parent = shortest_path_forest(g, src)
    n = xyz.shape[0]
    gc = g.tocoo()
    rows = np.concatenate([gc.row, np.full(src.size, n)])
    cols = np.concatenate([gc.col, src])
    vals = np.concatenate([gc.data, np.full(src.size, 1e-30)])
    aug = sparse.csr_matrix((vals, (rows, cols)), shape=(n + 1, n + 1))
    d0, p0 = dijkstra(aug, directed=False, indices=n, return_predecessors=True)
    p0 = p0[:n].astype(np.int64)
    p0[(p0 == n) | (p0 < 0)] = -1
    assert np.array_equal(dist, d0[:n]) and np.array_equal(parent, p0)


def _grid_cloud(n=4000, seed=5):
    """Points on a 1 mm grid (as LAS stores them): many equal distances, and duplicates."""
    rng = np.random.default_rng(seed)
    xyz = np.round(rng.normal(size=(n, 3)) * [0.05, 0.05, 0.5], 3)
    xyz[7] = xyz[8]
    return xyz


@pytest.mark.parametrize("make", [_grid_cloud, lambda: np.random.default_rng(1).random((3000, 3))])
def test_neighbour_cache_equals_fresh_query_after_removals(make):
    from biomorph.tree.neighbours import NeighbourCache

    xyz = make()
    cache = NeighbourCache.from_query(cKDTree(xyz), 17)
    rng = np.random.default_rng(2)
    keep = rng.random(xyz.shape[0]) > 0.1
    sub, c1 = xyz[keep], cache.select(keep)
    keep2 = np.flatnonzero(rng.random(sub.shape[0]) > 0.05)
    sub, c2 = sub[keep2], c1.select(keep2)
    tree = cKDTree(sub)
    for k in (1, 5, 11, 17, 20):
        d, i = c2.query(k, tree, sub)
        d0, i0 = tree.query(sub, k=k)
        assert np.array_equal(d, d0.reshape(d.shape)) and np.array_equal(i, i0.reshape(i.shape))


def test_prepare_keeps_the_outlier_query_for_the_graph():
    from biomorph.core.pointcloud import PointCloud
    from biomorph.tree.cloud import prepare, remove_outliers
    from biomorph.tree.pipeline import remove_sparse

    xyz = _grid_cloud(5000) + [4.0e5, 6.0e6, 120.0]
    xyz[:40] += np.random.default_rng(0).normal(size=(40, 3))  # strays for the filter
    cloud = PointCloud(xyz)
    plain = prepare(cloud, ground=None)
    prep = prepare(cloud, ground=None, neighbours=True)
    assert plain.neighbours is None and prep.neighbours is not None
    assert np.array_equal(plain.cloud.xyz, prep.cloud.xyz)
    pts = prep.cloud.xyz
    g0 = neighbour_graph(pts, k=10)
    g1 = neighbour_graph(pts, k=10, cache=prep.neighbours, tree=cKDTree(pts))
    assert (g0 != g1).nnz == 0 and np.array_equal(g0.indices, g1.indices)
    out, keep, cache = remove_outliers(PointCloud(xyz), return_neighbours=True)
    assert cache.n == out.n_points == keep.sum()
    dense, mask = remove_sparse(out, 4.0, return_mask=True)
    assert dense.n_points == mask.sum() and np.array_equal(dense.xyz, remove_sparse(out, 4.0).xyz)


def test_bridges_inserted_in_canonical_csr(cloud):
    from biomorph.tree.neighbours import _with_entries

    g = neighbour_graph(cloud - cloud.min(axis=0), k=6)
    n = g.shape[0]
    rng = np.random.default_rng(4)
    r = rng.integers(0, n, 50)
    c = (r + 1 + rng.integers(0, n - 1, 50)) % n
    w = rng.random(50)
    for rr, cc in ((r, c), (np.r_[r, r[:1]], np.r_[c, c[:1]])):  # the second repeats one entry
        ww = np.r_[w, w[: rr.size - w.size]]
        coo = g.tocoo()
        ref = sparse.csr_matrix(
            (np.r_[coo.data, ww], (np.r_[coo.row, rr], np.r_[coo.col, cc])), shape=g.shape
        )
        ref.sum_duplicates()
        out = _with_entries(g, rr, cc, ww)
        for a in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(out, a), getattr(ref, a))


def test_segment_kernel_equals_the_array_expressions():
    """The candidate-edge kernel of the metrics gives the very values of the numpy
    expressions it replaced (einsum / norm grouping of the three components)."""
    from biomorph.tree.metrics import _segment_kernel

    rng = np.random.default_rng(0)
    pos = rng.normal(size=(500, 3)) * 5
    parent = rng.integers(-1, 500, 500)
    xyz = rng.normal(size=(3000, 3)) * 5
    node = rng.integers(0, 500, (3000, 8))
    par = parent[node]
    b = pos[node]
    a = np.where((par >= 0)[..., None], pos[np.maximum(par, 0)], b)
    ab = b - a
    denom = np.einsum("...i,...i->...", ab, ab)
    ap = xyz[:, None, :] - a
    t0 = np.where(
        denom > 0, np.einsum("...i,...i->...", ap, ab) / np.where(denom > 0, denom, 1), 0.0
    ).clip(0, 1)
    d0 = np.linalg.norm(ap - ab * t0[..., None], axis=-1)
    t, d = _segment_kernel(xyz, node, par, pos)
    assert np.array_equal(t, t0) and np.array_equal(d, d0)
