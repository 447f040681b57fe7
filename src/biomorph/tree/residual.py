"""Wood the skeleton leaves out: residual branches from the points no cylinder explains.

A level-set skeleton resolves branches down to about one node spacing. Shoots shorter or
closer together than that — the needle-clad side shoots of a conifer's branches, the twigs
packed around a pine's whorls — fall into the level pieces of the branch that carries them,
so the finished cylinder model leaves their points far outside every surface: on the TreeLS
spruce 16 % of the points lie more than 10 cm from every cylinder and half of them more
than one node spacing (docs/tree.md, "Residual branches"). TreeQSM does not have this
blind spot because its cover sets segment every point into some branch.

:func:`residual_branches` closes it the same way the graph method builds the first
skeleton, restricted to what is left:

1. **Unexplained points**: the signed distance of every point to the nearest cylinder
   surface (:func:`biomorph.tree.metrics.surface_distance`), less
   :data:`RESIDUAL_RADIUS` (½) of that cylinder's radius (what a radius error can
   explain), exceeds ``threshold`` (default :data:`RESIDUAL_THRESHOLD` node spacings —
   below one node spacing the skeleton cannot resolve a shoot anyway).
2. **Pieces of wood**: unexplained points within ``link`` (default :data:`RESIDUAL_LINK`
   point spacings) of each other are one piece (connected components).
3. **Support**: a piece is kept only if it *touches the model* — its point nearest to a
   cylinder surface lies within ``threshold + link`` of it, i.e. the scan's points run
   continuously from the modelled wood into the piece — and it reaches at least
   ``min_length`` (default :data:`RESIDUAL_MIN_LENGTH` node spacings) along its own
   neighbour graph from that point. A floating cluster (a neighbour's branch, a bird, a
   ghost return) is never bridged to: nothing is drawn through empty air.
4. **Skeleton of each piece**: geodesic distance from its attachment point, contracted in
   level sets of one node spacing exactly as step ii of the graph method
   (:func:`biomorph.tree.neighbours.contract`), a shortest-path tree over the pieces'
   vertices; each piece's first vertex hangs from the model node nearest its attachment
   point (the nearer end of the nearest cylinder).

The pipeline (:func:`biomorph.tree.pipeline.residual_phase`) runs this once after the
radius stage and fits radii again on the grown skeleton, so the new shoots get the same
circle fits / taper model as every other branch and never exceed their parent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree.neighbours import contract, shortest_path_forest

if TYPE_CHECKING:
    from biomorph.tree.metrics import SegmentCandidates

__all__ = [
    "RESIDUAL_THRESHOLD",
    "RESIDUAL_RADIUS",
    "RESIDUAL_PROTRUDE",
    "RESIDUAL_MIN_ANGLE",
    "RESIDUAL_LINK",
    "RESIDUAL_MIN_LENGTH",
    "RESIDUAL_MIN_POINTS",
    "RESIDUAL_FINE",
    "RESIDUAL_NOISE",
    "residual_factor",
    "residual_branches",
]

#: points farther than this many node spacings outside every cylinder surface are not
#: explained by the model (one node spacing: the finest branch the level sets resolve)
RESIDUAL_THRESHOLD = 1.0
#: ... counted beyond this fraction of the local cylinder radius: the radius stage's error
#: on well-measured stems is up to 13 % and on modelled ones (taper model, no fit) up to
#: ~30 % on the synthetic presets (docs/tree.md, sessions 5–7); half the radius is beyond
#: both, and a real shoot leaving a cylinder of radius r protrudes far more than r / 2
RESIDUAL_RADIUS = 0.5
#: a kept piece reaches ``threshold + min_length`` beyond this many radii of its
#: cylinder: the stem-surface strips beside an off-axis stem path on the toy Y tree of
#: the tests (10 cm stem, path 10 cm off) reach 0.7 radii, a spruce shoot 5–10 radii
RESIDUAL_PROTRUDE = 1.0
#: a piece must leave its host's axis at more than this angle (radians; 30°) unless the
#: host is a tip: side shoots leave at 30–90° (conifer branches 60–90°), strips of the
#: host's own wood run along it
RESIDUAL_MIN_ANGLE = np.radians(30.0)
#: unexplained points within this many point spacings are one piece of wood (the
#: neighbour distance of a sampled surface with some holes: 1 spacing is the median
#: nearest neighbour, 2.5 bridges a missing point or two, not a gap between shoots)
RESIDUAL_LINK = 2.5
#: a piece is modelled only if it reaches this many node spacings from its attachment:
#: shorter pieces would become a single vertex (no cylinder) and are needle or leaf tufts
RESIDUAL_MIN_LENGTH = 1.0
#: the finer threshold (node spacings, for ``threshold`` and ``min_length`` alike) where
#: the scan's twigs present a surface (:func:`residual_factor`): shoots half a node spacing
#: long are then twigs the scanner resolved (rTwig: 24 twiglets of 5-15 cm that TreeQSM
#: models, left out at one node spacing; docs/tree.md, sessions 28-29)
RESIDUAL_FINE = 0.5
#: ... but never closer to the surface than this many times the scan's scatter about it
#: (``σ``): range noise does not throw points 6 σ off a surface (a chance of 10⁻⁹ per point
#: for Gaussian noise); the presets at 8 mm range noise (σ 4.6-4.7 mm) take 0.74-0.96
RESIDUAL_NOISE = 6.0


def residual_factor(surface: bool, scatter: float, node_spacing: float) -> float:
    """The residual threshold in node spacings when the scan does not say
    (``--residual-threshold auto``): 1 (:data:`RESIDUAL_THRESHOLD`) unless the points
    about the modelled twigs behave as a ``surface`` (the twig offset's test,
    :func:`biomorph.tree.radius.twig_surface`: needles and leaves about a shoot form an
    envelope the model never reaches, and their tufts would become shoots); on a surface
    :data:`RESIDUAL_FINE`, or :data:`RESIDUAL_NOISE` times the scan's ``scatter`` (m, its
    points' spread about the surface) where that is more, at most 1."""
    if not surface or node_spacing <= 0:
        return RESIDUAL_THRESHOLD
    return float(
        min(RESIDUAL_THRESHOLD, max(RESIDUAL_FINE, RESIDUAL_NOISE * scatter / node_spacing))
    )


#: ... and hold at least this many points (a level piece of the graph method needs a few
#: points to have a centroid worth a vertex; three collinear returns are not a shoot)
RESIDUAL_MIN_POINTS = 4


def residual_branches(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    point_spacing: float,
    node_spacing: float,
    *,
    base: BranchGraph | None = None,
    threshold: float | None = None,
    link: float | None = None,
    min_length: float | None = None,
    candidates: SegmentCandidates | None = None,
) -> tuple[BranchGraph, dict[str, Any]]:
    """Grow the skeleton into the wood its cylinders leave unexplained (module doc).

    ``graph`` is the cylinder model (radii set) the points are tested against; the new
    vertices are appended to ``base`` (default ``graph``), a graph with the same nodes —
    the pipeline passes the skeleton *before* its radius stage so that stage can run once
    more on the grown skeleton. ``threshold`` and ``min_length`` are in metres (defaults
    from ``node_spacing``), ``link`` in metres (default from ``point_spacing``).
    ``candidates``: the points' :func:`~biomorph.tree.metrics.segment_candidates` on
    ``graph``, if searched already.

    Returns the grown graph (new nodes after the old ones, ``radius`` copied from the
    attachment node, ``tree_id`` the attachment's tree, ``weight`` recomputed) and a
    record: unexplained points, pieces kept, branches re-routed (``joined``) and the
    shortcut nodes that removed, nodes added, points in kept pieces.
    """
    if graph.radius is None:
        raise ParameterError("residual_branches needs a cylinder model (radii set)")
    if not (point_spacing > 0 and node_spacing > 0):
        raise ParameterError(
            f"point and node spacing must be > 0 m, got {point_spacing} and {node_spacing}"
        )
    base = graph if base is None else base
    if base.n_nodes != graph.n_nodes:
        raise ParameterError(
            f"base has {base.n_nodes} nodes, the cylinder model {graph.n_nodes}; expected the same"
        )
    tau = RESIDUAL_THRESHOLD * node_spacing if threshold is None else float(threshold)
    lk = RESIDUAL_LINK * point_spacing if link is None else float(link)
    ml = RESIDUAL_MIN_LENGTH * node_spacing if min_length is None else float(min_length)
    info: dict[str, Any] = {
        "threshold": tau,
        "link": lk,
        "min_length": ml,
        "unexplained_points": 0,
        "pieces": 0,
        "joined": 0,
        "shortcut_nodes_removed": 0,
        "nodes_added": 0,
        "points_modelled": 0,
    }
    xyz = np.asarray(xyz, dtype=float)
    if graph.n_nodes == 0 or xyz.shape[0] == 0:
        return base, info
    pieces = _pieces(graph, xyz, tau, lk, ml, node_spacing, info, candidates)
    if pieces is None:
        return base, info
    _classify(graph, pieces, tau, ml)
    if not pieces.keep.any():
        return base, info
    grown, counts = _grow(base, pieces, max(node_spacing, lk), point_spacing)
    info.update(counts)
    return grown, info


@dataclass
class _Pieces:
    """Connected pieces of unexplained points (indices into ``u``, the points' indices)."""

    u: NDArray[np.int64]
    pu: NDArray[np.float64]
    adj: sparse.csr_matrix  # squared lengths of the links
    comp: NDArray[np.int64]  # piece of each point
    attach: NDArray[np.int64]  # per piece: its point nearest to a cylinder surface
    plen: NDArray[np.float64]  # geodesic distance from the attachment (inf: no piece)
    cand: NDArray[np.int64]  # pieces that touch the model, long and big enough
    far_pt: NDArray[np.float64]  # per candidate: centroid of its far end
    host: NDArray[np.int64]  # per candidate: model node it hangs from
    top: NDArray[np.float64]  # per candidate: farthest reach beyond the model at its far end
    reach: NDArray[np.float64]  # per candidate: geodesic length from the attachment, m
    #: set by :func:`_classify`, per candidate: kept, branch node it carries, grown from
    #: its far end
    keep: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    target: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    swap: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))


def _pieces(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    tau: float,
    lk: float,
    ml: float,
    node_spacing: float,
    info: dict[str, Any],
    candidates: SegmentCandidates | None = None,
) -> _Pieces | None:
    """Steps 1–3 of the module doc: unexplained points, their pieces, the candidates."""
    from biomorph.tree.metrics import surface_distance

    sd_raw, rad, near_node = surface_distance(graph, xyz, candidates=candidates, refine=tau)
    # what a cylinder's radius error can explain does not count: the distance beyond
    # RESIDUAL_RADIUS of the local radius (a 20 cm stem fitted 16 cm leaves its bark
    # 4 cm "outside"; a strip of it must not become a branch along the stem)
    sd = sd_raw - RESIDUAL_RADIUS * rad
    u = np.flatnonzero(sd > tau)
    info["unexplained_points"] = int(u.size)
    if u.size < 3:
        return None
    pu = xyz[u]
    pairs = cKDTree(pu).query_pairs(lk, output_type="ndarray")
    if pairs.size == 0:
        return None
    i, j = pairs[:, 0], pairs[:, 1]
    d2 = np.maximum(np.sum((pu[i] - pu[j]) ** 2, axis=1), 1e-18)
    nu = u.size
    adj = sparse.csr_matrix((d2, (i, j)), shape=(nu, nu))
    n_comp, comp = connected_components(adj, directed=False)
    # attachment point of each piece: its point nearest to a cylinder surface
    su = sd[u]
    order = np.lexsort((su, comp))
    first = np.ones(nu, dtype=bool)
    first[1:] = comp[order[1:]] != comp[order[:-1]]
    attach = order[first]  # one per component, in component order
    touches = su[attach] <= tau + lk
    plen, _ = shortest_path_forest(_geodesic(adj), attach[touches])
    reach = np.zeros(n_comp)
    fin = np.isfinite(plen)
    np.maximum.at(reach, comp[fin], plen[fin])
    count = np.bincount(comp, minlength=n_comp)
    cand = np.flatnonzero(touches & (reach >= ml) & (count >= RESIDUAL_MIN_POINTS))
    if cand.size == 0:
        return None
    # the piece's far end: its last node spacing of geodesic reach
    end = fin & (plen >= reach[comp] - node_spacing)
    e_sum = np.zeros((n_comp, 3))
    np.add.at(e_sum, comp[end], pu[end])
    e_cnt = np.bincount(comp[end], minlength=n_comp)
    top = np.full(n_comp, -np.inf)
    np.maximum.at(top, comp[end], (sd_raw[u] - RESIDUAL_PROTRUDE * rad[u])[end])
    return _Pieces(
        u=u,
        pu=pu,
        adj=adj,
        comp=comp,
        attach=attach,
        plen=plen,
        cand=cand,
        far_pt=e_sum[cand] / np.maximum(e_cnt[cand], 1)[:, None],
        host=near_node[u[attach[cand]]],
        top=top[cand],
        reach=reach[cand],
    )


def _geodesic(adj: sparse.csr_matrix) -> sparse.csr_matrix:
    geo = adj.copy()
    geo.data = np.sqrt(geo.data)
    return geo


def _classify(graph: BranchGraph, p: _Pieces, tau: float, ml: float) -> None:
    """Which candidates are shoots, which carry a re-routed branch (sets ``keep``,
    ``target``, ``swap``; a swapped piece hangs from its far end's node)."""
    from biomorph.tree.metrics import surface_distance

    h = p.host
    # (a) a *shoot* stands out from the model: its far end lies ``min_length`` beyond the
    # threshold and a whole radius of its cylinder (RESIDUAL_PROTRUDE). A strip of a
    # stem's surface beside a stem path pulled off the axis (or under-fitted) stays
    # within about a radius of the cylinder and would become a false branch along it.
    shoot = p.top >= tau + ml
    # ... and it leaves its host: a piece running within RESIDUAL_MIN_ANGLE of the host's
    # axis beside a node that already continues is the host's own wood (a parallel strip
    # where the skeleton cut a bend short), not a shoot; at a tip it may continue on
    hp = graph.parent[h]
    axis = np.where((hp >= 0)[:, None], graph.position[h] - graph.position[np.maximum(hp, 0)], 0.0)
    v = p.far_pt - p.pu[p.attach[p.cand]]
    nrm = np.linalg.norm(v, axis=1) * np.linalg.norm(axis, axis=1)
    cosang = np.abs(np.sum(v * axis, axis=1)) / np.maximum(nrm, 1e-12)
    n_child = np.bincount(graph.parent[graph.parent >= 0], minlength=graph.n_nodes)
    shoot &= ~((nrm > 0) & (cosang > np.cos(RESIDUAL_MIN_ANGLE)) & (n_child[h] > 0))
    # (b) a *missing branch base*: the far end lies on another branch of the model, one
    # the skeleton reached by a shortcut elsewhere (a level set joined the branch to the
    # stem higher up than its wood leaves it). That branch is re-routed through the piece
    # and the shortcut chain it leaves behind is removed (:func:`_join_targets`).
    sdf, radf, nearf = surface_distance(graph, p.far_pt, refine=tau)
    # (its points are all beyond the threshold by construction, so "at the model" means
    # within one more ``min_length``: the last level piece touches the branch's envelope)
    near_model = sdf - RESIDUAL_RADIUS * radf <= tau + ml
    # a shoot does not come back to where it left: a piece no longer than its host's
    # diameter whose far end is at the host again (the host or a neighbour of it) is a
    # bulge of the host's own wood (the flare of a junction beside a branch the skeleton
    # starts further out)
    par = graph.parent
    home = (nearf == h) | (par[nearf] == h) | (par[h] == nearf)
    assert graph.radius is not None
    shoot &= ~(near_model & home & (p.reach < 2 * graph.radius[h]))
    target = np.full(p.cand.size, -1, dtype=np.int64)
    swap = np.zeros(p.cand.size, dtype=bool)
    nm = np.flatnonzero(near_model)
    if nm.size:
        main = _main_child(graph)
        target[nm] = _join_targets(graph, main, h[nm], nearf[nm])
        # the piece may run the other way: from a branch (where it came nearest the
        # model) down to the stem its wood leaves -- then it hangs from the far end's
        # node and carries the branch node at its near end
        back = nm[target[nm] < 0]
        if back.size:
            tb = _join_targets(graph, main, nearf[back], h[back])
            ok = back[tb >= 0]
            target[ok] = tb[tb >= 0]
            swap[ok] = True
            h[ok] = nearf[ok]
    # a piece re-routes a branch of its own tree only: between two crowns it may touch a
    # neighbour's branch, which the crown partition gave to the neighbour's stem (the
    # TreeLS plot, voxel method: a pine's limb hung from the next pine's piece, and both
    # trunks ran through it)
    trees = graph.trees
    across = (target >= 0) & (trees[np.maximum(target, 0)] != trees[h])
    target[across] = -1
    p.keep = shoot | (target >= 0)
    p.target = np.where(p.keep, target, -1)
    p.swap = swap & p.keep


def _grow(
    base: BranchGraph, p: _Pieces, level: float, point_spacing: float
) -> tuple[BranchGraph, dict[str, int]]:
    """Step 4: contract the kept pieces (levels ``level`` wide), hang them from their
    hosts, re-route the joined branches."""
    n_comp = p.attach.size
    kept = p.cand[p.keep]  # pieces, in their new order 0..m-1
    far_of = p.far_pt[p.keep].copy()
    plen = p.plen
    if p.swap.any():
        # swapped pieces grow from their far end: geodesic levels from the piece's
        # farthest point, and the join goes to the vertex at the old attachment
        o = np.lexsort((-np.where(np.isfinite(plen), plen, -np.inf), p.comp))
        f1 = np.ones(o.size, dtype=bool)
        f1[1:] = p.comp[o[1:]] != p.comp[o[:-1]]
        far_idx = np.full(n_comp, -1, dtype=np.int64)
        far_idx[p.comp[o[f1]]] = o[f1]
        sw = p.swap[p.keep]
        far_of[sw] = p.pu[p.attach[kept[sw]]]
        src = p.attach[kept].copy()
        src[sw] = far_idx[kept[sw]]
        plen, _ = shortest_path_forest(_geodesic(p.adj), src)
    new_id = np.full(n_comp, -1, dtype=np.int64)
    new_id[kept] = np.arange(kept.size)
    point_tree = new_id[p.comp]
    point_tree[~np.isfinite(plen)] = -1
    # levels at least one link wide: on a cloud sparser than its node spacing (a node
    # spacing clipped to 2 % of a small tree's height) narrower levels cut a piece into
    # single points and every point would become a tip
    con = contract(p.pu, p.adj, plen, point_tree, level, point_spacing=point_spacing)
    counts = {"pieces": int(kept.size), "joined": 0, "shortcut_nodes_removed": 0}
    if con.position.shape[0] == 0:
        return base, counts
    _, vpar = shortest_path_forest(con.graph, con.roots)
    # vertices a root does not reach (cannot happen: every piece is connected) are dropped
    reached = vpar >= 0
    reached[con.roots] = True
    # each piece's root vertex hangs from the model node nearest its attachment point
    host = p.host[p.keep]
    n0 = base.n_nodes
    idx = np.full(reached.size, -1, dtype=np.int64)
    idx[reached] = n0 + np.arange(int(reached.sum()))
    par_new = np.where(vpar >= 0, idx[np.maximum(vpar, 0)], -1)
    roots = con.roots[reached[con.roots]]
    par_new[roots] = host[con.tree[roots]]
    hosts = host[con.tree[reached]]
    parent = np.concatenate([base.parent, par_new[reached]])
    drop, joined = _reroute(
        parent, n0, con.tree[reached], con.position[reached], p.target[p.keep], far_of
    )
    fields: dict[str, Any] = {"tree_id": np.concatenate([base.trees, base.trees[hosts]])}
    if base.radius is not None:
        fields["radius"] = np.concatenate([base.radius, base.radius[hosts]])
    if base.depth is not None:
        fields["depth"] = np.concatenate([base.depth, base.depth[hosts] + 1])
    grown = BranchGraph(np.vstack([base.position, con.position[reached]]), parent, **fields)
    if drop.any():
        grown = grown.subgraph(~drop)
    counts.update(
        joined=joined,
        shortcut_nodes_removed=int(drop.sum()),
        nodes_added=int(reached.sum()),
        points_modelled=int(np.isin(p.comp, kept).sum()),
    )
    return grown.with_(weight=grown.subtree_length()), counts


def _reroute(
    parent: NDArray[np.int64],
    n0: int,
    vtree: NDArray[np.int64],
    vpos: NDArray[np.float64],
    target: NDArray[np.int64],
    far_of: NDArray[np.float64],
) -> tuple[NDArray[np.bool_], int]:
    """Hang each joined branch node (``target`` per piece) from its piece's vertex nearest
    the piece's far end (``parent`` edited in place); the shortcut chain it leaves, up to
    the first fork, is marked for removal. Returns the removal mask and the join count."""
    drop = np.zeros(parent.size, dtype=bool)
    n_ch = np.bincount(parent[parent >= 0], minlength=parent.size)
    moved: set[int] = set()
    for t in np.flatnonzero(target >= 0):
        x = int(target[t])
        mine = np.flatnonzero(vtree == t)
        if mine.size == 0 or drop[x] or x in moved:
            continue
        fv = n0 + int(mine[np.argmin(np.sum((vpos[mine] - far_of[t]) ** 2, axis=1))])
        if _is_ancestor(parent, x, fv):
            continue  # an earlier join re-routed the host under x: no cycles
        moved.add(x)
        old = int(parent[x])
        parent[x] = fv
        n_ch[fv] += 1
        while old >= 0:
            n_ch[old] -= 1
            if n_ch[old] > 0 or parent[old] < 0:
                break
            drop[old] = True
            old = int(parent[old])
    return drop, len(moved)


def _main_child(graph: BranchGraph) -> NDArray[np.int64]:
    """The child carrying the most length (its subtree + its edge) of every node, -1 at
    tips; ties go to the lower index."""
    return treeops.main_child(graph.parent, graph.subtree_length() + graph.edge_length)


def _join_targets(
    graph: BranchGraph,
    main: NDArray[np.int64],
    host: NDArray[np.int64],
    near: NDArray[np.int64],
) -> NDArray[np.int64]:
    """For pieces from ``host`` whose far end lies at model node ``near``: ``near`` where
    the piece may carry that node's branch, else -1.

    Allowed when ``near`` lies on a *side branch* seen from the host: the tree path from
    the host and ``near``'s common ancestor down to ``near`` turns into a side child (not
    ``main``, the child carrying the most length: :func:`_main_child`) somewhere. Not
    allowed when ``near`` is the host, an ancestor of it (a cycle), further along the
    host's own axis (a strip of a stem's surface must not become the stem), or on the main
    axis a side branch of the host's hangs from (a branch must not carry the stem).
    """
    par = graph.parent
    depth = graph.node_depth
    out = np.full(host.size, -1, dtype=np.int64)
    for i, (hh, x) in enumerate(zip(host.tolist(), near.tolist(), strict=True)):
        if x == hh or par[x] == hh or par[hh] == x:
            continue
        # walk both up to their lowest common ancestor, noting if x's side turns off-axis
        a, b = x, hh
        side = False
        while depth[a] > depth[b]:
            pa = par[a]
            side |= main[pa] != a
            a = pa
        while depth[b] > depth[a]:
            b = par[b]
        while a != b:
            pa = par[a]
            side |= main[pa] != a
            a, b = pa, par[b]
        if a == x:  # x is an ancestor of the host (or the host itself)
            continue
        if side and par[x] >= 0:
            out[i] = x
    return out


def _is_ancestor(parent: NDArray[np.int64], a: int, b: int) -> bool:
    """Is node ``a`` on the path from node ``b`` to its root (``b`` itself included)?"""
    while b >= 0:
        if b == a:
            return True
        b = int(parent[b])
    return False
