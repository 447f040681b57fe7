"""Limbs the skeleton hung the wrong way round (issue 13, session 21).

The graph method's shortest-path forest reaches each point by the cheapest way from the
root. Where the scan misses a limb's junction (occlusion, a shadow behind the stem) the
cheapest way into the limb can come from *above*: along another branch, across where the
two touch, then down the limb to its base. The skeleton then runs the limb backwards: its
base is a tip that ends against the stem, and the limb hangs from the thin branch it was
entered from. The pipe model gives a limb hung from a twig a twig's radius and the taper
model sets its circle fits aside as envelopes (a fit 10× the model): on the synthetic
maple at 240,000 points with 8 mm noise one such limb (58 mm, 2 m) held 7 % of its volume.

:func:`reversed_limbs` finds such limbs and turns them round. A tip ``e`` is the base of a
reversed limb when all of these hold:

1. **The tip is thick.** The reliable circle fits
   (:func:`~biomorph.tree.radius.well_covered`, the taper model's own thresholds) along
   the way up from ``e`` span :data:`STRETCH_RADII` of their median radius ``m`` (three
   diameters, as the taper model's runs), at least :data:`MIN_FITS` of
   them, the first within :data:`MAX_GAP` nodes and none further apart, their quartiles
   within :data:`CONSISTENT` of the median (a needle envelope's fits scatter far wider;
   a real tip is not several centimetres thick), and ``m`` at least twice the model's
   radius at ``e`` (the model contradicts the fits: otherwise nothing is lost).
2. **The stretch is the limb's own wood**: at most a third of its nodes lie inside the
   cylinder of another branch at least as thick (a side branch's first nodes running
   inside the stem measure the stem), and its far end stands :data:`CLEARANCE` radii
   clear of the host's branch (the host's edges up and down from it as far as the stretch
   reaches): a chain running beside the stem does not.
3. **It ends against thicker wood**: a node ``t`` of the same tree, outside the stretch,
   modelled at least :data:`HOST_RATIO` ``m`` thick (the pipe model's parent, no thinner
   than its child, less the fits' scatter), whose edge passes within its own radius plus
   ``m`` of ``e``.
4. **The way through ``t`` is shorter**: path length root → ``t`` → ``e`` shorter than the
   skeleton's root → ``e``. The nodes turned round are those on the way up from ``e`` that
   this new way reaches by a shorter path (what the shortest-path forest would have given
   had the junction been seen), stopping before the first node modelled and measured under
   half of ``m`` (the thin wood the limb was entered from keeps its own parent). The whole
   measured stretch must be among them.
5. **The old attachment contradicts the limb**: the node the turned-round part hung from
   is modelled under half of ``m`` (a limb hung from a twig), else the skeleton is
   consistent and left alone.

Every test reads the cloud's own measures (fitted radii, the model's radii, node spacing
through the path lengths); the constants are ratios of those. The caller fits radii
again on the new skeleton, the turned limbs' radii from their own fits
(:func:`biomorph.tree.radius.taper_radii`'s ``trusted``: the pipe model under a turned
limb still lacks whatever the skeleton hangs elsewhere). Measured: ``docs/tree.md``,
session 21.

:func:`broken_ends` (session 25) mends the other side of the same break: a stem or limb
whose skeleton stops at a gap in the scan (occlusion behind a limb, a shadow) while the
wood beyond it hangs from somewhere else, reached the long way round (the synthetic maple
at 240,000 points with 8 mm noise, seed 3: the stem broke at 4.7 m and its upper part hung
from a limb, so the trunk ran 14 m out along the limb and back). A tip ``e`` is a broken
end when

1. **It is thick and well measured**: the same consistent stretch of fits as above
   (median ``m``), and the model at ``e`` under half of ``m`` (the pipe model gives the
   end of a broken stem a twig's radius: nothing hangs from it).
2. **Its wood goes on just ahead**: a node ``y`` of the same tree ahead of ``e`` along
   the stretch's direction (from its last node to ``e``), within ``m`` of that line and
   within the stretch's own length (:data:`STRETCH_RADII` ``m``) of ``e``: a gap no
   longer than the wood measured on its near side, the wood beyond continuing its line.
3. **The skeleton reached that wood the long way round**: the path from the root through
   ``e`` to ``y`` is shorter than ``y``'s own by more than that gap.

Of the nodes passing, the one saving the most path is hung from ``e``; the nodes on its
way up that the new way reaches first (what the shortest-path forest gives once the gap
is bridged) are turned round. A stem that really ends (a broken-off top) has nothing
ahead; a limb tip beside a twig of its own branch reaches it no more directly.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.core.curves import segment_projection
from biomorph.core.graph import BranchGraph
from biomorph.tree.radius import RadiusFit, well_covered

__all__ = [
    "reversed_limbs",
    "broken_ends",
    "mend_limbs",
    "STRETCH_RADII",
    "MIN_FITS",
    "CONSISTENT",
    "CLEARANCE",
]

#: the measured stretch at the tip spans this many of its median radius (3 diameters)
STRETCH_RADII = 6.0
#: at least this many reliable fits in the stretch
MIN_FITS = 5
#: at most this many nodes in a row without a reliable fit (the tip node included)
MAX_GAP = 3
#: the fits' quartiles lie within this factor of their median
CONSISTENT = 1.2
#: the stretch's far end stands this many of its radii clear of the host's surface
CLEARANCE = 3.0
#: share of the stretch's nodes allowed inside another, thicker branch's cylinder
INSIDE_SHARE = 1 / 3
#: the host is at least this share of the limb's radius (a parent no thinner than its
#: child, with the fits' scatter)
HOST_RATIO = 0.8
#: a limb's old attachment (and the thin wood it was entered from) is under this share of
#: its radius
THIN_RATIO = 0.5


@numba.njit(cache=True)
def _tip_stretches(parent, edge, tips, fit, reliable, radii, min_fits, max_gap):  # pragma: no cover
    """For each tip: the median reliable fit ``m`` over the way up from it until the way
    spans ``radii * m`` (NaN if the fits run out first), the stretch's last node and the
    fits' quartiles."""
    k = tips.size
    med = np.full(k, np.nan)
    q1 = np.full(k, np.nan)
    q3 = np.full(k, np.nan)
    end = np.full(k, -1, dtype=np.int64)
    buf = np.empty(4096)
    for i in range(k):
        x = tips[i]
        s = 0.0
        nf = 0
        gap = 0
        while True:
            if reliable[x]:
                buf[nf] = fit[x]
                nf += 1
                gap = 0
            else:
                gap += 1
                if gap > max_gap:
                    break
            if nf >= min_fits:
                m = np.median(buf[:nf])
                if s >= radii * m:
                    med[i] = m
                    q1[i] = np.quantile(buf[:nf], 0.25)
                    q3[i] = np.quantile(buf[:nf], 0.75)
                    end[i] = x
                    break
            if parent[x] < 0 or nf >= buf.size:
                break
            s += edge[x]
            x = parent[x]
    return med, q1, q3, end


class _Limbs:
    """One skeleton's parents being edited, and the tests of the module doc on them."""

    def __init__(self, graph: BranchGraph, fit: RadiusFit):
        assert graph.radius is not None
        self.pos = graph.position
        self.radius = np.asarray(graph.radius, dtype=float)
        self.tree = graph.trees
        self.fit = fit.radius
        self.reliable = well_covered(fit)
        self.usable = fit.radius > 0  # any circle found: where to cut, not what to keep
        self.kd = cKDTree(self.pos)
        self.rmax = float(self.radius.max())
        self.parent = np.array(graph.parent, dtype=np.int64)
        self.done: list[dict[str, Any]] = []
        self.joined: list[dict[str, Any]] = []
        self.update()

    def update(self) -> None:
        """Edge lengths, path lengths from the root and main children of the parents."""
        par, pos = self.parent, self.pos
        self.edge = np.where(par >= 0, np.linalg.norm(pos - pos[np.maximum(par, 0)], axis=1), 0.0)
        self.pl = treeops.accumulate_down(par, self.edge)
        self.main = treeops.main_child(par, treeops.subtree_sum(par, self.edge))

    def tips(self):
        """The tips whose measured stretch is consistent, thickest first, with its median
        fit and last node."""
        par = self.parent
        leaves = np.flatnonzero(np.bincount(par[par >= 0], minlength=par.size) == 0)
        med, q1, q3, end = _tip_stretches(
            par, self.edge, leaves, self.fit, self.reliable, STRETCH_RADII, MIN_FITS, MAX_GAP
        )
        ok = np.isfinite(med)
        ok[ok] &= (q3[ok] <= CONSISTENT * med[ok]) & (q1[ok] >= med[ok] / CONSISTENT)
        idx = np.flatnonzero(ok)
        idx = idx[np.argsort(-med[idx], kind="stable")]
        return zip(leaves[idx].tolist(), med[idx].tolist(), end[idx].tolist(), strict=True)

    def way_up(self, a: int, b: int) -> NDArray[np.int64] | None:
        """The nodes from ``a`` up to ``b``; None if ``b`` is no longer on the way (an
        earlier limb turned round changed it)."""
        way = [a]
        while way[-1] != b:
            nxt = int(self.parent[way[-1]])
            if nxt < 0:
                return None
            way.append(nxt)
        return np.asarray(way, dtype=np.int64)

    def own_wood(self, nodes: NDArray, m: float) -> bool:
        """At most :data:`INSIDE_SHARE` of ``nodes`` inside the cylinder of another branch
        at least :data:`HOST_RATIO` ``m`` thick."""
        par, own = self.parent, set(nodes.tolist())
        inside = 0
        for u, near in zip(
            nodes, self.kd.query_ball_point(self.pos[nodes], self.rmax), strict=True
        ):
            c = np.asarray([w for w in near if w not in own and par[w] >= 0], dtype=np.int64)
            if c.size == 0:
                continue
            c = c[(self.tree[c] == self.tree[u]) & (self.radius[c] >= HOST_RATIO * m)]
            if c.size == 0:
                continue
            d = segment_projection(self.pos[u], self.pos[par[c]], self.pos[c])[1]
            inside += bool((d < 0.9 * self.radius[c]).any())
        return inside <= INSIDE_SHARE * nodes.size

    def host(self, e: int, own: NDArray, m: float) -> tuple[int, float] | None:
        """The thicker node ``e`` ends against with the shortest way from the root, and
        that way's length to ``e``; None if there is none or that way is no shorter than
        the skeleton's."""
        par, pl = self.parent, self.pl
        near = np.asarray(self.kd.query_ball_point(self.pos[e], self.rmax + m), dtype=np.int64)
        near = near[(par[near] >= 0) & (self.tree[near] == self.tree[e])]
        near = near[(self.radius[near] >= HOST_RATIO * m) & ~np.isin(near, own)]
        if near.size == 0:
            return None
        d = segment_projection(self.pos[e], self.pos[par[near]], self.pos[near])[1]
        near = near[d <= self.radius[near] + m]
        if near.size == 0:
            return None
        way = pl[near] + np.linalg.norm(self.pos[near] - self.pos[e], axis=1)
        k = int(np.argmin(way))
        if way[k] >= pl[e]:
            return None
        return int(near[k]), float(way[k])

    def clear(self, t: int, start: int, last: int, m: float) -> bool:
        """The stretch ``start`` … ``last`` ends :data:`CLEARANCE` ``m`` outside the host's
        branch: the cylinders of the edges along ``t``'s ancestors and main descendants as
        far as the stretch reaches (a chain beside the stem stays near it; a limb leaving
        it, or continuing it beyond its end, does not)."""
        reach = float(np.linalg.norm(self.pos[last] - self.pos[start])) + CLEARANCE * m
        way = [t]
        for step in (self.parent, self.main):
            x, s = t, 0.0
            while s < reach and step[x] >= 0:
                s += float(np.linalg.norm(self.pos[step[x]] - self.pos[x]))
                x = int(step[x])
                way.append(x)
        w = np.asarray(way, dtype=np.int64)
        w = w[self.parent[w] >= 0]
        if w.size == 0:
            return True
        d = segment_projection(self.pos[last], self.pos[self.parent[w]], self.pos[w])[1]
        return float(np.min(d - self.radius[w])) >= CLEARANCE * m

    def turned(self, e: int, way_in: float, m: float, n: int) -> NDArray[np.int64]:
        """The nodes from ``e`` up that the way through the host reaches first, up to the
        last thick one before :data:`MAX_GAP` thin nodes in a row beyond the measured
        stretch (its first ``n`` nodes); thick: modelled or measured (any usable circle
        fit: where to cut, not what radius to keep) at least :data:`THIN_RATIO` ``m``."""
        par, pl = self.parent, self.pl
        out = [e]
        last_thick = 1
        x = int(par[e])
        while x >= 0 and way_in + (pl[e] - pl[x]) < pl[x]:
            out.append(x)
            fitted = self.fit[x] if self.usable[x] else 0.0
            if len(out) <= n or max(self.radius[x], fitted) >= THIN_RATIO * m:
                last_thick = len(out)
            elif len(out) - last_thick > MAX_GAP:
                break
            x = int(par[x])
        return np.asarray(out[:last_thick], dtype=np.int64)

    def join_ends(self) -> None:
        """Broken ends (module doc): a thick tip whose wood goes on just beyond it, reached
        the long way round, joined to it."""
        par, pos = self.parent, self.pos
        for e, m, last in self.tips():
            if m < 2.0 * self.radius[e] or np.any(par == e) or last == e:
                continue
            u = pos[e] - pos[last]
            n = float(np.linalg.norm(u))
            if n <= 0:
                continue
            u /= n
            gap = STRETCH_RADII * m
            near = np.asarray(self.kd.query_ball_point(pos[e], gap), dtype=np.int64)
            near = near[(self.tree[near] == self.tree[e]) & (near != e)]
            if near.size == 0:
                continue
            d = pos[near] - pos[e]
            t = d @ u
            side = np.linalg.norm(d - t[:, None] * u, axis=1)
            way = self.pl[e] + np.linalg.norm(d, axis=1)
            saving = self.pl[near] - way
            ok = (t > 0) & (side <= m) & (saving > gap)
            if not ok.any():
                continue
            k = int(np.flatnonzero(ok)[np.argmax(saving[ok])])
            y = int(near[k])
            # the way from y up that the bridge reaches first changes direction
            turn = [y]
            x = int(par[y])
            while x >= 0 and way[k] + (self.pl[y] - self.pl[x]) < self.pl[x]:
                turn.append(x)
                x = int(par[x])
            nodes = np.asarray(turn, dtype=np.int64)
            par[nodes[1:]] = nodes[:-1]
            par[y] = e
            self.joined.append(
                {
                    "tip": e,
                    "to": y,
                    "radius": m,
                    "gap": float(np.linalg.norm(d[k])),
                    "saving": float(saving[k]),
                    "nodes": nodes,
                }
            )
            self.update()

    def turn_tips(self) -> None:
        """Reversed limbs (module doc): a thick tip against thicker wood, turned round."""
        par, radius = self.parent, self.radius
        for e, m, last in self.tips():
            if m < 2.0 * radius[e] or np.any(par == e):  # not contradicted / no longer a tip
                continue
            stretch = self.way_up(e, last)
            if stretch is None or not self.own_wood(stretch, m):
                continue
            hit = self.host(e, stretch, m)
            if hit is None or not self.clear(hit[0], e, last, m):
                continue
            turn = self.turned(e, hit[1], m, stretch.size)
            old = int(par[turn[-1]])
            if turn.size < stretch.size or (old >= 0 and radius[old] >= THIN_RATIO * m):
                continue
            length = float(self.pl[e] - self.pl[turn[-1]])
            par[turn[1:]] = turn[:-1]
            par[e] = hit[0]
            self.done.append(
                {"tip": e, "host": hit[0], "radius": m, "length": length, "nodes": turn}
            )
            self.update()


def reversed_limbs(
    graph: BranchGraph, fit: RadiusFit
) -> tuple[NDArray[np.int64], list[dict[str, Any]]]:
    """New parents with every reversed limb (module doc) turned round, and one record per
    limb (``tip``: its base, a tip before; ``host``: the node it now hangs from;
    ``radius`` m: its fits' median; ``length`` m turned round; ``nodes``: those turned
    round, from the base up).

    ``graph``: the fitted skeleton (model radii); ``fit``: its circle fits, node for node.
    Limbs are taken thickest first; each later one is tested on the skeleton as the earlier
    ones left it."""
    parent, turned, _ = mend_limbs(graph, fit, broken=False)
    return parent, turned


def broken_ends(
    graph: BranchGraph, fit: RadiusFit
) -> tuple[NDArray[np.int64], list[dict[str, Any]]]:
    """New parents with every broken end (module doc) joined to the wood it breaks off
    from; one record per join (``tip``: the thick tip; ``to``: the node now hung from it;
    ``radius`` m: the tip's fits' median; ``gap`` m; ``saving`` m of path; ``nodes``: those
    whose parent changed, from ``to`` up)."""
    parent, _, joined = mend_limbs(graph, fit, reversed_=False)
    return parent, joined


def mend_limbs(
    graph: BranchGraph, fit: RadiusFit, *, reversed_: bool = True, broken: bool = True
) -> tuple[NDArray[np.int64], list[dict[str, Any]], list[dict[str, Any]]]:
    """Reversed limbs turned round (:func:`reversed_limbs`), then broken ends joined on
    the skeleton they left (:func:`broken_ends`), in one pass over the same fits:
    ``(parent, turned, joined)``."""
    if graph.radius is None or graph.n_nodes < 3 or fit.radius.size != graph.n_nodes:
        return np.array(graph.parent, dtype=np.int64), [], []
    limbs = _Limbs(graph, fit)
    if reversed_:
        limbs.turn_tips()
    if broken:
        limbs.join_ends()
    return limbs.parent, limbs.done, limbs.joined
