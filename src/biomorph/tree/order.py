"""Branch order (seed 001 §5.2, "Asttiefe") and segmentation by order.

Breadth-first from each root (order 0). A node with one child passes its order on. At a
fork ``v`` (incoming edge ``e(u, v)``), the children ``w`` whose weight share
``c̃_w / Σ_j c̃_j`` exceeds ``weight_share`` (0.5) **and** whose edge ``e(v, w)`` turns by
less than ``max_angle`` (45°) from ``e(u, v)`` are candidates; the heaviest candidate
continues the parent's order, all other children start a new branch with order + 1.
``c̃`` is the carried length (subtree length including the child's edge). At a root the
incoming direction is ``+Z``.

:func:`segments` cuts the skeleton into branches: a new segment starts at every root and at
every child that got a higher order than its parent (or that is not the continuation at a
fork), so each segment is one branch of constant order, as TreeQSM's branches.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError

__all__ = ["branch_order", "continuation", "segments", "with_order"]


@numba.njit(cache=True)
def _continuation(parent, order, indptr, idx, carried, pos, share, cos_max):
    n = parent.size
    cont = np.full(n, -1, dtype=np.int64)   # the child continuing each node's branch
    for k in range(n):
        v = order[k]
        a = indptr[v]
        b = indptr[v + 1]
        if b == a:
            continue
        if b - a == 1:
            cont[v] = idx[a]
            continue
        p = parent[v]
        if p >= 0:
            ix = pos[v, 0] - pos[p, 0]
            iy = pos[v, 1] - pos[p, 1]
            iz = pos[v, 2] - pos[p, 2]
        else:
            ix, iy, iz = 0.0, 0.0, 1.0
        ln = np.sqrt(ix * ix + iy * iy + iz * iz)
        if ln == 0:
            ix, iy, iz, ln = 0.0, 0.0, 1.0, 1.0
        tot = 0.0
        for j in range(a, b):
            tot += carried[idx[j]]
        best = -1
        bestw = -1.0
        for j in range(a, b):
            w = idx[j]
            if tot <= 0 or carried[w] / tot <= share:
                continue
            ox = pos[w, 0] - pos[v, 0]
            oy = pos[w, 1] - pos[v, 1]
            oz = pos[w, 2] - pos[v, 2]
            lo = np.sqrt(ox * ox + oy * oy + oz * oz)
            if lo == 0:
                continue
            c = (ix * ox + iy * oy + iz * oz) / (ln * lo)
            if c <= cos_max:
                continue
            if carried[w] > bestw:
                bestw = carried[w]
                best = w
        cont[v] = best
    return cont


def continuation(graph: BranchGraph, weight_share: float = 0.5,
                 max_angle: float = np.radians(45.0)) -> NDArray[np.int64]:
    """For every node, the child that continues its branch (-1 if none)."""
    if not 0 <= weight_share < 1:
        raise ParameterError(f"weight_share must lie in [0, 1), got {weight_share}")
    if not 0 < max_angle <= np.pi:
        raise ParameterError(f"max_angle must lie in (0, pi] radians, got {max_angle}")
    indptr, idx = graph.children_csr
    carried = graph.subtree_sum(graph.edge_length)
    return _continuation(graph.parent, graph.order, indptr, idx, carried, graph.position,
                         float(weight_share), float(np.cos(max_angle)))


def branch_order(graph: BranchGraph, weight_share: float = 0.5,
                 max_angle: float = np.radians(45.0)) -> NDArray[np.int64]:
    """Branch order per node (0 = trunk); ``max_angle`` in radians."""
    cont = continuation(graph, weight_share, max_angle)
    par = graph.parent
    inc = np.zeros(graph.n_nodes)
    ch = np.flatnonzero(par >= 0)
    inc[ch] = (cont[par[ch]] != ch).astype(float)
    from biomorph.core import treeops

    return treeops.accumulate_down(par, inc, graph.order).astype(np.int64)


def segments(graph: BranchGraph, weight_share: float = 0.5,
             max_angle: float = np.radians(45.0)) -> NDArray[np.int64]:
    """Segment (branch) id per node: ids 0.. in topological order of the segment starts."""
    cont = continuation(graph, weight_share, max_angle)
    par = graph.parent
    n = graph.n_nodes
    start = np.ones(n, dtype=bool)
    ch = np.flatnonzero(par >= 0)
    start[ch] = cont[par[ch]] != ch
    order = graph.order
    sid = np.full(n, -1, dtype=np.int64)
    starts_in_order = order[start[order]]
    sid[starts_in_order] = np.arange(starts_in_order.size)
    _fill_segments(par, order, sid)
    return sid


@numba.njit(cache=True)
def _fill_segments(parent, order, sid):
    for k in range(order.size):
        v = order[k]
        if sid[v] < 0:
            sid[v] = sid[parent[v]]


def with_order(graph: BranchGraph, weight_share: float = 0.5,
               max_angle: float = np.radians(45.0)) -> BranchGraph:
    """The graph with ``depth`` set to the branch order."""
    return graph.with_(depth=branch_order(graph, weight_share, max_angle))
