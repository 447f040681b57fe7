"""Branch order (seed 001 §5.2, "Asttiefe"): one trunk per tree, orders that rise only where
a branch leaves its parent, and segmentation into branches.

Every node with children passes its order on to exactly one of them, the *continuation*;
all other children start a new branch with order + 1. Two rules choose it:

``rule="supported"`` (default, TreeQSM-style): the continuation is the child carrying the
    largest *supported length* ``c̃`` (its subtree's length plus its own edge). Children
    carrying at least ``tie`` (0.5) × the largest ``c̃`` are a codominant fork; among
    those the one turning least from the incoming direction continues (the angle is a
    tie-breaker, never a cut). The trunk is therefore the path from the base that always
    follows the most wood: on a conifer it runs to the top through every whorl, and a
    stem that bends more than 45° (wind, phototropism, a leaning pine) stays order 0.
    Directions are taken over ``look`` (3) edges on both sides of the fork, so a single
    noisy skeleton edge does not decide a tie.
    **The trunk keeps to its axis** (``trunk_angle``, 60°: beyond it a stem rises less than
    half its length along its axis): above breast height the trunk
    (order 0) continues only into children heading within ``trunk_angle`` of the trunk's
    own axis (base to breast height, 1.3 m; the whole trunk on trees under 2.6 m) and
    carrying at least ``tie`` × the heaviest child's length; with none, the trunk ends
    there (a thin twig pointing up does not carry it on). A heading is the direction to
    the node :data:`TRUNK_LOOK` edges or :data:`TRUNK_REACH` of the height (``reach``)
    down the child's heaviest path, or to that path's highest node, or to the tree's top
    if the child's subtree holds it (a skeleton that detours through a whorl, or routes
    the stem out along a limb and back, still climbs to the top). Among the children
    passing, the trunk follows the *leader*: those whose subtree climbs within ``reach``
    of the highest along the axis, then the supported rule's choice or the heaviest (on
    the pine plot the least-turning child of a whorl fork topped out 1–2 m below the
    leader on 4 of 16 pines); a leader holding the tree's top goes first (the trunk runs
    from the base to the top, as TreeQSM's stem search does: on rTwig's coffee tree two
    arms of a fork climb to 3.69 and 3.52 m, within ``reach`` of each other, and the trunk
    took the lower one whenever it turned less). Step by step the heaviest child
    turns only a little, but on a decurrent crown those steps add up: rTwig's coffee
    tree's trunk bent over into a horizontal limb for 1.2 m (4.14 m of trunk for
    TreeQSM's 3.46 m). The axis, not the vertical, so a leaning stem stays one trunk.
``rule="angle"`` (the seed's rule): the children whose weight share ``c̃_w / Σ_j c̃_j``
    exceeds ``weight_share`` **and** whose edge turns by less than ``max_angle`` (45°)
    are candidates; the heaviest candidate continues, otherwise *nobody* does (the order
    rises on all children). On real scans the stem climbs order at every bend: a 20 m pine
    got no order-0 trunk at all and reached order 21 (issue 13).

At a root the incoming direction is ``+Z``. The same rule runs on graph and voxel
skeletons (``skeletonize``'s order phase). :func:`segments` cuts the skeleton into
branches: a new segment starts at every root and at every child that is not the
continuation of its parent, so each segment is one branch of constant order, as TreeQSM's
branches.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError

__all__ = [
    "branch_order",
    "continuation",
    "segments",
    "with_order",
    "RULES",
    "continuation_from_segments",
    "order_from_segments",
]

RULES = ("supported", "angle")


@numba.njit(cache=True)
def _continuation(parent, order, indptr, idx, carried, pos, share, cos_max):
    n = parent.size
    cont = np.full(n, -1, dtype=np.int64)  # the child continuing each node's branch
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


@numba.njit(cache=True)
def _heaviest_child(v, indptr, idx, carried):
    best = -1
    bw = -1.0
    for j in range(indptr[v], indptr[v + 1]):
        w = idx[j]
        if carried[w] > bw:
            bw = carried[w]
            best = w
    return best


@numba.njit(cache=True)
def _continuation_supported(parent, order, indptr, idx, carried, pos, tie, look):
    n = parent.size
    cont = np.full(n, -1, dtype=np.int64)
    for k in range(n):
        v = order[k]
        a = indptr[v]
        b = indptr[v + 1]
        if b == a:
            continue
        if b - a == 1:
            cont[v] = idx[a]
            continue
        # incoming direction over up to ``look`` edges
        u = v
        for _ in range(look):
            if parent[u] < 0:
                break
            u = parent[u]
        ix = pos[v, 0] - pos[u, 0]
        iy = pos[v, 1] - pos[u, 1]
        iz = pos[v, 2] - pos[u, 2]
        ln = np.sqrt(ix * ix + iy * iy + iz * iz)
        if ln == 0:
            ix, iy, iz, ln = 0.0, 0.0, 1.0, 1.0
        cmax = 0.0
        for j in range(a, b):
            if carried[idx[j]] > cmax:
                cmax = carried[idx[j]]
        best = -1
        bestc = -2.0
        bestw = -1.0
        for j in range(a, b):
            w = idx[j]
            if carried[w] < tie * cmax:
                continue
            # outgoing direction: ``look`` edges down the child's heaviest path
            x = w
            for _ in range(look - 1):
                y = _heaviest_child(x, indptr, idx, carried)
                if y < 0:
                    break
                x = y
            ox = pos[x, 0] - pos[v, 0]
            oy = pos[x, 1] - pos[v, 1]
            oz = pos[x, 2] - pos[v, 2]
            lo = np.sqrt(ox * ox + oy * oy + oz * oz)
            c = (ix * ox + iy * oy + iz * oz) / (ln * lo) if lo > 0 else -1.0
            if c > bestc or (c == bestc and carried[w] > bestw):
                bestc = c
                bestw = carried[w]
                best = w
        cont[v] = best
    return cont


#: the height (m) above the base up to which the trunk's axis is taken: breast height
BREAST_HEIGHT = 1.3
#: a child's heading for the trunk rule is taken this many edges (node spacings) down its
#: heaviest path, at least: over 2 edges the skeleton's node-to-node noise turned a
#: spruce's stem 46° off its axis at a whorl (its trunk ended at 10 of 17 m); over 10, 8°
TRUNK_LOOK = 10
#: ... and at least this share of the tree's height: a skeleton kink at a whorl (the path
#: doubling back for 30 cm) must not end the trunk
TRUNK_REACH = 0.05
TRUNK_TIE = 0.5
#: a leader holding the tree's top takes the trunk only if the way up to that top never
#: drops more than this many node spacings below where it has been: a stem does not go
#: down. The trunks of the real clouds here drop at most 3.8 spacings (a hook at a fork,
#: the skeleton's zig-zag); a way out along a branch, across the twigs of a crown whose
#: branches overtop the stem and up another branch to the top drops 12.6 (the demo's
#: birch: its trunk ran 21.6 m to a branch tip 5 m out, for a 15 m stem)
TRUNK_DROP = 5.0


def continuation(
    graph: BranchGraph,
    weight_share: float = 0.5,
    max_angle: float = np.radians(45.0),
    *,
    rule: str = "supported",
    tie: float = 0.5,
    look: int = 3,
    trunk_angle: float | None = np.radians(60.0),
) -> NDArray[np.int64]:
    """For every node, the child that continues its branch (-1 if none); see the module
    doc for the two rules (``weight_share``/``max_angle`` belong to ``rule="angle"``,
    ``tie``/``look``/``trunk_angle`` to ``rule="supported"``; ``trunk_angle=None`` lets the
    trunk follow the most wood wherever it turns)."""
    if rule not in RULES:
        raise ParameterError(f"order rule {rule!r}; expected one of {', '.join(RULES)}")
    indptr, idx = graph.children_csr
    carried = graph.subtree_sum(graph.edge_length)
    if rule == "supported":
        if not 0 < tie <= 1:
            raise ParameterError(f"order tie must lie in (0, 1], got {tie}")
        if look < 1:
            raise ParameterError(f"order look must be >= 1 edge, got {look}")
        if trunk_angle is not None and not 0 < trunk_angle <= np.pi:
            raise ParameterError(f"trunk angle must lie in (0, pi] radians, got {trunk_angle}")
        cont = _continuation_supported(
            graph.parent, graph.order, indptr, idx, carried, graph.position, float(tie), int(look)
        )
        if trunk_angle is not None and trunk_angle < np.pi:
            _keep_trunk_axis(graph, cont, carried, indptr, idx, float(trunk_angle), float(tie))
        return cont
    if not 0 <= weight_share < 1:
        raise ParameterError(f"weight_share must lie in [0, 1), got {weight_share}")
    if not 0 < max_angle <= np.pi:
        raise ParameterError(f"max_angle must lie in (0, pi] radians, got {max_angle}")
    return _continuation(
        graph.parent,
        graph.order,
        indptr,
        idx,
        carried,
        graph.position,
        float(weight_share),
        float(np.cos(max_angle)),
    )


def _trunk_path(root: int, cont: NDArray[np.int64]) -> list[int]:
    path = [root]
    while cont[path[-1]] >= 0:
        path.append(int(cont[path[-1]]))
    return path


@numba.njit(cache=True)
def _heaviest_child(v, indptr, idx, carried):  # pragma: no cover - numba
    """``v``'s child carrying the most (the first of equal ones, as ``np.argmax``); -1
    at a tip."""
    best = -1
    for e in range(indptr[v], indptr[v + 1]):
        w = idx[e]
        if best < 0 or carried[w] > carried[best]:
            best = w
    return best


@numba.njit(cache=True)
def _ahead(v, indptr, idx, carried, el, reach):  # pragma: no cover - numba
    """The first node at least ``reach`` (m of path) down ``v``'s heaviest path (its tip if
    the path is shorter)."""
    run = 0.0
    while run < reach:
        w = _heaviest_child(v, indptr, idx, carried)
        if w < 0:
            break
        v = w
        run += el[v]
    return v


@numba.njit(cache=True)
def _subtree_top(parent, order, h):
    """For every node, the node of its subtree (itself included) highest in ``h``."""
    top = np.arange(parent.size)
    for k in range(order.size - 1, -1, -1):
        v = order[k]
        p = parent[v]
        if p >= 0 and h[top[v]] > h[top[p]]:
            top[p] = top[v]
    return top


@numba.njit(cache=True)
def _highest_ahead(v, indptr, idx, carried, h):  # pragma: no cover - numba
    """The node of ``v``'s heaviest path (to its tip) highest in ``h``."""
    best = v
    while True:
        w = _heaviest_child(v, indptr, idx, carried)
        if w < 0:
            return best
        v = w
        if h[v] > h[best]:
            best = v


def _trunk_axis(graph: BranchGraph, root: int, cont) -> NDArray[np.float64] | None:
    """The trunk's axis: base to breast height; the whole trunk on a tree under 2 x 1.3 m."""
    pos = graph.position
    path = _trunk_path(root, cont)
    z = pos[path, 2] - pos[root, 2]
    at = np.flatnonzero(z >= BREAST_HEIGHT)
    ref = path[int(at[0])] if at.size and z.max() >= 2 * BREAST_HEIGHT else path[-1]
    axis = pos[ref] - pos[root]
    n = float(np.linalg.norm(axis))
    return axis / n if n > 0 else None


def _keep_trunk_axis(graph, cont, carried, indptr, idx, angle: float, tie: float) -> None:
    """Lead each root's trunk to the top along its axis (see the module doc): above breast
    height, among the children carrying at least ``TRUNK_TIE`` x the heaviest and heading
    within ``angle`` of the axis, the trunk continues into one whose subtree climbs highest
    (within ``reach``: then the supported rule's choice, else the heaviest); with none it
    ends. ``cont`` is changed in place."""
    pos = graph.position
    el = graph.edge_length
    med_edge = float(np.median(el[el > 0])) if (el > 0).any() else 0.0
    cos_max = np.cos(angle)
    top_z = _subtree_top(graph.parent, graph.order, pos[:, 2])
    for root in graph.roots:
        _climb_to_breast_height(int(root), cont, carried, indptr, idx, pos, top_z)
        axis = _trunk_axis(graph, int(root), cont)
        if axis is None:
            continue
        h = pos @ axis
        top = _subtree_top(graph.parent, graph.order, h)
        height = float(pos[graph.trees == graph.trees[root], 2].max() - pos[root, 2])
        reach = max(TRUNK_LOOK * med_edge, TRUNK_REACH * height)
        v = int(root)
        chain = [v]
        barred: dict[int, int] = {}  # a trunk node -> its child that led the trunk down
        walk = (graph.parent, carried, indptr, idx, el, pos, h, top)
        rule = (axis, reach, cos_max, med_edge)
        while True:
            _walk_trunk(v, chain, barred, cont, walk, rule, root)
            # the way on from the trunk's highest point dropped below it, or ended short
            # of the tree's top: that way is a branch hanging from it; the trunk turns
            # there into another child that climbs, if one does (a heavier limb hanging
            # down from a pine's crown, reached from above, had set the bar for its top)
            k = _turn_point(chain, h, TRUNK_DROP * med_edge, float(h[top[root]]) - reach)
            if k < 0 or len(barred) >= MAX_TRUNK_TURNS or chain[k] in barred:
                break
            barred[chain[k]] = chain[k + 1]
            del chain[k + 1 :]
            v = chain[k]
        _end_at_the_top(chain, cont, h, TRUNK_DROP * med_edge)


def _walk_trunk(v, chain, barred, cont, walk, rule, root: int) -> None:
    """Follow the trunk up from ``v`` (the last node of ``chain``, which grows), choosing at
    each fork above breast height among :func:`_trunk_candidates` the child that climbs
    highest (within ``reach``: then the supported rule's choice, else the heaviest), the
    one holding the tree's top if it climbs as a stem does; ``barred``: per node a child
    the trunk may no longer take. ``walk`` is ``(parent, carried, indptr, idx,
    edge_length, position, height along the axis,`` :func:`_subtree_top` ``)``, ``rule``
    ``(axis, reach, cos_max, median edge)``; ``cont`` is changed in place."""
    parent, carried, indptr, idx, el, pos, h, top = walk
    axis, reach, cos_max, med_edge = rule
    while True:
        kids = idx[indptr[v] : indptr[v + 1]]
        turn = v in barred  # re-decided without the child that led the trunk down
        if turn:
            kids = kids[kids != barred[v]]
            cont[v] = -1 if kids.size == 0 else cont[v]
        if kids.size == 0:
            return
        if turn or (kids.size > 1 and pos[v, 2] - pos[root, 2] >= BREAST_HEIGHT):
            ctx = (carried, indptr, idx, el, pos, h, top, int(top[root]))
            ok = _trunk_candidates(v, kids, ctx, axis, reach, cos_max)
            if ok:  # the leaders: children climbing within ``reach`` of the highest
                hi = max(h[top[w]] for w in ok)
                ok = [w for w in ok if h[top[w]] >= hi - reach]
                # ... and of those the one holding the tree's top, if one does and
                # the way up to it climbs as a stem does
                ok = [
                    w
                    for w in ok
                    if top[w] == top[root]
                    and _way_drop(parent, v, int(top[w]), h) <= TRUNK_DROP * med_edge
                ] or ok
            if int(cont[v]) not in ok:
                cont[v] = max(ok, key=lambda w: carried[w]) if ok else -1
        if cont[v] < 0:
            return
        v = int(cont[v])
        chain.append(v)


def _climb_to_breast_height(root: int, cont, carried, indptr, idx, pos, top_z) -> None:
    """Below breast height the trunk continues only into children whose subtree climbs
    past it (``top_z``: :func:`_subtree_top` of the heights): a stem rises, and a child
    that never gets above 1.3 m is a root flare, a low branch along the ground or a
    neighbour's fallen limb, however much wood it carries (a pine of the TreeLS plot,
    voxel method: a 9.3 m limb lying from its base took the trunk, which then ended at
    0.47 m, 11.3 m under the tree's top). ``cont`` is changed in place."""
    z0 = float(pos[root, 2])
    v = root
    while pos[v, 2] - z0 < BREAST_HEIGHT:
        kids = idx[indptr[v] : indptr[v + 1]]
        if kids.size > 1:
            ok = [int(w) for w in kids if pos[top_z[w], 2] - z0 >= BREAST_HEIGHT]
            if ok and int(cont[v]) not in ok:
                cont[v] = max(ok, key=lambda w: carried[w])
        if cont[v] < 0:
            return
        v = int(cont[v])


#: at most this many trunk nodes are re-decided after the trunk's way dropped from them
MAX_TRUNK_TURNS = 4


def _turn_point(chain: list[int], h, drop: float, short: float) -> int:
    """The index in ``chain`` of its highest node in ``h`` if the chain goes on past it and
    then drops more than ``drop`` below it or stays below ``short`` (the tree's top less
    the trunk rule's reach), else -1."""
    z = np.asarray(h)[np.asarray(chain, dtype=np.int64)]
    k = int(np.argmax(z))
    if k + 1 >= len(chain):
        return -1
    return k if float(z[k] - z[k + 1 :].min()) > drop or z[k] < short else -1


def _end_at_the_top(chain: list[int], cont, h, drop: float) -> None:
    """End the trunk (its nodes ``chain`` from the root, linked by ``cont``) at its highest
    point in ``h`` when the chain then drops more than ``drop`` below it: a stem does not
    go down, the tail is a branch hanging from the top (a pine's leader merged with a
    drooping branch at the plot's tree 13: 0.77 m down to a twig's tip)."""
    z = np.asarray(h)[np.asarray(chain, dtype=np.int64)]
    k = int(np.argmax(z))
    if k + 1 < len(chain) and float(z[k] - z[k + 1 :].min()) > drop:
        cont[chain[k]] = -1


def _way_drop(parent, v: int, x: int, h) -> float:
    """How far the way from ``v`` down the tree to its descendant ``x`` drops below the
    highest point it has reached before, in ``h``."""
    way = [x]
    while way[-1] != v and parent[way[-1]] >= 0:
        way.append(int(parent[way[-1]]))
    z = np.asarray(h)[np.asarray(way[::-1], dtype=np.int64)]
    return float((np.maximum.accumulate(z) - z).max())


def _trunk_candidates(v, kids, ctx, axis, reach: float, cos_max: float) -> list[int]:
    """The children of trunk node ``v`` that may carry the trunk on: carrying at least
    ``TRUNK_TIE`` x the heaviest and heading within ``arccos(cos_max)`` of the axis; ``ctx``
    is ``(carried, indptr, idx, edge_length, position, height along the axis,``
    :func:`_subtree_top` ``, the tree's top node)``."""
    carried, indptr, idx, el, pos, h, top, tree_top = ctx
    heavy = float(carried[kids].max())
    ok = []
    for w in kids:
        if carried[w] < TRUNK_TIE * heavy:
            continue
        # near, or to the highest node of its heaviest path: a skeleton detour through a
        # whorl (a kink, a stem routed out along a limb and back) ends up high; or to the
        # tree's top if this child holds it (the leader, however the skeleton routes wood)
        heads = [int(_ahead(int(w), indptr, idx, carried, el, float(reach)))]
        heads.append(int(_highest_ahead(int(w), indptr, idx, carried, h)))
        if top[w] == tree_top:
            heads.append(int(top[w]))
        for x in heads:
            d = pos[x] - pos[v]
            ln = np.linalg.norm(d)
            if ln > 0 and d @ axis / ln >= cos_max:
                ok.append(int(w))
                break
    return ok


def continuation_from_segments(graph: BranchGraph, segment: NDArray[np.int64]) -> NDArray[np.int64]:
    """The continuation implied by a segmentation: the child in its parent's segment."""
    par = graph.parent
    cont = np.full(graph.n_nodes, -1, dtype=np.int64)
    ch = np.flatnonzero(par >= 0)
    same = ch[np.asarray(segment)[ch] == np.asarray(segment)[par[ch]]]
    cont[par[same]] = same
    return cont


def branch_order(
    graph: BranchGraph, weight_share: float = 0.5, max_angle: float = np.radians(45.0), **rule: Any
) -> NDArray[np.int64]:
    """Branch order per node (0 = trunk); ``max_angle`` in radians; ``rule``, ``tie``,
    ``look`` as :func:`continuation`."""
    cont = continuation(graph, weight_share, max_angle, **rule)
    par = graph.parent
    inc = np.zeros(graph.n_nodes)
    ch = np.flatnonzero(par >= 0)
    inc[ch] = (cont[par[ch]] != ch).astype(float)
    from biomorph.core import treeops

    return treeops.accumulate_down(par, inc, graph.order).astype(np.int64)


def segments(
    graph: BranchGraph, weight_share: float = 0.5, max_angle: float = np.radians(45.0), **rule: Any
) -> NDArray[np.int64]:
    """Segment (branch) id per node: ids 0.. in topological order of the segment starts."""
    cont = continuation(graph, weight_share, max_angle, **rule)
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


def order_from_segments(graph: BranchGraph, segment: NDArray[np.int64]) -> NDArray[np.int64]:
    """Branch order implied by a segmentation: +1 at every segment start below a root."""
    par = graph.parent
    inc = np.zeros(graph.n_nodes)
    ch = np.flatnonzero(par >= 0)
    seg = np.asarray(segment)
    inc[ch] = (seg[ch] != seg[par[ch]]).astype(float)
    from biomorph.core import treeops

    return treeops.accumulate_down(par, inc, graph.order).astype(np.int64)


def with_order(
    graph: BranchGraph, weight_share: float = 0.5, max_angle: float = np.radians(45.0), **rule: Any
) -> BranchGraph:
    """The graph with ``depth`` set to the branch order."""
    return graph.with_(depth=branch_order(graph, weight_share, max_angle, **rule))


#: the trunk's axis is smoothed over wiggles shorter than this share of the tree's height
#: (:func:`smooth_trunk`): level-set centroids sit a few centimetres off the axis from node
#: to node and are pulled towards each whorl's branches, which made a straight 16.7 m
#: spruce's trunk 21.7 m long (30 % over its height, its volume with it); a stem's sweep
#: and lean change over metres, so over a tenth of the height its axis is straight
TRUNK_WAVELENGTH = 0.1
#: ... and at least this many node spacings (small trees)
TRUNK_MIN_EDGES = 10.0


def tree_heights(graph: BranchGraph) -> NDArray[np.float64]:
    """Per node, the height of its tree: the span in z of the tree's nodes (m)."""
    from biomorph.core import treeops

    z = graph.position[:, 2]
    return treeops.per_label(graph.trees, z, np.maximum) - treeops.per_label(
        graph.trees, z, np.minimum
    )


def smooth_trunk(graph: BranchGraph, segment: NDArray[np.int64]) -> BranchGraph:
    """The graph with each tree's trunk (order 0, ``graph.depth == 0``, along ``segment``)
    smoothed by :func:`biomorph.tree.resample.smooth_branches` over
    :data:`TRUNK_WAVELENGTH` of the tree's height (:func:`tree_heights`; at least
    :data:`TRUNK_MIN_EDGES` edges of the trunks' median length). Run after the order rule:
    the trunk is chosen on the skeleton as built, only its geometry changes (length and
    volume; branches stay where they are and keep their first edge to the moved trunk
    node). No node moves farther than
    its radius or the trunk's median edge: the node-to-node wiggle goes, the route stays
    (where the trunk runs through a crown's branches, out of sight of the stem, a
    straightened path would leave their wood without a cylinder; detours beside a visible
    stem are :func:`biomorph.tree.cleanup.reroute_detours`' job)."""
    from biomorph.tree.resample import smooth_branches

    if graph.depth is None or graph.n_nodes < 3:
        return graph
    par = graph.parent
    seg = np.asarray(segment)
    trunk = graph.depth == 0
    cont = np.zeros(graph.n_nodes, dtype=bool)
    ch = par >= 0
    cont[ch] = trunk[ch] & (seg[ch] == seg[par[ch]])
    el = graph.edge_length
    # each trunk's median edge is the unit of its wavelength (a voxel skeleton's edges
    # differ from tree to tree); the loop runs over the trunks' nodes only
    uniq, inv = np.unique(graph.trees, return_inverse=True)
    inv = inv.reshape(-1)
    nodes = np.flatnonzero(cont)
    per_tree = np.zeros(uniq.size)
    for k in np.unique(inv[nodes]):
        e = el[nodes[inv[nodes] == k]]
        per_tree[k] = float(np.median(e[e > 0])) if (e > 0).any() else 0.0
    edge = per_tree[inv]
    wave = np.where(
        edge > 0,
        np.maximum(
            TRUNK_MIN_EDGES, TRUNK_WAVELENGTH * tree_heights(graph) / np.maximum(edge, 1e-12)
        ),
        0.0,
    )
    step = float(np.median(el[cont])) if cont.any() else 0.0
    out = smooth_branches(graph, cont, wave)
    if graph.radius is None:
        return out
    # the wiggle goes, not the route: no node moves farther than its radius or an edge
    # (where the skeleton's trunk runs through a crown's branches, out of sight of the
    # stem, a straightened path would leave their wood without a cylinder)
    limit = np.maximum(graph.radius, step)
    move = out.position - graph.position
    norm = np.linalg.norm(move, axis=1)
    scale = np.minimum(1.0, limit / np.maximum(norm, 1e-12))
    return out.with_(position=graph.position + move * scale[:, None])


#: the trunk's radii go through a running median over this many nodes before the
#: non-increasing fit (:func:`taper_trunk`): two nodes either side, about the reach of one
#: whorl's branch bases in a cross-section slab at the default node spacing
TRUNK_TAPER_WINDOW = 5


def taper_trunk(graph: BranchGraph, segment: NDArray[np.int64]) -> BranchGraph:
    """The graph with each tree's trunk radii (order 0, along ``segment``) made
    non-increasing from the base up: the least-squares non-increasing fit to them, each
    node weighted by its edge length (``scipy.optimize.isotonic_regression``); side
    branches are then kept no thicker than their new parent node
    (:func:`biomorph.tree.radius.cap_down`).

    Why: a circle fit at a whorl takes in the branch bases and needles of its slab, and the
    taper model keeps a reliable fit up to three scatters above it, so the spruce's trunk
    swelled by 10–25 % at every whorl (beads in a render; 0.5 m windows spanning 8.0–11.3 cm).
    A stem's radius does not grow upwards; the fit pools each swelling with its neighbours
    and keeps the butt flare."""
    from scipy.ndimage import median_filter
    from scipy.optimize import isotonic_regression

    from biomorph.core import treeops

    if graph.depth is None or graph.radius is None or graph.n_nodes < 2:
        return graph
    par = graph.parent
    seg = np.asarray(segment)
    trunk = graph.depth == 0
    indptr, idx = graph.children_csr
    radius = np.array(graph.radius, dtype=np.float64)
    w = np.maximum(graph.edge_length, 1e-9)
    changed = False
    for root in graph.roots:
        if not trunk[root]:
            continue
        path = [int(root)]
        while True:
            v = path[-1]
            kids = idx[indptr[v] : indptr[v + 1]]
            nxt = kids[trunk[kids] & (seg[kids] == seg[v])]
            if nxt.size == 0:
                break
            path.append(int(nxt[0]))
        if len(path) < 3:
            continue
        p = np.asarray(path)
        # a running median first: one node swollen by a whorl's branch bases, or one hidden
        # behind it and fitted too thin, must not move the fit of its neighbours
        med = median_filter(radius[p], size=TRUNK_TAPER_WINDOW, mode="nearest")
        fit = isotonic_regression(med, weights=w[p], increasing=False).x
        radius[p] = fit
        changed = True
    if not changed:
        return graph
    slack = np.ones(graph.n_nodes)
    ch = par >= 0
    slack[ch] = np.where(seg[ch] == seg[par[ch]], 1.1, 1.0)
    slack[trunk] = np.inf  # the fit is the trunk's radius
    return graph.with_(radius=treeops.cap_down(par, radius, slack, graph.order))
