"""The crown partition of a plot: which tree every point belongs to (issue 13).

Livny's segmentation (:func:`~biomorph.tree.neighbours.segment_trees`) hangs every point
from the stem whose shortest path (squared edge lengths) reaches it at least cost. Where
the scan is continuous that path is the wood's own connection. Where it is not -- the
upper stem of a tree hidden behind its neighbours' crowns, the sparse top of a suppressed
pine -- the cheapest path runs through a neighbour's dense crown, and the neighbour annexes
the top: it grows too tall, its trunk climbs into the other's top, and the robbed tree
comes out metres short (the TreeLS pine plot: a 15 m pine carried its neighbour's top
3 m sideways; synthetic stands, :func:`~biomorph.tree.synthetic.generate_stand`: heights
up to 5.7 m short).

:func:`partition_trees` keeps the shortest-path forest wherever it follows the wood and
re-decides only the pieces it reaches *across a gap* -- an edge longer than the bridging
rule's ``short`` gap (:data:`~biomorph.tree.neighbours.GAP_SHORT` node spacings). Such a
piece moves to another tree when two independent tests name the same tree:

* it continues that tree's **measured stem**: some of its points lie above the stem's
  measured top, within the bridging rule's direction limit
  (:data:`~biomorph.tree.neighbours.GAP_ANGLE`) of the stem's axis and no farther than the
  stem is long (the rule for bridging any gap: it must continue the piece and be no longer
  than it), and of all stems it continues, that one's top is the nearest;
* most of its points **stand over that stem**: horizontally nearest to its axis
  (extrapolated along the stem's lean) of all stems that reach their height -- the Voronoi
  partition of the stems that forest plot tools use where the scan cannot tell, here
  applied only where the graph has no wood to follow.

The same two tests adopt the pieces no root reaches at all -- the bridging rule refuses a
sparse top above a long occlusion gap, and its points dropped out of the skeleton. Every
moved or adopted piece is bridged to its new tree at their nearest points.

A measured stem is followed up from its root points (:func:`track_stems`), slab by slab,
through at most :data:`TRACK_GAPS` gaps' height of missing points; its axis is the line
from the stem's base centre to the highest point found on it. On the synthetic stands (4-7 conifers,
50-150 k points, 16 runs, ``bench/tree.py --only stand``) the graph method's share of points
on their true tree went 0.952 -> 0.988 and its worst height error per run 4.6 -> 0.8 m on
average, together with the contracted graph keeping to one tree per edge (figures in
docs/tree.md, session 16).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.tree.neighbours import GAP_ANGLE, _with_entries, segmentation_forest

__all__ = [
    "StemAxes",
    "TRACK_GAPS",
    "TRACK_WINDOW",
    "add_edges",
    "partition_trees",
    "same_tree_edges",
    "track_stems",
]

#: steepest stem axis used for the partition (a lean of at most 60 degrees from vertical)
MIN_AXIS_Z = 0.5


@dataclass
class StemAxes:
    """Per tree: ``base`` (the stem's centre at its root points) and ``top`` (the highest
    point found on the stem) of the measured stem, metres; ``ok`` where the stem rises
    more than two slabs above its base."""

    base: NDArray[np.float64]
    top: NDArray[np.float64]
    ok: NDArray[np.bool_]

    @property
    def length(self) -> NDArray[np.float64]:
        return np.asarray(np.linalg.norm(self.top - self.base, axis=1))

    def direction(self) -> NDArray[np.float64]:
        d = self.top - self.base
        n = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
        return np.asarray(d / n[:, None])


#: the stem tracker follows a stem through at most this many bridging gaps of height
#: without points (an occluded stretch of stem). Synthetic stands, 14 runs, mean worst
#: height error per run: 1, 2, 3, 4 gaps -> 1.17, 1.04, 1.12, 0.93 m; at 4 one plot pine's
#: trunk ends 2.4 m below its top (a neighbour's top piece), at 1-3 none by more than 1 m
TRACK_GAPS = 2.0

#: the stem tracker's lean estimate: a line fitted to the axis positions of this much
#: stem below the slab (metres), once they span half of it
TRACK_WINDOW = 2.0


def _stem_centre(xyz, zs, zsorted, base, radius, height, rounds=5):
    """The stem's centre (x, y) over ``height`` above ``base``: the mean of the points within
    ``radius`` of the current estimate, from the root points' centre (mean shift; root
    points often lie on the scanned side of the ring)."""
    lo, hi = np.searchsorted(zsorted, (base[2], base[2] + height))
    p = xyz[zs[lo:hi], :2]
    c = base[:2].copy()
    for _ in range(rounds):
        m = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]) <= radius
        if m.sum() < 3:
            break
        c = p[m].mean(axis=0)
    return c


def _track_one(xyz, zs, zsorted, base, r0, step, max_gap):
    """Follow one stem up from ``base`` (see :func:`track_stems`); returns the index of the
    highest point found on it (-1 if none)."""
    pos = base[:2].copy()
    radius = r0
    hist = [(float(base[2]), pos[0], pos[1])]
    z, empty, top = float(base[2]), 0.0, -1
    while empty <= max_gap:
        h = np.asarray(hist)
        w = h[h[:, 0] >= z - TRACK_WINDOW]
        pred = pos
        if w.shape[0] >= 4 and np.ptp(w[:, 0]) >= TRACK_WINDOW / 2:
            a = np.c_[w[:, 0] - z, np.ones(w.shape[0])]
            coef = np.linalg.lstsq(a, w[:, 1:], rcond=None)[0]
            pred = coef[1] + coef[0] * step
        lo, hi = np.searchsorted(zsorted, (z, z + step))
        idx = zs[lo:hi]
        near = idx[np.hypot(xyz[idx, 0] - pred[0], xyz[idx, 1] - pred[1]) <= radius]
        if near.size >= 3:
            pos = np.median(xyz[near, :2], axis=0)
            hist.append((z + step / 2, pos[0], pos[1]))
            spread = np.median(np.hypot(xyz[near, 0] - pos[0], xyz[near, 1] - pos[1]))
            radius = float(np.clip(2.0 * spread, step, r0))
            top = int(near[np.argmax(xyz[near, 2])])
            empty = 0.0
        else:
            pos = pred
            empty += step
        z += step
    return top


def track_stems(
    xyz: NDArray[np.float64],
    roots: NDArray[np.int64],
    root_tree: NDArray[np.int64],
    ntree: int,
    step: float,
    max_gap: float,
    zs: NDArray[np.int64] | None = None,
) -> StemAxes:
    """The measured stem of every tree, followed up from its root points slab by slab
    (``step`` high): the points of the slab (any tree's: the partition is what is being
    decided) within the search radius of the axis predicted by the lean of the last
    :data:`TRACK_WINDOW` metres; their median is the next axis position; the tracking
    stops when no slab has 3 points for more than ``max_gap`` of height. The base centre
    is the mean-shift centre of the lowest metre's points from the root points' centre
    (root points often lie on the scanned side of the ring). The search radius starts at
    twice the root points' RMS distance from their centre (at least two slabs' height)
    and follows the stem's taper: twice the median distance of the slab's points from the
    axis, never below one slab's height. ``zs``: the points' order by height, if known."""
    zs = np.argsort(xyz[:, 2], kind="stable") if zs is None else zs
    zsorted = xyz[zs, 2]
    base = np.zeros((ntree, 3))
    top = np.zeros((ntree, 3))
    ok = np.zeros(ntree, dtype=bool)
    for u in range(ntree):
        r = roots[root_tree == u]
        if r.size == 0:
            continue
        c = xyz[r].mean(axis=0)
        rms = float(np.sqrt(np.mean(np.sum((xyz[r, :2] - c[:2]) ** 2, axis=1))))
        radius = max(2.0 * rms, 2.0 * step)
        c[:2] = _stem_centre(xyz, zs, zsorted, c, 1.5 * radius, TRACK_WINDOW / 2)
        base[u] = top[u] = c
        hi = _track_one(xyz, zs, zsorted, c, radius, step, max_gap)
        if hi >= 0:
            top[u] = xyz[hi]
            ok[u] = xyz[hi, 2] - c[2] > 2 * step
    return StemAxes(base, top, ok)


def _owners(xyz: NDArray[np.float64], axes: StemAxes, block: int = 65536) -> NDArray[np.int64]:
    """Per point the tree whose stem axis (extrapolated up the stem's direction) passes
    horizontally nearest at the point's height, among stems whose measured top lies no
    more than the stem's length below the point (-1 if none)."""
    n = xyz.shape[0]
    out = np.full(n, -1, dtype=np.int64)
    cand = np.flatnonzero(axes.ok)
    if cand.size == 0:
        return out
    unit = axes.direction()[cand]
    d = unit / np.maximum(unit[:, 2:3], MIN_AXIS_Z)  # per metre of height
    b = axes.base[cand]
    reach_top = axes.top[cand, 2] + axes.length[cand] * np.maximum(unit[:, 2], 0)
    for s in range(0, n, block):
        p = xyz[s : s + block]
        dz = p[:, 2:3] - b[None, :, 2]
        ax = b[None, :, 0] + dz * d[None, :, 0]
        ay = b[None, :, 1] + dz * d[None, :, 1]
        h2 = (p[:, 0:1] - ax) ** 2 + (p[:, 1:2] - ay) ** 2
        h2[p[:, 2:3] > reach_top[None, :]] = np.inf
        j = np.argmin(h2, axis=1)
        good = np.isfinite(h2[np.arange(p.shape[0]), j])
        out[s : s + block] = np.where(good, cand[j], -1)
    return out


@numba.njit(cache=True)
def _preorder(indptr, indices, starts):  # pragma: no cover - numba
    """Depth-first preorder of a forest (children CSR) from ``starts``; ``pos[v]`` is
    v's index in it, so a subtree is the slice ``pre[pos[v] : pos[v] + size[v]]``."""
    n = indptr.size - 1
    pre = np.empty(n, dtype=np.int64)
    pos = np.full(n, -1, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    k = 0
    for s in starts:
        stack[0] = s
        top = 1
        while top > 0:
            top -= 1
            v = stack[top]
            pre[k] = v
            pos[v] = k
            k += 1
            for e in range(indptr[v + 1] - 1, indptr[v] - 1, -1):
                stack[top] = indices[e]
                top += 1
    return pre[:k], pos


def _cones(
    xyz: NDArray[np.float64], axes: StemAxes, zs: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Per point the tree whose measured stem it continues with the nearest stem top --
    above the top, within :data:`~biomorph.tree.neighbours.GAP_ANGLE` of the stem's axis,
    no farther than the stem is long -- and that distance (-1 and inf where none).
    ``zs``: the points' order by height."""
    n = xyz.shape[0]
    best = np.full(n, np.inf)
    who = np.full(n, -1, dtype=np.int64)
    dirs = axes.direction()
    zsorted = xyz[zs, 2]
    cos_max = np.cos(GAP_ANGLE)
    for u in np.flatnonzero(axes.ok):
        t = axes.top[u]
        length = float(axes.length[u])
        lo, hi = np.searchsorted(zsorted, (t[2], t[2] + length))
        idx = zs[lo:hi]
        v = xyz[idx] - t
        d = np.linalg.norm(v, axis=1)
        ahead = (v @ dirs[u] >= cos_max * d) & (d > 0) & (d <= length) & (d < best[idx])
        best[idx[ahead]] = d[ahead]
        who[idx[ahead]] = u
    return who, best


@numba.njit(cache=True)
def _subtree_argmin(parent, order, value):  # pragma: no cover - numba
    """Per node the node of its subtree with the least ``value``."""
    n = parent.size
    arg = np.arange(n)
    for k in range(order.size - 1, -1, -1):
        v = order[k]
        p = parent[v]
        if p >= 0 and value[arg[v]] < value[arg[p]]:
            arg[p] = arg[v]
    return arg


def partition_trees(
    xyz: NDArray[np.float64],
    graph: sparse.csr_matrix,
    roots: NDArray[np.int64],
    root_tree: NDArray[np.int64],
    gap: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The tree of every point of a plot (-1 where no root is reached) and the bridges
    ``(rows, cols)`` that join each re-assigned piece to its new tree (the nearest pair of
    points; add them to the graph before contracting).

    Livny's shortest-path forest (``graph``'s weights) from all root points; then, from
    the roots outwards, every piece the forest reaches across an edge longer than ``gap``
    (metres) moves to another tree when both tests name that tree: the measured stem it
    continues with the nearest stem top (:func:`_cones`) and the stem most of its points
    stand over (:func:`_owners`); the pieces no root reaches join a tree by the same
    tests (:func:`_adopt_unreached`). See the module doc."""
    n = xyz.shape[0]
    roots = np.asarray(roots, dtype=np.int64)
    root_tree = np.asarray(root_tree, dtype=np.int64)
    par, order, tree = segmentation_forest(graph, roots, root_tree)
    empty = np.zeros(0, dtype=np.int64)
    ntree = int(root_tree.max()) + 1 if root_tree.size else 0
    if ntree < 2 or not np.isfinite(gap):
        return tree, empty, empty
    has = par >= 0
    edge = np.zeros(n)
    edge[has] = np.linalg.norm(xyz[has] - xyz[par[has]], axis=1)
    cut = np.flatnonzero(has & (edge > gap) & (tree >= 0))
    if cut.size == 0 and np.all(tree >= 0):
        return tree, empty, empty
    zs = np.argsort(xyz[:, 2], kind="stable")
    axes = track_stems(xyz, roots, root_tree, ntree, gap / 2, TRACK_GAPS * gap, zs)
    who, dist = _cones(xyz, axes, zs)
    arg = _subtree_argmin(par, order, dist)  # each piece's point nearest a stem top
    owner = _owners(xyz, axes)
    indptr, indices = treeops.children_csr(par)
    pre, pos = _preorder(indptr, indices, np.flatnonzero((par < 0) & (tree >= 0)))
    size = treeops.subtree_sum(par, np.ones(n), order).astype(np.int64)
    cut = cut[np.argsort(treeops.depth(par, order)[cut], kind="stable")]  # roots outwards
    moved: list[tuple[NDArray[np.int64], int]] = []
    first = tree.copy()
    for v in cut:
        u = int(who[arg[v]])
        if u < 0 or u == tree[v]:
            continue  # continues no stem, or its own tree's
        members = pre[pos[v] : pos[v] + size[v]]
        own = owner[members]
        votes = np.bincount(own[own >= 0], minlength=ntree)
        if 2 * votes[u] <= members.size:
            continue  # most of it does not stand over that stem
        tree[members] = u
        moved.append((members, u))
    moved += _adopt_unreached(graph, tree, who, dist, owner, ntree)
    if not moved:
        return tree, empty, empty
    return tree, *_bridges(xyz, tree, first, moved)


def _adopt_unreached(
    graph: sparse.csr_matrix,
    tree: NDArray[np.int64],
    who: NDArray[np.int64],
    dist: NDArray[np.float64],
    owner: NDArray[np.int64],
    ntree: int,
) -> list[tuple[NDArray[np.int64], int]]:
    """The pieces no root reaches (the bridging rule refused them: a sparse top above an
    occluded stretch of stem) that pass both tests for one stem go to it (``tree`` is
    updated); returns them as ``(points, tree)``."""
    un = np.flatnonzero(tree < 0)
    if un.size == 0:
        return []
    sub = sparse.csr_matrix(graph)[un][:, un]
    _, lab = connected_components(sub, directed=False)
    order = np.argsort(lab, kind="stable")
    bounds = np.flatnonzero(np.r_[True, np.diff(lab[order]) != 0, True])
    out = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        members = un[order[a:b]]
        j = members[int(np.argmin(dist[members]))]
        u = int(who[j])
        if u < 0:
            continue
        own = owner[members]
        if 2 * np.bincount(own[own >= 0], minlength=ntree)[u] <= members.size:
            continue
        tree[members] = u
        out.append((members, u))
    return out


def _bridges(
    xyz: NDArray[np.float64],
    tree: NDArray[np.int64],
    first: NDArray[np.int64],
    moved: list[tuple[NDArray[np.int64], int]],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Edges that join every moved piece to the part of its new tree its root reaches:
    per tree, the points it kept from the shortest-path forest (``first``: the trees
    before any move) are joined; then, nearest first, the piece closest to the joined part
    is bridged to it at their nearest pair of points and joins it (Prim's order: a piece
    hangs from a nearer moved piece rather than across the whole crown)."""
    rows: list[int] = []
    cols: list[int] = []
    by_tree: dict[int, list[NDArray[np.int64]]] = {}
    for members, u in moved:
        members = members[tree[members] == u]
        if members.size:
            by_tree.setdefault(u, []).append(members)
    for u, pieces in by_tree.items():
        joined = np.flatnonzero((tree == u) & (first == u))
        while pieces and joined.size:
            kd = cKDTree(xyz[joined])
            best = (np.inf, -1, -1, -1)
            for i, members in enumerate(pieces):
                d, j = kd.query(xyz[members], k=1)
                k = int(np.argmin(d))
                if d[k] < best[0]:
                    best = (float(d[k]), i, int(members[k]), int(joined[j[k]]))
            _, i, r, c = best
            rows.append(r)
            cols.append(c)
            joined = np.concatenate([joined, pieces.pop(i)])
    return np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)


def add_edges(
    xyz: NDArray[np.float64], graph: sparse.csr_matrix, rows: NDArray, cols: NDArray
) -> sparse.csr_matrix:
    """``graph`` (squared-length weights) with the edges ``rows[i] - cols[i]`` added where
    it has none yet (in either direction)."""
    if rows.size == 0:
        return graph
    g = sparse.csr_matrix(graph)
    new = (np.asarray(g[rows, cols]).ravel() == 0) & (np.asarray(g[cols, rows]).ravel() == 0)
    r, c = rows[new], cols[new]
    if r.size == 0:
        return g
    w = np.maximum(np.sum((xyz[r] - xyz[c]) ** 2, axis=1), 1e-18)
    return _with_entries(g, r, c, w)


def same_tree_edges(graph: sparse.csr_matrix, tree: NDArray[np.int64]) -> sparse.csr_matrix:
    """A copy of ``graph`` without the edges that join points of two trees (or a point of
    no tree)."""
    g = sparse.csr_matrix(graph)
    rows = np.repeat(np.arange(g.shape[0]), np.diff(g.indptr))
    keep = (tree[rows] == tree[g.indices]) & (tree[rows] >= 0)
    counts = np.bincount(rows[keep], minlength=g.shape[0])
    indptr = np.zeros(g.shape[0] + 1, dtype=g.indptr.dtype)
    np.cumsum(counts, out=indptr[1:])
    return sparse.csr_matrix((g.data[keep], g.indices[keep], indptr), shape=g.shape)
