"""Skeleton cleanup after Livny et al. 2010, step viii (seed 001 §2.4 viii, §3.4 viii).

1. :func:`remove_false_branches` — false branches on thick stems (the Dijkstra tree over
   surface points sprouts short spurs on the trunk) are removed whole when their radius is
   much smaller than the stem's (*radius contrast*) **and** they are short relative to the
   stem radius; optionally any side branch shorter than ``min_length``.
2. :func:`collapse_overlaps` — branches as generalised cylinders (radius per edge = mean of
   its end radii). Rule 1 (fork ``u → {v, w}``): if the part of cylinder ``(u, w)`` inside
   cylinder ``(u, v)`` exceeds ``overlap`` (½) of ``(u, w)``, ``w`` merges with ``u`` or ``v``
   (the nearer). Rule 2 (chain ``u → v → w``, ``v`` with one child): if cylinder
   ``(u, v + (v − u))`` holds more than ½ of ``(v, w)``, ``u`` and ``v`` merge. Merged vertex
   at ``(c_u u + c_v v) / (c_u + c_v)``; repeated until no edge qualifies, shortest pairs
   first (as in the thesis).

The overlap volume is approximated by the fraction of the second cylinder's *axis* inside the
first cylinder (closed form per pair; exact for thin second cylinders); the thesis used the
same ray-intersection simplification.
"""

from __future__ import annotations

import math
from itertools import chain

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.core.curves import kasa_circle, segment_projection
from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree.neighbours import query_workers, segment_cover

__all__ = [
    "remove_false_branches",
    "collapse_overlaps",
    "cleanup",
    "cleanup_skeleton",
    "axis_inside_fraction",
    "smooth_chains",
    "prune_small_trees",
    "tip_chains",
    "prune_unsupported_tips",
    "prune_empty_tips",
    "empty_tips",
    "inside_wood",
    "EMPTY_REACH",
    "EMPTY_SHARE",
    "merge_inside_tips",
]


def _carried(graph: BranchGraph) -> NDArray[np.float64]:
    """Subtree length including the node's own incoming edge (metres)."""
    return graph.subtree_sum(graph.edge_length)


def remove_false_branches(
    graph: BranchGraph,
    *,
    radius_ratio: float = 0.5,
    length_factor: float = 3.0,
    min_length: float = 0.0,
) -> BranchGraph:
    """Remove side branches that are thin **and** short next to their parent stem.

    A child ``v`` of a fork ``u`` (not the heaviest child) is removed with its subtree if
    ``r_v / r_u < radius_ratio`` and its carried length ``< length_factor * r_u``, or if its
    carried length is below ``min_length`` (metres). Needs ``graph.radius``.
    """
    if graph.radius is None:
        raise ParameterError("remove_false_branches needs radii (run allometric_radii first)")
    n = graph.n_nodes
    if n < 3:
        return graph
    ct = _carried(graph)
    par = graph.parent
    ch = np.flatnonzero(par >= 0)
    # heaviest child of each node
    heavy = np.full(n, -1, dtype=np.int64)
    best = np.full(n, -np.inf)
    order = np.lexsort((ch, ct[ch]))
    for v in ch[order]:  # ascending weight: the last write per parent is the heaviest
        heavy[par[v]] = v
        best[par[v]] = ct[v]
    side = ch[(graph.n_children[par[ch]] >= 2) & (heavy[par[ch]] != ch)]
    r = graph.radius
    u = par[side]
    thin = r[side] < radius_ratio * np.maximum(r[u], 1e-12)
    short = ct[side] < length_factor * r[u]
    bad = side[(thin & short) | (ct[side] < min_length)]
    if bad.size == 0:
        return graph
    flag = np.zeros(n)
    flag[bad] = 1.0
    removed = treeops.accumulate_down(par, flag, graph.order) > 0
    return graph.subgraph(~removed)


def axis_inside_fraction(
    a: NDArray, d1: NDArray, len1: NDArray, rad1: NDArray, b: NDArray, d2: NDArray, len2: NDArray
) -> NDArray[np.float64]:
    """Fraction of segment ``b + s d2, s ∈ [0, len2]`` inside the cylinder
    ``a + t d1, t ∈ [0, len1]`` of radius ``rad1`` (``d1``, ``d2`` unit vectors, rows).

    Exact for a segment that starts inside the cylinder (as in both rules); the inside part
    is the interval from ``s = 0`` to the first exit through the mantle or a cap.
    """
    rel = b - a
    t0 = np.einsum("ij,ij->i", rel, d1)
    cos = np.einsum("ij,ij->i", d2, d1)
    perp0 = rel - t0[:, None] * d1
    pd = d2 - cos[:, None] * d1
    # |perp0 + s pd|^2 = R^2: quadratic in s
    qa = np.einsum("ij,ij->i", pd, pd)
    qb = 2 * np.einsum("ij,ij->i", perp0, pd)
    qc = np.einsum("ij,ij->i", perp0, perp0) - rad1**2
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = np.maximum(qb * qb - 4 * qa * qc, 0.0)
        s_mantle = np.where(qa > 1e-18, (-qb + np.sqrt(disc)) / (2 * qa), np.inf)
        s_cap = np.where(cos > 1e-12, (len1 - t0) / cos, np.where(cos < -1e-12, -t0 / cos, np.inf))
    s_exit = np.minimum(np.maximum(s_mantle, 0), np.maximum(s_cap, 0))
    inside0 = (qc <= 1e-12) & (t0 >= -1e-12) & (t0 <= len1 + 1e-12)
    frac = np.minimum(s_exit, len2) / np.maximum(len2, 1e-300)
    return np.where(inside0, frac, 0.0)


def _unit(v: NDArray) -> tuple[NDArray, NDArray]:
    n = np.linalg.norm(v, axis=1)
    return v / np.maximum(n, 1e-300)[:, None], n


def _candidates(
    graph: BranchGraph, overlap: float, max_edge: float | None, min_radius: float = 0.0
):
    """``(keep, drop, dist)`` merge candidates of both rules for the current graph."""
    par = graph.parent
    pos = graph.position
    r = graph.radius
    indptr, idx = graph.children_csr
    nch = graph.n_children
    keeps, drops, dists = [], [], []
    # ---- rule 1: forks
    forks = np.flatnonzero(nch >= 2)
    if forks.size:
        k = nch[forks]
        # all ordered pairs (v, w) of distinct children of each fork
        starts = indptr[forks]
        pair_fork = np.repeat(forks, k * k)
        base = np.repeat(starts, k * k)
        kk = np.repeat(k, k * k)
        local = np.arange(pair_fork.size) - np.repeat(np.cumsum(k * k) - k * k, k * k)
        v = idx[base + local // kk]
        w = idx[base + local % kk]
        m = v != w
        u, v, w = pair_fork[m], v[m], w[m]
        dv, lv = _unit(pos[v] - pos[u])
        dw, lw = _unit(pos[w] - pos[u])
        rv = np.maximum(0.5 * (r[u] + r[v]), min_radius)
        frac = axis_inside_fraction(pos[u], dv, lv, rv, pos[u], dw, lw)
        hit = (frac > overlap) & (lw > 0)
        # w merges with the nearer of u and v
        u, v, w = u[hit], v[hit], w[hit]
        du = np.linalg.norm(pos[w] - pos[u], axis=1)
        dvw = np.linalg.norm(pos[w] - pos[v], axis=1)
        tgt = np.where(dvw < du, v, u)
        keeps.append(tgt)
        drops.append(w)
        dists.append(np.minimum(du, dvw))
    # ---- rule 1b: a child w of a fork u lying inside the cylinder of u's own incoming
    # edge (u -> parent p): a chain running back along the stem it left (the far side of
    # a thick stem's ring, a level behind) -- rule 1 only compares the children
    w = np.flatnonzero(par >= 0)
    u = par[w]
    ok = (nch[u] >= 2) & (par[u] >= 0)
    w, u = w[ok], u[ok]
    if w.size:
        p = par[u]
        d1, l1 = _unit(pos[p] - pos[u])
        d2, l2 = _unit(pos[w] - pos[u])
        rad = np.maximum(0.5 * (r[p] + r[u]), min_radius)
        frac = axis_inside_fraction(pos[u], d1, l1, rad, pos[u], d2, l2)
        hit = (frac > overlap) & (l1 > 0) & (l2 > 0)
        keeps.append(u[hit])
        drops.append(w[hit])
        dists.append(l2[hit])
    # ---- rule 2: chains u -> v -> w
    chain = np.flatnonzero((nch == 1) & (par >= 0))
    if chain.size:
        v = chain
        u = par[v]
        w = idx[indptr[v]]
        ok = par[u] >= 0  # never move a root
        v, u, w = v[ok], u[ok], w[ok]
        d1, l1 = _unit(pos[v] - pos[u])
        d2, l2 = _unit(pos[w] - pos[v])
        rad = 0.5 * (r[u] + r[v])
        frac = axis_inside_fraction(pos[u], d1, 2 * l1, rad, pos[v], d2, l2)
        hit = (frac > overlap) & (l1 > 0) & (l2 > 0)
        if max_edge is not None:
            hit &= np.linalg.norm(pos[w] - pos[u], axis=1) <= max_edge
        keeps.append(u[hit])
        drops.append(v[hit])
        dists.append(l1[hit])
    if not keeps:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    return (
        np.concatenate(keeps).astype(np.int64),
        np.concatenate(drops).astype(np.int64),
        np.concatenate(dists),
    )


@numba.njit(cache=True)
def _merge_round(keep, drop, order, par, pos, rad, c, removed, redirect):  # pragma: no cover
    """One round of :func:`collapse_overlaps`: the candidates in ``order`` (shortest
    first), each merged unless one of its nodes or their parents took part in an earlier
    merge of the round; ``drop`` moves into ``keep`` (weighted by ``c``), in place."""
    used = np.zeros(par.size, dtype=np.bool_)
    for i in order:
        a, b = keep[i], drop[i]
        pa, pb = par[a], par[b]
        if used[a] or used[b] or (pa >= 0 and used[pa]) or (pb >= 0 and used[pb]):
            continue
        used[a] = True
        used[b] = True
        if pa >= 0:
            used[pa] = True
        if pb >= 0:
            used[pb] = True
        ca, cb = c[a], c[b]
        for j in range(3):
            pos[a, j] = (ca * pos[a, j] + cb * pos[b, j]) / (ca + cb)
        rad[a] = (ca * rad[a] + cb * rad[b]) / (ca + cb)
        removed[b] = True
        redirect[b] = a


def collapse_overlaps(
    graph: BranchGraph,
    *,
    overlap: float = 0.5,
    max_edge: float | None = None,
    max_rounds: int = 200,
    min_radius: float = 0.0,
) -> BranchGraph:
    """Apply both cylinder-overlap rules until stable (see module doc).

    ``max_edge`` (metres) caps the length of edges rule 2 may create (``None``: no cap).
    ``min_radius`` (metres) floors the cylinder radius of rule 1 (forks): a skeleton built
    from noisy points runs spurs a range-noise width beside thin twigs, outside their
    allometric cylinders (see ``MIN_CYLINDER_RADIUS`` in :mod:`biomorph.tree.pipeline`).
    Rule 2 keeps the allometric radius: with the floor there, stem chains of small trees
    collapsed further and the DBH moved by +9–18 % on two real clouds.
    Each round merges a conflict-free set of candidates, shortest first; weights ``c`` are
    recomputed from the new geometry between rounds.
    """
    if graph.radius is None:
        raise ParameterError("collapse_overlaps needs radii (run allometric_radii first)")
    if not 0 < overlap < 1:
        raise ParameterError(f"overlap must lie in (0, 1), got {overlap}")
    if not (min_radius >= 0 and np.isfinite(min_radius)):
        raise ParameterError(f"minimum cylinder radius must be >= 0 metres, got {min_radius}")
    for _ in range(max_rounds):
        keep, drop, dist = _candidates(graph, overlap, max_edge, min_radius)
        if keep.size == 0:
            break
        n = graph.n_nodes
        par = graph.parent.copy()
        pos = graph.position.copy()
        rad = graph.radius.copy()
        c = graph.subtree_length() + 1e-9
        removed = np.zeros(n, dtype=bool)
        redirect = np.arange(n)
        _merge_round(
            keep, drop, np.argsort(dist, kind="stable"), par, pos, rad, c, removed, redirect
        )
        if not removed.any():
            break
        par = np.where(par >= 0, redirect[np.maximum(par, 0)], -1)
        par[removed] = -1
        g2 = graph.with_(
            position=pos,
            parent=par,
            radius=rad,
            weight=None if graph.weight is None else graph.weight,
        )
        graph = g2.subgraph(~removed)
        graph = graph.with_(weight=graph.subtree_length())
    return graph


def prune_small_trees(graph: BranchGraph, min_length: float) -> BranchGraph:
    """Drop whole trees whose total skeleton length is below ``min_length`` (metres)."""
    if graph.n_nodes == 0:
        return graph
    t = graph.trees
    _, inv = np.unique(t, return_inverse=True)
    tot = np.bincount(inv.reshape(-1), weights=graph.edge_length)
    keep = tot[inv] >= min_length
    return graph if keep.all() else graph.subgraph(keep)


def cleanup(
    graph: BranchGraph,
    *,
    radius_ratio: float = 0.5,
    length_factor: float = 3.0,
    min_length: float = 0.0,
    overlap: float = 0.5,
    max_edge: float | None = None,
    min_radius: float = 0.0,
) -> BranchGraph:
    """Step viii: collapse overlapping cylinders, then remove false branches (the order the
    thesis found better), then collapse again until nothing changes."""
    g = collapse_overlaps(graph, overlap=overlap, max_edge=max_edge, min_radius=min_radius)
    for _ in range(10):
        n0 = g.n_nodes
        g = remove_false_branches(
            g, radius_ratio=radius_ratio, length_factor=length_factor, min_length=min_length
        )
        g = collapse_overlaps(g, overlap=overlap, max_edge=max_edge, min_radius=min_radius)
        if g.n_nodes == n0:
            break
    return g.with_(weight=g.subtree_length())


def smooth_chains(graph: BranchGraph, iterations: int = 2) -> BranchGraph:
    """Smooth the skeleton along its branches: every node with a parent and exactly one
    child moves to ``(p + 2 v + c) / 4``, ``iterations`` times (Jacobi sweeps); roots,
    forks and tips stay where they are.

    Why: vertices are centroids of point pieces (or fitted circle centres after
    re-centring), each off the branch axis by a few millimetres of noise. Such a zig-zag
    adds length quadratically in the lateral noise over the node spacing: on the synthetic
    presets it inflated TBL by up to 11 % (conifer); two sweeps remove it (98–105 %) and
    raise skeleton F1. A straight, evenly spaced chain is a fixed point (tested), and a
    sweep moves a node of a circular arc inwards by ``(1 − cos θ) / 2`` of the radius
    (θ the angle per edge), well below the node spacing.
    """
    if iterations < 0:
        raise ParameterError(f"smoothing iterations must be >= 0, got {iterations}")
    if iterations == 0 or graph.n_nodes < 3:
        return graph
    par = graph.parent
    inner = np.flatnonzero((par >= 0) & (graph.n_children == 1))
    if inner.size == 0:
        return graph
    child = np.full(graph.n_nodes, -1, dtype=np.int64)
    ch = np.flatnonzero(par >= 0)
    child[par[ch]] = ch  # the only child, for one-child nodes
    pos = graph.position.copy()
    pi, ci = par[inner], child[inner]
    for _ in range(iterations):
        pos[inner] = 0.25 * pos[pi] + 0.5 * pos[inner] + 0.25 * pos[ci]
    return graph.with_(position=pos)


#: alias exported by :mod:`biomorph.tree` (``cleanup`` is also the module's name there)
cleanup_skeleton = cleanup


def tip_chains(graph: BranchGraph) -> NDArray[np.int64]:
    """Label of the tip chain each node belongs to (the chain's top node), ``-1`` elsewhere.

    A tip chain is the unbranched run of nodes from a tip up to (not including) the nearest
    fork; a tree without forks is one chain whose top is its root."""
    n = graph.n_nodes
    leaf = np.zeros(n)
    leaf[graph.leaves] = 1.0
    lc = graph.subtree_sum(leaf)
    par = graph.parent
    top = (lc == 1) & ((par < 0) | (lc[np.maximum(par, 0)] > 1))
    val = np.where(top, np.arange(n) + 1.0, 0.0)
    lab = treeops.accumulate_down(par, val, graph.order)
    return np.where(lc == 1, lab - 1, -1).astype(np.int64)


def _side_chains(
    graph: BranchGraph,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray]:
    """The side tip chains (those not starting at a root): the :func:`tip_chains` labels,
    the chains' nodes, each node's chain index into ``tops`` (the chains' top nodes), and
    the chains' lengths (m)."""
    lab = tip_chains(graph)
    side = np.flatnonzero((lab >= 0) & (graph.parent[np.maximum(lab, 0)] >= 0))
    tops, inv = np.unique(lab[side], return_inverse=True)
    clen = np.bincount(inv, weights=graph.edge_length[side], minlength=tops.size)
    return lab, side, inv, tops, clen


def _without_chains(graph: BranchGraph, lab: NDArray[np.int64], bad: NDArray) -> BranchGraph:
    """``graph`` without the tip chains whose tops are ``bad`` (``weight`` recomputed)."""
    if bad.size == 0:
        return graph
    g = graph.subgraph(~np.isin(lab, bad))
    return g.with_(weight=g.subtree_length())


def prune_unsupported_tips(
    graph: BranchGraph, xyz: NDArray[np.float64], ratio: float = 0.3, max_length: float = np.inf
) -> BranchGraph:
    """Remove side tip chains (:func:`tip_chains`) shorter than ``max_length`` metres that
    hold fewer points per node than ``ratio`` × the median over all side tip chains (every
    point of ``xyz`` counts for its nearest node).

    Why: on dense leafy scans (240,000 points, 5 % leaf clutter) a twig tip surrounded by
    leaves grows extra tip chains through the clutter; each rests on a point or two per node
    where the twigs of the same scan have several (measured on the leafy maple's final
    skeleton: median 0.8 against 2.9 points per node). Where twigs themselves are sparsely
    sampled (60,000 points) real twig tips look the same and are lost, hence off by default
    in ``skeletonize``.
    """
    if not 0 < ratio < 1:
        raise ParameterError(
            f"tip support ratio must lie in (0, 1) (a share of the median "
            f"points per node of the tip chains), got {ratio}"
        )
    if graph.n_nodes < 3:
        return graph
    lab, side, inv, tops, clen = _side_chains(graph)
    if side.size == 0:
        return graph
    _, owner = cKDTree(graph.position).query(xyz, workers=-1)
    per_node = np.bincount(owner, minlength=graph.n_nodes).astype(float)
    dens = np.bincount(inv, weights=per_node[side]) / np.bincount(inv)
    return _without_chains(graph, lab, tops[(dens < ratio * np.median(dens)) & (clen < max_length)])


#: a node is *empty* when no point lies within this many point spacings of it: a twig's
#: axis is at most its radius from its surface points, and the twigs the taper model draws
#: without a circle fit are at most 2 point spacings thick (``radius.CENTROID_MAX_RADIUS``),
#: plus one spacing for the gap between two samples
EMPTY_REACH = 3.0
#: ... and a chain goes when at least this share of its nodes is empty: the clutter chains
#: are about half empty (their centroids alternate between scattered points and the gaps);
#: at 2/3 the noisy conifer keeps NOB 178 % of 185 % (60,000 points, seed 0)
EMPTY_SHARE = 0.5


def empty_tips(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    spacing: float,
    max_length: float = np.inf,
    kdtree: cKDTree | None = None,
) -> NDArray[np.bool_]:
    """Nodes of the side tip chains (:func:`tip_chains`) shorter than ``max_length`` metres
    whose nodes are mostly *empty*: for at least :data:`EMPTY_SHARE` (half) of them no
    point of ``xyz`` lies within :data:`EMPTY_REACH` point ``spacing`` (m).

    Why: the finished skeleton must lie in its wood. Through leaf clutter and the halo of
    range noise around twigs (8 mm noise, 5 % leaf clutter on the synthetic presets) the
    level sets string together scattered points whose centroids, once the radius stage has
    centred the thin nodes, lie in the empty space between them: on the noisy conifer
    (60,000 points) 181 of the skeleton's 315 tips were such chains, median 11 cm long,
    5–8 cm off every true branch, with no point within 2 spacings of most of their nodes
    (3–9 % of the true twig chains look like that). :func:`prune_empty_tips` removes them.
    ``kdtree``: a k-d tree of ``xyz`` if the caller has one (the pipeline's, built once).
    """
    if spacing <= 0:
        raise ParameterError(f"point spacing must be > 0 m, got {spacing}")
    drop = np.zeros(graph.n_nodes, dtype=bool)
    if graph.n_nodes < 3 or xyz.shape[0] == 0:
        return drop
    lab, side, inv, tops, clen = _side_chains(graph)
    if side.size == 0:
        return drop
    near = (kdtree if kdtree is not None else cKDTree(xyz)).query_ball_point(
        graph.position[side],
        EMPTY_REACH * spacing,
        return_length=True,
        workers=query_workers(side.size),
    )
    empty = np.bincount(inv, weights=(near == 0).astype(float))
    bad = tops[(empty >= EMPTY_SHARE * np.bincount(inv)) & (clen < max_length)]
    return np.isin(lab, bad)


def prune_empty_tips(
    graph: BranchGraph, xyz: NDArray[np.float64], spacing: float, max_length: float = np.inf
) -> BranchGraph:
    """The graph without its :func:`empty_tips` chains (``weight`` = subtree length)."""
    drop = empty_tips(graph, xyz, spacing, max_length)
    if not drop.any():
        return graph
    g = graph.subgraph(~drop)
    return g.with_(weight=g.subtree_length())


#: :func:`inside_wood`: a host branch is at least this many times thicker than a node it
#: holds (a stem-surface piece is a few millimetres against the stem's decimetres; two
#: twigs of a split branch end, about equal, are left to :func:`merge_inside_tips`)
INSIDE_HOST_RATIO = 2.0


#: ... and a side subtree goes when this share of its length lies inside (a stem-surface
#: piece strays out by the scan's noise here and there: on the noisy conifer a 2.2 m piece
#: had one tip 8 mm past the stem's surface + 1 spacing; a real branch leaving a stem of
#: radius R has only R of its length inside, so it would have to be shorter than 1.1 R)
INSIDE_SHARE = 0.9


def _inside_hosts(
    graph: BranchGraph, samples: NDArray, sample_edge: NDArray[np.int64], spacing: float, k: int
) -> NDArray[np.bool_]:
    """Per node: inside the modelled cylinder (+ ``spacing``) of one of the edges (child
    nodes ``sample_edge``) of its ``k`` nearest ``samples``, at least
    :data:`INSIDE_HOST_RATIO` times the node's radius thick and not its own edge."""
    n = graph.n_nodes
    par, r, pos = graph.parent, np.asarray(graph.radius, dtype=float), graph.position
    kk = min(k, samples.shape[0])
    _, idx = cKDTree(samples).query(pos, kk, workers=query_workers(n))
    hc = sample_edge[np.asarray(idx).reshape(n, kk)]
    hp = par[hc]
    tt, d = segment_projection(pos[:, None, :], pos[hp], pos[hc])
    rh = (1 - tt) * r[hp] + tt * r[hc]
    me = np.arange(n)[:, None]
    ok = (d <= rh + spacing) & (rh >= INSIDE_HOST_RATIO * r[:, None]) & (hc != me) & (hp != me)
    return ok.any(axis=1)


def inside_wood(graph: BranchGraph, spacing: float, k: int = 8) -> NDArray[np.bool_]:
    """Nodes of the side subtrees lying inside thicker wood: :data:`INSIDE_SHARE` of the
    subtree's length (edges into nodes so placed) lies within the modelled cylinder of
    another edge (its radius interpolated along it, plus one point ``spacing``), at least
    :data:`INSIDE_HOST_RATIO` times the node's own radius thick. Host edges are those
    thicker than two point spacings (a section the scan resolves); a side subtree is one
    hanging off a fork other than the fork's heaviest child (by carried length).

    Why: a branch is wood outside its parent's. On the noisy conifer (8 mm noise,
    occlusion, 240,000 points) the contraction left pieces of the stem's surface as side
    branches — 0.6–2.3 m each, 5–12 mm thick, up to 8 tips, their nodes a median 2–14 mm
    inside the true stem surface (session 23): length with no wood of its own, which the
    F1 and the total length count as branches. ``graph.radius`` must be set."""
    from biomorph.tree.metrics import resample_graph

    if graph.radius is None:
        raise ParameterError("inside_wood needs radii (fit them first)")
    if spacing <= 0:
        raise ParameterError(f"point spacing must be > 0 m, got {spacing}")
    n = graph.n_nodes
    drop = np.zeros(n, dtype=bool)
    if n < 3:
        return drop
    par, r = graph.parent, np.asarray(graph.radius, dtype=float)
    ch = np.flatnonzero(par >= 0)
    # host edges (by child node) and their thickness class, a factor 2 apart: the nearest
    # axes are the thin ones beside a node, while a stem holding it has its axis a stem
    # radius away, so each class is searched on its own
    cls = np.full(n, -1, dtype=np.int64)
    rm = 0.5 * (r[ch] + r[par[ch]])
    thick = rm > 2 * spacing
    if not thick.any():
        return drop
    cls[ch[thick]] = np.floor(np.log2(rm[thick] / (2 * spacing))).astype(np.int64)
    el = graph.edge_length[ch]
    step = max(0.5 * float(np.median(el[el > 0])) if (el > 0).any() else 0.01, 1e-4)
    pts, edge, _ = resample_graph(graph, step)
    inside = np.zeros(n, dtype=bool)
    for c in np.unique(cls[ch[thick]]):
        m = cls[edge] == c
        inside |= _inside_hosts(graph, pts[m], edge[m], spacing, k)
    heavy = treeops.main_child(par, _carried(graph))
    side = ch[(graph.n_children[par[ch]] >= 2) & (heavy[par[ch]] != ch)]
    length = graph.edge_length
    share = graph.subtree_sum(np.where(inside, length, 0.0)) / np.maximum(
        graph.subtree_sum(length), 1e-300
    )
    bad = side[share[side] >= INSIDE_SHARE]
    if bad.size == 0:
        return drop
    flag = np.zeros(n)
    flag[bad] = 1.0
    return treeops.accumulate_down(par, flag, graph.order) > 0


def _measured_radius(graph: BranchGraph, xyz: NDArray, owner: NDArray) -> NDArray:
    """RMS distance of each node's points (``owner``: nearest node of every point) to the
    node's incoming edge; ``nan`` for roots and nodes with fewer than 3 points."""
    par = graph.parent
    pos = graph.position
    v = owner
    p = np.where(par[v] >= 0, par[v], v)
    d2 = segment_projection(xyz, pos[p], pos[v])[1] ** 2
    n = graph.n_nodes
    cnt = np.bincount(v, minlength=n)
    ms = np.bincount(v, weights=d2, minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.sqrt(ms / cnt)
    out[(cnt < 3) | (par < 0)] = np.nan
    return out


def _host_edges(graph, vert, chain_of, lab, spacing):
    """For each chain vertex, up to 48 candidate host edges (child ids) near it, the
    distance to each and whether it is the vertex's own chain (edges sampled every 2
    spacings, a k-d tree over the samples)."""
    par = graph.parent
    pos = graph.position
    e = np.flatnonzero(par >= 0)
    step = 2.0 * spacing
    ns = np.ceil(graph.edge_length[e] / step).astype(np.int64) + 1
    se = np.repeat(e, ns)
    off = np.repeat(np.cumsum(ns) - ns, ns)
    frac = (np.arange(se.size) - off) / np.repeat(np.maximum(ns - 1, 1), ns)
    samples = pos[par[se]] + frac[:, None] * (pos[se] - pos[par[se]])
    k = int(min(48, se.size))
    _, nb = cKDTree(samples).query(pos[vert], k=k, workers=query_workers(vert.size))
    host = se[nb.reshape(vert.size, k)]
    own = chain_of[host] == lab[vert][:, None]
    dist = segment_projection(pos[vert][:, None, :], pos[par[host]], pos[host])[1]
    return host, dist, own


def _split_end_slack(graph, tops, inv, vert, clen, tol):
    """Per chain vertex: distance beyond the fork's incoming edge continued past the fork
    (by the chain's length, radius the smaller tolerance of the fork's and its parent's
    edges), counted only where a sibling chain lies in it too (``inf`` elsewhere)."""
    n = graph.n_nodes
    par = graph.parent
    pos = graph.position
    u = par[tops]
    pu = par[np.maximum(u, 0)]
    has = (u >= 0) & (pu >= 0)
    du, _ = _unit(pos[u] - pos[np.maximum(pu, 0)])
    tu = np.where(has, np.minimum(tol[u], tol[np.maximum(pu, 0)]), -np.inf)
    rel = pos[vert] - pos[u[inv]]
    s_ax = np.clip(np.einsum("ij,ij->i", rel, du[inv]), 0, clen[inv] + tu[inv])
    d_ext = np.linalg.norm(rel - s_ax[:, None] * du[inv], axis=1)
    ext = np.where(has[inv], d_ext - tu[inv], np.inf)
    # two pieces of one branch end; a chain continuing its parent beside a twig is the
    # branch itself
    in_ext = np.bincount(inv, weights=ext > 0, minlength=tops.size) == 0
    n_ext = np.bincount(np.maximum(u, 0), weights=in_ext & has, minlength=n)
    return np.where(n_ext[np.maximum(u, 0)][inv] >= 2, ext, np.inf)


def merge_inside_tips(
    graph: BranchGraph, xyz: NDArray[np.float64], spacing: float, max_rounds: int = 10
) -> BranchGraph:
    """Remove side tip chains (:func:`tip_chains`) lying wholly inside the rest of the
    skeleton: every vertex of the chain lies (a) within ``r + spacing`` of some edge
    outside the chain, ``r`` the RMS distance of that edge's own points (nearest node) to
    it -- its allometric radius where it holds fewer than 3 points -- and ``spacing`` the
    point spacing, or (b) in the fork's incoming edge continued past the fork by the
    chain's length (radius the smaller ``r + spacing`` of the fork's and its parent's
    edges) when a sibling chain lies wholly in it too: a split branch end.

    Why: the contraction's level pieces on the surface of a clean dense stem (a level
    behind the ring) give chains that run beside the stem's path inside the stem's own
    points -- parallel paths and split branch ends (``level_merge="adaptive"``). A real twig
    leaves its parent's point envelope; a chain that never does adds no wood.
    Where two chains lie in each other the shorter goes first, one chain per fork and
    round; repeated until stable. Every threshold is a measure of the cloud (point
    spacing, RMS spreads) -- none was tuned on a file.
    """
    if graph.radius is None:
        raise ParameterError("merge_inside_tips needs radii (run allometric_radii first)")
    if not (spacing > 0 and np.isfinite(spacing)):
        raise ParameterError(f"point spacing must be > 0 metres, got {spacing}")
    return merge_inside_tips_mapped(graph, xyz, spacing, max_rounds)[0]


def merge_inside_tips_mapped(
    graph: BranchGraph, xyz: NDArray[np.float64], spacing: float, max_rounds: int = 10
) -> tuple[BranchGraph, NDArray[np.int64]]:
    """:func:`merge_inside_tips` and, for every input node, its node in the result (a
    removed chain's nodes map to the fork the chain left: its points merge there)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    index = np.arange(graph.n_nodes, dtype=np.int64)
    for _ in range(max_rounds):
        n = graph.n_nodes
        if n < 3 or xyz.shape[0] == 0:
            break
        par = graph.parent
        pos = graph.position
        lab = tip_chains(graph)
        side = (lab >= 0) & (par[np.maximum(lab, 0)] >= 0)
        if not side.any():
            break
        _, owner = cKDTree(pos).query(xyz, workers=-1)
        rms = _measured_radius(graph, xyz, owner)
        r_edge = 0.5 * (graph.radius + graph.radius[np.maximum(par, 0)])
        tol = np.where(np.isfinite(rms), rms, r_edge) + spacing
        vert = np.flatnonzero(side)
        chain_of = np.where(side, lab, -1)
        host, dist, own = _host_edges(graph, vert, chain_of, lab, spacing)
        slack = np.where(own, np.inf, dist - tol[host])
        j = np.argmin(slack, axis=1)
        hv = host[np.arange(vert.size), j]
        best = slack[np.arange(vert.size), j]
        host_chain = chain_of[hv]
        tops, inv = np.unique(lab[vert], return_inverse=True)
        clen = np.bincount(inv, weights=graph.edge_length[vert], minlength=tops.size)
        u = par[tops]
        ext = _split_end_slack(graph, tops, inv, vert, clen, tol)
        host_chain = np.where(ext < best, -1, host_chain)
        inside_v = np.minimum(best, ext) <= 0
        inside = np.bincount(inv, weights=~inside_v, minlength=tops.size) == 0
        if not inside.any():
            break
        # a candidate waits while one of its hosts is a shorter (or equal, lower id) candidate
        cand_len = np.full(n, np.inf)
        cand_len[tops[inside]] = clen[inside]
        hc = np.maximum(host_chain, 0)
        hl = np.where(host_chain >= 0, cand_len[hc], np.inf)
        mine = clen[inv]
        blocked_v = (hl < mine) | ((hl == mine) & (hc < lab[vert]))
        blocked = np.bincount(inv, weights=blocked_v, minlength=tops.size) > 0
        ok = np.flatnonzero(inside & ~blocked)
        # one chain per fork and round, the shortest: a fork keeps a child
        ok = ok[np.lexsort((tops[ok], clen[ok]))]
        _, first = np.unique(u[ok], return_index=True)
        bad = tops[ok[first]]
        if bad.size == 0:
            break
        drop = np.isin(lab, bad)
        new = np.full(n, -1, dtype=np.int64)
        new[~drop] = np.arange(int((~drop).sum()))
        new[drop] = new[par[lab[drop]]]  # the fork the chain left
        index = new[index]
        graph = graph.subgraph(~drop)
        graph = graph.with_(weight=graph.subtree_length())
    return graph, index


#: a trunk path at least this factor longer than the straight line between two of its
#: nodes is a detour (:func:`trunk_shortcuts`): a stem's sweep over a tenth of its height
#: stays within a few per cent of the chord (an arc is 20 % longer only past 63° of bend)
DETOUR_EXCESS = 1.2
#: a node within the stem's interpolated radius plus this many point spacings of the line
#: is on the stem (the surface points' noise and the centroid's pull); a detour reaches a
#: stem diameter or at least this reach beyond the surface; and a slab of
#: :func:`_stem_support` searches this far beyond the radius
SHORTCUT_REACH = 2.0
#: ... and both ends at least this many point spacings thick: a stem whose surface the
#: scan resolves, not a fork of twigs whose points lie within reach of any line
SHORTCUT_MIN_RADIUS = 3.0
#: ... and the stem's circle around the line in three of four slabs that can be fitted
#: (whorl branches and needles in a slab pull some circles off)
SHORTCUT_RING_SHARE = 0.75
#: ``trunk_shortcuts(sparse=True)``: the stem test's slabs are this share of the stem's
#: radius thick (half-thickness; at least a point spacing): the TreeLS spruce's stem at
#: 11-12.6 m holds 1-9 points per slab of a point spacing, seen from below through the crown
SPARSE_SLAB_RADII = 0.5


def trunk_shortcuts(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    spacing: float,
    max_span: float | None = None,
    kdtree: cKDTree | None = None,
    sparse: bool = False,
) -> list[tuple[int, int]]:
    """Detours of each tree's trunk out along a branch and back, as ``(i, j)`` pairs of
    trunk nodes (``j`` downstream of ``i``) to join directly.

    The trunk here is the path from the root always into the child carrying the most
    length. Where the skeleton's stem breaks — the level set of a whorl merged with a
    branch, the contraction pulled a stem piece out — the path runs out along a branch and
    back (the TreeLS spruce: 0.4–0.6 m out at 4 and 5.7 m, beside a fully scanned stem
    circle). A pair qualifies when the path between is :data:`DETOUR_EXCESS` × longer
    than the straight line (and longer by two edges) and leaves the stem (a node a stem
    diameter beyond its surface, at least :data:`SHORTCUT_REACH` spacings: not the
    skeleton crossing between the arms of a fork), both ends are
    :data:`SHORTCUT_MIN_RADIUS` spacings thick (a stem the scan resolves), the line spans
    at most ``max_span`` (m; default a tenth of the tree's height,
    :data:`biomorph.tree.order.TRUNK_WAVELENGTH`), heads within 60° of vertical, and the
    points show the stem around it (:func:`_stem_support`; with ``sparse`` in slabs
    :data:`SPARSE_SLAB_RADII` of the stem's radius thick, where a stem seen through a
    crown leaves a few points per point-spacing slab). No bridge through empty space:
    the stem must be there in the scan. For each ``i`` the farthest qualifying ``j`` is
    taken, then the search goes on from ``j``. ``kdtree``: a k-d tree of ``xyz`` if the
    caller has one."""
    from biomorph.tree.order import TRUNK_WAVELENGTH, tree_heights

    if spacing <= 0:
        raise ParameterError(f"point spacing must be > 0 m, got {spacing}")
    out: list[tuple[int, int]] = []
    if graph.n_nodes < 4 or xyz.shape[0] == 0 or graph.radius is None:
        return out
    pos, rad = graph.position, graph.radius
    main = treeops.main_child(graph.parent, graph.subtree_length() + graph.edge_length)
    el = graph.edge_length
    med = float(np.median(el[el > 0])) if (el > 0).any() else spacing
    kd = kdtree if kdtree is not None else cKDTree(xyz)
    cos_max = np.cos(np.radians(60.0))
    thick = rad >= SHORTCUT_MIN_RADIUS * spacing
    heights = tree_heights(graph)
    for root in graph.roots:
        path = [int(root)]
        while main[path[-1]] >= 0:
            path.append(int(main[path[-1]]))
        p = np.asarray(path)
        if p.size < 4:
            continue
        span = max_span if max_span is not None else TRUNK_WAVELENGTH * heights[root]
        cum = np.concatenate([[0.0], np.cumsum(el[p[1:]])])
        i = 0
        while i < p.size - 2:
            ahead = p[i + 2 :]
            d = np.linalg.norm(pos[ahead] - pos[p[i]], axis=1)
            pl = cum[i + 2 :] - cum[i]
            heading = (pos[ahead, 2] - pos[p[i], 2]) / np.maximum(d, 1e-12)
            cand = np.flatnonzero(
                thick[p[i]]
                & thick[ahead]
                & (d <= span)
                & (pl >= DETOUR_EXCESS * d)
                & (pl - d >= 2 * med)
                & (heading >= cos_max)
            )
            done = False
            # a detour leaves the stem: some node between a stem diameter beyond its
            # surface (a skeleton crossing between the arms of a fork stays nearer)
            far = rad[p[i]] + max(2 * rad[p[i]], SHORTCUT_REACH * spacing)
            js = []
            for c in cand[::-1]:
                j = i + 2 + int(c)
                if segment_projection(pos[p[i + 1 : j]], pos[p[i]], pos[p[j]])[1].max() >= far:
                    js.append(j)
            # most lines fail the stem test at a slab with no point in reach: found for all
            # of them in one query (the same slabs; the test's answer is False there)
            slab = (
                np.maximum(spacing, SPARSE_SLAB_RADII * np.minimum(rad[p[i]], rad[p[js]]))
                if sparse
                else np.full(len(js), spacing)
            )
            gap = _slab_gaps(kd, pos[p[i]], pos[p[js]], rad[p[i]], rad[p[js]], spacing, slab)
            for j, empty, h in zip(js, gap, slab, strict=True):
                if empty:
                    continue
                if _stem_support(
                    kd, xyz, pos[p[i]], pos[p[j]], rad[p[i]], rad[p[j]], spacing, float(h)
                ):
                    out.append((int(p[i]), int(p[j])))
                    i, done = j, True
                    break
            if not done:
                i += 1
    return out


#: :func:`_stem_support` gathers the slabs in its walk order in chunks of this many, then
#: twice as many each time (a line that fails usually does so within the first few)
SLAB_CHUNK = 6


def _cross3(a, b) -> NDArray[np.float64]:
    """``np.cross(a, b)`` of two 3-vectors, the same products and differences (without
    its broadcasting machinery, ~30x slower for one pair)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _slab_chunk(kd, xyz, c, reach, axes, spacing) -> list | None:
    """For the slabs centred at ``c`` (reach ``reach``; ``axes`` the rows ``e1``, ``e2``,
    ``u``): per slab the in-plane ``x``, ``y`` of its ball's points (sorted by index) and
    which of them lie in the slab, as :func:`_stem_support` computes them slab by slab
    (one ball query and one product per axis for the chunk: a product's rows are those of
    each slab's own array, save a one-point slab's, which is recomputed as such). None if
    a slab holds no point near the line (none in its ball, or none in the slab)."""
    lists = kd.query_ball_point(c, np.hypot(reach, spacing), return_sorted=True)
    cnt = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
    if not cnt.all():
        return None
    start = np.concatenate([[0], np.cumsum(cnt)])
    d = xyz[np.fromiter(chain.from_iterable(lists), dtype=np.int64, count=int(start[-1]))]
    d -= np.repeat(c, cnt, axis=0)
    e1, e2, u = axes
    x, y, h = d @ e1, d @ e2, d @ u
    for s in start[:-1][cnt == 1]:
        one = d[s : s + 1]
        x[s], y[s], h[s] = (one @ e1)[0], (one @ e2)[0], (one @ u)[0]
    inside = (np.abs(h) <= spacing) & (np.hypot(x, y) <= np.repeat(reach, cnt))
    if not np.add.reduceat(inside.astype(np.int64), start[:-1]).all():
        return None
    return [
        (x[start[j] : start[j + 1]], y[start[j] : start[j + 1]], inside[start[j] : start[j + 1]])
        for j in range(cnt.size)
    ]


def _slab_gaps(kd, a, b, ra: float, rb, spacing: float, slab=None) -> NDArray[np.bool_]:
    """For the lines from ``a`` to each row of ``b`` (radii ``ra`` to ``rb``): whether one
    of :func:`_stem_support`'s slabs has no point within its ball (the same slab centres
    and ball radii, computed the same way), where that test answers False. One
    nearest-neighbour query for all the lines' slabs."""
    b = np.asarray(b, dtype=float).reshape(-1, 3)
    out = np.zeros(b.shape[0], dtype=bool)
    if b.shape[0] == 0:
        return out
    rb = np.asarray(rb, dtype=float).reshape(-1)
    h = np.broadcast_to(np.asarray(spacing if slab is None else slab, dtype=float), rb.shape)
    ab = b - a
    ln = np.linalg.norm(ab, axis=1)
    k = np.maximum(2, np.ceil(ln / (2 * h)).astype(np.int64) + 1)
    line = np.repeat(np.arange(b.shape[0]), k)
    first = np.concatenate([[0], np.cumsum(k)[:-1]])
    idx = np.arange(int(k.sum())) - np.repeat(first, k)
    # np.linspace(0, 1, k): i × (1 / (k − 1)), the last exactly 1
    ts = idx * (1.0 / (k - 1))[line]
    ts[first + k - 1] = 1.0
    r = ra + ts * (rb - ra)[line]
    ball = np.hypot(r + SHORTCUT_REACH * spacing, h[line])
    d, _ = kd.query(a + ts[:, None] * ab[line], k=1, distance_upper_bound=float(ball.max()))
    out[np.unique(line[d > ball])] = True
    return out & (ln > 0)


def _stem_support(
    kd, xyz, a, b, ra: float, rb: float, spacing: float, slab: float | None = None
) -> bool:
    """Whether the scan shows a stem around the straight line ``a → b`` (radii ``ra`` to
    ``rb``): in every slab (two point spacings apart, one spacing thick) points within the
    radius plus :data:`SHORTCUT_REACH` spacings of the line (no gap); at least half of them
    hold 5 points or more, and in :data:`SHORTCUT_RING_SHARE` of those a circle through the
    points (algebraic fit) is centred within half the radius of the line, its radius within
    a factor 2 of the stem's. A circle fit finds the stem's own axis from an arc of it, so a line
    leaving the stem fails where it runs outside, however one-sided the scan. The slabs'
    points are gathered a chunk at a time (:func:`_slab_chunk`). ``slab``: the slabs'
    half-thickness and half their spacing instead of one point spacing (m; a sparse stem
    fills thicker slabs, :data:`SPARSE_SLAB_RADII`)."""
    ab = b - a
    ln = float(np.linalg.norm(ab))
    if ln <= 0:
        return False
    u = ab / ln
    e1 = _cross3(u, (0.0, 0.0, 1.0) if abs(u[2]) < 0.9 else (1.0, 0.0, 0.0))
    e1 /= np.linalg.norm(e1)
    e2 = _cross3(u, e1)
    h = spacing if slab is None else float(slab)  # the slabs' half-thickness
    k = max(2, int(np.ceil(ln / (2 * h))) + 1)
    ts = np.linspace(0.0, 1.0, k)
    r = ra + ts * (rb - ra)
    reach = r + SHORTCUT_REACH * spacing
    # the middle first: a line beside the stem leaves it there (the answer does not
    # depend on the order)
    walk = np.argsort(np.abs(ts - 0.5), kind="stable")
    good = fitted = done = 0
    size = SLAB_CHUNK
    while done < k:
        chunk = walk[done : done + size]
        got = _slab_chunk(kd, xyz, a + ts[chunk, None] * ab, reach[chunk], (e1, e2, u), h)
        if got is None:
            # an empty slab (no ball points, or none near the line) is the answer wherever
            # the walk meets it
            return False
        for q, j in enumerate(chunk):
            # the answer is known once even every slab left fitted and good cannot meet
            # the two shares (a bad slab only lowers them): stop there, the same answer
            left = k - done - q
            if fitted + left < 0.5 * k or good + left < SHORTCUT_RING_SHARE * (fitted + left):
                return False
            if got[q][2].sum() < 5:  # too few to fit: neither for nor against
                continue
            fitted += 1
            x, y, m = got[q]
            xy = np.column_stack([x[m], y[m]])
            _, c, rr2 = kasa_circle(xy)
            cx, cy = c + xy.mean(axis=0)  # about the line, not the points' mean
            rj = r[j]
            if rr2 > 0 and np.hypot(cx, cy) <= 0.5 * rj and 0.5 * rj <= np.sqrt(rr2) <= 2 * rj:
                good += 1
        done += chunk.size
        size *= 2
    return fitted >= 0.5 * k and good >= SHORTCUT_RING_SHARE * fitted


def reroute_detours(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    spacing: float,
    max_span: float | None = None,
    kdtree: cKDTree | None = None,
    sparse: bool = False,
) -> tuple[NDArray[np.int64], NDArray[np.bool_], int]:
    """New parents that take each trunk detour (:func:`trunk_shortcuts`) out of the trunk;
    returns ``(parent, keep, detours)``: apply ``parent``, then keep the nodes in ``keep``.

    For a shortcut ``(i, j)``: ``a`` is the last node after ``i`` and ``b`` the first before
    ``j`` still on the straight stem (within its interpolated radius plus
    :data:`SHORTCUT_REACH` point spacings of the line). ``b`` is joined to ``a`` (the long
    new edge is to be densified by the caller). The way out, up to the node farthest from
    the line, stays a branch of ``a`` (the branch the skeleton ran out along, whose own
    continuation hangs from it). The way back is the skeleton crossing over to the stem
    (between the arms of a fork, from one whorl branch to the next): it is dropped, except
    the part from ``b`` out to the last of its nodes that carries other wood, which is
    turned round into a branch of ``b``. ``kdtree``: as :func:`trunk_shortcuts`."""
    parent = np.array(graph.parent, dtype=np.int64)
    keep = np.ones(graph.n_nodes, dtype=bool)
    pos, rad = graph.position, graph.radius
    done = 0
    if rad is None:
        return parent, keep, done
    n_kids = graph.n_children
    for i, j in trunk_shortcuts(graph, xyz, spacing, max_span, kdtree, sparse):
        path = [j]
        while path[-1] != i:
            path.append(int(parent[path[-1]]))
        p = np.asarray(path[::-1])  # i ... j
        t, off = segment_projection(pos[p], pos[i], pos[j])
        on = off <= rad[i] + t * (rad[j] - rad[i]) + SHORTCUT_REACH * spacing
        ka = 0
        while ka + 1 < p.size and on[ka + 1]:
            ka += 1
        kb = p.size - 1
        while kb - 1 > ka and on[kb - 1]:
            kb -= 1
        if kb - ka < 2:
            continue
        a, b = int(p[ka]), int(p[kb])
        km = ka + 1 + int(np.argmax(off[ka + 1 : kb]))  # the far end of the detour
        parent[b] = a
        back = p[km + 1 : kb]  # from the far end towards b
        carrying = np.flatnonzero(n_kids[back] > 1)  # other wood hangs from these
        cut = int(carrying[0]) if carrying.size else back.size
        keep[back[:cut]] = False
        kept = back[cut:]
        if kept.size:  # turned round: b <- kept[-1] <- ... <- kept[0]
            parent[kept[-1]] = b
            parent[kept[:-1]] = kept[1:]
        done += 1
    return parent, keep, done


#: a hook is searched among the ancestors within this many node spacings of path above a
#: node: a level set that merged the arms of a fork spans two or three spacings, and its
#: way back at most as many again
HOOK_REACH = 8.0
#: ... and taken out when the straight way from that ancestor saves at least this many
#: node spacings of path (a hook runs at least one level up the wrong arm and back; the
#: zig-zag of centroids along a straight branch saves a small fraction of one)
HOOK_SAVING = 2.0
#: ... from the nearest ancestor whose saving is within this many node spacings of the
#: most any saves: an ancestor below the fork saves a little more by cutting the fork's
#: corner (a few millimetres), one up the wrong arm almost a node spacing less
HOOK_CORNER = 0.5


def fork_hooks(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    spacing: float,
    node_spacing: float,
    kdtree: cKDTree | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.bool_], list[dict]]:
    """Hooks at forks taken out of the skeleton: ``(parent, keep, hooks)``; apply
    ``parent``, then keep the nodes in ``keep`` (the new edges are to be densified).

    Where the level sets of the graph method merge the two arms of a fork, the shortest-
    path forest can enter one arm from a node a level or two *up the other*: the path
    climbs the wrong arm, turns, and comes back down into its own (AdTree tree7: the trunk
    went 0.1 m up one leader above the fork and back down into the other, 0.28 m of
    path for a 0.1 m step). A node ``x`` is hooked when an ancestor ``q`` within
    :data:`HOOK_REACH` node spacings of path reaches it by a straight way at least
    :data:`HOOK_SAVING` node spacings shorter, the way between turns back (it first climbs
    more than a node spacing farther from ``x`` than ``q`` is: a bend of a branch only
    ever draws nearer) at a node carrying other wood too (the wrong arm goes on beyond
    the turn; where two twigs' tips touch, neither does) and standing outside ``q``'s
    radius (within one cross-section of a thick stem the order of the nodes means
    nothing), and the points cover the straight way: a point within the
    thicker end's radius plus ``spacing`` (the point spacing) of every step of one node
    spacing along it (nothing is drawn through empty space). Nodes are visited from the
    roots (their ancestors already straightened), each taking the nearest ancestor that
    saves within :data:`HOOK_CORNER` node spacings of the most any saves (the fork, not a
    stem node below it). ``x`` then hangs from ``q``; the nodes of the old way that carry
    nothing any more (the way back down) are dropped, those carrying other wood (the wrong
    arm itself) stay. Each record gives ``node``, ``anchor``, ``saving`` (m) and
    ``dropped`` (nodes)."""
    n = graph.n_nodes
    parent = np.array(graph.parent, dtype=np.int64)
    keep = np.ones(n, dtype=bool)
    hooks: list[dict] = []
    if n < 4 or xyz.shape[0] == 0 or spacing <= 0 or node_spacing <= 0:
        return parent, keep, hooks
    pos = graph.position
    rad = graph.radius if graph.radius is not None else np.zeros(n)
    kd = kdtree if kdtree is not None else cKDTree(xyz)
    reach = HOOK_REACH * node_spacing
    need = HOOK_SAVING * node_spacing
    # plain floats and math.dist: the walk visits every node and up to HOOK_REACH of its
    # ancestors, numpy's per-call overhead would dominate
    pts = [tuple(v) for v in pos.tolist()]
    pl = [0.0] * n  # path length from the root, on the straightened skeleton
    par = parent.tolist()
    kids0 = graph.n_children
    had_children = kids0 > 0
    for x in graph.order.tolist():
        p = par[x]
        if p < 0:
            continue
        px = pts[x]
        pl[x] = pl[p] + math.dist(px, pts[p])
        # a hook turns back: the way from q climbs away from x (farther than q is, by a
        # node spacing) before it comes down to it; a bend only ever draws nearer
        # ... at a fork: the wrong arm goes on beyond the turn (the node where the way
        # turns carries other wood; two twigs' tips touching turn where neither goes on),
        # and the turn stands outside q's own wood (nodes zig-zagging within one cross-
        # section of a thick stem are no arm)
        ups, q, away, apex = [], par[p], math.dist(px, pts[p]), p
        while q >= 0 and pl[x] - pl[q] <= reach:
            dq = math.dist(px, pts[q])
            if (
                away > dq + node_spacing
                and kids0[apex] >= 2
                and math.dist(pts[apex], pts[q]) > rad[q]
            ):
                ups.append((q, pl[x] - pl[q] - dq))
            if dq > away:
                away, apex = dq, q
            q = par[q]
        top = max((sv for _, sv in ups), default=0.0)
        anchor, best = -1, 0.0
        if top >= need:
            # the nearest ancestor saving about the most: the fork itself, not a stem node
            # below it whose straight way also cuts the fork's corner inside the wood
            for q, sv in ups:
                if sv >= max(need, top - HOOK_CORNER * node_spacing) and (
                    segment_cover(
                        kd, pos[q], pos[x], node_spacing, max(rad[q], rad[x]) + spacing, True
                    )
                    == 1.0
                ):
                    anchor, best = q, sv
                    break
        if anchor < 0:
            continue
        parent[x] = par[x] = anchor
        pl[x] = pl[anchor] + math.dist(px, pts[anchor])
        hooks.append({"node": int(x), "anchor": int(anchor), "saving": float(best)})
    if hooks:
        # the old ways back that carry nothing now: dropped from their ends up
        kids = np.bincount(parent[parent >= 0], minlength=n)
        for h in hooks:
            v = int(graph.parent[h["node"]])
            dropped = 0
            while v >= 0 and keep[v] and kids[v] == 0 and had_children[v]:
                keep[v] = False
                dropped += 1
                u = int(parent[v])
                if u >= 0:
                    kids[u] -= 1
                v = u
            h["dropped"] = dropped
    return parent, keep, hooks
