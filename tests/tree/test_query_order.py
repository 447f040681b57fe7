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
