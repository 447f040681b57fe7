"""Skeleton quality metrics (seed 001 §4 and beyond).

* The thesis's measures: **NOB** (number of branches = tip count), **TBL** (total branch
  length, m), **MSE** (mean squared distance of the cloud's points to the skeleton, m²),
  per tree. Per-phase run times ``t1..t4`` are reported by the methods themselves.
* Against a ground truth: skeleton precision/recall/F1 within a tolerance, NOB and TBL
  ratios, median relative radius error on thick branches, stem diameter at breast height
  (DBH, 1.3 m above the tree's lowest point) and total wood volume (frusta).

All distances are metres in the graphs' common frame; nothing here aligns frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core.graph import BranchGraph
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError
from biomorph.tree.neighbours import grid_query, query_ordered

__all__ = [
    "skeleton_metrics",
    "compare_to_truth",
    "dbh",
    "dbh_per_tree",
    "tree_kinds",
    "BREAST_HEIGHT",
    "STEM_FITS",
    "volume",
    "resample_graph",
    "point_to_skeleton_distance",
    "segment_candidates",
    "surface_distance",
    "axis_distance",
    "SegmentCandidates",
    "DIAMETER_CLASSES",
    "class_labels",
    "edge_volumes",
    "volume_by_class",
    "volume_by_order",
    "tree_attributes",
    "cylinder_fit",
    "qsm_report",
    "summary_rows",
    "scan_rows",
]


def resample_graph(graph: BranchGraph, step: float) -> tuple[NDArray, NDArray, NDArray]:
    """Points every ``step`` metres along all edges (both end nodes included).

    Returns ``(points[m,3], edge_child[m], t[m])``: the child node of the edge each sample lies
    on and its parameter (0 at the parent, 1 at the child). Isolated roots give one sample.
    """
    if step <= 0:
        raise ParameterError(f"resampling step must be > 0 (metres); got {step}")
    child = np.flatnonzero(graph.parent >= 0)
    par = graph.parent[child]
    a = graph.position[par]
    b = graph.position[child]
    length = np.linalg.norm(b - a, axis=1)
    k = np.maximum(np.ceil(length / step).astype(np.int64), 1)
    rep = np.repeat(np.arange(child.size), k)
    start = np.repeat(np.cumsum(k) - k, k)
    t = (np.arange(rep.size) - start + 1) / k[rep]  # (0, 1], the parent end comes from roots
    pts = a[rep] + (b[rep] - a[rep]) * t[:, None]
    roots = graph.roots
    pts = np.concatenate([graph.position[roots], pts])
    ec = np.concatenate([roots, child[rep]])
    tt = np.concatenate([np.ones(roots.size), t])
    return pts, ec, tt


@dataclass(frozen=True)
class SegmentCandidates:
    """For every point its ``k`` candidate skeleton edges (those of its ``k`` nearest
    samples of the resampled skeleton): ``node`` the edge's child node (or a root),
    ``par`` its parent (-1 at a root), ``t`` the parameter of the closest point on the
    edge (0 at the parent) and ``d`` the distance to it (m); all ``[n, k]``. Computed once
    by :func:`segment_candidates` for the MSE and the cylinder fit of one skeleton."""

    node: NDArray[np.int64]
    par: NDArray[np.int64]
    t: NDArray[np.float64]
    d: NDArray[np.float64]
    #: the skeleton's samples behind them (k-d tree, sample → edge), for a second look
    #: at some points with more candidates without resampling (:func:`surface_distance`)
    samples: _Samples | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class _Samples:
    """A skeleton resampled for :func:`segment_candidates`: the samples, the edge (child
    node, or a root) of each sample and their k-d tree, built on first use (the grid
    search asks it only for the points it does not decide, often none)."""

    points: NDArray[np.float64]
    edge: NDArray[np.int64]
    _tree: list = field(default_factory=list, repr=False, compare=False)

    def tree(self) -> cKDTree:
        if not self._tree:
            self._tree.append(cKDTree(self.points))
        return self._tree[0]


def _skeleton_samples(graph: BranchGraph) -> _Samples:
    el = graph.edge_length[graph.parent >= 0]
    step = max(float(np.median(el)) / 2 if el.size else 1.0, 1e-4)
    pts, ec, _ = resample_graph(graph, step)
    return _Samples(np.ascontiguousarray(pts, dtype=np.float64), ec)


#: :func:`segment_candidates` finds up to this many candidates per point through a grid of
#: the samples (:func:`~biomorph.tree.neighbours.grid_query`; 1.5-2x faster than their k-d
#: tree for 8 to 32 on the spruce), more through their k-d tree
GRID_K = 32


def segment_candidates(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    k: int = 8,
    *,
    _samples: _Samples | None = None,
    order: NDArray | None = None,
) -> SegmentCandidates:
    """The :class:`SegmentCandidates` of ``xyz`` on ``graph`` (samples spaced half the
    median edge length; ``_samples``: those of an earlier call on the same graph). They
    depend on the skeleton's positions and parents, the points and ``k``, not on radii.
    ``order``: a spatial order of ``xyz`` known already (the leaf order of its k-d tree),
    which the query follows."""
    if graph.n_nodes == 0:
        raise InputError("skeleton is empty; expected at least one node")
    xyz = np.asarray(xyz, dtype=float)
    smp = _samples if _samples is not None else _skeleton_samples(graph)
    kk = min(k, smp.points.shape[0])
    if kk <= GRID_K:
        # the k-d tree's answers, from a grid of the samples (ties, far points: the tree)
        _, idx = grid_query(smp.points, xyz, kk, tree=smp.tree, order=order)
    else:
        _, idx = query_ordered(smp.tree(), xyz, kk, order=order)
    idx = idx.reshape(xyz.shape[0], kk)
    node = smp.edge[idx]  # child node of candidate edges (or a root)
    par = graph.parent[node]
    t, d = _segment_kernel(xyz, node, par, np.ascontiguousarray(graph.position, dtype=float))
    return SegmentCandidates(node, par, t, d, smp)


@numba.njit(cache=True)
def _segment_kernel(xyz, node, par, pos):  # pragma: no cover - numba
    """Closest-point parameter and distance of each point to each of its candidate edges,
    in one pass (no ``[n, k, 3]`` temporaries). Sums are grouped as numpy's ``einsum``
    and ``norm`` group them over three components, so every value equals the array
    expressions it replaced (tested)."""
    n, k = node.shape
    t = np.empty((n, k))
    d = np.empty((n, k))
    for i in range(n):
        px, py, pz = xyz[i, 0], xyz[i, 1], xyz[i, 2]
        for j in range(k):
            v = node[i, j]
            p = par[i, j]
            bx, by, bz = pos[v, 0], pos[v, 1], pos[v, 2]
            if p >= 0:
                ax, ay, az = pos[p, 0], pos[p, 1], pos[p, 2]
            else:
                ax, ay, az = bx, by, bz
            abx, aby, abz = bx - ax, by - ay, bz - az
            den = (abx * abx + abz * abz) + aby * aby
            apx, apy, apz = px - ax, py - ay, pz - az
            tt = ((apx * abx + apz * abz) + apy * aby) / den if den > 0 else 0.0
            tt = min(max(tt, 0.0), 1.0)
            ex, ey, ez = apx - abx * tt, apy - aby * tt, apz - abz * tt
            t[i, j] = tt
            d[i, j] = np.sqrt((ex * ex + ey * ey) + ez * ez)
    return t, d


def point_to_skeleton_distance(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    k: int = 8,
    *,
    candidates: SegmentCandidates | None = None,
) -> NDArray[np.float64]:
    """Exact distance (m) of each point to the nearest skeleton edge segment.

    Candidate segments are the edges of the ``k`` nearest samples of the resampled skeleton
    (spacing a fraction of the median edge length); the exact point-to-segment distance is
    then taken over those candidates (``candidates``: from :func:`segment_candidates`).
    """
    if graph.n_nodes == 0:
        raise InputError("skeleton is empty; expected at least one node")
    c = candidates if candidates is not None else segment_candidates(graph, xyz, k)
    return c.d.min(axis=1)


def skeleton_metrics(
    graph: BranchGraph,
    cloud: PointCloud | NDArray | None = None,
    *,
    candidates: SegmentCandidates | None = None,
) -> dict:
    """The thesis's NOB, TBL and (with a cloud) MSE, overall and per tree.

    Returns ``{"nob", "tbl", "mse", "n_nodes", "n_trees", "trees": [{"tree", "nob",
    "tbl", "mse", "n_nodes", "n_points"}, ...]}``; ``mse`` (m²) is ``None`` without a cloud.
    Points are attributed to the tree of their nearest skeleton segment. ``candidates``:
    the cloud's :func:`segment_candidates`, if already computed.
    """
    labels = graph.trees
    uniq = np.unique(labels)
    leaf = graph.n_children == 0
    el = graph.edge_length
    d2 = None
    near_tree = None
    if cloud is not None:
        xyz = cloud.xyz if isinstance(cloud, PointCloud) else np.asarray(cloud, dtype=float)
        if xyz.shape[0]:
            d = point_to_skeleton_distance(graph, xyz, candidates=candidates)
            d2 = d**2
            if uniq.size == 1:  # one tree: every point is its own
                near_tree = np.full(xyz.shape[0], uniq[0], dtype=labels.dtype)
            else:
                # the tree of the nearest node (cheap, adequate for attributing points)
                _, ni = query_ordered(cKDTree(graph.position), xyz)
                near_tree = labels[ni]
    trees = []
    for t in uniq:
        m = labels == t
        rec = {
            "tree": int(t),
            "nob": int(leaf[m].sum()),
            "tbl": float(el[m].sum()),
            "n_nodes": int(m.sum()),
            "mse": None,
            "n_points": 0,
        }
        if d2 is not None:
            pm = near_tree == t
            rec["n_points"] = int(pm.sum())
            rec["mse"] = float(d2[pm].mean()) if pm.any() else None
        trees.append(rec)
    return {
        "nob": int(leaf.sum()),
        "tbl": float(el.sum()),
        "mse": None if d2 is None else float(d2.mean()),
        "n_nodes": graph.n_nodes,
        "n_trees": int(uniq.size),
        "trees": trees,
    }


def _interp_radius(graph: BranchGraph, ec: NDArray, t: NDArray) -> NDArray:
    r = graph.radius
    assert r is not None
    par = graph.parent[ec]
    rp = np.where(par >= 0, r[np.maximum(par, 0)], r[ec])
    return rp + (r[ec] - rp) * t


#: breast height (m): a stem reaching it has a DBH, the inventory's threshold for a tree
BREAST_HEIGHT = 1.3
#: reliable circle fits the lower half of a trunk must hold for a tree to stand on a stem
#: the scan measured (the taper model's own anchoring rule, :func:`biomorph.tree.radius.
#: taper_radii`: fewer leave the stem to the plot's pooled model)
STEM_FITS = 3


def tree_kinds(
    graph: BranchGraph, reliable: NDArray[np.bool_] | None, heights: dict[int, float]
) -> dict[int, str]:
    """``"tree"`` or ``"fragment"`` per tree label: a tree reaches breast height
    (:data:`BREAST_HEIGHT`, ``heights`` per label) and its trunk (order 0) holds at least
    :data:`STEM_FITS` ``reliable`` circle fits in its lower half — a stem the scan
    measured. Anything else (an understorey plant, a stump, a piece of crown or a stem the
    scan does not show) is a fragment, reported as such rather than counted as a tree. With
    no fit quality (``reliable`` None or of another size: allometric radii) only the height
    decides."""
    z = graph.position[:, 2]
    labels = graph.trees
    have = reliable is not None and np.size(reliable) == graph.n_nodes
    out: dict[int, str] = {}
    for t in np.unique(labels):
        tall = heights.get(int(t), 0.0) >= BREAST_HEIGHT
        measured = True
        if have and tall:
            trunk = np.flatnonzero((labels == t) & (graph.depth == 0))
            if trunk.size:
                zb, zt = z[trunk].min(), z[trunk].max()
                low = trunk[z[trunk] <= zb + 0.5 * (zt - zb)]
                measured = int(np.count_nonzero(np.asarray(reliable)[low])) >= STEM_FITS
            else:
                measured = False
        out[int(t)] = "tree" if tall and measured else "fragment"
    return out


def dbh_per_tree(graph: BranchGraph, height: float = 1.3) -> NDArray[np.float64]:
    """Stem diameter (m) at ``height`` above each tree's lowest node, per tree label.

    The stem is the path from the root up the thickest child; the diameter is twice the
    radius interpolated on the edge of that path crossing the height. NaN when the tree has
    no radii or is lower than ``height``.
    """
    labels = graph.trees
    uniq = np.unique(labels)
    out = np.full(uniq.size, np.nan)
    if graph.radius is None:
        return out
    pos, r = graph.position, graph.radius
    indptr, indices = graph.children_csr
    for k, t in enumerate(uniq):
        nodes = np.flatnonzero(labels == t)
        z0 = pos[nodes, 2].min()
        zc = z0 + height
        roots = nodes[graph.parent[nodes] < 0]
        if roots.size == 0:
            continue
        cur = int(roots[np.argmax(r[roots])])
        # walk up the thickest child until the stem crosses zc (Python loop over the stem
        # only, a few hundred nodes at most)
        while True:
            ch = indices[indptr[cur] : indptr[cur + 1]]
            if ch.size == 0:
                break
            nxt = int(ch[np.argmax(r[ch])])
            za, zb = pos[cur, 2], pos[nxt, 2]
            if (za - zc) * (zb - zc) <= 0 and za != zb:
                s = (zc - za) / (zb - za)
                out[k] = 2 * (r[cur] + s * (r[nxt] - r[cur]))
                break
            cur = nxt
    return out


def dbh(graph: BranchGraph, height: float = 1.3) -> float:
    """Stem diameter (m) at ``height`` m above the lowest point of the largest tree (by
    total edge length); NaN without radii. See :func:`dbh_per_tree`."""
    per = dbh_per_tree(graph, height)
    labels = graph.trees
    uniq, inv = np.unique(labels, return_inverse=True)
    tbl = np.bincount(inv, weights=graph.edge_length, minlength=uniq.size)
    return float(per[int(np.argmax(tbl))]) if per.size else float("nan")


def volume(graph: BranchGraph) -> float:
    """Total wood volume (m³): frusta ``π L (r₁² + r₁r₂ + r₂²) / 3`` along branches,
    cylinders of the branch's radius where a branch leaves its parent
    (:func:`edge_volumes`)."""
    if graph.radius is None:
        return float("nan")
    return float(edge_volumes(graph)[3].sum())


def compare_to_truth(
    graph: BranchGraph,
    truth: BranchGraph,
    tolerance: float | None = None,
    *,
    step: float | None = None,
    thick: float = 0.03,
    cloud: PointCloud | NDArray | None = None,
    observed_margin: float = 0.03,
) -> dict:
    """Compare a skeleton with a ground-truth skeleton in the same frame.

    Both are resampled every ``step`` metres (default ``tolerance / 4``). **Precision** is
    the fraction of skeleton samples within ``tolerance`` of the truth, **recall** the
    fraction of truth samples within ``tolerance`` of the skeleton (length-weighted, so they
    are the shares of skeleton / truth *length*), F1 their harmonic mean. The default
    tolerance is ``max(0.05, 0.5 * truth stem base radius)`` metres.

    Also: ``nob_ratio`` and ``tbl_ratio`` (skeleton / truth), ``radius_error`` (median of
    ``|r - r_true| / r_true`` over truth samples on branches thicker than ``thick`` m whose
    nearest skeleton sample is within tolerance), ``dbh`` / ``dbh_truth`` / ``dbh_error``
    (relative), ``volume`` / ``volume_truth`` / ``volume_error`` (relative).

    With the scanned ``cloud`` (same frame; points labelled ``is_leaf``/``is_ground`` by
    :func:`~biomorph.tree.synthetic.simulate_scan` are left out), the part of the truth the scan
    saw at all is measured: a truth sample is *observed* when a point lies within its true
    radius + ``observed_margin`` (3 cm) of it. Adds ``observed_fraction`` (length share),
    ``tbl_ratio_observed`` (skeleton length / observed truth length) and ``recall_observed``
    (recall over observed samples) — these separate the method's error from twigs that
    occlusion or sparse sampling left without a single point.
    """
    if graph.n_nodes == 0:
        raise InputError("skeleton is empty; cannot compare with the truth")
    if truth.n_nodes == 0:
        raise InputError("truth skeleton is empty")
    if tolerance is None:
        rb = float(truth.radius[truth.roots].max()) if truth.radius is not None else 0.0
        tolerance = max(0.05, 0.5 * rb)
    if tolerance <= 0:
        raise ParameterError(f"tolerance must be > 0 (metres); got {tolerance}")
    step = step or tolerance / 4
    ps, ecs, ts = resample_graph(graph, step)
    pt, ect, tt = resample_graph(truth, step)
    d_s, _ = cKDTree(pt).query(ps, workers=-1)
    d_t, near_s = cKDTree(ps).query(pt, workers=-1)
    precision = float((d_s <= tolerance).mean())
    recall = float((d_t <= tolerance).mean())
    f1 = 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)
    nob_s, nob_t = int(graph.leaves.size), int(truth.leaves.size)
    out = {
        "tolerance": float(tolerance),
        "precision": precision,
        "recall": recall,
        "f1": f1,
        "nob": nob_s,
        "nob_truth": nob_t,
        "nob_ratio": nob_s / max(nob_t, 1),
        "tbl": graph.total_length,
        "tbl_truth": truth.total_length,
        "tbl_ratio": graph.total_length / truth.total_length
        if truth.total_length
        else float("nan"),
        "mean_distance": float(d_s.mean()),
        "radius_error": float("nan"),
        "radius_samples": 0,
    }
    if graph.radius is not None and truth.radius is not None:
        rt = _interp_radius(truth, ect, tt)
        rs = _interp_radius(graph, ecs, ts)[near_s]
        m = (rt > thick) & (d_t <= tolerance)
        if m.any():
            out["radius_error"] = float(np.median(np.abs(rs[m] - rt[m]) / rt[m]))
            out["radius_samples"] = int(m.sum())
    if cloud is not None:
        if isinstance(cloud, PointCloud):
            wood = np.ones(cloud.n_points, dtype=bool)
            for name in ("is_leaf", "is_ground"):  # labels of simulated scans
                if name in cloud.attributes:
                    wood &= ~np.asarray(cloud.attributes[name]).astype(bool)
            xyz = cloud.xyz[wood]
        else:
            xyz = np.asarray(cloud, dtype=float)
        if xyz.ndim != 2 or xyz.shape[0] == 0:
            raise InputError("cloud for the observed-truth measures has no wood points")
        rt_all = (
            _interp_radius(truth, ect, tt) if truth.radius is not None else np.zeros(pt.shape[0])
        )
        d_c, _ = cKDTree(xyz).query(pt, workers=-1)
        seen = d_c <= rt_all + observed_margin
        frac = float(seen.mean())
        out.update(
            observed_fraction=frac,
            tbl_ratio_observed=graph.total_length / (truth.total_length * frac)
            if frac > 0
            else float("nan"),
            recall_observed=float((d_t[seen] <= tolerance).mean()) if seen.any() else float("nan"),
        )
    d_g, d_true = dbh(graph), dbh(truth)
    v_g, v_true = volume(graph), volume(truth)
    out.update(
        dbh=d_g,
        dbh_truth=d_true,
        dbh_error=(d_g - d_true) / d_true if np.isfinite(d_true) and d_true else float("nan"),
        volume=v_g,
        volume_truth=v_true,
        volume_error=(v_g - v_true) / v_true if np.isfinite(v_true) and v_true else float("nan"),
    )
    return out


# ---------------------------------------------------------------- QSM measures (issue 13)

#: foresters' diameter classes (m): < 2.5 cm, 2.5–7 cm, 7–20 cm, > 20 cm
DIAMETER_CLASSES = (0.025, 0.07, 0.20)


def class_labels(bounds: tuple[float, ...] = DIAMETER_CLASSES) -> list[str]:
    """``["<2.5cm", "2.5-7cm", "7-20cm", ">20cm"]`` for the default bounds."""
    cm = [f"{100 * b:g}" for b in bounds]
    return (
        [f"<{cm[0]}cm"]
        + [f"{a}-{b}cm" for a, b in zip(cm[:-1], cm[1:], strict=True)]
        + [f">{cm[-1]}cm"]
    )


def edge_volumes(graph: BranchGraph) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Per edge (child node ``c``): ``(c, length m, mean diameter m, volume m³)``.

    An edge inside a branch is a frustum between its end radii; the first edge of a branch
    leaving its parent (order rises; without orders: any child at a fork) is a cylinder of
    the branch's own radius — its start node carries the parent's radius, and a frustum
    from there would give every twig a cone of stem wood (TreeQSM's cylinders also carry
    one radius each).
    """
    child = np.flatnonzero(graph.parent >= 0)
    if graph.radius is None:
        raise InputError("the skeleton has no radii; expected a radius per node")
    par = graph.parent[child]
    r2 = graph.radius[child]
    if graph.depth is not None:
        start = graph.depth[child] > graph.depth[par]
    else:
        start = graph.n_children[par] > 1
    r1 = np.where(start, r2, graph.radius[par])
    length = graph.edge_length[child]
    vol = np.pi * length * (r1 * r1 + r1 * r2 + r2 * r2) / 3
    return child, length, r1 + r2, vol


def volume_by_class(
    graph: BranchGraph, bounds: tuple[float, ...] = DIAMETER_CLASSES
) -> dict[str, dict[str, float]]:
    """Wood volume (m³) and length (m) per diameter class (an edge's class is its mean
    diameter): ``{"<2.5cm": {"volume", "length"}, ...}``."""
    _, length, diam, vol = edge_volumes(graph)
    cls = np.searchsorted(np.asarray(bounds), diam, side="right")
    k = len(bounds) + 1
    v = np.bincount(cls, weights=vol, minlength=k)
    ln = np.bincount(cls, weights=length, minlength=k)
    return {
        lab: {"volume": float(v[i]), "length": float(ln[i])}
        for i, lab in enumerate(class_labels(bounds))
    }


def volume_by_order(graph: BranchGraph) -> dict[int, dict[str, float]]:
    """Wood volume (m³), length (m) and branch count per branch order (``depth``; an edge
    has its child's order): ``{0: {"volume", "length", "branches"}, 1: ...}``."""
    if graph.depth is None:
        raise InputError("the skeleton has no branch order; run tree.order.with_order")
    child, length, _, vol = edge_volumes(graph)
    order = np.asarray(graph.depth)[child]
    par = graph.parent
    starts = order > np.asarray(graph.depth)[par[child]]  # a branch leaves its parent
    out: dict[int, dict[str, float]] = {}
    for o in np.unique(order):
        m = order == o
        n_br = int((starts & m).sum()) if o > 0 else int(np.unique(graph.trees[child[m]]).size)
        out[int(o)] = {
            "volume": float(vol[m].sum()),
            "length": float(length[m].sum()),
            "branches": n_br,
        }
    return out


def tree_attributes(graph: BranchGraph, height: float = 1.3) -> list[dict[str, float]]:
    """TreeQSM ``treedata``-style attributes per tree: total / trunk / branch volume (m³)
    and length (m), number of order-1 branches, height (m, top minus base),
    ``trunk_top_gap`` (m, the tree's top minus the trunk's highest node), DBH (m),
    crown base height (m, lowest order-1 branch start above the base), crown length (m)
    and crown diameter (m, mean of the x/y extents of the non-trunk nodes)."""
    if graph.depth is None or graph.radius is None:
        raise InputError("tree attributes need radii and branch orders")
    dbhs = dbh_per_tree(graph, height)
    labels = graph.trees
    depth = np.asarray(graph.depth)
    child, length, _, vol = edge_volumes(graph)
    par = graph.parent
    pos = graph.position
    out = []
    for k, t in enumerate(np.unique(labels)):
        nodes = np.flatnonzero(labels == t)
        e = labels[child] == t
        trunk = e & (depth[child] == 0)
        z0 = float(pos[nodes, 2].min())
        first = e & (depth[child] == 1) & (depth[par[child]] == 0)
        crown = nodes[depth[nodes] > 0]
        cbh = float(pos[par[child[first]], 2].min() - z0) if first.any() else float("nan")
        ext = pos[crown, :2].max(axis=0) - pos[crown, :2].min(axis=0) if crown.size else [0, 0]
        top = float(pos[nodes, 2].max() - z0)
        stem_nodes = nodes[depth[nodes] == 0]
        trunk_top = float(pos[stem_nodes, 2].max() - z0) if stem_nodes.size else 0.0
        out.append(
            {
                "tree": int(t),
                "total_volume": float(vol[e].sum()),
                "trunk_volume": float(vol[trunk].sum()),
                "branch_volume": float(vol[e & ~trunk].sum()),
                "total_length": float(length[e].sum()),
                "trunk_length": float(length[trunk].sum()),
                "branch_length": float(length[e & ~trunk].sum()),
                "branches_order1": int(first.sum()),
                "height": top,
                "trunk_top_gap": top - trunk_top,
                "dbh": float(dbhs[k]),
                "crown_base_height": cbh,
                "crown_length": top - cbh if np.isfinite(cbh) else float("nan"),
                "crown_diameter": float(np.mean(ext)),
                "max_order": int(depth[nodes].max()),
            }
        )
    return out


def _surface_candidates(
    graph: BranchGraph, xyz: NDArray, k: int = 8, candidates: SegmentCandidates | None = None
) -> tuple[NDArray, NDArray]:
    """Per point and candidate edge (``k`` nearest skeleton samples): signed distance to
    the cylinder (frustum) surface, m (> 0 outside), and the local radius, m."""
    c = candidates if candidates is not None else segment_candidates(graph, xyz, k)
    node, par, t = c.node, c.par, c.t
    r = graph.radius
    rp = np.where(par >= 0, r[np.maximum(par, 0)], r[node])
    rad = rp + (r[node] - rp) * t
    return c.d - rad, rad


@numba.njit(cache=True)
def _nearest_surface(node, par, t, d, r):  # pragma: no cover - numba
    """Per point, of its candidate edges the one whose surface is nearest (first of equal
    ones, a NaN first, as ``argmin(abs(...))``): the signed distance to it, its radius
    there (``rp + (rn - rp) t``, the expression of :func:`_surface_candidates`) and the
    nearer end of its axis. One pass, no ``[n, k]`` temporaries."""
    n, k = node.shape
    sd = np.empty(n)
    rd = np.empty(n)
    near = np.empty(n, dtype=np.int64)
    for i in range(n):
        best = 0
        best_a = np.inf
        best_s = 0.0
        best_r = 0.0
        for j in range(k):
            v = node[i, j]
            p = par[i, j]
            rn = r[v]
            rp = r[p] if p >= 0 else rn
            rad = rp + (rn - rp) * t[i, j]
            sv = d[i, j] - rad
            a = abs(sv)
            if j == 0 or a < best_a or (np.isnan(a) and not np.isnan(best_a)):
                best, best_a, best_s, best_r = j, a, sv, rad
        p = par[i, best]
        sd[i] = best_s
        rd[i] = best_r
        near[i] = p if (p >= 0 and t[i, best] < 0.5) else node[i, best]
    return sd, rd, near


def surface_distance(
    graph: BranchGraph,
    xyz: NDArray,
    k: int = 8,
    candidates: SegmentCandidates | None = None,
    *,
    refine: float | None = None,
    refine_k: int = 32,
) -> tuple[NDArray, NDArray, NDArray]:
    """Signed distance of every point to the nearest cylinder (frustum) surface, m (> 0
    outside), that cylinder's radius there (m), and the model node nearest to the point:
    the nearer end of that cylinder's axis (its parent where the closest axis point lies
    in the parent's half). ``refine`` (m): points whose surface distance exceeds it are
    looked at again with ``refine_k`` candidate edges instead of ``k`` (their nearest
    surface is kept where the wider look finds a nearer one)."""
    c = candidates if candidates is not None else segment_candidates(graph, xyz, k)
    if graph.radius is None:
        raise InputError("the skeleton has no radii; expected a cylinder model")
    sd, rd, near = _nearest_surface(
        c.node, c.par, c.t, c.d, np.ascontiguousarray(graph.radius, dtype=np.float64)
    )
    if refine is not None and xyz.shape[0]:
        # the k candidates are the edges with the nearest *axis* samples: on a thick stem
        # at a whorl they can all be branch bases, whose thin surfaces lie farther than
        # the stem's own; look again with more candidates where the first look was far
        far = np.flatnonzero(np.abs(sd) > refine)
        if far.size and refine_k > k:
            sub = np.asarray(xyz, dtype=float)[far]
            # the same samples: no second resampling and k-d tree build
            wide = segment_candidates(graph, sub, refine_k, _samples=c.samples)
            sd2, rd2, near2 = surface_distance(graph, sub, refine_k, wide)
            better = np.abs(sd2) < np.abs(sd[far])
            idx = far[better]
            sd[idx], rd[idx], near[idx] = sd2[better], rd2[better], near2[better]
    return sd, rd, near


def axis_distance(
    graph: BranchGraph, xyz: NDArray, k: int = 8, candidates: SegmentCandidates | None = None
) -> tuple[NDArray, NDArray, NDArray]:
    """As :func:`surface_distance`, but each point goes to the cylinder whose *axis* is
    nearest (of its ``k`` candidate edges): the signed distance to that cylinder's surface
    (m, > 0 outside), its radius there and the nearer end of its axis. Which cylinder a
    point belongs to then does not depend on the radii: an over-thick cylinder keeps its
    inside points (by the nearest surface they go to thin neighbours, whose surfaces lie
    nearer) and does not gather its neighbours' points about its inflated surface."""
    c = candidates if candidates is not None else segment_candidates(graph, xyz, k)
    if graph.radius is None:
        raise InputError("the skeleton has no radii; expected a cylinder model")
    n = c.d.shape[0]
    if n == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64)
    radius = np.asarray(graph.radius, dtype=float)
    j = np.argmin(c.d, axis=1)
    rows = np.arange(n)
    v, p, t, d = c.node[rows, j], c.par[rows, j], c.t[rows, j], c.d[rows, j]
    rn = radius[v]
    rp = np.where(p >= 0, radius[np.maximum(p, 0)], rn)
    rad = rp + (rn - rp) * t
    near = np.where((p >= 0) & (t < 0.5), p, v)
    return d - rad, rad, near


def cylinder_fit(
    graph: BranchGraph,
    cloud: PointCloud | NDArray,
    *,
    far: float = 0.10,
    bounds: tuple[float, ...] = DIAMETER_CLASSES,
    k: int = 8,
    candidates: SegmentCandidates | None = None,
) -> dict:
    """Reference-free fit of a cylinder model to its cloud, as a forest scientist checks it.

    ``far_share``: share of points farther than ``far`` (10 cm) from every cylinder surface
    (TreeQSM's models leave about 11 % on real scans). Each point belongs to the cylinder
    whose surface is nearest; ``residual`` per diameter class is the median of ``(distance
    to the axis − radius) / radius`` over the points within one radius of that surface
    (negative = cylinders too thick, positive = too thin); ``points`` the count behind it.
    ``axis_residual`` (and ``axis_points``): the same median with each point given to the
    cylinder whose *axis* is nearest (of its ``k`` candidates). The nearest surface hides
    an over-thick cylinder where others run near it: a point deep inside it is nearer to a
    thin neighbour's surface than to its own and counts for the neighbour (plantscan3d's
    A3B4 model on its 2.5-7 cm branches: -4 % by surface, -25 % by axis; docs/tree.md,
    session 32).
    ``candidates``: the cloud's :func:`segment_candidates` (``k``), if already computed.
    """
    if graph.radius is None:
        raise InputError("the skeleton has no radii; expected a cylinder model")
    xyz = cloud.xyz if isinstance(cloud, PointCloud) else np.asarray(cloud, dtype=float)
    if xyz.shape[0] == 0 or graph.n_nodes == 0:
        raise InputError("cylinder_fit needs points and a non-empty skeleton")
    # points that look far are looked at again with more candidate cylinders: "every
    # cylinder surface" must not mean "the 8 with the nearest axis samples"
    c = candidates if candidates is not None else segment_candidates(graph, xyz, k)
    sb, rb, _ = surface_distance(graph, xyz, k, c, refine=far)
    near = np.abs(sb) <= rb
    cls = np.searchsorted(np.asarray(bounds), 2 * rb, side="right")
    sa, ra, _ = axis_distance(graph, xyz, k, c)
    near_a = (np.abs(sa) <= ra) & (ra > 0)
    cls_a = np.searchsorted(np.asarray(bounds), 2 * ra, side="right")
    res = {}
    for i, lab in enumerate(class_labels(bounds)):
        m = near & (cls == i)
        ma = near_a & (cls_a == i)
        res[lab] = {
            "residual": float(np.median(sb[m] / rb[m])) if m.any() else float("nan"),
            "points": int(m.sum()),
            "axis_residual": float(np.median(sa[ma] / ra[ma])) if ma.any() else float("nan"),
            "axis_points": int(ma.sum()),
        }
    return {"far_share": float((np.abs(sb) > far).mean()), "far": far, "classes": res}


def qsm_report(
    graph: BranchGraph,
    cloud: PointCloud | NDArray | None = None,
    *,
    candidates: SegmentCandidates | None = None,
) -> dict:
    """All QSM measures in one dict: ``classes`` (:func:`volume_by_class`), ``orders``
    (:func:`volume_by_order`), ``trees`` (:func:`tree_attributes`) and, with a cloud,
    ``fit`` (:func:`cylinder_fit`; ``candidates`` as in :func:`skeleton_metrics`)."""
    out = {
        "classes": volume_by_class(graph),
        "orders": volume_by_order(graph),
        "trees": tree_attributes(graph),
    }
    if cloud is not None:
        out["fit"] = cylinder_fit(graph, cloud, candidates=candidates)
    return out


def summary_rows(m: dict) -> list[tuple[str, str]]:
    """What a forester reads first, from a run's ``metrics`` (:func:`qsm_report`'s keys):
    wood volume in all and per diameter class (L), and for a single tree its height, trunk
    length and DBH (a plot's per-tree figures are in treedata.csv); label and text pairs
    for the CLI's summary table and the studio's."""
    rows: list[tuple[str, str]] = []
    trees = m.get("trees") or []
    if trees:
        rows.append(("wood volume (L)", f"{1e3 * sum(t['total_volume'] for t in trees):,.1f}"))
    classes = m.get("classes") or {}
    if classes:
        cells = ", ".join(f"{k} {1e3 * v['volume']:,.1f}" for k, v in classes.items())
        rows.append(("volume by diameter (L)", cells))
    if len(trees) == 1:
        t = trees[0]
        rows.append(("height / trunk (m)", f"{t['height']:.2f} / {t['trunk_length']:.2f}"))
        if t.get("dbh") is not None and np.isfinite(t["dbh"]):
            rows.append(("DBH (cm)", _dbh_text(t)))
    return rows


def _dbh_text(t: dict) -> str:
    """The DBH row: the taper model's (TreeQSM's ``DBHqsm``) and the stem circles' at
    breast height (``DBHcyl``, :func:`biomorph.tree.radius.breast_height_fits`)."""
    lo, hi = t.get("dbh_fit_band") or (1.0, 1.6)
    band = f"{lo:.1f}-{hi:.1f} m"
    text = f"{100 * t['dbh']:.1f} model"
    fit, n = t.get("dbh_fit"), t.get("dbh_fits")
    if fit is not None and n:
        text += f"; {100 * fit:.1f} from {n} stem circles at {band}"
        if t.get("dbh_fit_wider"):
            text += " (searched wider: a stem seen from one side)"
    elif "dbh_fits" in t:
        text += f"; no stem circle at {band}"
    return text


def scan_rows(params: dict, info: dict) -> list[tuple[str, str]]:
    """What a run read from the scan, from its ``params`` and ``info``: point and node
    spacing (mm) and the residual stage's threshold (node spacings; ``auto``: the twigs'
    points a surface or an envelope, :func:`biomorph.tree.residual.residual_factor`);
    label and text pairs for the CLI's summary table and the studio's."""
    rows = []
    ps, ns = info.get("point_spacing"), params.get("node_spacing") or info.get("node_spacing")
    if ps and ns:
        rows.append(("point / node spacing (mm)", f"{1e3 * ps:.1f} / {1e3 * ns:.1f}"))
    f = params.get("residual_factor")
    if f is not None:
        how = "set"
        if params.get("residual_threshold") is None:
            how = "auto, twigs: " + ("a surface" if info.get("residual_surface") else "an envelope")
        rows.append(("residual threshold (node spacings)", f"{f:.2f} ({how})"))
    return rows
