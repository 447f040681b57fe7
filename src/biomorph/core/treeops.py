"""Traversal kernels over parent-index forests (no recursion, O(n), 10^6 nodes in milliseconds).

A forest is an ``int[n]`` parent array with -1 at roots. ``order`` is a topological order
(every parent before its children), as returned by :func:`topological_order`.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order

from biomorph.errors import InputError


def children_csr(parent: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Children of every node as CSR ``(indptr, indices)``: children of ``i`` are
    ``indices[indptr[i]:indptr[i+1]]``, in increasing index order."""
    parent = np.asarray(parent, dtype=np.int64)
    n = parent.size
    child = np.flatnonzero(parent >= 0)
    order = np.argsort(parent[child], kind="stable")
    indices = child[order]
    counts = np.bincount(parent[child], minlength=n)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    return indptr, indices.astype(np.int64)


def main_child(parent: ArrayLike, weight: ArrayLike) -> NDArray[np.int64]:
    """Per node, its child of largest ``weight`` (ties: the lower index); -1 at tips."""
    par = np.asarray(parent, dtype=np.int64)
    w = np.asarray(weight, dtype=np.float64)
    c = np.flatnonzero(par >= 0)
    o = c[np.lexsort((c, -w[c], par[c]))]
    first = np.ones(o.size, dtype=bool)
    first[1:] = par[o[1:]] != par[o[:-1]]
    main = np.full(par.size, -1, dtype=np.int64)
    main[par[o[first]]] = o[first]
    return main


def per_label(labels: ArrayLike, values: ArrayLike, reduce: np.ufunc = np.maximum) -> NDArray:
    """Per element, the ``reduce`` (an idempotent ufunc: ``np.maximum`` or ``np.minimum``)
    of ``values`` over all elements sharing its label (e.g. a tree's highest node)."""
    v = np.asarray(values)
    _, first, inv = np.unique(np.asarray(labels), return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    out = v[first].copy()
    reduce.at(out, inv, v)
    return out[inv]


def topological_order(parent: ArrayLike) -> NDArray[np.int64]:
    """Breadth-first order from all roots (parents before children).

    Raises :class:`InputError` if the parent array has a cycle or an index out of range.
    """
    parent = np.asarray(parent, dtype=np.int64)
    n = parent.size
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if parent.max(initial=-1) >= n or parent.min(initial=-1) < -1:
        raise InputError(f"parent index out of range [-1, {n - 1}]")
    # A virtual node n joined to every root turns the forest into one tree for csgraph.
    src = np.where(parent >= 0, parent, n)
    adj = csr_matrix((np.ones(n, dtype=np.int8), (src, np.arange(n))), shape=(n + 1, n + 1))
    order = breadth_first_order(adj, n, directed=True, return_predecessors=False)
    order = order[1:]
    if order.size != n:
        raise InputError(f"parent array has a cycle: only {order.size} of {n} nodes reach a root")
    return order.astype(np.int64)


@numba.njit(cache=True)
def _subtree_sum(parent: np.ndarray, order: np.ndarray, values: np.ndarray) -> np.ndarray:
    acc = values.copy()
    for k in range(order.size - 1, -1, -1):
        i = order[k]
        p = parent[i]
        if p >= 0:
            acc[p] += acc[i]
    return acc


@numba.njit(cache=True)
def _accumulate_down(parent: np.ndarray, order: np.ndarray, values: np.ndarray) -> np.ndarray:
    acc = values.copy()
    for k in range(order.size):
        i = order[k]
        p = parent[i]
        if p >= 0:
            acc[i] += acc[p]
    return acc


@numba.njit(cache=True)
def _cap_down(parent: np.ndarray, order: np.ndarray, values: np.ndarray, factor: np.ndarray):
    out = values.copy()
    for k in range(order.size):
        v = order[k]
        p = parent[v]
        if p >= 0 and out[v] > factor[v] * out[p]:
            out[v] = factor[v] * out[p]
    return out


def cap_down(
    parent: ArrayLike, values: ArrayLike, factor: ArrayLike, order: ArrayLike | None = None
) -> NDArray[np.float64]:
    """``values`` with every node limited to ``factor`` (per node) times its parent's
    already limited value, parents first (a branch no thicker than the stem carrying it)."""
    parent = np.asarray(parent, dtype=np.int64)
    order = topological_order(parent) if order is None else np.asarray(order, dtype=np.int64)
    return _cap_down(
        parent,
        order,
        np.asarray(values, dtype=np.float64),
        np.broadcast_to(np.asarray(factor, dtype=np.float64), parent.shape).copy(),
    )


def subtree_sum(
    parent: ArrayLike, values: ArrayLike, order: ArrayLike | None = None
) -> NDArray[np.float64]:
    """For every node, the sum of ``values`` over its subtree (itself included)."""
    parent = np.asarray(parent, dtype=np.int64)
    order = topological_order(parent) if order is None else np.asarray(order, dtype=np.int64)
    return _subtree_sum(parent, order, np.asarray(values, dtype=np.float64))


def accumulate_down(
    parent: ArrayLike, values: ArrayLike, order: ArrayLike | None = None
) -> NDArray[np.float64]:
    """For every node, the sum of ``values`` over the path root..node (both included)."""
    parent = np.asarray(parent, dtype=np.int64)
    order = topological_order(parent) if order is None else np.asarray(order, dtype=np.int64)
    return _accumulate_down(parent, order, np.asarray(values, dtype=np.float64))


def depth(parent: ArrayLike, order: ArrayLike | None = None) -> NDArray[np.int64]:
    """Number of ancestors of each node (roots 0)."""
    parent = np.asarray(parent, dtype=np.int64)
    ones = (parent >= 0).astype(np.float64)
    return accumulate_down(parent, ones, order).astype(np.int64)


def root_of(parent: ArrayLike, order: ArrayLike | None = None) -> NDArray[np.int64]:
    """Index of the root of each node's tree."""
    parent = np.asarray(parent, dtype=np.int64)
    order = topological_order(parent) if order is None else np.asarray(order, dtype=np.int64)
    root = np.arange(parent.size, dtype=np.int64)
    for_nodes = order[parent[order] >= 0]
    # parents are visited first, so one ordered gather pass suffices
    _propagate_root(parent, for_nodes, root)
    return root


@numba.njit(cache=True)
def _propagate_root(parent: np.ndarray, nodes: np.ndarray, root: np.ndarray) -> None:
    for k in range(nodes.size):
        i = nodes[k]
        root[i] = root[parent[i]]
