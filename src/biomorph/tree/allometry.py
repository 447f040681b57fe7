"""Shared allometry and point-to-skeleton helpers of the graph, voxel and radius code.

* :func:`allometric_radii` -- the pipe model ``r_v = r_u (c̃_v / c̃_u)^(1/exponent)`` scaled
  per tree by the mean point-to-skeleton distance (Livny et al. 2010 step vii; the
  derivation is in :mod:`biomorph.tree.livny`);
* :func:`skeleton_distance` -- distance of every point to the skeleton polyline;
* :func:`edge_length` -- length of each node's incoming edge.

Split out of :mod:`biomorph.tree.livny` (issue 12).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.tree.neighbours import grid_nearest_label

__all__ = ["allometric_radii", "skeleton_distance", "edge_length"]


def edge_length(parent: NDArray[np.int64], position: NDArray[np.float64]) -> NDArray:
    out = np.zeros(parent.size)
    ch = parent >= 0
    out[ch] = np.linalg.norm(position[ch] - position[parent[ch]], axis=1)
    return out


def allometric_radii(
    parent: NDArray[np.int64],
    position: NDArray[np.float64],
    weight: NDArray[np.float64],
    mean_distance: NDArray[np.float64] | float,
    tree: NDArray[np.int64] | None = None,
    exponent: float = 2.5,
    order=None,
) -> NDArray[np.float64]:
    """Step vii: radii with ``r_v = r_u (c̃_v / c̃_u)^(1/exponent)`` along every edge
    (ΣR = 0) scaled per tree so that ``Σ c̃ r / Σ c̃`` equals the mean point-to-skeleton
    distance of that tree (ΣD). ``c̃_v = c_v + |e(v_p, v)|`` (the carried length including
    the node's own edge, so tips are not zero). Metres."""
    parent = np.asarray(parent, dtype=np.int64)
    order = treeops.topological_order(parent) if order is None else order
    el = edge_length(parent, position)
    ct = np.asarray(weight, dtype=float) + el
    floor = max(float(np.median(el[el > 0])) if (el > 0).any() else 1e-3, 1e-6) * 1e-3
    ct = np.maximum(ct, floor)
    ch = parent >= 0
    logratio = np.zeros(parent.size)
    logratio[ch] = np.log(ct[ch] / ct[parent[ch]]) / exponent
    logr = treeops.accumulate_down(parent, logratio, order)
    rel = np.exp(logr)  # radius relative to the root (root = 1)
    root = treeops.root_of(parent, order)
    tree = root if tree is None else np.asarray(tree)
    _, tix = np.unique(tree, return_inverse=True)
    tix = tix.reshape(-1)
    num = np.bincount(tix, weights=ct)
    den = np.bincount(tix, weights=ct * rel)
    md = np.broadcast_to(np.asarray(mean_distance, dtype=float), num.shape)
    scale = md * num / np.maximum(den, 1e-30)
    return rel * scale[tix]


def skeleton_distance(
    points: NDArray[np.float64],
    parent: NDArray[np.int64],
    position: NDArray[np.float64],
    step: float | None = None,
    *,
    order: NDArray | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Distance of every point to the skeleton polyline (metres) and the nearest node.

    Edges are sampled every ``step`` (default a quarter of the median edge length), so the
    error is at most ``step/2``. The nearest node is the parent or child end of the edge
    sample, whichever is closer along the edge. ``order``: a spatial order of ``points``
    (the leaf order of their k-d tree) for :func:`~biomorph.tree.neighbours.grid_nearest_label`,
    which answers as ``cKDTree(samples).query(points)``.
    """
    ch = np.flatnonzero(parent >= 0)
    if ch.size == 0:
        d, i = cKDTree(position).query(points)
        return d, i.astype(np.int64)
    el = edge_length(parent, position)[ch]
    step = step or max(float(np.median(el)) / 4, 1e-6)
    m = np.maximum(np.ceil(el / step).astype(np.int64), 1)
    eid = np.repeat(np.arange(ch.size), m + 1)
    start = np.repeat(np.cumsum(m + 1) - (m + 1), m + 1)
    t = (np.arange(eid.size) - start) / m[eid]
    a = position[parent[ch]][eid]
    b = position[ch][eid]
    samples = a + t[:, None] * (b - a)
    node = np.where(t < 0.5, parent[ch][eid], ch[eid])
    # a node's position repeats as the start of each edge leaving it (exactly) and, mostly,
    # as the end of the edge reaching it: the grid searches one of each, the answer is
    # the same (same point, same node)
    keep = t > 0
    start_of = np.flatnonzero(t == 0)  # one per edge, in edge order
    keep[start_of[np.unique(parent[ch], return_index=True)[1]]] = True
    n_kids = np.bincount(parent[ch], minlength=parent.size)
    end = np.flatnonzero(t == 1)
    c = ch[eid[end]]
    keep[end[(n_kids[c] > 0) & (samples[end] == position[c]).all(axis=1)]] = False
    # the k-d tree's answers, from a grid of the samples (ties of one node decide; other
    # ties, far points: the tree of all the samples)
    return grid_nearest_label(
        samples[keep],
        np.asarray(points, dtype=np.float64),
        node[keep],
        order=order,
        ties=2,
        full=(samples, node),
    )
