"""Step ii of the graph method (Livny et al. 2010): the neighbour graph and its contraction.

* :func:`neighbour_graph` -- symmetric kNN (or radius) graph from ``cKDTree`` with squared
  distance weights;
* :func:`bridge_components` -- disconnected pieces (gappy scans) joined by their shortest
  inter-component edges (Borůvka rounds: a minimum spanning forest over components);
* :func:`shortest_path_forest` -- Dijkstra from a virtual root joined to every root point;
* :func:`contract` -- geodesic level-set pieces of width ``node_spacing`` become the
  vertices of the contracted graph Q (see :mod:`biomorph.tree.livny`).

Split out of :mod:`biomorph.tree.livny` (issue 12).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import chain

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.errors import InputError, ParameterError

__all__ = [
    "estimate_spacing",
    "morton_codes",
    "smooth_median",
    "components",
    "NeighbourCache",
    "PointIndex",
    "grid_query",
    "grid_nearest_label",
    "query_workers",
    "spatial_order",
    "query_ordered",
    "query_blocks",
    "neighbour_graph",
    "bridge_components",
    "shortest_path_forest",
    "segment_trees",
    "segmentation_forest",
    "BridgeRule",
    "bridge_supported",
    "GAP_SHORT",
    "GAP_ANGLE",
    "GAP_COVER",
    "GAP_EXTENT",
    "Contraction",
    "contract",
    "NODE_SPACING",
    "NODE_SPACING_MIN",
    "default_node_spacing",
    "LEVEL_CELL",
    "LEVEL_MERGE",
    "FINE_CELL",
]


@numba.njit(cache=True)
def _morton_codes(xyz):  # pragma: no cover - numba
    """The 63-bit Morton code of every point: its cell of a grid of 2²¹ cells per axis
    over the bounding cube (``(xyz - lo) * (2²¹ - 1) / span``, clipped and truncated as
    numpy's ``astype(uint64)`` does), the bits of x, y and z interleaved. Two passes
    over the points, no ``[n, 3]`` temporaries (numpy's ``min(axis=0)`` of an ``[n, 3]``
    array alone took longer)."""
    n = xyz.shape[0]
    lo = np.empty(3)
    hi = np.empty(3)
    for axis in range(3):
        lo[axis] = xyz[0, axis]
        hi[axis] = xyz[0, axis]
    for i in range(1, n):
        for axis in range(3):
            v = xyz[i, axis]
            if v < lo[axis]:
                lo[axis] = v
            elif v > hi[axis]:
                hi[axis] = v
    span = max(max(hi[0] - lo[0], hi[1] - lo[1]), hi[2] - lo[2])
    scale = (2.0**21 - 1.0) / max(span, 1e-300)
    top = 2.0**21 - 1.0
    code = np.empty(n, dtype=np.uint64)
    for i in range(n):
        c = np.uint64(0)
        for axis in range(3):
            f = min(max((xyz[i, axis] - lo[axis]) * scale, 0.0), top)
            v = np.uint64(f)
            v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
            v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
            v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
            v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
            v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
            c |= v << np.uint64(axis)
        code[i] = c
    return code


def morton_codes(xyz: NDArray[np.float64]) -> NDArray[np.uint64]:
    """Every point's 63-bit Morton (Z-order) code on a grid of 2²¹ cells per axis over the
    bounding cube (:func:`_morton_codes`)."""
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    if xyz.shape[0] == 0:
        return np.zeros(0, dtype=np.uint64)
    return _morton_codes(xyz)


def spatial_order(xyz: NDArray[np.float64]) -> NDArray[np.int64]:
    """A permutation visiting the points along a Morton (Z-order) curve of 2²¹ cells per
    axis: neighbouring positions in it are neighbouring points in space."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=np.int64)
    return np.argsort(morton_codes(xyz), kind="stable")


#: query points per block of :func:`query_ordered` (bounds its temporaries)
QUERY_BLOCK = 1 << 18


def query_ordered(
    tree: cKDTree,
    points: NDArray[np.float64] | None = None,
    k: int = 1,
    *,
    workers: int = -1,
    index_dtype: type = np.intp,
    block: int = QUERY_BLOCK,
    order: NDArray | None = None,
    **kwargs,
) -> tuple[NDArray[np.float64], NDArray]:
    """``tree.query(points, k, workers=workers, **kwargs)``, the same arrays, faster.

    The queries run in spatial order (the tree's own leaf order for ``points=None``, the
    tree's data; :func:`spatial_order` otherwise) in blocks of ``block`` points and are
    scattered back: consecutive queries then walk the same nodes, which halves the CPU
    time of a 10⁶-point query whose points come in scan order (each query is independent,
    so every row equals the one of a direct query). ``index_dtype`` may shrink the index
    array (``np.int32``). ``order``: a spatial order of ``points`` known already (the leaf
    order of their own k-d tree, ``indices``), instead of :func:`spatial_order`."""
    pts, perm = _query_order(tree, points, order)
    n = pts.shape[0]
    shape = (n,) if k == 1 else (n, k)
    dist = np.empty(shape, dtype=np.float64)
    idx = np.empty(shape, dtype=index_dtype)
    for p, d, i in query_blocks(
        tree, points, k, workers=workers, block=block, order=perm, **kwargs
    ):
        dist[p] = d
        idx[p] = i
    return dist, idx


def ball_lists(
    tree: cKDTree, centres: NDArray[np.float64], radius, *, workers: int = -1
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``tree.query_ball_point(centres, radius)`` flattened: the number of points found per
    centre and their indices, centre after centre (one C-level concatenation of the lists:
    a per-index generator took ~25 % of the radius stage at 10⁶ points)."""
    lists = tree.query_ball_point(centres, radius, workers=workers, return_sorted=False)
    counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
    total = int(counts.sum())
    if not total:
        return counts, np.zeros(0, dtype=np.int64)
    # one pass over the chained lists (no array per list)
    return counts, np.fromiter(chain.from_iterable(lists), dtype=np.int64, count=total)


#: the cells of a :class:`PointIndex` grid: at most this many per point of the cloud
GRID_CELLS_PER_POINT = 2


class PointIndex(cKDTree):
    """A ``cKDTree`` of a cloud's points (built and queried exactly as ``cKDTree(xyz)``)
    that also answers box-bounded searches in ball-query order: :meth:`grid` buckets the
    points in a uniform grid, each cell's points in the tree's leaf order, so a search
    through the cells that returns its hits sorted by leaf-order rank lists them as
    ``query_ball_point(..., return_sorted=False)`` does (that order is the leaf order).
    Built once per cloud and handed on (the pipeline's ``run.point_index()``)."""

    _grid: tuple | None = None

    def grid(self) -> tuple:
        """``(lo, cell, dims, start, rank, pts)``: the grid's lower corner, cell size and
        cell counts per axis, the CSR start of every cell (cells numbered ``(ix * ny + iy)
        * nz + iz``), and per grid slot the point's leaf-order rank and coordinates. Built
        on first use; at most :data:`GRID_CELLS_PER_POINT` cells per point."""
        if self._grid is None:
            self._grid = _build_grid(np.asarray(self.data), np.asarray(self.indices))
        return self._grid


def _build_grid(xyz: NDArray[np.float64], leaf_order: NDArray) -> tuple:
    n = xyz.shape[0]
    lo = xyz.min(axis=0) if n else np.zeros(3)
    span = np.maximum(xyz.max(axis=0) - lo, 0.0) if n else np.zeros(3)
    vol = float(np.prod(np.maximum(span, 1e-9)))
    cell = max((vol / max(GRID_CELLS_PER_POINT * n, 1)) ** (1 / 3), 1e-6)
    dims = (np.floor(span / cell).astype(np.int64) + 1).astype(np.int64)
    while int(np.prod(dims)) > GRID_CELLS_PER_POINT * max(n, 1) + 8:  # flat clouds
        cell *= 1.25
        dims = (np.floor(span / cell).astype(np.int64) + 1).astype(np.int64)
    rank = np.empty(n, dtype=np.int64)
    rank[leaf_order] = np.arange(n, dtype=np.int64)
    ijk = np.minimum(np.floor((xyz - lo) / cell).astype(np.int64), dims - 1)
    cid = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    # leaf order first, then a stable sort by cell: each cell's points stay in leaf order
    slot = np.asarray(leaf_order, dtype=np.int64)[np.argsort(cid[leaf_order], kind="stable")]
    start = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
    np.cumsum(np.bincount(cid, minlength=start.size - 1), out=start[1:])
    pts = np.ascontiguousarray(xyz[slot], dtype=np.float64)
    return lo.astype(np.float64), float(cell), dims, start, rank[slot], pts


#: :func:`grid_query`'s grid has about this many cells per data point
KNN_CELLS_PER_POINT = 4
#: ... and looks at most this many rings of cells around a query point before it leaves
#: the point to the k-d tree (points far from every data point)
KNN_MAX_RING = 4
#: margin of :func:`grid_query`'s exactness tests: a point whose ``k``-th and ``k + 1``-th
#: squared distances lie within it (relative), or whose ``k + 1``-th lies within this many
#: cell sizes of the unsearched cells, goes to the k-d tree
KNN_MARGIN = 1e-9


@numba.njit(cache=True)
def _insert(bd, bi, m, dd, j):  # pragma: no cover - numba
    """``dd`` (index ``j``) into the ascending ``bd``/``bi`` holding ``m`` of at most
    ``bd.size`` (after equal ones; dropped when no nearer than a full list's last);
    returns the new count."""
    kk = bd.size
    if m == kk and not dd < bd[kk - 1]:
        return m
    p = m if m < kk else kk - 1
    while p > 0 and bd[p - 1] > dd:
        bd[p] = bd[p - 1]
        bi[p] = bi[p - 1]
        p -= 1
    bd[p] = dd
    bi[p] = j
    return m + 1 if m < kk else m


@numba.njit(cache=True)
def _scan_ring(  # noqa: PLR0913 - a compiled kernel takes its arrays one by one
    data, start, slot, dims, c0, r, q, i, bd, bi, m
):  # pragma: no cover - numba
    """The data points of the grid cells at Chebyshev distance ``r`` from cell ``c0``
    into query point ``q[i]``'s nearest list ``bd``/``bi`` (squared distances summed as
    cKDTree does, ``(dx² + dy²) + dz²``); returns its new count. A column's cells are
    consecutive slots: on an x or y face of the ring its z range is one run of them."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    cx, cy, cz = c0[0], c0[1], c0[2]
    qx, qy, qz = q[i, 0], q[i, 1], q[i, 2]
    zlo, zhi = max(cz - r, 0), min(cz + r, nz - 1)
    for ix in range(max(cx - r, 0), min(cx + r, nx - 1) + 1):
        ex = ix == cx - r or ix == cx + r
        for iy in range(max(cy - r, 0), min(cy + r, ny - 1) + 1):
            col = (ix * ny + iy) * nz
            face = ex or iy == cy - r or iy == cy + r
            # on a face every z of the ring (one run), inside it only its two z faces
            for h in range(1 if face else 2):
                if face:
                    if zlo > zhi:
                        break
                    a, b = start[col + zlo], start[col + zhi + 1]
                else:  # r > 0 here
                    iz = cz - r if h == 0 else cz + r
                    if iz < 0 or iz >= nz:
                        continue
                    a, b = start[col + iz], start[col + iz + 1]
                for s in range(a, b):
                    dx = qx - data[s, 0]
                    dy = qy - data[s, 1]
                    dz = qz - data[s, 2]
                    m = _insert(bd, bi, m, (dx * dx + dy * dy) + dz * dz, slot[s])
    return m


@numba.njit(cache=True)
def _ring_bound(lo, cell, dims, c0, r, q, i):  # pragma: no cover - numba
    """Distance (m) from ``q[i]`` beyond which the cells outside rings 0..``r`` around cell
    ``c0`` lie (inf: there are none)."""
    bound = np.inf
    for a in range(3):
        if c0[a] - r > 0:
            bound = min(bound, q[i, a] - (lo[a] + (c0[a] - r) * cell))
        if c0[a] + r < dims[a] - 1:
            bound = min(bound, lo[a] + (c0[a] + r + 1) * cell - q[i, a])
    return bound


@numba.njit(cache=True)
def _ring_search(  # noqa: PLR0913 - a compiled kernel takes its arrays one by one
    data, start, slot, lo, cell, dims, q, i, kk, max_ring, margin, bd, bi, c0
):  # pragma: no cover - numba
    """The ``kk`` nearest data points of ``q[i]`` into ``bd`` (squared distances,
    ascending) and ``bi``, searched ring by ring of grid cells around the point's cell
    until no unsearched cell can hold a nearer one; False where fewer than ``kk`` were
    found within ``max_ring`` rings (or the bound, less ``margin`` cells, is not sure)."""
    for a in range(3):
        # the point's cell, clipped to a few cells outside the grid (a far point: no
        # ring reaches the grid within ``max_ring``, the k-d tree answers it)
        f = np.floor((q[i, a] - lo[a]) / cell)
        c0[a] = int(min(max(f, -1.0 - max_ring), dims[a] + max_ring))
    m = 0
    for r in range(max_ring + 1):
        m = _scan_ring(data, start, slot, dims, c0, r, q, i, bd, bi, m)
        # less an absolute slack for the rounding of the cell boundaries
        bound = _ring_bound(lo, cell, dims, c0, r, q, i) - margin * cell
        if m == kk and (bound == np.inf or (bound > 0 and bd[kk - 1] < bound * bound)):
            return True
        if bound == np.inf:
            return False  # every cell searched, fewer than kk points
    return False


@numba.njit(cache=True)
def _knn_cells(  # noqa: PLR0913 - a compiled kernel takes its arrays one by one
    data, start, slot, lo, cell, dims, q, order, kk, max_ring, margin, dist, ind
):  # pragma: no cover - numba
    """The ``kk`` nearest data points of every query point ``q[order[t]]``
    (:func:`_ring_search`); the first ``kk - 1`` into ``dist`` (the square roots of the squared
    distances, summed as cKDTree sums them) and ``ind`` (data indices), ascending.
    Returns ``sure``, False where the answer may differ from cKDTree's: fewer than ``kk``
    found within ``max_ring`` rings, equal distances among the first ``kk - 1`` (their
    order is the tree's), or the ``kk - 1``-th and ``kk``-th within ``margin`` (relative;
    the unsearched cells' distance bound less ``margin`` cells)."""
    sure = np.zeros(q.shape[0], dtype=np.bool_)
    bd = np.empty(kk)
    bi = np.empty(kk, dtype=np.int64)
    c0 = np.empty(3, dtype=np.int64)
    for t in range(order.size):
        i = order[t]
        ok = _ring_search(data, start, slot, lo, cell, dims, q, i, kk, max_ring, margin, bd, bi, c0)
        if ok:
            for a in range(kk - 2):
                ok = ok and bd[a] != bd[a + 1]
            ok = ok and bd[kk - 1] > bd[kk - 2] * (1.0 + margin)
        sure[i] = ok
        if ok:
            for a in range(kk - 1):
                dist[i, a] = np.sqrt(bd[a])
                ind[i, a] = bi[a]
    return sure


def _knn_grid(data: NDArray[np.float64]) -> tuple:
    """The grid of :func:`grid_query`: ``(lo, cell, dims, start, slot)``, about
    :data:`KNN_CELLS_PER_POINT` cells per data point, ``slot`` the data in cell order."""
    nd = data.shape[0]
    lo = data.min(axis=0)
    span = np.maximum(data.max(axis=0) - lo, 0.0)
    vol = float(np.prod(np.maximum(span, 1e-9)))
    cell = max((vol / (KNN_CELLS_PER_POINT * nd)) ** (1 / 3), 1e-9)
    dims = np.floor(span / cell).astype(np.int64) + 1
    while int(np.prod(dims)) > KNN_CELLS_PER_POINT * nd + 64:  # flat data
        cell *= 1.25
        dims = np.floor(span / cell).astype(np.int64) + 1
    ijk = np.minimum(np.floor((data - lo) / cell).astype(np.int64), dims - 1)
    cid = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    start, slot = _bucket(cid, int(np.prod(dims)))
    return lo, float(cell), dims, start, slot


@numba.njit(cache=True)
def _bucket(cid, m):  # pragma: no cover - numba
    """A counting sort of the labels ``cid`` (``0..m-1``): the CSR ``start`` of every
    label and ``slot``, the indices by label, in index order within one (the permutation
    ``np.argsort(cid, kind="stable")`` gives)."""
    start = np.zeros(m + 1, dtype=np.int64)
    for i in range(cid.size):
        start[cid[i] + 1] += 1
    for c in range(m):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    slot = np.empty(cid.size, dtype=np.int64)
    for i in range(cid.size):
        c = cid[i]
        slot[fill[c]] = i
        fill[c] += 1
    return start, slot


#: a query of fewer points than this runs in the calling thread: scipy starts a thread
#: per worker and query, which costs more than it saves on a few thousand points
THREAD_MIN_QUERIES = 16384


def query_workers(n: int) -> int:
    """``workers`` for a k-d tree query of ``n`` points (all cores from
    :data:`THREAD_MIN_QUERIES` on; the answers do not depend on it)."""
    return -1 if n >= THREAD_MIN_QUERIES else 1


def _tree_of(data: NDArray[np.float64], tree) -> cKDTree:
    if tree is None:
        return cKDTree(data)
    return tree if isinstance(tree, cKDTree) else tree()


def grid_query(
    data: NDArray[np.float64],
    points: NDArray[np.float64],
    k: int = 1,
    *,
    tree: cKDTree | Callable[[], cKDTree] | None = None,
    order: NDArray | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """``cKDTree(data).query(points, k)``, the same arrays (distances and indices, shapes
    as the query's), faster for many points near the data (the resampled skeleton of a
    cloud): the ``k + 1`` nearest by a ring search through a grid of the data
    (:func:`_knn_cells`), in spatial order (``order``, else :func:`spatial_order`); the
    points whose ``k`` nearest that does not decide as the tree does (ties, points far
    from the data) are queried from ``tree`` (a k-d tree of ``data``, or a function
    returning one, called only then; built if None). Needs more than ``k + 1`` data
    points (else the tree answers all)."""
    data = np.ascontiguousarray(data, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    n, nd = points.shape[0], data.shape[0]
    if nd <= k + 1 or n == 0:
        return _tree_of(data, tree).query(points, k, workers=-1)
    lo, cell, dims, start, slot = _knn_grid(data)
    order = spatial_order(points) if order is None else np.asarray(order, dtype=np.int64)
    dist = np.empty((n, k))
    ind = np.empty((n, k), dtype=np.intp)
    sure = _knn_cells(
        np.ascontiguousarray(data[slot]),
        start,
        slot,
        lo,
        cell,
        dims,
        points,
        order,
        k + 1,
        KNN_MAX_RING,
        KNN_MARGIN,
        dist,
        ind,
    )
    redo = np.flatnonzero(~sure)
    if redo.size:
        d, i = _tree_of(data, tree).query(points[redo], k, workers=query_workers(redo.size))
        dist[redo] = d.reshape(redo.size, k)
        ind[redo] = i.reshape(redo.size, k)
    if k == 1:
        return dist.reshape(n), ind.reshape(n)
    return dist, ind


#: :func:`grid_nearest_label` searches this many nearest data points: a skeleton's
#: samples repeat a node's position at most once per edge meeting there (a fork of two)
LABEL_TIES = 4


@numba.njit(cache=True)
def _label_cells(  # noqa: PLR0913 - a compiled kernel takes its arrays one by one
    data, start, slot, label, lo, cell, dims, q, order, kk, max_ring, margin, dist, lab
):  # pragma: no cover - numba
    """:func:`_knn_cells` for the nearest data point's ``label``: the ``kk`` nearest found
    by the same ring search, and ``sure`` also where the nearest are exact ties (equal
    squared distances) of one label, the first beyond them more than ``margin`` farther
    (relative); the distance into ``dist``, the label into ``lab``."""
    sure = np.zeros(q.shape[0], dtype=np.bool_)
    bd = np.empty(kk)
    bi = np.empty(kk, dtype=np.int64)
    c0 = np.empty(3, dtype=np.int64)
    for t in range(order.size):
        i = order[t]
        ok = _ring_search(data, start, slot, lo, cell, dims, q, i, kk, max_ring, margin, bd, bi, c0)
        if ok:
            first = label[bi[0]]
            c = 1
            while c < kk and not bd[c] > bd[0] * (1.0 + margin):
                ok = ok and bd[c] == bd[0] and label[bi[c]] == first
                c += 1
            ok = ok and c < kk
        sure[i] = ok
        if ok:
            dist[i] = np.sqrt(bd[0])
            lab[i] = label[bi[0]]
    return sure


def grid_nearest_label(
    data: NDArray[np.float64],
    points: NDArray[np.float64],
    label: NDArray[np.int64],
    *,
    order: NDArray | None = None,
    ties: int = LABEL_TIES,
    full: tuple[NDArray[np.float64], NDArray[np.int64]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``d, j = cKDTree(data).query(points)`` as ``(d, label[j])``: :func:`grid_query`
    for the label of the nearest data point, where exact ties of one label (a skeleton's
    samples at a node shared by its edges) decide as well as a unique nearest (among the
    ``ties`` nearest); the other points (ties of different labels, near ties, points far
    from the data) are queried from a k-d tree of ``data``. ``full``: ``(data, label)``
    whose answer this is, ``data`` holding their points less exact repeats of a point with
    the same label (the same answer, from fewer points; the k-d tree is of ``full``'s).
    ``order``: a spatial order of ``points``."""
    data = np.ascontiguousarray(data, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    label = np.ascontiguousarray(label, dtype=np.int64)
    all_data, all_label = (data, label) if full is None else full
    n, nd = points.shape[0], data.shape[0]
    if nd <= ties or n == 0:
        d, j = cKDTree(all_data).query(points, workers=query_workers(n))
        return d, all_label[j]
    lo, cell, dims, start, slot = _knn_grid(data)
    order = spatial_order(points) if order is None else np.asarray(order, dtype=np.int64)
    dist = np.empty(n)
    lab = np.empty(n, dtype=np.int64)
    sure = _label_cells(
        np.ascontiguousarray(data[slot]),
        start,
        slot,
        label,
        lo,
        cell,
        dims,
        points,
        order,
        ties,
        KNN_MAX_RING,
        KNN_MARGIN,
        dist,
        lab,
    )
    redo = np.flatnonzero(~sure)
    if redo.size:
        d, j = cKDTree(all_data).query(points[redo], workers=query_workers(redo.size))
        dist[redo] = d
        lab[redo] = all_label[j]
    return dist, lab


def _query_order(
    tree: cKDTree, points: NDArray | None, order: NDArray | None = None
) -> tuple[NDArray, NDArray]:
    if points is None:
        return tree.data, np.asarray(tree.indices) if order is None else order
    pts = np.asarray(points, dtype=np.float64)
    return pts, spatial_order(pts) if order is None else np.asarray(order)


def query_blocks(
    tree: cKDTree,
    points: NDArray[np.float64] | None = None,
    k: int = 1,
    *,
    workers: int = -1,
    block: int = QUERY_BLOCK,
    order: NDArray | None = None,
    **kwargs,
):
    """The blocks of :func:`query_ordered`: ``(rows, dist, idx)`` per block of at most
    ``block`` query points (``rows`` indexes ``points``, or the tree's data), for callers
    that reduce each block and never hold the whole ``n × k`` result. ``order``: as in
    :func:`query_ordered`."""
    pts, perm = _query_order(tree, points, order)
    for a in range(0, pts.shape[0], block):
        p = perm[a : a + block]
        w = query_workers(p.size) if workers == -1 else workers
        d, i = tree.query(pts[p], k=k, workers=w, **kwargs)
        yield p, d, i


@numba.njit(cache=True)
def _find(root, v):  # pragma: no cover - numba
    r = v
    while root[r] != r:
        r = root[r]
    while root[v] != r:  # path compression
        nxt = root[v]
        root[v] = r
        v = nxt
    return r


@numba.njit(cache=True)
def _union(root, u, v):  # pragma: no cover - numba
    a = _find(root, u)
    b = _find(root, v)
    if a != b:
        if a < b:
            root[b] = a
        else:
            root[a] = b


@numba.njit(cache=True)
def _union_pairs(root, rows, cols):  # pragma: no cover - numba
    for e in range(rows.size):
        _union(root, rows[e], cols[e])


@numba.njit(cache=True)
def _union_csr(root, indptr, indices):  # pragma: no cover - numba
    for i in range(indptr.size - 1):
        for e in range(indptr[i], indptr[i + 1]):
            _union(root, i, indices[e])


@numba.njit(cache=True)
def _union_level_edges(root, indptr, indices, level, tree, ok):  # pragma: no cover - numba
    """Union the edges of a CSR graph whose ends are kept points of one tree and level."""
    for i in range(indptr.size - 1):
        if not ok[i]:
            continue
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            if ok[j] and level[j] == level[i] and tree[j] == tree[i]:
                _union(root, i, j)


@numba.njit(cache=True)
def _cross_keys(indptr, indices, label, m):  # pragma: no cover - numba
    """``min * m + max`` of the labels of every CSR edge joining two labelled pieces."""
    cnt = 0
    for i in range(indptr.size - 1):
        li = label[i]
        if li < 0:
            continue
        for e in range(indptr[i], indptr[i + 1]):
            lj = label[indices[e]]
            if lj >= 0 and lj != li:
                cnt += 1
    keys = np.empty(cnt, dtype=np.int64)
    cnt = 0
    for i in range(indptr.size - 1):
        li = label[i]
        if li < 0:
            continue
        for e in range(indptr[i], indptr[i + 1]):
            lj = label[indices[e]]
            if lj >= 0 and lj != li:
                keys[cnt] = min(li, lj) * m + max(li, lj)
                cnt += 1
    return keys


@numba.njit(cache=True)
def _canonical_labels(root):  # pragma: no cover - numba
    n = root.size
    label = np.full(n, -1, dtype=np.int32)
    count = 0
    for v in range(n):
        r = _find(root, v)
        if label[r] < 0:
            label[r] = count
            count += 1
        label[v] = label[r]
    return count, label


def components(
    n: int,
    edges: tuple[tuple[NDArray, NDArray], ...] = (),
    graph: sparse.csr_matrix | None = None,
) -> tuple[int, NDArray[np.int32]]:
    """Connected components of the undirected graph on ``n`` vertices whose edges are the
    ``(rows, cols)`` pairs of ``edges`` plus the stored entries of ``graph`` (CSR).

    The same ``(count, labels)`` as ``scipy.sparse.csgraph.connected_components(...,
    directed=False)`` on the sum of those matrices (components numbered by their lowest
    vertex, as scipy's search does), by union-find: no sparse matrix, no transpose."""
    root = np.arange(n, dtype=np.int64)
    if graph is not None:
        g = graph.tocsr()
        _union_csr(root, g.indptr, g.indices)
    for r, c in edges:
        _union_pairs(root, np.asarray(r, dtype=np.int64), np.asarray(c, dtype=np.int64))
    count, label = _canonical_labels(root)
    return int(count), label


@numba.njit(cache=True)
def _cached_rows(index, dist, n, kk, out_i, out_d):  # pragma: no cover - numba
    """Per row the first ``kk`` entries of ``index`` below ``n`` (points still present)
    into ``out_i``/``out_d``; returns the rows whose answer is not unique (see
    :meth:`NeighbourCache.query`)."""
    rows, m = index.shape
    unsure = np.zeros(rows, dtype=np.bool_)
    for r in range(rows):
        c = 0
        for j in range(m):
            q = index[r, j]
            if q >= n:
                continue
            dj = dist[r, j]
            if c < kk:
                if c > 0 and not dj > out_d[r, c - 1]:
                    unsure[r] = True  # a tie inside the first kk: order not unique
                out_i[r, c] = q
                out_d[r, c] = dj
                c += 1
            else:
                if not dj > out_d[r, kk - 1]:
                    unsure[r] = True  # a tie at the cut: set not unique
                c += 1
                break
        if c < kk:
            unsure[r] = True  # too few left in the list
        elif c == kk and not out_d[r, kk - 1] < dist[r, m - 1]:
            unsure[r] = True  # points outside the list may lie as close
    return unsure


@dataclass
class NeighbourCache:
    """The ``m`` nearest neighbours of every point of a cloud (itself first), from one
    k-d tree query, carried through point removals so a later query of fewer neighbours
    on the remaining points needs no new query (issue 13: the outlier filter's k = 16
    query serves the neighbour graph's k = 10).

    ``index[i]`` are row numbers of the current cloud, or ``n`` (the number of points,
    cKDTree's "missing" marker) where the neighbour was removed; ``dist[i]`` the distances
    as the query returned them. The list of a point holds every remaining point closer
    than its last distance ``dist[i, -1]``."""

    index: NDArray[np.int32]
    dist: NDArray[np.float64]
    #: a k-d tree of the current points, once one is built (the foliage pass's, for the
    #: neighbour graph); :meth:`select` drops it
    tree: cKDTree | None = field(default=None, repr=False, compare=False)

    @property
    def n(self) -> int:
        return int(self.index.shape[0])

    @classmethod
    def from_query(cls, tree: cKDTree, m: int) -> NeighbourCache:
        """One query of ``m`` neighbours of every point of ``tree.data``."""
        n = tree.n
        dt = np.int32 if n < 2**31 - 1 else np.int64
        dist, index = query_ordered(tree, None, m, index_dtype=dt)
        return cls(index, dist)

    def select(self, keep: NDArray) -> NeighbourCache:
        """The cache of the points ``keep`` (boolean mask or sorted indices) retains."""
        keep = np.asarray(keep)
        if keep.dtype == bool:
            rows = np.flatnonzero(keep)
        else:
            rows = keep.astype(np.int64)
        new = rows.size
        remap = np.full(self.n + 1, new, dtype=self.index.dtype)
        remap[rows] = np.arange(new, dtype=self.index.dtype)
        return NeighbourCache(remap[self.index[rows]], self.dist[rows])

    def query(
        self,
        k: int,
        tree: cKDTree | None = None,
        xyz: NDArray[np.float64] | None = None,
        start: int = 0,
        stop: int | None = None,
    ) -> tuple[NDArray[np.float64], NDArray]:
        """``tree.query(xyz, k)`` of the cloud's own points (``tree`` built on ``xyz``),
        the same arrays: rows whose ``k`` nearest remaining neighbours are unique (no
        equal distances among them or at the cut, all inside the cached list) come from
        the cache, the other rows (duplicates, ties, too few left) from ``tree``.
        ``start``, ``stop``: only the rows of the points ``start:stop``
        (``tree.query(xyz[start:stop], k)``, for a block at a time)."""
        n = self.n
        m = self.index.shape[1]
        start, stop = max(int(start), 0), n if stop is None else min(int(stop), n)
        index, dist = self.index[start:stop], self.dist[start:stop]
        nr = index.shape[0]
        # every row is either filled from the cache or re-queried whole
        out_i = np.empty((nr, k), dtype=self.index.dtype)
        out_d = np.empty((nr, k))
        if k <= m:
            unsure = _cached_rows(index, dist, n, k, out_i, out_d)
        else:
            unsure = np.ones(nr, dtype=bool)
        redo = np.flatnonzero(unsure)
        if redo.size:
            if tree is None or xyz is None:
                raise ParameterError("NeighbourCache.query needs the tree and points")
            d, i = query_ordered(tree, xyz[redo + start], k)
            out_d[redo] = d.reshape(redo.size, k)
            out_i[redo] = i.reshape(redo.size, k)
        return out_d, out_i


def estimate_spacing(
    xyz: NDArray[np.float64], sample: int = 20000, seed: int = 0, kdtree: cKDTree | None = None
) -> float:
    """Median nearest-neighbour distance of the points (metres), on a random subsample.
    ``kdtree``: a k-d tree of ``xyz``, if one is built already. The pipeline measures it
    once per cloud and hands it on (``point_spacing`` in the run's record)."""
    n = xyz.shape[0]
    if n < 2:
        raise InputError(f"need at least 2 points to estimate a point spacing, got {n}")
    tree = kdtree if kdtree is not None else cKDTree(xyz)
    idx = np.random.default_rng(seed).choice(n, size=min(n, sample), replace=False)
    d, _ = query_ordered(tree, xyz[idx], 2)
    pos = d[:, 1][d[:, 1] > 0]
    return smooth_median(pos) if pos.size else 0.0


#: :func:`smooth_median` averages the values between these quantiles ...
SMOOTH_MEDIAN_BAND = (0.45, 0.55)
#: ... where at least this share of the values lie within 0.1 % of the median: a grid's
#: step (the TreeLS spruce, thinned at 1 cm: 22 % of its nearest-neighbour distances are
#: √3 cm); a scan's continuous spread puts about 0.1 % there (the other real clouds)
GRID_ATOM_SHARE = 0.05


def smooth_median(values: NDArray[np.float64]) -> float:
    """The median of nearest-neighbour distances, made continuous where the cloud lies on
    a grid. A cloud thinned on a voxel grid (CloudCompare's or lidR's subsampling, the
    TreeLS spruce at 1 cm) has distances of 1, √2 and √3 edges only, and its median sits
    on the step between two of them: dropping the spruce's 3,242 duplicate points (3.9 %)
    moved it from 17.3 to 14.1 mm, and every constant derived from the spacing with it
    (the graph model's volume 436 → 510 L). Where :data:`GRID_ATOM_SHARE` of the values
    sit at the median, the mean of the values between the 45th and 55th percentiles
    (:data:`SMOOTH_MEDIAN_BAND`), which moves by a fraction of a step when a few per cent
    of the points change (spruce 15.4 mm with or without its duplicates); elsewhere the
    median itself."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return 0.0
    med = float(np.median(v))
    if np.mean(np.abs(v - med) <= 1e-3 * med) < GRID_ATOM_SHARE:
        return med
    lo, hi = np.quantile(v, SMOOTH_MEDIAN_BAND)
    band = v[(v >= lo) & (v <= hi)]
    return float(band.mean()) if band.size else med


def neighbour_graph(
    xyz: NDArray[np.float64],
    *,
    k: int = 10,
    radius: float | None = None,
    tree: cKDTree | None = None,
    workers: int = -1,
    cache: NeighbourCache | None = None,
) -> sparse.csr_matrix:
    """Neighbour graph with squared-distance weights (``csr``, n×n).

    kNN (``k`` neighbours of every point) or all pairs within ``radius`` when given. The
    matrix stores each edge in at least one direction; every consumer treats it as
    undirected (``csgraph`` with ``directed=False``), which is the symmetric kNN graph
    without building the transpose (a large saving at 10⁶ points). Duplicate points get a
    tiny positive weight so csgraph keeps the edge. A :class:`NeighbourCache` of these
    points (``cache``) replaces the kNN query where its lists decide it (the same graph).
    """
    n = xyz.shape[0]
    tree = tree or cKDTree(xyz)
    if radius is not None:
        pairs = tree.query_pairs(radius, output_type="ndarray")
        r, c = pairs[:, 0], pairs[:, 1]
    else:
        kk = min(k + 1, n)
        idt = np.int32 if n < 2**31 else np.int64
        if cache is not None and cache.n == n and kk > 1:
            d, nb = cache.query(kk, tree, xyz)
        else:
            own = tree.data.shape == xyz.shape and np.array_equal(tree.data, xyz)
            d, nb = query_ordered(tree, None if own else xyz, kk, workers=workers, index_dtype=idt)
        nb = nb[:, 1:]
        ok = nb < n
        # rows come sorted from the query: build the CSR arrays directly (no COO sort)
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(ok.sum(axis=1), out=indptr[1:])
        w = np.maximum(d[:, 1:][ok] ** 2, 1e-18)
        return sparse.csr_matrix((w, nb[ok], indptr), shape=(n, n))
    w = np.sum((xyz[r] - xyz[c]) ** 2, axis=1)
    w = np.maximum(w, 1e-18)
    return sparse.csr_matrix((w, (r, c)), shape=(n, n))


def bridge_components(
    xyz: NDArray[np.float64],
    graph: sparse.csr_matrix,
    tree: cKDTree | None = None,
    max_rounds: int = 64,
    max_query: int = 200_000,
    rule: BridgeRule | None = None,
    anchors: NDArray[np.int64] | None = None,
) -> tuple[sparse.csr_matrix, int]:
    """Join the connected pieces of ``graph`` by their shortest inter-piece edges.

    Borůvka rounds over components: each component except the largest finds its nearest
    point in another component (kNN queries with growing k, exact fallback), and those
    edges (squared-length weights) are added. The added edges form a minimum spanning
    forest of the component graph under Euclidean distance (exact while the pieces other
    than the largest hold at most ``max_query`` points; beyond that each piece queries a
    seeded random sample, so a bridge is the shortest edge from that sample). Returns the
    new graph and the number of components before bridging.

    With a ``rule`` (:class:`BridgeRule`) a bridge is only added where the wood supports it
    (:func:`bridge_supported`); pieces left unbridged stay apart (their points reach no
    root and drop out of the skeleton). Pieces holding an ``anchors`` point (root points)
    are always bridged: a stem base cut off by occlusion must not lose its tree.
    """
    n = xyz.shape[0]
    n0, lab = components(n, graph=graph)
    if n0 <= 1:
        return graph, n0
    tree = tree or cKDTree(xyz)
    add_r: list[int] = []
    add_c: list[int] = []
    refused_pts: list[tuple[int, int]] = []  # (a point, its piece's size) of refused pieces
    ncomp, cur = n0, lab
    for _ in range(max_rounds):
        if ncomp <= 1:
            break
        sizes = np.bincount(cur, minlength=ncomp)
        big = int(np.argmax(sizes))
        best_d = np.full(ncomp, np.inf)
        best_r = np.full(ncomp, -1, dtype=np.int64)
        best_c = np.full(ncomp, -1, dtype=np.int64)
        refused = np.zeros(ncomp, dtype=bool)
        if rule is not None and refused_pts:
            rp = np.asarray(refused_pts, dtype=np.int64)
            same = sizes[cur[rp[:, 0]]] == rp[:, 1]  # unchanged since it was refused
            refused[cur[rp[same, 0]]] = True
        todo = np.flatnonzero((cur != big) & ~refused[cur])  # every piece but the largest
        if todo.size > max_query:
            # large pieces: query a seeded sample of their points (per piece at most
            # max_query / #pieces); the bridge is then the shortest edge from the sample
            rng = np.random.default_rng(0)
            share = max(max_query // max(ncomp - 1, 1), 64)
            sizes_t = sizes[cur[todo]]
            keep = rng.random(todo.size) < share / np.maximum(sizes_t, 1)
            todo = todo[keep]
        kk = 8
        while todo.size and kk <= 256:
            kq = min(kk, n)
            d, nb = query_ordered(tree, xyz[todo], kq)
            d = d.reshape(todo.size, kq)
            nb = nb.reshape(todo.size, kq)
            valid = nb < n
            other = valid & (cur[np.minimum(nb, n - 1)] != cur[todo][:, None])
            has = other.any(axis=1)
            first = np.argmax(other, axis=1)
            rows = np.flatnonzero(has)
            dd = d[rows, first[rows]]
            comp = cur[todo[rows]]
            o = np.lexsort((dd, comp))  # per component, nearest first
            comp_o = comp[o]
            lead = np.ones(o.size, dtype=bool)
            lead[1:] = comp_o[1:] != comp_o[:-1]
            sel = o[lead]
            cs = comp[sel]
            better = dd[sel] < best_d[cs]
            cs, sel = cs[better], sel[better]
            best_d[cs] = dd[sel]
            best_r[cs] = todo[rows[sel]]
            best_c[cs] = nb[rows[sel], first[rows[sel]]]
            # components that found nothing yet: retry their points with a larger k
            missing = np.zeros(ncomp, dtype=bool)
            missing[np.flatnonzero(best_r < 0)] = True
            missing[big] = False
            missing[refused] = False
            todo = todo[missing[cur[todo]]]
            kk *= 4
        for comp in np.flatnonzero((best_r < 0) & (np.arange(ncomp) != big) & ~refused):
            members = np.flatnonzero(cur == comp)  # exact fallback, rare
            outside = np.flatnonzero(cur != comp)
            d, j = cKDTree(xyz[outside]).query(xyz[members])
            i = int(np.argmin(d))
            best_r[comp], best_c[comp] = members[i], outside[j[i]]
        found = best_r >= 0
        if rule is not None:
            found &= ~refused
            cand = np.flatnonzero(found)
            ok, best_r[cand], best_c[cand] = bridge_supported(
                xyz, best_r[cand], best_c[cand], cur, tree, rule
            )
            if anchors is not None and anchors.size:
                anchored = np.zeros(ncomp, dtype=bool)
                anchored[cur[anchors]] = True
                ok |= anchored[cand]  # the asking piece holds a stem base
            bad = best_r[cand[~ok]]
            refused_pts.extend(zip(bad.tolist(), sizes[cur[bad]].tolist(), strict=True))
            found[cand[~ok]] = False
            if not found.any():
                break
        add_r.extend(best_r[found].tolist())
        add_c.extend(best_c[found].tolist())
        # the new pieces: components of the small graph over the original pieces (the
        # same partition as of graph + bridges, without adding to the n x n matrix)
        r = lab[np.asarray(add_r, dtype=np.int64)]
        c = lab[np.asarray(add_c, dtype=np.int64)]
        small = sparse.coo_matrix((np.ones(r.size), (r, c)), shape=(n0, n0))
        ncomp, merged = connected_components(small, directed=False)
        cur = merged[lab]
    r = np.asarray(add_r, dtype=np.int64)
    c = np.asarray(add_c, dtype=np.int64)
    w = np.maximum(np.sum((xyz[r] - xyz[c]) ** 2, axis=1), 1e-18)
    if r.size == 0:
        return graph, n0
    # the bridges join different pieces, so no entry of the graph repeats: inserting them
    # and sorting each row by column gives the canonical sum (what scipy's COO -> CSR
    # conversion returns) without a 10⁶ x 10⁶ sparse addition or a COO copy
    return _with_entries(sparse.csr_matrix(graph), r, c, w), n0


@numba.njit(cache=True)
def _merge_rows(
    indptr, indices, data, aptr, acol, aval, out_ptr, out_idx, out_val
):  # pragma: no cover
    """Rows of a CSR matrix plus added entries (grouped by row in ``aptr``), each row
    sorted by column (insertion sort: rows are short); False if a column repeats."""
    for i in range(indptr.size - 1):
        o = out_ptr[i]
        m = 0
        for e in range(indptr[i], indptr[i + 1]):
            out_idx[o + m] = indices[e]
            out_val[o + m] = data[e]
            m += 1
        for e in range(aptr[i], aptr[i + 1]):
            out_idx[o + m] = acol[e]
            out_val[o + m] = aval[e]
            m += 1
        for a in range(1, m):
            ci = out_idx[o + a]
            vi = out_val[o + a]
            b = a - 1
            while b >= 0 and out_idx[o + b] > ci:
                out_idx[o + b + 1] = out_idx[o + b]
                out_val[o + b + 1] = out_val[o + b]
                b -= 1
            out_idx[o + b + 1] = ci
            out_val[o + b + 1] = vi
        for a in range(1, m):
            if out_idx[o + a] == out_idx[o + a - 1]:
                return False
    return True


def _with_entries(
    g: sparse.csr_matrix, r: NDArray[np.int64], c: NDArray[np.int64], w: NDArray[np.float64]
) -> sparse.csr_matrix:
    """``g`` plus the entries ``(r, c, w)`` in canonical CSR form (rows sorted by column,
    duplicates summed): the same arrays as building it from COO."""
    n = g.shape[0]
    order = np.argsort(r, kind="stable")
    aptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(r, minlength=n), out=aptr[1:])
    out_ptr = g.indptr.astype(np.int64) + aptr
    nnz = int(out_ptr[-1])
    idt = np.int32 if max(n, nnz) < 2**31 else np.int64
    out_idx = np.empty(nnz, dtype=idt)
    out_val = np.empty(nnz, dtype=np.result_type(g.data, w))
    ok = _merge_rows(
        g.indptr, g.indices, g.data, aptr, c[order].astype(idt), w[order], out_ptr, out_idx, out_val
    )
    if not ok:  # a repeated entry: let scipy sum it
        coo = g.tocoo()
        out = sparse.csr_matrix(
            (
                np.concatenate([coo.data, w]),
                (np.concatenate([coo.row, r]), np.concatenate([coo.col, c])),
            ),
            shape=g.shape,
        )
        out.sum_duplicates()
        return out
    return sparse.csr_matrix((out_val, out_idx, out_ptr.astype(idt)), shape=g.shape)


#: gaps up to this many node spacings are bridged without further support: the kNN graph
#: of a real scan falls apart at 4-15 point spacings (occlusion, sparse twigs) into pieces
#: of hundreds of points (measured on ``../shared/data/trees``), i.e. at most ~5 node
#: spacings (3 point spacings each)
GAP_SHORT = 4.0
#: a longer bridge must continue the piece's branch: within this angle of the principal
#: axis of the piece's points around its end
GAP_ANGLE = np.radians(35.0)
#: … or run through points: this share of its samples has a point within ``2 ×`` spacing
GAP_COVER = 0.5
#: … or join a piece at least this many times longer than the gap (a 2 m branch piece cut
#: off by a 40 cm occlusion shadow is wood; a 30 cm cluster 1 m away in the air is not).
#: Measured on the synthetic conifer (2 scanners, 8 mm noise, occlusion): real branch
#: pieces refused by the direction rule alone were 1.5-2.4 m long behind 36-40 cm gaps
GAP_EXTENT = 2.0


@dataclass(frozen=True)
class BridgeRule:
    """When a gap between two pieces of the neighbour graph may be bridged (all metres).

    ``short``: gaps up to this are always bridged (default ``GAP_SHORT`` node spacings);
    ``spacing``: the point spacing (tube radius and sample step of the coverage test);
    ``angle``: the direction-continuity limit (radians); ``cover``: the coverage limit.
    A longer gap is bridged when it is covered by points, when the asking piece is
    ``GAP_EXTENT`` times longer than the gap, or when it continues the asking piece's axis
    and is no longer than that piece (:func:`bridge_supported`)."""

    short: float
    spacing: float
    angle: float = GAP_ANGLE
    cover: float = GAP_COVER


def _piece_axis(
    xyz: NDArray, kd: cKDTree, end: int, members_of: NDArray, comp: int, radius: float
) -> tuple[NDArray | None, float]:
    """Principal axis of the piece's points within ``radius`` of its end point and the
    piece's linearity there (``1 - λ2/λ1``); ``None`` with fewer than 5 points."""
    idx = np.asarray(kd.query_ball_point(xyz[end], radius), dtype=np.int64)
    idx = idx[members_of[idx] == comp]
    if idx.size < 5:
        return None, 0.0
    q = xyz[idx] - xyz[idx].mean(axis=0)
    w, v = np.linalg.eigh(q.T @ q)
    return v[:, 2], float(1.0 - w[1] / max(w[2], 1e-30))


def segment_cover(
    kd: cKDTree, pa: NDArray, pb: NDArray, step: float, reach: float, ends: bool = False
) -> float:
    """The share of the stations ``step`` apart along ``pa → pb`` (at least one between
    them; with ``ends`` the two ends too) that have a point of ``kd`` within ``reach``."""
    m = max(int(np.ceil(float(np.linalg.norm(pb - pa)) / step)), 2)
    t = np.linspace(0.0, 1.0, m + 1)
    if not ends:
        t = t[1:-1]
    d, _ = kd.query(pa + t[:, None] * (pb - pa), k=1)
    return float(np.mean(d <= reach))


def _covered(xyz: NDArray, kd: cKDTree, pa: NDArray, pb: NDArray, rule: BridgeRule) -> bool:
    """Whether ``rule.cover`` of the samples (one per spacing) along ``pa → pb`` have a point
    within two spacings: a gap the kNN graph missed inside sampled wood."""
    return segment_cover(kd, pa, pb, rule.spacing, 2.0 * rule.spacing) >= rule.cover


def _continues(
    xyz: NDArray,
    kd: cKDTree,
    end: int,
    target: NDArray,
    comp: NDArray,
    extent: float,
    rule: BridgeRule,
) -> bool:
    """Whether the bridge ``end → target`` continues the piece's axis at ``end`` (within
    ``rule.angle``) and is no longer than the piece (``extent``)."""
    vec = target - xyz[end]
    gap = float(np.linalg.norm(vec))
    if gap > extent or gap == 0:
        return gap == 0
    axis, lin = _piece_axis(xyz, kd, end, comp, int(comp[end]), max(0.5 * gap, 5.0 * rule.spacing))
    return (
        axis is not None and lin > 0.5 and abs(float(np.dot(axis, vec / gap))) >= np.cos(rule.angle)
    )


def _end_bridge(
    xyz: NDArray, kd: cKDTree, members: NDArray, comp: NDArray, extent: float, rule: BridgeRule
) -> tuple[int, int] | None:
    """A bridge from one of the piece's two ends (extremes along its principal axis) to the
    nearest point of another piece ahead of it, if that bridge continues the piece."""
    q = xyz[members] - xyz[members].mean(axis=0)
    axis = np.linalg.eigh(q.T @ q)[1][:, 2]
    proj = q @ axis
    for end in (int(members[np.argmin(proj)]), int(members[np.argmax(proj)])):
        near = np.asarray(kd.query_ball_point(xyz[end], extent), dtype=np.int64)
        near = near[comp[near] != comp[end]]
        if near.size == 0:
            continue
        j = int(near[np.argmin(np.linalg.norm(xyz[near] - xyz[end], axis=1))])
        if _continues(xyz, kd, end, xyz[j], comp, extent, rule):
            return end, j
    return None


def bridge_supported(
    xyz: NDArray[np.float64],
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    comp: NDArray[np.int64],
    kd: cKDTree,
    rule: BridgeRule,
) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.int64]]:
    """For candidate bridges ``a[i] → b[i]`` (``a`` in the piece asking to be joined, ``b``
    its nearest point elsewhere): is the gap supported by the wood (:class:`BridgeRule`)?

    A gap longer than ``rule.short`` is bridged when points cover it, when the piece is at
    least ``GAP_EXTENT`` times longer than the gap, or when it continues the piece's axis
    at ``a`` and is no longer than the piece. Otherwise the piece may
    still join through one of its *ends*: the nearest point is often beside a branch
    crossing it, while the branch reaches its parent through an occlusion gap at its
    base. Returns ``(ok, a, b)`` with the bridge actually chosen."""
    ok = np.ones(a.size, dtype=bool)
    a, b = a.copy(), b.copy()
    length = np.linalg.norm(xyz[b] - xyz[a], axis=1)
    for i in np.flatnonzero(length > rule.short):
        if _covered(xyz, kd, xyz[a[i]], xyz[b[i]], rule):
            continue
        members = np.flatnonzero(comp == comp[a[i]])
        extent = float(np.linalg.norm(np.ptp(xyz[members], axis=0)))
        if extent >= GAP_EXTENT * length[i]:
            continue  # a piece much longer than the gap is wood
        if _continues(xyz, kd, int(a[i]), xyz[b[i]], comp, extent, rule):
            continue
        alt = _end_bridge(xyz, kd, members, comp, extent, rule) if members.size >= 5 else None
        if alt is None:
            ok[i] = False
        else:
            a[i], b[i] = alt
    return ok, a, b


def shortest_path_forest(
    graph: sparse.csr_matrix, sources: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Dijkstra from a virtual root joined to ``sources`` by 0-weight edges.

    Returns ``(dist, parent)`` for the n real vertices; ``parent`` is -1 at sources and at
    unreachable vertices (``dist = inf`` there). Weights are those of ``graph``.
    """
    n = graph.shape[0]
    g = sparse.csr_matrix(graph)
    src = np.asarray(sources, dtype=np.int64)
    # zero weights are "no edge" in csgraph, so the virtual edges carry a tiny epsilon;
    # the virtual root is one more CSR row (canonical form as from COO: sorted, summed)
    eps = 1e-30
    aug = sparse.csr_matrix(
        (
            np.concatenate([g.data, np.full(src.size, eps)]),
            np.concatenate([g.indices, src]),
            np.concatenate([g.indptr, [g.indptr[-1] + src.size]]),
        ),
        shape=(n + 1, n + 1),
    )
    aug.sum_duplicates()
    dist, pred = dijkstra(aug, directed=False, indices=n, return_predecessors=True)
    parent = pred[:n].astype(np.int64)
    parent[(parent == n) | (parent < 0)] = -1
    return dist[:n], parent


def segmentation_forest(
    graph: sparse.csr_matrix, roots: NDArray[np.int64], root_tree: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Livny's segmentation with its forest: the shortest-path forest of ``graph``'s
    weights (the graph method's squared lengths) from all root vertices at once, as
    ``(parent, order, tree)``: each vertex's parent in it (-1 at roots and unreached
    vertices), a topological order, and the tree of the root it hangs from (-1 where no
    root is reached); ``root_tree[i]`` is the tree of ``roots[i]``."""
    n = graph.shape[0]
    _, par = shortest_path_forest(graph, roots)
    order = treeops.topological_order(par)
    proot = treeops.root_of(par, order)
    tree_of_root = np.full(n, -1, dtype=np.int64)
    tree_of_root[np.asarray(roots, dtype=np.int64)] = np.asarray(root_tree, dtype=np.int64)
    return par, order, tree_of_root[proot]


def segment_trees(
    graph: sparse.csr_matrix, roots: NDArray[np.int64], root_tree: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Livny's segmentation: the tree of every vertex (-1 where no root is reached), from
    :func:`segmentation_forest`."""
    return segmentation_forest(graph, roots, root_tree)[2]


@dataclass
class Contraction:
    """Vertices of the contracted graph: ``label`` per point (-1 = dropped), centroids,
    tree of each vertex, root vertex per tree, the contracted neighbour graph Q, the point
    count per vertex and its ``spread``: the RMS distance of its points from the centroid
    (m), how far from the centroid the vertex's own points reach."""

    label: NDArray[np.int64]
    position: NDArray[np.float64]
    tree: NDArray[np.int64]
    roots: NDArray[np.int64]
    graph: sparse.csr_matrix
    count: NDArray[np.int64]
    spread: NDArray[np.float64] | None = None


def _voxel_level_edges(xyz, level, tree, ok, cell):
    """Edges joining points of the same (tree, level) whose voxels (size ``cell``) are
    26-adjacent: one representative point per voxel, linked to the representatives of
    its neighbour voxels and to every point of its own voxel. Closes the small gaps a kNN
    graph leaves inside a thin level band (sparse rings on thick stems)."""
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ijk = np.floor((xyz[idx] - xyz[idx].min(axis=0)) / cell).astype(np.int64) + 1
    dims = ijk.max(axis=0) + 2
    sc = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    us, srank = np.unique(sc, return_inverse=True)
    srank = srank.reshape(-1)
    lk = tree[idx].astype(np.int64) * (int(level[idx].max()) + 1) + level[idx]
    code = lk * us.size + srank
    ucode, first, cinv = np.unique(code, return_index=True, return_inverse=True)
    rep = idx[first]  # representative point of each cell
    rows = [idx]
    cols = [rep[cinv.reshape(-1)]]
    cell_lk = lk[first]
    cell_sc = sc[first]
    offsets = [
        (a, b, c)
        for a in (-1, 0, 1)
        for b in (-1, 0, 1)
        for c in (-1, 0, 1)
        if (a, b, c) > (0, 0, 0)
    ]
    for a, b, c in offsets:
        nsc = cell_sc + (a * dims[1] + b) * dims[2] + c
        pos = np.minimum(np.searchsorted(us, nsc), us.size - 1)
        hit = us[pos] == nsc
        ncode = cell_lk[hit] * us.size + pos[hit]
        p2 = np.minimum(np.searchsorted(ucode, ncode), ucode.size - 1)
        hit2 = ucode[p2] == ncode
        src = np.flatnonzero(hit)[hit2]
        rows.append(rep[src])
        cols.append(rep[p2[hit2]])
    return np.concatenate(rows), np.concatenate(cols)


NODE_SPACING = 3.0  #: default contraction level width, in median point spacings
#: … but at least this fraction of the cloud's height (bounds the vertex count of huge
#: clouds). 0.2 %: on the synthetic presets 0.3 % (5 cm on an 18 m birch) merged sparse
#: twigs (F1 0.88 on noisy scans), 0.2 % gives F1 ≥ 0.91, 0.15 % adds spurious tips
NODE_SPACING_MIN = 0.002


def default_node_spacing(point_spacing: float, extent: float) -> float:
    """The graph method's level width (metres) for a cloud of median point spacing
    ``point_spacing`` and height ``extent``: :data:`NODE_SPACING` point spacings, bounded
    to [:data:`NODE_SPACING_MIN`, 2 %] of the height (and at least 0.1 mm)."""
    ns = float(np.clip(NODE_SPACING * point_spacing, NODE_SPACING_MIN * extent, 0.02 * extent))
    return max(ns, 1e-4)


LEVEL_CELL = 1.5  #: voxel size of the level-set connectivity, in node spacings
#: how adjacent pieces of one level join (:func:`contract`)
LEVEL_MERGE = ("adjacent", "overlap", "adaptive", "two-scale")
#: ``merge="two-scale"``: pieces of a level whose voxels of this size (in point spacings)
#: touch always join — a level band's own sampling gaps. 3 = ``LEVEL_CELL`` × the 2 point
#: spacings a kNN neighbourhood spans on a scanned surface (its 10th neighbour lies ~1.8
#: spacings away), half the coarse cell of the default 3-spacing level
FINE_CELL = 3.0


def _merge_overlapping(
    xyz: NDArray[np.float64],
    lab: NDArray[np.int64],
    vr: NDArray,
    vc: NDArray,
    floor: float,
    wide: float = 0.0,
) -> NDArray[np.int64]:
    """Join level pieces that the voxel adjacency ``(vr, vc)`` links when the gap between
    them is smaller than their extents: the shortest linking point pair is shorter than the
    sum of the two pieces' RMS spreads (each at least ``floor``, the point spacing). Arcs of
    a partly scanned stem ring, several cm long and a few cm apart, become one ring (one
    vertex on the axis); two twigs side by side in one level, each a few cm across and
    farther apart than that, stay two vertices. ``wide`` > 0 (the level width, for
    ``merge="adaptive"``) also joins two pieces whose spreads both reach it: arcs of one
    stem ring thicker than the level band, behind an occlusion gap wider than the arcs."""
    la, lb = lab[vr], lab[vc]
    cand = la != lb
    if not cand.any():
        return lab
    m = int(lab.max()) + 1
    la, lb = np.minimum(la[cand], lb[cand]), np.maximum(la[cand], lb[cand])
    gap = np.linalg.norm(xyz[vr[cand]] - xyz[vc[cand]], axis=1)
    key, inv = np.unique(la * m + lb, return_inverse=True)
    g = np.full(key.size, np.inf)
    np.minimum.at(g, inv.reshape(-1), gap)
    pa, pb = key // m, key % m
    cnt = np.bincount(lab, minlength=m).astype(float)
    cen = np.stack([np.bincount(lab, weights=xyz[:, d], minlength=m) for d in range(3)], 1)
    cen /= np.maximum(cnt, 1)[:, None]
    d2 = np.sum((xyz - cen[lab]) ** 2, axis=1)
    spread = np.sqrt(np.bincount(lab, weights=d2, minlength=m) / np.maximum(cnt, 1))
    spread = np.maximum(spread, floor)
    join = g < spread[pa] + spread[pb]
    if wide > 0:
        # two arcs of one stem ring: both wider than the level band (a twig's cross-section
        # is narrower than the level width) lie on a stem thicker than the level, whose
        # occlusion gaps may exceed the arcs' own spreads
        w = spread >= wide
        join |= w[pa] & w[pb]
    if not join.any():
        return lab
    j = sparse.coo_matrix((np.ones(int(join.sum()), np.int8), (pa[join], pb[join])), shape=(m, m))
    _, plab = connected_components(j, directed=False)
    return plab[lab]


MIN_PIECE = 3  #: pieces with fewer points are no cross-section (see _absorb_fragments)


def _absorb_fragments(g, label, ok, m, into: int = 0):
    """Pieces of fewer than :data:`MIN_PIECE` points (a point whose path length lags its
    neighbours' by a level is alone in its level) join the neighbouring piece of at least
    ``max(MIN_PIECE, into)`` points they share the most kNN edges with; returns the new
    labels and piece count. ``into = k + 1`` (``merge="adaptive"``): only into a piece that
    can hold a whole kNN neighbourhood, a stem's cross-section — on a sparse scan the
    pieces of a twig hold 1–5 points each, and absorbing its 1–2-point pieces into the
    next ones merged the twig across levels (5 cm-thinned birch F1 0.79 → 0.50)."""
    count = np.bincount(label[ok], minlength=m)
    small = count < MIN_PIECE
    if not small.any():
        return label, m
    e = ok[g.row] & ok[g.col]
    la, lb = label[g.row[e]], label[g.col[e]]
    la, lb = np.concatenate([la, lb]), np.concatenate([lb, la])
    keep = small[la] & (count[lb] >= max(MIN_PIECE, into))  # into a real cross-section
    # only (a sparse twig's pieces are small one after another and stay)
    key, cnt = np.unique(la[keep] * m + lb[keep], return_counts=True)
    src, dst = key // m, key % m
    best = np.lexsort((-cnt, src))  # per source, the most shared edges first
    first = np.unique(src[best], return_index=True)[1]
    target = np.arange(m)
    target[src[best[first]]] = dst[best[first]]
    new = np.where(label >= 0, target[np.maximum(label, 0)], -1)
    uniq, inv = np.unique(new[ok], return_inverse=True)
    new[ok] = inv.reshape(-1)
    return new, uniq.size


def contract(
    xyz: NDArray[np.float64],
    graph: sparse.csr_matrix,
    path_length: NDArray,
    point_tree: NDArray[np.int64],
    spacing: float,
    cell: float | None = None,
    point_spacing: float | None = None,
    merge: str = "adjacent",
    k: int = 10,
) -> Contraction:
    """Contract points into geodesic level-set pieces of width ``spacing`` (see module doc).

    ``path_length`` is the distance along the shortest-path forest from the root set;
    ``point_tree`` the tree of each point (-1 unreachable: dropped). ``merge``: how the
    kNN pieces of one level that are 26-adjacent in voxels of ``cell`` (default
    ``LEVEL_CELL`` node spacings) join: ``"adjacent"`` (this function's default) all
    of them (closes the sparse rings of thick stems, but also merges twigs
    up to ~2 cells apart into one vertex between them); ``"overlap"`` only when the gap is
    smaller than their spreads (:func:`_merge_overlapping`; ``point_spacing`` is the floor
    of a spread), then pieces under :data:`MIN_PIECE` points join a neighbour
    (:func:`_absorb_fragments`); ``"adaptive"`` (opt-in) the overlap test, plus two pieces whose
    spreads both reach the level width ``spacing`` (arcs of one thick stem ring), and
    fragments join only pieces of at least ``k + 1`` points (``k``: the kNN graph's
    neighbours): on sparse scans most pieces hold 1–3 points (a 5 cm-thinned birch: median
    2), and absorbing them into the next level's 3-point piece merged twigs across levels
    (F1 0.79 → 0.50 there). ``"two-scale"`` (the graph method's default): pieces
    26-adjacent in voxels of :data:`FINE_CELL` point spacings always join, and pieces
    adjacent only at ``cell`` join by the adaptive test (gap below the sum of their spreads,
    or both spreads at least the level width) — a side twiglet a few cm off its branch
    stays its own vertex while the arcs of a thick stem's ring still close; where
    ``cell`` is no coarser than the fine cell it is ``"adjacent"``.
    """
    if merge not in LEVEL_MERGE:
        raise ParameterError(f"merge {merge!r}; expected one of {', '.join(LEVEL_MERGE)}")
    n = xyz.shape[0]
    ok = np.isfinite(path_length) & (point_tree >= 0)
    if spacing <= 0:
        level = np.arange(n, dtype=np.int64)
    else:
        level = np.floor(np.where(ok, path_length, 0) / spacing).astype(np.int64)
    # pieces: union-find over the kNN edges within a (tree, level) and the edge lists
    # below (the partition csgraph's connected_components gives on their sparse sum,
    # without building it or a COO copy of the 10⁶-point graph)
    g = sparse.csr_matrix(graph)
    root = np.arange(n, dtype=np.int64)
    _union_level_edges(root, g.indptr, g.indices, level, np.asarray(point_tree), ok)
    # all level-0 points of a tree are one piece (one root vertex per tree): tie every
    # tree's level-0 points together through its first level-0 point
    lvl0 = np.flatnonzero(ok & (level == 0))
    if lvl0.size:
        t0 = point_tree[lvl0]
        first = np.full(int(point_tree.max()) + 1, -1, dtype=np.int64)
        first[t0[::-1]] = lvl0[::-1]
        _union_pairs(root, lvl0, first[t0])
    if spacing > 0:
        vr, vc = _voxel_level_edges(
            xyz, level, point_tree, ok, cell if cell else LEVEL_CELL * spacing
        )
        if merge in ("overlap", "adaptive"):
            floor = spacing / NODE_SPACING if point_spacing is None else point_spacing
            # fine scale first: points of a level within ~2 point spacings always join
            # (a kNN graph leaves points at a level's edge alone in their level)
            fr, fc = _voxel_level_edges(xyz, level, point_tree, ok, floor)
            _union_pairs(root, fr, fc)
            lab = _canonical_labels(root)[1]
            wide = spacing if merge == "adaptive" else 0.0
            lab = _merge_overlapping(xyz, lab, vr, vc, floor, wide)
        elif (
            merge == "two-scale"
            and point_spacing
            and FINE_CELL * point_spacing < (cell if cell else LEVEL_CELL * spacing)
        ):
            # fine scale: pieces whose voxels touch at FINE_CELL point spacings are one
            # piece; coarse scale (the "adjacent" cell): pieces join only where the gap is
            # below their spreads or both are wider than the level (arcs of a stem ring)
            fr, fc = _voxel_level_edges(xyz, level, point_tree, ok, FINE_CELL * point_spacing)
            _union_pairs(root, fr, fc)
            lab = _canonical_labels(root)[1]
            lab = _merge_overlapping(xyz, lab, vr, vc, point_spacing, spacing)
        else:  # "adjacent": every voxel-adjacent piece of a level joins
            _union_pairs(root, vr, vc)
            lab = _canonical_labels(root)[1]
    else:
        lab = _canonical_labels(root)[1]
    del root
    # number the pieces holding kept points 0..m-1 in label order (np.unique's numbering)
    present = np.zeros(int(lab.max()) + 1 if n else 0, dtype=bool)
    present[lab[ok]] = True
    renumber = np.cumsum(present) - 1
    label = np.full(n, -1, dtype=np.int64)
    label[ok] = renumber[lab[ok]]
    m = int(present.sum())
    if merge in ("overlap", "adaptive") and spacing > 0:
        into = k + 1 if merge == "adaptive" else 0
        label, m = _absorb_fragments(g.tocoo(), label, ok, m, into)
    count = np.bincount(label[ok], minlength=m)
    pos = (
        np.stack(
            [np.bincount(label[ok], weights=xyz[ok, d], minlength=m) for d in range(3)], axis=1
        )
        / count[:, None]
    )
    d2 = np.sum((xyz[ok] - pos[label[ok]]) ** 2, axis=1)
    spread = np.sqrt(np.bincount(label[ok], weights=d2, minlength=m) / np.maximum(count, 1))
    vtree = np.zeros(m, dtype=np.int64)
    vtree[label[ok]] = point_tree[ok]
    vlevel = np.zeros(m, dtype=np.int64)
    vlevel[label[ok]] = level[ok]
    # root vertex per tree: its level-0 piece (or the lowest level present)
    ntree = int(vtree.max()) + 1 if m else 0
    roots = np.full(ntree, -1, dtype=np.int64)
    ordv = np.lexsort((vlevel, vtree))
    first_of_tree = np.unique(vtree[ordv], return_index=True)[1]
    roots[vtree[ordv[first_of_tree]]] = ordv[first_of_tree]
    # contracted neighbour graph Q
    key = np.unique(_cross_keys(g.indptr, g.indices, label, m))
    qr, qc = key // m, key % m
    # no edge between two trees' vertices: the points' segmentation is final, so the
    # spanning forest on Q (and its re-weighting) cannot move a stem from its tree
    same = vtree[qr] == vtree[qc]
    qr, qc = qr[same], qc[same]
    w = np.maximum(np.sum((pos[qr] - pos[qc]) ** 2, axis=1), 1e-18)
    q = sparse.coo_matrix((w, (qr, qc)), shape=(m, m)).tocsr()
    q = q.maximum(q.T).tocsr()
    return Contraction(label, pos, vtree, roots[roots >= 0], q, count, spread)
