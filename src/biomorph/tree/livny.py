"""Graph-based tree skeletonisation after Livny et al. 2010 ("branch-structure graph").

Every step of the method (seed 001, §2.4 / SPEC §2) is here, with the least-squares
problems **solved exactly**: the orientation field (ΣO + ΣE) and the position refinement
(ΣA + ΣF) are quadratic forms whose Hessians are *tree-structured* (a weighted tree
Laplacian plus block-diagonal terms), so they are solved by O(n) Gaussian elimination
from the leaves to the roots and back-substitution (:func:`solve_tree_system`, numba);
the result equals ``scipy.sparse.linalg.spsolve`` on the same matrix (tested), without
fill-in and without iterations. The thesis used gradient descent (~20 min at 14k points).

Pipeline (frames: metres, Z up, cloud frame):

i.   **roots**: the lowest slice of points (``root_slice`` above the ground, or above the
     lowest point) projected to XY and clustered by density on a 2-D grid (DBSCAN-like,
     number of trees found automatically) or by k-means when ``n_trees`` is given; the
     base points of each cluster are that tree's root set.
ii.  **neighbour graph** P: symmetric kNN (or radius) graph from ``cKDTree`` with squared
     distance weights; disconnected pieces (gappy scans) are *bridged* by their shortest
     inter-component edges (Borůvka rounds = a minimum spanning forest over components),
     so no point is lost. A virtual root joined by 0-weight edges to every root point;
     ``scipy.sparse.csgraph.dijkstra`` with predecessors gives the shortest-path forest,
     which segments the trees automatically; on a plot, the pieces it reaches only
     across a gap are re-decided by the stems they continue and stand over
     (:mod:`biomorph.tree.crowns`: tops behind occluded upper stems).
     **Contraction** (documented deviation for scale): a Livny graph over all points has
     one vertex per point. We contract it to about one vertex per ``node_spacing``: points
     are binned by their geodesic distance along the shortest-path forest
     (``floor(path_length / node_spacing)``), each bin is split into its connected pieces
     in P (per tree), and every piece becomes one vertex at its centroid (Xu et al. 2007's
     level sets, which also centres vertices on fully scanned stems). The contracted
     neighbour graph Q joins pieces of one tree that share an edge of P (the segmentation
     is final: no edge joins two trees' vertices); the Livny steps iii–viii then
     run on Q exactly as on P (``node_spacing=0`` keeps one vertex per point).
iii. importance weights ``c_v`` = total edge length of the subtree of ``v``.
iv.  orientation field: minimise ΣO + ΣE exactly (three independent tree systems).
v.   positions: minimise ΣA + ΣF exactly.
     Edge weights (``edge_weights``): ``"livny"`` is the seed's, ``c_v`` in ΣE/ΣF and the
     mean ``(c_p + c_v)/2`` in ΣO/ΣA. At a fork that mean is dominated by the heavy
     parent, so a twig's first edge is pulled to the *parent branch's* orientation and the
     whole twig swings off its points (and a tip edge, ``c_v = 0``, has no ΣF anchor at
     all). ``"branch"`` (default) weights every term of the edge p→v by the length that
     edge carries, ``c̃_v = c_v + |e(p, v)|`` (the same ``c̃`` as step vii): along a branch
     it equals Livny's within one edge length, at a fork each twig is smoothed with its
     own weight. Measured on the synthetic presets (clean scans, bench/tree.py) skeleton F1
     rises from 0.94–0.97 to 0.95–0.98 with NOB/TBL unchanged or closer to the truth.
vi.  re-weighting: each refined edge finds the nearest edge of Q (nearest vertices of its
     two ends); its weight is multiplied by ``1 - reweight * |cos|`` of the angle between
     the two (see below), the spanning forest is recomputed, and iii–v repeat until the
     structure (parent array) stops changing or ``max_iter`` is reached (default 5).
vii. allometric radii (:func:`allometric_radii`).
viii. cleanup: :mod:`biomorph.tree.cleanup`.

On step vi: the seed says the weight is "scaled by the dot product of the edge directions".
Dijkstra prefers *small* weights, so a literal product would favour edges that disagree
with the refined skeleton; we scale by ``1 - reweight*|dot|`` (default ``reweight=0.5``),
which makes edges that agree with the refined skeleton cheaper, the stated intent.

On step vii: the seed prints ``ΣR = Σ |r_u − (c_u/c_v)^2.5 r_v|²``. Read literally, a parent
carrying twice its child's length would be 5.7× thicker; the allometry it cites (Xu et
al. 2007, pipe model ``r^2.5 ∝ c``) and the thesis's own code use ``r_v = r_u
(c_v/c_u)^(1/2.5)``. We use the latter. On a tree, ΣR has an exact zero (propagate the
ratios from the root) up to one scale per tree, which ΣD fixes: the ``c``-weighted mean
radius equals the mean point-to-skeleton distance. That closed form *is* the exact
least-squares solution.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.core.graph import BranchGraph
from biomorph.errors import InputError, ParameterError
from biomorph.tree.allometry import allometric_radii, skeleton_distance
from biomorph.tree.crowns import add_edges, partition_trees, same_tree_edges
from biomorph.tree.foliage import require_wood
from biomorph.tree.neighbours import (
    GAP_SHORT,
    LEVEL_CELL,
    NODE_SPACING,
    NODE_SPACING_MIN,
    BridgeRule,
    Contraction,
    NeighbourCache,
    bridge_components,
    contract,
    default_node_spacing,
    estimate_spacing,
    neighbour_graph,
    segment_trees,
    shortest_path_forest,
    spatial_order,
)
from biomorph.tree.resample import densify, extend_tips
from biomorph.tree.roots import check_single_tree, check_trunk_reaches_ground, find_roots
from biomorph.tree.treesolve import (
    EDGE_WEIGHTS,
    importance_weights,
    orientation_field,
    orientation_system,
    refine_positions,
    refinement_system,
    reweight_edges,
    solve_tree_system,
    tree_matrix,
)

#: names kept importable from here while callers move to the split modules (issue 12):
#: roots (:mod:`~biomorph.tree.roots`), graph building (:mod:`~biomorph.tree.neighbours`),
#: tree solves (:mod:`~biomorph.tree.treesolve`), allometry
#: (:mod:`~biomorph.tree.allometry`), resampling (:mod:`~biomorph.tree.resample`)
__all__ = [
    "LivnyResult",
    "skeletonize_graph",
    "find_roots",
    "neighbour_graph",
    "bridge_components",
    "shortest_path_forest",
    "contract",
    "importance_weights",
    "orientation_field",
    "refine_positions",
    "solve_tree_system",
    "allometric_radii",
    "skeleton_distance",
    "estimate_spacing",
    "densify",
    "extend_tips",
    "Contraction",
    "orientation_system",
    "refinement_system",
    "tree_matrix",
    "EDGE_WEIGHTS",
    "NODE_SPACING",
    "NODE_SPACING_MIN",
    "LEVEL_CELL",
]


#: step v may move a vertex at most this many RMS spreads of its own points (at least one
#: point spacing) from their centroid. Livny's ΣA/ΣO pair weights ``(c_p + c_v)/2`` are
#: dominated by a heavy parent, and a tip (``c_v = 0``) has no ΣF anchor, so unbounded
#: refinement swung twigs up to 20-40 cm off their points (AdTree tree1: median vertex
#: shift 4 cm, 10 % over 21 cm; 28 % of the points then lay > 10 cm from every cylinder).
#: One spread keeps every vertex inside the points it stands for (1.0: the spread itself,
#: no tuning; 0.5 measured the same within 1 % on the real clouds here). On clean dense
#: thick stems the bound keeps stray surface pieces on the surface (the unbounded solve
#: pulls them onto the axis); cleanup rule 1b merges them there.
REACH = 1.0

#: how the kNN pieces of one contraction level join (:func:`~biomorph.tree.neighbours.contract`).
#: ``"adjacent"``: every voxel-adjacent piece, which puts one vertex between twigs 5–20 cm
#: apart. ``"adaptive"`` (opt-in, issue 13 session 7) joins them when their gap is below
#: the sum of their RMS spreads or both are wider than the level (arcs of one thick stem
#: ring): AdTree tree1 wood points > 10 cm from every cylinder 10.0 → 8.5 %, spruce 15.8 →
#: 11.3 %, rTwig F1 0.944 → 0.962, 5 cm sparse scans F1 unchanged or higher — but on clean
#: dense synthetic stems it still splits some branch ends and stem rings (the 4,000-point
#: Y tree through the pipeline: 4 tips instead of 3 on 2 of 5 seeds), so it is not the default
#: (docs/tree.md "Session 7 (tree B)").
#: ``"two-scale"`` (default since issue 13 session 15): pieces touching at
#: ``neighbours.FINE_CELL`` (3) point spacings always join, pieces touching only at the
#: coarse cell by the adaptive test — rTwig F1 vs TreeQSM / SimpleForest 0.973 / 0.981 →
#: 0.978 / 0.986, far share pine plot 12.97 → 11.7 %, spruce 6.4 → 4.6 %, the synthetic
#: presets unchanged within seed scatter (docs/tree.md, "Session 15")
LEVEL_MERGE_DEFAULT = "two-scale"

#: remove tip chains lying wholly inside the rest of the skeleton after step vii
#: (:func:`biomorph.tree.cleanup.merge_inside_tips`); ``None``: with the adaptive merge
#: only. Off (opt-in): on the real clouds it costs the default 0.4-1 point of far share
#: (spruce, pine plot) and does not fix the adaptive merge's Y tree through the whole
#: pipeline (docs/tree.md, "Session 8 (tree B)")
INSIDE_TIPS: bool | None = False


def clamp_to_points(
    position: NDArray[np.float64], centroid: NDArray[np.float64], reach: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Limit each refined vertex to ``reach`` (m) from the centroid of its own points."""
    d = position - centroid
    n = np.linalg.norm(d, axis=1)
    f = np.minimum(1.0, reach / np.maximum(n, 1e-30))
    return centroid + d * f[:, None]


def _optimise(q, qpos, roots, parent, max_iter, reweight, edge_weights, limit):
    """Steps iii-vi: weights, orientation field, positions, re-weighting until the
    spanning forest is stable (``limit``: optional per-vertex reach, :func:`clamp_to_points`)."""
    qtree_kd = cKDTree(qpos)
    pos = qpos
    iterations = 0
    for it in range(max_iter):
        iterations = it + 1
        order = treeops.topological_order(parent)
        c = importance_weights(parent, qpos, order)
        o = orientation_field(parent, qpos, c, order, edge_weights)
        pos = refine_positions(parent, qpos, c, o, order, edge_weights)
        if limit is not None:
            pos = clamp_to_points(pos, qpos, limit)
        if it + 1 >= max_iter:
            break
        q = reweight_edges(q, qpos, parent, pos, reweight, qtree_kd)
        _, new_parent = shortest_path_forest(q, roots)
        if np.array_equal(new_parent, parent):
            break
        parent = new_parent
    return parent, pos, iterations


def _segment(xyz, p_graph, roots, root_tree, gap, crown_partition):
    """Step ii's segmentation: the tree of every point (-1: no root reaches it), the
    neighbour graph with the partition's bridges, and every point's geodesic distance from
    its root (Euclidean edge lengths, within its own tree on a plot: a contraction level
    counts along the point's own tree). One tree: every reachable point is its. Several:
    Livny's squared-weight shortest-path forest from all roots, the pieces it reaches across
    a gap (or not at all) re-decided by :func:`~biomorph.tree.crowns.partition_trees`."""
    if np.unique(root_tree).size < 2:
        geo = p_graph.copy()
        geo.data = np.sqrt(geo.data)
        plen, _ = shortest_path_forest(geo, roots)
        return p_graph, np.where(np.isfinite(plen), 0, -1).astype(np.int64), plen
    if crown_partition:
        point_tree, br, bc = partition_trees(xyz, p_graph, roots, root_tree, gap)
        p_graph = add_edges(xyz, p_graph, br, bc)
    else:
        point_tree = segment_trees(p_graph, roots, root_tree)
    geo = same_tree_edges(p_graph, point_tree)
    geo.data = np.sqrt(geo.data)
    plen, _ = shortest_path_forest(geo, roots)
    return p_graph, point_tree, plen


@dataclass
class LivnyResult:
    """Output of :func:`skeletonize_graph`.

    graph : skeleton (positions, parent, allometric ``radius``, ``weight`` = c_v, ``tree_id``).
    point_node : for every input point the skeleton vertex it was contracted into (-1 when
        dropped); ``point_tree`` its tree.
    timings : seconds per phase: ``t1`` roots, ``t2`` initial skeleton (graph, bridging,
        Dijkstra, contraction), ``t3`` global optimisation (iii–vi), plus sub-phases.
    info : counts (points, components bridged, iterations, trees, vertices).
    kdtree : the k-d tree of the input points (for later queries on the same points).
    """

    graph: BranchGraph
    point_node: NDArray[np.int64]
    point_tree: NDArray[np.int64]
    timings: dict[str, float] = field(default_factory=dict)
    info: dict[str, object] = field(default_factory=dict)
    kdtree: cKDTree | None = field(default=None, repr=False)


def _inside_tips_on(flag: bool | None, level_merge: str) -> bool:
    flag = INSIDE_TIPS if flag is None else flag
    return level_merge == "adaptive" if flag is None else bool(flag)


def _merge_inside_tips(graph, keep, label, xyz, spacing_pts):
    """:func:`~biomorph.tree.cleanup.merge_inside_tips` on the step-vii graph (vertices
    ``keep`` of the contracted graph) and the points' vertex labels carried along."""
    from biomorph.tree.cleanup import merge_inside_tips_mapped

    idx = np.flatnonzero(keep)
    vmap = np.full(keep.size, -1, dtype=np.int64)  # contracted vertex -> graph node
    vmap[idx] = np.arange(idx.size)
    ok = label >= 0
    graph, new = merge_inside_tips_mapped(graph, xyz[ok], max(spacing_pts, 1e-6))
    g = vmap[np.maximum(label, 0)]
    return graph, np.where(ok & (g >= 0), new[np.maximum(g, 0)], -1)


def _kdtree(xyz: NDArray[np.float64], neighbours: NeighbourCache | None) -> cKDTree:
    """The k-d tree of ``xyz``: the one built on these points before (the foliage
    pass's, carried by the neighbour lists) or a new one."""
    t = None if neighbours is None else neighbours.tree
    if t is not None and t.n == xyz.shape[0] and t.m == 3 and np.array_equal(t.data, xyz):
        return t
    return cKDTree(xyz)


def skeletonize_graph(
    xyz: NDArray[np.float64],
    *,
    n_trees: int | None = None,
    k: int = 10,
    search_radius: float | None = None,
    node_spacing: float | None = None,
    max_iter: int = 5,
    reweight: float = 0.5,
    height: NDArray[np.float64] | None = None,
    root_slice: float = 0.5,
    min_tree_distance: float = 0.6,
    allometry_exponent: float = 2.5,
    seed: int = 0,
    edge_weights: str = "livny",
    progress=None,
    source: str = "point cloud",
    bridge_gap: float | None = None,
    reach: float | None = REACH,
    level_merge: str = LEVEL_MERGE_DEFAULT,
    crown_partition: bool = True,
    inside_tips: bool | None = None,
    neighbours: NeighbourCache | None = None,
) -> LivnyResult:
    """Livny et al. 2010 steps i–vii on a point cloud (cleanup is :mod:`~biomorph.tree.cleanup`).

    Parameters
    ----------
    xyz : ``float[n, 3]`` points, metres, Z up (ground already removed).
    n_trees : number of trees, or ``None`` to find them by density clustering.
    k : neighbours per point in the neighbour graph (ignored if ``search_radius`` given).
    search_radius : radius-search neighbour graph instead of kNN (metres).
    node_spacing : contraction level width (metres); default ``NODE_SPACING`` (3) × the
        median point spacing, clipped to [``NODE_SPACING_MIN`` (0.2 %), 2 %] of the cloud
        height; 0 keeps every point as a vertex.
    max_iter : cap of the re-weighting iterations (step vi); 1 = no re-weighting.
    reweight : strength of the step-vi weight change (0..1).
    height : height above ground per point (from ground removal), for the root slice.
    root_slice, min_tree_distance : see :func:`find_roots`.
    allometry_exponent : pipe-model exponent of step vii.
    edge_weights : weights of steps iv–v: the seed's ``"livny"`` (default) or ``"branch"``
        (see the module doc).
    progress : optional ``advance(n, description)`` callback.
    source : name of the cloud in error messages.
    bridge_gap : gaps of the neighbour graph up to this (m) are always bridged; longer ones
        only where the wood supports it (:class:`~biomorph.tree.neighbours.BridgeRule`:
        points along the bridge, or a bridge continuing its piece's axis and no longer
        than that piece). Default ``GAP_SHORT`` (4) node spacings; ``inf`` bridges every
        gap (the earlier behaviour). Unbridged pieces drop out (``info["unbridged_points"]``).
    reach : step v keeps each vertex within ``reach`` RMS spreads of its own points (at
        least one point spacing) from their centroid (default :data:`REACH`); ``None`` =
        the unbounded refinement of the paper.
    level_merge : how adjacent pieces of one contraction level join (default
        :data:`LEVEL_MERGE_DEFAULT`, ``"two-scale"``; ``"adjacent"``, ``"adaptive"``, ``"overlap"``;
        :func:`~biomorph.tree.neighbours.contract`).
    inside_tips : after step vii remove tip chains lying wholly inside the rest of the
        skeleton (:func:`~biomorph.tree.cleanup.merge_inside_tips`: parallel paths and
        split branch ends from stem-surface pieces); default :data:`INSIDE_TIPS` (off;
        ``None``: with ``level_merge="adaptive"`` only).
    crown_partition : on a plot, re-decide the pieces Livny's segmentation reaches across a
        gap (or not at all) by the stems they continue and stand over
        (:func:`~biomorph.tree.crowns.partition_trees`); ``False``: the segmentation alone.
    neighbours : neighbour lists of ``xyz`` from an earlier query with at least ``k + 1``
        neighbours (:class:`~biomorph.tree.neighbours.NeighbourCache`, e.g. the outlier
        filter's): the kNN graph takes its rows from them where they decide it (the same
        graph) and they are released once it is built.

    Raises :class:`~biomorph.errors.InputError` (one line, exit 2 at the CLI) for clouds
    with no tree model to give: foliage only (:func:`~biomorph.tree.foliage.check_not_only_leaves`),
    no trunk reaching a found ground (:func:`~biomorph.tree.roots.check_trunk_reaches_ground`),
    or two stems in a one-tree run, ``n_trees=1`` (:func:`~biomorph.tree.roots.check_single_tree`).
    """
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    n = xyz.shape[0]
    if n < 4:
        raise InputError(f"the graph method needs at least 4 points, got {n}")
    if max_iter < 1:
        raise ParameterError(f"max_iter must be >= 1, got {max_iter}")
    if not 0 <= reweight < 1:
        raise ParameterError(f"reweight must lie in [0, 1), got {reweight}")
    if edge_weights not in EDGE_WEIGHTS:
        raise ParameterError(
            f"edge_weights {edge_weights!r}; expected one of {', '.join(EDGE_WEIGHTS)}"
        )
    require_wood(xyz, source)
    check_trunk_reaches_ground(height, source=source)
    if n_trees == 1:
        check_single_tree(
            xyz,
            height=height,
            root_slice=root_slice,
            min_tree_distance=min_tree_distance,
            source=source,
        )
    timings: dict[str, float] = {}

    def tick(name: str, t0: float) -> float:
        t = time.perf_counter()
        timings[name] = timings.get(name, 0.0) + (t - t0)
        if progress is not None:
            progress(1, name)
        return t

    t0 = time.perf_counter()
    t_start = t0
    kd = _kdtree(xyz, neighbours)
    spacing_pts = estimate_spacing(xyz, kdtree=kd)
    extent = float(np.ptp(xyz[:, 2]))
    if node_spacing is None:
        node_spacing = default_node_spacing(spacing_pts, extent)
    roots, root_tree = find_roots(
        xyz,
        n_trees=n_trees,
        height=height,
        root_slice=root_slice,
        min_tree_distance=min_tree_distance,
        base_height=max(node_spacing / 2, 2 * spacing_pts),
        seed=seed,
    )
    t0 = tick("roots", t0)
    timings["t1"] = t0 - t_start

    t2s = t0
    p_graph = neighbour_graph(xyz, k=k, radius=search_radius, tree=kd, cache=neighbours)
    neighbours = None  # frees the 10⁶ × 17 lists before bridging
    t0 = tick("neighbour_graph", t0)
    gap = GAP_SHORT * node_spacing if bridge_gap is None else float(bridge_gap)
    if not gap >= 0:
        raise ParameterError(f"bridge_gap must be >= 0 (metres), got {bridge_gap}")
    rule = None if np.isinf(gap) else BridgeRule(short=gap, spacing=max(spacing_pts, 1e-6))
    p_graph, n_comp = bridge_components(xyz, p_graph, tree=kd, rule=rule, anchors=roots)
    t0 = tick("bridging", t0)
    p_graph, point_tree, plen = _segment(xyz, p_graph, roots, root_tree, gap, crown_partition)
    t0 = tick("dijkstra", t0)
    con = contract(
        xyz,
        p_graph,
        plen,
        point_tree,
        node_spacing,
        point_spacing=spacing_pts,
        merge=level_merge,
        k=k,
    )
    t0 = tick("contraction", t0)
    timings["t2"] = t0 - t2s

    # ---- steps iii-vi on the contracted graph Q
    t3s = t0
    q = con.graph
    qpos = con.position
    _, parent = shortest_path_forest(q, con.roots)
    unreached = parent < 0
    unreached[con.roots] = False
    limit = None
    if reach is not None and con.spread is not None:
        limit = np.maximum(reach * con.spread, spacing_pts)
    parent, pos, iterations = _optimise(
        q, qpos, con.roots, parent, max_iter, reweight, edge_weights, limit
    )
    t0 = tick("optimisation", t0)
    timings["t3"] = t0 - t3s
    timings["iterations"] = float(iterations)

    # drop vertices that no root reaches (cannot happen after bridging, kept for safety)
    keep = np.ones(parent.size, dtype=bool)
    keep[unreached & (parent < 0)] = False
    order = treeops.topological_order(parent)
    c = importance_weights(parent, pos, order)
    # ---- step vii: allometric radii with ΣD from the mean point-to-skeleton distance
    ok = con.label >= 0
    # the points in spatial order (the same distances, half the query's cache misses)
    pts = xyz[ok]
    perm = spatial_order(pts)
    d = np.empty(pts.shape[0])
    d[perm] = skeleton_distance(pts[perm], parent, pos)[0]
    del pts
    ptree = con.tree[con.label[ok]]
    ntree = int(con.tree.max()) + 1
    md = np.bincount(ptree, weights=d, minlength=ntree) / np.maximum(
        np.bincount(ptree, minlength=ntree), 1
    )
    root = treeops.root_of(parent, order)
    vtree = con.tree[root]
    r = allometric_radii(
        parent, pos, c, md[np.unique(vtree)], tree=vtree, exponent=allometry_exponent, order=order
    )
    t0 = tick("radii", t0)
    graph = BranchGraph(pos, parent, radius=r, weight=c, tree_id=vtree)
    point_node = con.label
    if not keep.all():
        graph = graph.subgraph(keep)
    if _inside_tips_on(inside_tips, level_merge):
        n0 = graph.n_nodes
        graph, point_node = _merge_inside_tips(graph, keep, con.label, xyz, spacing_pts)
        timings["inside_tips_removed"] = float(n0 - graph.n_nodes)
        t0 = tick("inside tips", t0)
    info = {
        "points": n,
        "point_spacing": spacing_pts,
        "node_spacing": node_spacing,
        "components": int(n_comp),
        "trees": int(np.unique(vtree).size),
        "bridge_gap": gap,
        "unbridged_points": int((~np.isfinite(plen)).sum()),
        "iterations": iterations,
        "vertices": graph.n_nodes,
        "edge_weights": edge_weights,
        "reach": reach,
        "level_merge": level_merge,
        "mean_point_distance": md.tolist(),
    }
    return LivnyResult(graph, point_node, point_tree, timings, info, kdtree=kd)
