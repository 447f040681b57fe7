"""Per-node branch radius from the cloud (seed 001 §5.1), vectorised over all nodes.

For every skeleton node ``v`` (parent ``u``, children ``w_i``):

1. **Cross-section plane** through ``v`` with normal ``n = (e_in + e_out) / ‖·‖``,
   ``e_in = (v − u)/‖v − u‖``, ``e_out`` the normalised sum of the unit child directions
   (eq. 5.1); tangents from ``n × e_z`` (eq. 5.2, any perpendicular pair when ``n ∥ e_z``).
2. **Search cylinder** around the axis: half-height ``h`` (``search_depth``) and radius
   ``R_s = search_factor × prior radius``; the prior is the median distance of the node's
   own points (points whose nearest skeleton segment is at ``v``), so no trunk radius is
   asked for. Points inside are projected onto the plane.
3. **RANSAC circle** (``trials`` random triples, radius capped by ``R_s``, inlier band
   ``tolerance``), then a **least-squares refit** on the inliers (algebraic Kåsa fit
   followed by Gauss–Newton on the geometric distance).
4. **Smoothing along the graph**: the log-ratio ``δ = log r_fit − log r_allometric`` is
   smoothed by minimising ``Σ_ok (δ_v − δ̂_v)² + λ Σ_edges (δ_v − δ_parent)²`` — a
   tree-structured system solved exactly (:func:`biomorph.tree.livny.solve_tree_system`).
   Nodes without a reliable fit (few inliers, small angular coverage) take the allometric
   taper anchored by their fitted neighbours, so tips taper and stems follow the data.
5. Optional **re-centring**: nodes move to the fitted circle centre (fixes the graph
   method's off-centre stems), if the move is smaller than ``R_s``; the shifts are smoothed
   along the graph first (the bias is slow, the fit noise is per node).

RANSAC and refit run in one numba kernel over all nodes (one seed, deterministic).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree.livny import allometric_radii, skeleton_distance, solve_tree_system
from biomorph.tree.neighbours import PointIndex, _build_grid
from biomorph.tree.run_cylinders import SegmentFit, fit_segments

if TYPE_CHECKING:
    from collections.abc import Callable

    from biomorph.tree.metrics import SegmentCandidates

    #: per tree label the stem as tracked (stem nodes, radii there, the share of the stem
    #: path on it), from (graph, fit, stem mask, reliable mask):
    #: :func:`biomorph.tree.stem.stem_tracks`
    StemTracker = Callable[
        [BranchGraph, "RadiusFit", NDArray[np.bool_], NDArray[np.bool_]],
        dict[int, tuple[NDArray[np.int64], NDArray[np.float64], float]],
    ]

__all__ = [
    "RadiusFit",
    "node_axes",
    "fit_radii",
    "fit_circles",
    "smooth_log_ratio",
    "cap_down",
    "taper_radii",
    "segment_radii",
    "breast_height_fits",
    "DBH_BAND",
    "MIN_RADIUS",
    "PIPE_EXPONENT",
    "RELIABLE_COVERAGE",
    "RELIABLE_MAD",
    "WITHIN_SLOPE_BOUNDS",
    "BRANCH_PRIOR_FITS",
    "branch_ids",
    "centre_thin_nodes",
    "CENTROID_MAX_RADIUS",
    "twig_offset",
    "twig_surface",
    "TWIG_MIN_POINTS",
    "TWIG_MAX_OFFSET",
    "TWIG_SURFACE_RATIO",
    "STEM_POOL_RATIO",
    "STEM_INSIDE",
    "INSIDE_RADIUS",
]

#: a circle fit is kept as measured only where at least a third of the circumference holds
#: inliers (4 of 12 sectors): an arc under 120° leaves the radius poorly determined (the
#: centre slides along the arc's axis), and a single scan position sees at most half of a
#: stem; below that the taper model decides
RELIABLE_COVERAGE = 1 / 3
#: ... and where the inliers scatter by at most this share of the radius: a cross-section
#: whose scan noise is comparable to its radius (thin twigs, needle clumps) is not measured
RELIABLE_MAD = 0.1
#: a stem's circle fit is kept as measured only where its slab holds at most this many
#: points in the inner half of the circle per inlier (:data:`INSIDE_RADIUS`): a scanner sees
#: a stem's surface, never its inside, so a circle with points inside it is an envelope —
#: of the stem and the needles of its whorl, of two stems. Measured (session 17): true stem
#: fits hold none (median; 95th percentile 0.12-0.17 on the TreeLS spruce and pine plot, 0
#: on the synthetic presets at 8 mm noise); at a quarter of the spruce's points the stem's
#: lower half held envelopes of 25-33 cm around its 11 cm, which anchored the taper model at
#: 24 cm (4.7x the full cloud's volume). Branch fits are left to the one-sided test against
#: the model (step 4): applied to them the rule moved AdTree's volumes by 10-30 % and the
#: rTwig voxel model out of its references' range, with nothing to say which was right
STEM_INSIDE = 0.2
#: "inside": nearer to the fitted centre than this share of the radius (half: a slab cut
#: obliquely through a stem holds an ellipse, whose short axis lies inside the circle; at
#: 0.8, about the inlier band, the rTwig and A3B4 voxel models lost 16 and 13 % of volume)
INSIDE_RADIUS = 0.5
#: the radius floor (m) of the taper model: 1 mm, the finest woody twig a QSM reports;
#: thinner predictions are extrapolations beyond any measured cross-section
MIN_RADIUS = 0.001
#: the exponent ``e`` of the taper model's pipe rule ``r^e ∝ supported length``: 2, da Vinci's
#: rule of area-preserving branching (the sum of the children's cross-sections equals the
#: parent's), which West, Brown & Enquist's plant-network model (1999) also takes for the
#: branches as wholes; their Murray-like e = 3 applies to the conduits inside, not to the
#: wood cross-section. With the supported length proportional to the terminal shoots carried
#: (Shinozaki's unit pipes) ``r ∝ L^(1/2)``; Livny's 2.5 (step vii) made the thin branches of
#: every synthetic preset 1.3–1.9× too thick when anchored on the stem (docs/tree.md)
PIPE_EXPONENT = 2.0
#: bounds of the within-branch taper slope ``b_w`` (``r ∝ L^b_w`` along one branch) fitted
#: from the reliable cross-sections: 1/3 is Murray's cube law (West, Brown & Enquist's
#: e = 3), the slowest taper a branch of the pipe family shows; 1 a cone-like taper whose
#: radius falls in proportion to the wood carried (the Weber–Penn / TreeQSM cone). Outside
#: it the fitted slope is fit noise (birch scans, 8 mm noise: 1.2–6)
WITHIN_SLOPE_BOUNDS = (1 / 3, 1.0)
#: a branch's own taper slope (from its own reliable fits) is shrunk towards the tree's as
#: if the tree's slope were this many extra fits on the branch (a branch with three fits
#: gets half of each)
BRANCH_PRIOR_FITS = 3
#: a reliable fit more than this factor above the taper model is not kept as measured,
#: whatever the model's scatter: the same factor 2 at which :func:`fit_radii` drops a fit
#: from the smoothed profile
KEEP_MAX_RATIO = 2.0
#: ... unless it belongs to a *run*: consecutive reliable fits along the skeleton, each
#: within :data:`RUN_STEP` of its parent's, spanning at least this many of their median
#: diameter. A circle seen the same along three of its diameters is a piece of wood, not a
#: needle envelope or a junction's flare (those change from slab to slab and span about one
#: diameter); the model under it is wrong there (the skeleton routed the wood the branch
#: carries elsewhere: on the noisy 240,000-point maple 179 nodes on 7-20 cm branches had
#: model radii of 5-18 mm under fits within 4 % of the truth). Measured: such runs of
#: above-model fits hold 149 nodes on that maple and none on the TreeLS spruce, the pine
#: plot or AdTree tree1 (1 diameter: 108 on the spruce, 2 diameters: 13)
RUN_DIAMETERS = 3.0
#: ... the largest ratio between neighbouring fits of a run (20 %)
RUN_STEP = 1.2


def node_axes(
    graph: BranchGraph, continuation: NDArray[np.int64] | None = None
) -> NDArray[np.float64]:
    """Unit branch direction at every node (eq. 5.1): the unit edge in plus the normalised
    sum of the unit edges out to the children; ``e_z`` where undefined. With
    ``continuation`` (per node the child continuing its branch, -1 at tips), only the edge
    to that child counts: the axis of the node's own branch (the tube mesh: eq. 5.1's
    plane, which the cross-sections need, tilts a stem's ring towards every branch of a
    whorl — collars in a render of the spruce)."""
    n = graph.n_nodes
    pos = graph.position
    par = graph.parent
    ch = np.flatnonzero(par >= 0)
    e = pos[ch] - pos[par[ch]]
    ln = np.linalg.norm(e, axis=1)
    e = np.where(ln[:, None] > 0, e / np.maximum(ln, 1e-300)[:, None], 0.0)
    e_in = np.zeros((n, 3))
    e_in[ch] = e
    out = np.zeros((n, 3))
    if continuation is None:
        np.add.at(out, par[ch], e)
    else:
        cont = np.asarray(continuation)
        has = np.flatnonzero(cont >= 0)
        out[has] = e_in[cont[has]]
    on = np.linalg.norm(out, axis=1)
    out = np.where(on[:, None] > 0, out / np.maximum(on, 1e-300)[:, None], 0.0)
    ax = e_in + out
    an = np.linalg.norm(ax, axis=1)
    bad = an < 1e-9
    ax[bad] = np.where(
        np.linalg.norm(e_in[bad], axis=1)[:, None] > 0, e_in[bad], np.array([0.0, 0.0, 1.0])
    )
    an = np.linalg.norm(ax, axis=1)
    return ax / an[:, None]


def _tangents(nrm: NDArray) -> tuple[NDArray, NDArray]:
    ez = np.array([0.0, 0.0, 1.0])
    t0 = np.cross(nrm, ez)
    ln = np.linalg.norm(t0, axis=1)
    par = ln < 1e-9
    t0[par] = np.array([1.0, 0.0, 0.0])
    t0 /= np.linalg.norm(t0, axis=1)[:, None]
    t1 = np.cross(nrm, t0)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return t0, t1


@numba.njit(cache=True)
def _circle3(x1, y1, x2, y2, x3, y3):
    d = 2.0 * (x1 * (y2 - y3) + x2 * (y3 - y1) + x3 * (y1 - y2))
    if abs(d) < 1e-18:
        return 0.0, 0.0, -1.0
    s1 = x1 * x1 + y1 * y1
    s2 = x2 * x2 + y2 * y2
    s3 = x3 * x3 + y3 * y3
    cx = (s1 * (y2 - y3) + s2 * (y3 - y1) + s3 * (y1 - y2)) / d
    cy = (s1 * (x3 - x2) + s2 * (x1 - x3) + s3 * (x2 - x1)) / d
    return cx, cy, np.sqrt((x1 - cx) ** 2 + (y1 - cy) ** 2)


@numba.njit(cache=True)
def _lsq_circle(x, y, cx, cy, r, rmax):
    """Kåsa algebraic fit then Gauss-Newton on the geometric residual."""
    m = x.size
    if m >= 3:
        # Kåsa: x² + y² + D x + E y + F = 0
        a = np.zeros((3, 3))
        b = np.zeros(3)
        for i in range(m):
            row0, row1, row2 = x[i], y[i], 1.0
            z = -(x[i] * x[i] + y[i] * y[i])
            a[0, 0] += row0 * row0
            a[0, 1] += row0 * row1
            a[0, 2] += row0 * row2
            a[1, 1] += row1 * row1
            a[1, 2] += row1 * row2
            a[2, 2] += row2 * row2
            b[0] += row0 * z
            b[1] += row1 * z
            b[2] += row2 * z
        a[1, 0] = a[0, 1]
        a[2, 0] = a[0, 2]
        a[2, 1] = a[1, 2]
        if abs(np.linalg.det(a)) > 1e-24:
            sol = np.linalg.solve(a, b)
            kx = -sol[0] / 2
            ky = -sol[1] / 2
            rr = kx * kx + ky * ky - sol[2]
            if rr > 0 and np.sqrt(rr) <= rmax:
                cx, cy, r = kx, ky, np.sqrt(rr)
    for _ in range(8):
        jtj = np.zeros((3, 3))
        jtr = np.zeros(3)
        for i in range(m):
            dx = x[i] - cx
            dy = y[i] - cy
            di = np.sqrt(dx * dx + dy * dy)
            if di < 1e-12:
                continue
            res = di - r
            j0 = -dx / di
            j1 = -dy / di
            j2 = -1.0
            jtj[0, 0] += j0 * j0
            jtj[0, 1] += j0 * j1
            jtj[0, 2] += j0 * j2
            jtj[1, 1] += j1 * j1
            jtj[1, 2] += j1 * j2
            jtj[2, 2] += j2 * j2
            jtr[0] += j0 * res
            jtr[1] += j1 * res
            jtr[2] += j2 * res
        jtj[1, 0] = jtj[0, 1]
        jtj[2, 0] = jtj[0, 2]
        jtj[2, 1] = jtj[1, 2]
        for k in range(3):
            jtj[k, k] += 1e-12
        if abs(np.linalg.det(jtj)) < 1e-30:
            break
        step = np.linalg.solve(jtj, -jtr)
        cx += step[0]
        cy += step[1]
        r += step[2]
        if r > rmax:
            r = rmax
        if r <= 0:
            r = 1e-6
        if abs(step[0]) + abs(step[1]) + abs(step[2]) < 1e-10:
            break
    return cx, cy, r


@numba.njit(cache=True)
def _fit_kernel(
    u,
    w,
    indptr,
    rmax,
    rmin,
    tol_rel,
    tol_abs,
    tol_max,
    trials,
    min_inliers,
    seed,
    out_cx,
    out_cy,
    out_r,
    out_n,
    out_cov,
    out_mad,
    out_in,
    inner_share,
):
    np.random.seed(seed)  # noqa: NPY002 - numba's per-thread generator
    m = indptr.size - 1
    for v in range(m):
        a = indptr[v]
        b = indptr[v + 1]
        k = b - a
        out_r[v] = -1.0
        out_n[v] = 0
        out_cov[v] = 0.0
        if k < 3:
            continue
        x = u[a:b]
        y = w[a:b]
        best_n = 0
        best_res = 1e300
        bcx = 0.0
        bcy = 0.0
        br = -1.0
        for _ in range(trials):
            i1 = np.random.randint(k)  # noqa: NPY002
            i2 = np.random.randint(k)  # noqa: NPY002
            i3 = np.random.randint(k)  # noqa: NPY002
            if i1 == i2 or i2 == i3 or i1 == i3:
                continue
            # a trial that cannot reach the best count so far (nor ``min_inliers``: most
            # twig sections hold fewer points) can neither become the best nor be kept:
            # its draws are made, its circle and count skipped (the same fit is chosen)
            if k < max(best_n, min_inliers):
                continue
            cx, cy, r = _circle3(x[i1], y[i1], x[i2], y[i2], x[i3], y[i3])
            if r <= rmin[v] or r > rmax[v]:
                continue
            tol = min(max(tol_rel * r, tol_abs), tol_max)
            cnt = 0
            res = 0.0
            for i in range(k):
                d = abs(np.sqrt((x[i] - cx) ** 2 + (y[i] - cy) ** 2) - r)
                if d < tol:
                    cnt += 1
                    res += d
            if cnt > best_n or (cnt == best_n and res < best_res):
                best_n = cnt
                best_res = res
                bcx, bcy, br = cx, cy, r
        if br <= 0 or best_n < min_inliers:
            continue
        tol = min(max(tol_rel * br, tol_abs), tol_max)
        sel = np.zeros(k, dtype=np.bool_)
        for i in range(k):
            sel[i] = abs(np.sqrt((x[i] - bcx) ** 2 + (y[i] - bcy) ** 2) - br) < tol
        xi = x[sel]
        yi = y[sel]
        cx, cy, r = _lsq_circle(xi, yi, bcx, bcy, br, rmax[v])
        # angular coverage in 12 sectors around the fitted centre
        occ = np.zeros(12, dtype=np.bool_)
        mad = 0.0
        for i in range(xi.size):
            ang = np.arctan2(yi[i] - cy, xi[i] - cx)
            s = int((ang + np.pi) / (2 * np.pi) * 12) % 12
            occ[s] = True
            mad += abs(np.sqrt((xi[i] - cx) ** 2 + (yi[i] - cy) ** 2) - r)
        out_mad[v] = mad / max(xi.size, 1)
        # the slab's points well inside the circle (INSIDE_RADIUS): a scanner sees a
        # stem's surface, never its inside
        inner = inner_share * r
        n_in = 0
        for i in range(k):
            if (x[i] - cx) ** 2 + (y[i] - cy) ** 2 < inner * inner:
                n_in += 1
        out_in[v] = n_in
        out_cx[v] = cx
        out_cy[v] = cy
        out_r[v] = r
        out_n[v] = xi.size
        out_cov[v] = occ.sum() / 12.0


def _cross_sections(
    pos: NDArray, axes: NDArray, xyz: NDArray, kd: cKDTree, rs: NDArray, depth: float
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """The points of each node's flat search cylinder (radius ``rs``, half-height ``depth``
    about ``axes`` through ``pos``) in its cross-section plane: the plane's tangents
    ``t0``, ``t1`` and the CSR ``indptr``, ``u``, ``w`` of :func:`_slab_points`.

    The cylinder's points are those of its bounding ball (``kd.query_ball_point``) inside
    the slab, in the ball query's order (the k-d tree's leaf order, which the RANSAC's
    draws index): found through the cells of a grid (:meth:`PointIndex.grid`) that the
    cylinder's bounding box covers, not through the ball, which holds up to ``rs / depth``
    times more points (the ball's test is repeated, so the lists are the same)."""
    t0, t1 = _tangents(axes)
    grid = kd.grid() if isinstance(kd, PointIndex) else _build_grid(xyz, np.asarray(kd.indices))
    lo, cell, dims, start, rank, pts = grid
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    rs = np.ascontiguousarray(rs, dtype=np.float64)
    indptr, u, w = _slab_points(
        start,
        rank,
        pts,
        lo,
        float(cell),
        dims,
        pos,
        axes,
        t0,
        t1,
        float(depth),
        rs,
        np.sqrt(rs**2 + depth**2),  # the bounding ball's radius, as it was queried
    )
    return t0, t1, indptr, u, w


@numba.njit(cache=True)
def _slab_points(start, rank, pts, lo, cell, dims, pos, axes, t0, t1, depth, rs, ball):
    """Every node's points in its flat search cylinder that its bounding ball (radius
    ``ball``, cKDTree's test: ``(dx² + dy²) + dz² <= ball²``) holds, projected onto its
    cross-section plane, in leaf order (``rank``): CSR ``indptr`` and the in-plane ``u``,
    ``w``. The candidates are the grid cells (``start`` of each, ``pts`` in cell order)
    under the cylinder's bounding box, padded by a relative 10⁻⁷."""
    n = pos.shape[0]
    indptr = np.zeros(n + 1, dtype=np.int64)
    cap = max(1024, 8 * n)
    u = np.empty(cap)
    w = np.empty(cap)
    hr = np.empty(64, dtype=np.int64)
    hu = np.empty(64)
    hw = np.empty(64)
    ny = dims[1]
    nz = dims[2]
    box0 = np.empty(3, dtype=np.int64)
    box1 = np.empty(3, dtype=np.int64)
    k = 0
    for v in range(n):
        r2 = rs[v] * rs[v]
        b2 = ball[v] * ball[v]
        px, py, pz = pos[v, 0], pos[v, 1], pos[v, 2]
        for c in range(3):
            a = abs(axes[v, c])
            ext = depth * a + rs[v] * np.sqrt(max(1.0 - a * a, 0.0))
            ext = min(ext, ball[v]) * (1.0 + 1e-7) + 1e-12
            i0 = np.floor((pos[v, c] - ext - lo[c]) / cell)
            i1 = np.floor((pos[v, c] + ext - lo[c]) / cell)
            box0[c] = int(max(i0, 0.0))
            box1[c] = int(min(i1, dims[c] - 1.0))
        m = 0
        # a cylinder wholly outside the grid (a stem followed past the cloud's top,
        # tree.stem) holds nothing: its z range would index past its column's cells
        outside = box0[0] > box1[0] or box0[1] > box1[1] or box0[2] > box1[2]
        if outside:
            box1[0] = box0[0] - 1
        for ix in range(box0[0], box1[0] + 1):
            for iy in range(box0[1], box1[1] + 1):
                col = (ix * ny + iy) * nz
                for j in range(start[col + box0[2]], start[col + box1[2] + 1]):
                    dx = pts[j, 0] - px
                    dy = pts[j, 1] - py
                    dz = pts[j, 2] - pz
                    if (dx * dx + dy * dy) + dz * dz > b2:
                        continue
                    hn = dx * axes[v, 0] + dy * axes[v, 1] + dz * axes[v, 2]
                    if abs(hn) > depth:
                        continue
                    uu = dx * t0[v, 0] + dy * t0[v, 1] + dz * t0[v, 2]
                    ww = dx * t1[v, 0] + dy * t1[v, 1] + dz * t1[v, 2]
                    if uu * uu + ww * ww <= r2:
                        if m == hr.size:
                            hr2 = np.empty(2 * m, dtype=np.int64)
                            hu2 = np.empty(2 * m)
                            hw2 = np.empty(2 * m)
                            hr2[:m] = hr
                            hu2[:m] = hu
                            hw2[:m] = hw
                            hr, hu, hw = hr2, hu2, hw2
                        hr[m] = rank[j]
                        hu[m] = uu
                        hw[m] = ww
                        m += 1
        if k + m > u.size:
            grow = max(2 * u.size, k + m)
            u2 = np.empty(grow)
            w2 = np.empty(grow)
            u2[:k] = u[:k]
            w2[:k] = w[:k]
            u, w = u2, w2
        _by_rank(hr, hu, hw, m)
        u[k : k + m] = hu[:m]
        w[k : k + m] = hw[:m]
        k += m
        indptr[v + 1] = k
    return indptr, u[:k].copy(), w[:k].copy()


#: :func:`_by_rank` sorts at most this many hits by insertion, more by ``np.argsort``
INSERTION_SORT_MAX = 32


@numba.njit(cache=True)
def _by_rank(hr, hu, hw, m):  # pragma: no cover - numba
    """The first ``m`` hits of a slab put in order of their (unique) ranks ``hr``, their
    ``hu``, ``hw`` with them, in place: by insertion for the few hits of most slabs (an
    argsort's allocations took longer), else by ``np.argsort`` (the same order)."""
    if m > INSERTION_SORT_MAX:
        o = np.argsort(hr[:m])
        hr[:m], hu[:m], hw[:m] = hr[o], hu[o], hw[o]
        return
    for q in range(1, m):
        rq, uq, wq = hr[q], hu[q], hw[q]
        p = q
        while p > 0 and hr[p - 1] > rq:
            hr[p], hu[p], hw[p] = hr[p - 1], hu[p - 1], hw[p - 1]
            p -= 1
        hr[p], hu[p], hw[p] = rq, uq, wq


@dataclass
class RadiusFit:
    """Per-node circle fits: ``centre`` (m, cloud frame), ``radius`` (m, -1 = no fit),
    ``inliers`` count, angular ``coverage`` in [0, 1] (share of 12 sectors holding an
    inlier, TreeQSM's ``SurfCov`` in one slab), ``ok`` mask of usable fits, ``mad`` mean
    absolute residual of the inliers (m, TreeQSM's ``mad``), ``reliable`` mask of the fits
    kept as measured (set by :func:`taper_radii`; None before), ``inside`` the count of the
    slab's points within :data:`INSIDE_RADIUS` of the radius from the centre;
    ``segment`` the nodes whose radius a run's cylinder measured (``--run-cylinders``) and
    ``segment_centre`` the foot of each such node on its run's axis (NaN elsewhere)."""

    centre: NDArray[np.float64]
    radius: NDArray[np.float64]
    inliers: NDArray[np.int64]
    coverage: NDArray[np.float64]
    ok: NDArray[np.bool_]
    search_radius: NDArray[np.float64]
    mad: NDArray[np.float64] | None = None
    reliable: NDArray[np.bool_] | None = None
    model: dict | None = None
    inside: NDArray[np.int64] | None = None
    segment: NDArray[np.bool_] | None = None
    segment_centre: NDArray[np.float64] | None = None


def fit_circles(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    prior: NDArray[np.float64],
    *,
    search_factor: float = 1.5,
    search_depth: float | None = None,
    min_search: float = 0.0,
    trials: int = 64,
    tolerance: float = 0.15,
    tolerance_abs: float = 0.003,
    tolerance_max: float = 0.01,
    min_inliers: int = 8,
    min_coverage: float = 0.25,
    spacing: float | None = None,
    min_density: float = 0.1,
    seed: int = 0,
    kdtree: cKDTree | None = None,
    axes: NDArray[np.float64] | None = None,
) -> RadiusFit:
    """RANSAC + least-squares circle per node in its cross-section plane (steps 1–3).

    ``prior``: radius guess per node (m); the search cylinder has radius
    ``max(search_factor * prior, min_search)`` and half-height ``search_depth`` (default
    half the median edge length). ``tolerance``: inlier band as a fraction of the radius,
    clipped to [``tolerance_abs``, ``tolerance_max``] metres (a large circle through a few
    points of neighbouring twigs must not pass as a stem). ``spacing`` (median point
    spacing, m): with it, a fit also needs ``min_density`` of the points a fully sampled
    arc of its coverage would hold. ``axes``: the planes' unit normals per node if known
    (default :func:`node_axes`).
    """
    n = graph.n_nodes
    if search_factor <= 1:
        raise ParameterError(f"search_factor must be > 1, got {search_factor}")
    el = graph.edge_length
    if search_depth is None:
        search_depth = 0.5 * float(np.median(el[el > 0])) if (el > 0).any() else 0.02
    kd = kdtree if kdtree is not None else PointIndex(xyz)
    rs = np.maximum(search_factor * np.asarray(prior, dtype=float), min_search)
    rs = np.maximum(rs, 1e-4)
    t0, t1, indptr, u, w = _cross_sections(
        graph.position, node_axes(graph) if axes is None else axes, xyz, kd, rs, float(search_depth)
    )
    cx = np.zeros(n)
    cy = np.zeros(n)
    r = np.zeros(n)
    ni = np.zeros(n, dtype=np.int64)
    cov = np.zeros(n)
    mad = np.zeros(n)
    inside = np.zeros(n, dtype=np.int64)
    rmin = np.full(n, 1e-4)
    _fit_kernel(
        np.ascontiguousarray(u),
        np.ascontiguousarray(w),
        indptr,
        rs,
        rmin,
        tolerance,
        tolerance_abs,
        tolerance_max,
        trials,
        min_inliers,
        seed,
        cx,
        cy,
        r,
        ni,
        cov,
        mad,
        inside,
        INSIDE_RADIUS,
    )
    centre = graph.position + cx[:, None] * t0 + cy[:, None] * t1
    ok = (r > 0) & (ni >= min_inliers) & (cov >= min_coverage) & (r < 0.98 * rs)
    if spacing is not None and spacing > 0:
        # a real stem section yields about (arc length x slab height) / spacing² points on
        # its scanned arc; a large circle through a few points of nearby twigs does not
        expected = cov * 2 * np.pi * np.maximum(r, 0) * 2 * search_depth / spacing**2
        ok &= ni >= min_density * expected
    return RadiusFit(centre, r, ni, cov, ok, rs, mad, inside=inside)


@numba.njit(cache=True)
def _cap_down(parent, order, r, slack):
    out = r.copy()
    for k in range(order.size):  # parents first: out[p] is already capped
        v = order[k]
        p = parent[v]
        if p >= 0 and out[v] > slack * out[p]:
            out[v] = slack * out[p]
    return out


def cap_down(
    graph: BranchGraph, radius: NDArray[np.float64], slack: float = 1.1
) -> NDArray[np.float64]:
    """Limit every radius to ``slack`` times its (capped) parent's radius (pipe model: a
    branch is not thicker than the stem carrying it).

    Per edge, not the smallest radius on the whole path to the root: one underestimated
    node (a stem cross-section hidden behind a whorl) would otherwise cap the whole stem
    above it — on the noisy conifer preset that halved the upper stem (radius error 40 %);
    per edge, the stem recovers by ``slack`` per node."""
    return _cap_down(graph.parent, graph.order, np.asarray(radius, dtype=float), float(slack))


def smooth_log_ratio(
    graph: BranchGraph, values: NDArray[np.float64], ok: NDArray[np.bool_], strength: float = 1.0
) -> NDArray[np.float64]:
    """Minimise ``Σ_ok (x_v − values_v)² + strength Σ_edges (x_v − x_parent)²`` exactly.

    Nodes outside ``ok`` are filled from their neighbours. Trees without any ``ok`` node
    get 0 (no correction).
    """
    par = graph.parent
    ch = par >= 0
    lam = np.where(ch, strength, 0.0)
    diag = ok.astype(float) + lam
    np.add.at(diag, par[ch], lam[ch])
    diag += 1e-9
    off = -lam
    rhs = np.where(ok, values, 0.0)
    return solve_tree_system(par, diag, off, rhs, graph.order)


@numba.njit(cache=True)
def _group_medians(group, values, n):  # pragma: no cover - numba
    """Per group ``0..n-1`` the value at position ``count // 2`` of its values sorted
    ascending (NaN for an empty group): the element ``np.lexsort((values, group))``
    puts there, without sorting all the values."""
    cnt = np.zeros(n, dtype=np.int64)
    for i in range(group.size):
        cnt[group[i]] += 1
    start = np.zeros(n + 1, dtype=np.int64)
    for v in range(n):
        start[v + 1] = start[v] + cnt[v]
    fill = start[:-1].copy()
    vals = np.empty(group.size)
    for i in range(group.size):
        g = group[i]
        vals[fill[g]] = values[i]
        fill[g] += 1
    out = np.full(n, np.nan)
    for v in range(n):
        if cnt[v]:
            out[v] = np.sort(vals[start[v] : start[v + 1]])[cnt[v] // 2]
    return out


def fit_radii(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    *,
    recentre: bool = True,
    search_factor: float = 1.5,
    search_depth: float | None = None,
    smoothing: float = 1.0,
    passes: int = 2,
    trials: int = 64,
    tolerance: float = 0.15,
    min_inliers: int = 8,
    min_coverage: float = 0.25,
    allometry_exponent: float = 2.5,
    max_radius: float | None = None,
    slack: float = 1.1,
    shift_smoothing: float = 4.0,
    taper: bool = False,
    min_radius: float = MIN_RADIUS,
    taper_exponent: float = PIPE_EXPONENT,
    seed: int = 0,
    spacing: float | None = None,
    kdtree: cKDTree | None = None,
    trusted: NDArray[np.bool_] | None = None,
    stems: StemTracker | None = None,
) -> tuple[BranchGraph, RadiusFit]:
    """Radii (and optionally re-centred positions) from the points; see the module doc.
    ``trusted``, ``stems``: as :func:`taper_radii`.

    Radii never exceed ``slack`` times the parent's (:func:`cap_down`; pipe model: a
    branch is not thicker than the stem carrying it). With ``recentre`` the shifts to the
    fitted centres are smoothed along the graph first (``shift_smoothing``, the λ of
    :func:`smooth_log_ratio` per coordinate; 0 = each node to its own fit): the skeleton's
    off-centre bias varies slowly along a branch, the fits' noise from node to node, and
    unsmoothed shifts add a wiggle (conifer preset, 240,000 points: TBL 109 → 106 %).
    Two passes by default: the first searches around a prior from the node's own points,
    the second around the smoothed first-pass radii. ``spacing``: the cloud's point spacing
    (:func:`~biomorph.tree.neighbours.estimate_spacing`) if measured already; ``kdtree``: a
    k-d tree of ``xyz`` (a :class:`~biomorph.tree.neighbours.PointIndex`, whose grid the
    cross-sections search, else one is built). Returns the new
    graph (``radius`` set, ``weight`` = subtree length) and the last :class:`RadiusFit`.
    """
    if graph.n_nodes == 0:
        return graph, RadiusFit(
            np.zeros((0, 3)),
            np.zeros(0),
            np.zeros(0, np.int64),
            np.zeros(0),
            np.zeros(0, bool),
            np.zeros(0),
        )
    kd = kdtree if kdtree is not None else PointIndex(xyz)
    if spacing is None and xyz.shape[0] >= 2:
        from biomorph.tree.livny import estimate_spacing

        spacing = estimate_spacing(xyz, kdtree=kd)
    el = graph.edge_length
    med_edge = float(np.median(el[el > 0])) if (el > 0).any() else 0.05
    d, near = skeleton_distance(xyz, graph.parent, graph.position, order=kd.indices)
    n = graph.n_nodes
    # per-node median distance (the upper one of an even count)
    prior = _group_medians(np.asarray(near, dtype=np.int64), np.asarray(d, dtype=np.float64), n)
    weight = graph.subtree_length()
    tree = graph.trees
    md = float(np.nanmedian(prior)) if np.isfinite(prior).any() else med_edge
    allo = allometric_radii(
        graph.parent,
        graph.position,
        weight,
        md,
        tree=tree,
        exponent=allometry_exponent,
        order=graph.order,
    )
    prior = np.where(np.isfinite(prior), prior, allo)
    g = graph
    fit = None
    radius = prior
    for _ in range(max(passes, 1)):
        fit = fit_circles(
            g,
            xyz,
            radius,
            search_factor=search_factor,
            search_depth=search_depth,
            min_search=0.5 * med_edge,
            trials=trials,
            tolerance=tolerance,
            min_inliers=min_inliers,
            min_coverage=min_coverage,
            spacing=spacing,
            seed=seed,
            kdtree=kd,
        )
        ok = fit.ok.copy()
        delta = np.zeros(n)
        delta[ok] = np.log(fit.radius[ok] / allo[ok])
        sm = smooth_log_ratio(g, delta, ok, smoothing)
        # robust: drop fits more than a factor 2 off the smoothed profile, smooth again
        for _ in range(2):
            bad = ok & (np.abs(delta - sm) > np.log(2.0))
            if not bad.any():
                break
            ok &= ~bad
            sm = smooth_log_ratio(g, delta, ok, smoothing)
        # nodes of trees without any fit keep the allometric radii (scaled by distances)
        radius = allo * np.exp(sm)
        if max_radius is not None:
            radius = np.minimum(radius, max_radius)
        radius = cap_down(g, radius, slack)
        if recentre:
            d = fit.centre - g.position
            move = ok & (np.linalg.norm(d, axis=1) < fit.search_radius)
            if shift_smoothing > 0 and move.any():
                # the off-centre bias of the skeleton varies slowly along a branch, the
                # circle fits' noise from node to node: smooth the shifts along the graph
                d = np.stack(
                    [smooth_log_ratio(g, d[:, c], move, shift_smoothing) for c in range(3)], axis=1
                )
            pos = g.position.copy()
            pos[move] += d[move]
            g = g.with_(position=pos)
    if taper and fit is not None:
        radius, fit = taper_radii(
            g,
            fit,
            min_radius=min_radius,
            exponent=taper_exponent,
            slack=slack,
            trusted=trusted,
            stems=stems,
        )
    if recentre and fit is not None and spacing:
        g = centre_thin_nodes(g, xyz, radius, fit.ok, spacing, search_depth, kdtree=kd)
    return g.with_(radius=radius, weight=g.subtree_length()), fit


#: :func:`breast_height_fits` reads the stem's circles within this distance (m) of breast
#: height (1.0–1.6 m: TreeQSM fits its ``DBHcyl`` cylinder to 1.1–1.5 m)
DBH_BAND = 0.3
#: ... searching this many times wider at most, in steps of 1.5, where the stem's own
#: searches held no reliable circle there
DBH_WIDER = (1.5, 2.25, 3.375)


def breast_height_fits(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    fit: RadiusFit,
    *,
    spacing: float | None = None,
    kdtree: cKDTree | None = None,
    seed: int = 0,
    height: float = 1.3,
) -> dict[int, dict]:
    """Each tree's DBH from its stem's circle fits, as a forester measures it, beside the
    taper model's (``DBHqsm``): twice the median radius of the well-covered circles
    (:func:`well_covered`, not envelopes: :data:`STEM_INSIDE`) of the trunk's nodes
    (order 0) within :data:`DBH_BAND` of ``height`` above the tree's lowest node, among
    those the taper model kept as measured (``fit.reliable`` where set: none over
    :data:`KEEP_MAX_RATIO` × the model).

    Where the pipeline's searches closed no circle there at all, the band's nodes are
    fitted again in wider searches (:data:`DBH_WIDER` × the radius they had): a stem seen
    from one scan position is half an arc, the skeleton runs along that face 0.6–0.8 radii
    off the axis, and every circle its searches allowed was smaller than the stem (the aspen preset
    scanned once: no usable fit below 3.5 m, and the taper model's DBH 24.0 cm for 32.6).
    These fits are not fed back into the model: a wider search changes the stem's anchor,
    and on the leafy real clouds the model then moved by 10–40 % (docs/tree.md, session
    30). Returns per tree label ``{"dbh": m or NaN, "fits": count, "wider": bool,
    "band": [lo, hi] m above the tree's lowest node}``;
    trees without radii, depth or a trunk in the band are left out."""
    out: dict[int, dict] = {}
    if graph.depth is None or graph.radius is None or fit.radius.size != graph.n_nodes:
        return out
    labels = graph.trees
    z = graph.position[:, 2]
    depth = np.asarray(graph.depth)

    def measured(f: RadiusFit) -> NDArray[np.bool_]:
        return well_covered(f) & _not_envelope(f)

    seen = measured(fit)
    good = seen.copy()
    if fit.reliable is not None:
        # the circles the taper model kept as measured (step 4: none over KEEP_MAX_RATIO x
        # the model): a lone needle envelope in the band is not the stem's DBH (a quarter
        # of the TreeLS spruce's points: one 55 cm circle on an 11 cm stem gave 109 cm)
        good &= fit.reliable
    for t in np.unique(labels):
        nodes = np.flatnonzero(labels == t)
        h = z[nodes] - z[nodes].min()
        trunk = nodes[(depth[nodes] == 0) & (np.abs(h - height) <= DBH_BAND)]
        if trunk.size == 0:
            continue
        trunk = trunk[np.argsort(z[trunk])]
        band = [height - DBH_BAND, height + DBH_BAND]
        rec = {"dbh": float("nan"), "fits": 0, "wider": False, "band": band}
        if good[trunk].any():
            rec.update(dbh=2 * float(np.median(fit.radius[trunk][good[trunk]])))
            rec.update(fits=int(good[trunk].sum()))
        elif trunk.size >= 2 and not seen[trunk].any():
            # no circle closed in the band's searches (cut by them, not too large for the
            # model): the band's trunk as a chain (its own axes), searched wider
            chain = BranchGraph(graph.position[trunk], np.arange(-1, trunk.size - 1))
            base = graph.radius[trunk]
            for k, wider in enumerate(DBH_WIDER):
                f = fit_circles(
                    chain, xyz, wider * base, spacing=spacing, kdtree=kdtree, seed=seed + 1 + k
                )
                ok = measured(f)
                if ok.any():
                    rec.update(dbh=2 * float(np.median(f.radius[ok])), fits=int(ok.sum()))
                    rec.update(wider=True)
                    break
        out[int(t)] = rec
    return out


def segment_radii(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    fit: RadiusFit,
    spacing: float,
    *,
    min_radius: float = MIN_RADIUS,
    exponent: float = PIPE_EXPONENT,
    slack: float = 1.1,
    kdtree: PointIndex | None = None,
    trusted: NDArray[np.bool_] | None = None,
    stems: StemTracker | None = None,
) -> tuple[NDArray[np.float64], RadiusFit]:
    """The taper model again (:func:`taper_radii`, ``trusted`` and ``stems`` as there), now with the
    cylinders of runs of nodes (:func:`biomorph.tree.run_cylinders.fit_segments`) as
    measurements where no circle fit is reliable, off the stem. Run once on the final
    skeleton (``fit``: its last circle fits; ``graph.radius``: the radii so far, the runs'
    estimate): the skeleton's cleanup decisions are left as the circle fits made them.
    Without three reliable circle fits (no measure of the scan's noise) the runs are not
    used."""
    if graph.radius is None or fit.ok.size != graph.n_nodes or spacing <= 0:
        raise ParameterError("segment_radii needs a skeleton with radii and its circle fits")
    kd = kdtree if kdtree is not None else PointIndex(xyz)
    carried = np.maximum(graph.subtree_length() + graph.edge_length, 1e-6)
    reliable, stem = _reliable_fits(graph, fit, carried)
    noise = _scatter(fit, reliable, stem)
    if noise <= 0:
        return taper_radii(
            graph,
            fit,
            min_radius=min_radius,
            exponent=exponent,
            slack=slack,
            trusted=trusted,
            stems=stems,
        )
    d, near = skeleton_distance(xyz, graph.parent, graph.position, order=kd.indices)
    bid, _ = branch_ids(graph, carried)
    segs = fit_segments(
        graph,
        xyz,
        near,
        d,
        graph.radius,
        bid,
        spacing,
        RELIABLE_COVERAGE,
        need=~reliable & ~stem,
        noise=noise,
    )
    return taper_radii(
        graph,
        fit,
        min_radius=min_radius,
        exponent=exponent,
        slack=slack,
        segments=segs,
        trusted=trusted,
        stems=stems,
    )


#: a node without a circle fit is moved to the centroid of its cross-section's points when
#: its radius is at most this many point spacings: a twig a few points across, whose
#: contracted vertex lies wherever its level piece's points happened to be (rTwig: 10.8 mm
#: from TreeQSM's axis against 3–5 mm where circles fit), and where the centroid's pull
#: towards a one-sided scan (at most 2r/π) stays within a point spacing or so; thicker
#: unfitted sections (an occluded stem) keep their position
CENTROID_MAX_RADIUS = 2.0


def centre_thin_nodes(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    radius: NDArray[np.float64],
    fitted: NDArray[np.bool_],
    spacing: float,
    search_depth: float | None = None,
    *,
    kdtree: cKDTree | None = None,
) -> BranchGraph:
    """Thin nodes without a usable circle fit (``~fitted``, radius at most
    :data:`CENTROID_MAX_RADIUS` point spacings) move to the centroid of the points in their
    cross-section slab (half-height ``search_depth``, default half the median edge; within
    ``max(2 r, 2 spacing)`` of the node in the plane), the slab used by :func:`fit_circles`.
    On the synthetic presets this brings those twig axes 0–3 mm nearer the truth's and the
    twig class's median signed residual from +0.11–0.25 to +0.01–0.13 (docs/tree.md)."""
    n = graph.n_nodes
    target = ~np.asarray(fitted, dtype=bool) & (radius <= CENTROID_MAX_RADIUS * spacing)
    if n == 0 or not target.any() or spacing <= 0:
        return graph
    el = graph.edge_length
    if search_depth is None:
        search_depth = 0.5 * float(np.median(el[el > 0])) if (el > 0).any() else spacing
    sub = np.flatnonzero(target)
    rs = np.maximum(2.0 * radius[sub], 2.0 * spacing)
    t0, t1, indptr, u, w = _cross_sections(
        graph.position[sub], node_axes(graph)[sub], xyz, kdtree or cKDTree(xyz), rs, search_depth
    )
    cnt = np.diff(indptr)
    has = cnt >= 3
    if not has.any():
        return graph
    seg = np.repeat(np.arange(sub.size), cnt)
    mu = np.bincount(seg, weights=u, minlength=sub.size)[has] / cnt[has]
    mw = np.bincount(seg, weights=w, minlength=sub.size)[has] / cnt[has]
    new = graph.position.copy()
    new[sub[has]] += mu[:, None] * t0[has] + mw[:, None] * t1[has]
    return graph.with_(position=new)


#: the twig offset of a tree is measured only on at least this many points (the median of
#: 30 samples has a standard error of about a quarter of their spread)
TWIG_MIN_POINTS = 30
#: ... and is at most this many point spacings either way: a scan cannot place a surface
#: more finely than its spacing, so a larger offset is clutter (needles, leaves), not wood
TWIG_MAX_OFFSET = 0.5
#: the model is looked at this many times, each look on the model thickened by the looks
#: before it (the points within one radius of a surface are a window that widens with the
#: radius, so one look sees only part of what a too-thin twig leaves outside); together
#: they say whether the points are a surface the model can reach, and their sum is the
#: offset (sessions 17–18 summed two: rTwig's twig residual +0.29 → +0.20 → +0.12 after
#: one and two looks, +0.06 after six; the rTwig voxel model +0.144 → +0.106)
TWIG_LOOKS = 6
#: ... which they are where the last look finds less than this share of what the first
#: found: around a surface the looks shrink as the model nears it, around an envelope
#: (needles about a spruce's shoots, the halo of a sparse, noisy scan) the widening window
#: keeps finding more. Over six looks the real clouds and synthetic scans measured (session
#: 19) gave 0.31–0.88 on twig surfaces (rTwig, A3B4, aRchi, graph and voxel, with and without
#: run cylinders; the presets clean and at 8 mm) and 1.00–1.64 around envelopes (TreeLS
#: spruce, AdTree tree1 and tree7). Two looks alone (sessions 17–18) gave 0.72–1.04 against
#: 1.02–1.33 and flipped on the voxel models once runs had measured the thicker twigs: a
#: model far thinner than its twig first reads *more* missing as its window reaches the bark
TWIG_SURFACE_RATIO = 0.95


def twig_offset(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    measured: NDArray[np.bool_],
    spacing: float,
    *,
    slack: float = 1.1,
    candidates: SegmentCandidates | None = None,
    noise: float = 0.0,
) -> tuple[NDArray[np.float64], dict[int, dict]]:
    """The modelled twigs' radii set to what their points say, per tree.

    The taper model extrapolates the thin end of a tree from its thick, measurable cross-
    sections; where no circle fits (a twig a few points across) nothing checks it. The
    points do, in aggregate: around the *modelled twigs* of a tree — nodes not
    ``measured`` (no kept circle fit) whose radius is at most :data:`CENTROID_MAX_RADIUS`
    point spacings, the nodes :func:`centre_thin_nodes` put on their points' centroid —
    the median signed distance of the points to the model's surface (those within one
    radius of it, the reference-free check of :func:`biomorph.tree.metrics.cylinder_fit`)
    is the radius the model is missing (> 0) or has in excess (< 0). It is added to those
    nodes' radii (an offset, not a factor: what separates a scanned twig from its model —
    beam footprint, range noise, a twig between two points — is a few millimetres whatever
    the twig's size; on the rTwig cloud the thinnest twigs miss 2.1 mm, those of 1–1.5 and
    1.5–2 spacings 1.5 and 0.8 mm, where a factor would thicken the thicker ones most).

    The offset is measured on at least :data:`TWIG_MIN_POINTS` points, in
    :data:`TWIG_LOOKS` looks (each on the model thickened by those before; their sum),
    clipped to :data:`TWIG_MAX_OFFSET` point spacings either way, and no node more than
    doubles or halves; a branch then stays no thicker than its parent node (the
    continuation at most ``slack`` × it, as :func:`taper_radii`). With the scan's surface
    scatter ``noise`` (m, the mean absolute residual of its stem circles,
    :func:`surface_scatter`) each look is read against what it would show about an exact
    model (:func:`_noise_median`): points scattered about a thin twig lie farther from its
    axis than its radius, a deficit that is noise, not wood (at 8 mm range noise the
    presets' twigs took +0.9 mm from it). It is applied only where the points behave as a
    surface: the last raw look finds less than :data:`TWIG_SURFACE_RATIO` of what the
    first found, and less by more than two standard errors of the first look's median
    (a tree of a few hundred points around its twigs cannot tell a surface from an envelope
    otherwise). Returns the new radii and, per tree, the applied ``offset`` (m; 0 where not
    applied), the raw ``looks`` (m), the ``noise`` and the first look's noise ``bias`` (m),
    ``surface``, the ``points`` behind the first look and the ``nodes`` concerned; trees
    without enough points are not in it and keep their radii.
    ``candidates``: the points' :func:`~biomorph.tree.metrics.segment_candidates` on this
    skeleton, if searched already. Turned off by ``RadiusOptions.twig_scale = False``
    (``--no-twig-scale``), e.g. when the species' twig radius is known (``--min-radius``,
    rTwig's way).
    """
    from biomorph.tree.metrics import SegmentCandidates, segment_candidates, surface_distance

    radius = np.asarray(graph.radius, dtype=float)
    info: dict[int, dict] = {}
    n = graph.n_nodes
    if n == 0 or spacing <= 0 or xyz.shape[0] == 0:
        return radius, info
    target = ~np.asarray(measured, dtype=bool) & (radius <= CENTROID_MAX_RADIUS * spacing)
    if not target.any():
        return radius, info
    trees = graph.trees
    lim = TWIG_MAX_OFFSET * spacing
    _, cont = branch_ids(graph)
    slack_v = np.where(cont, float(slack), 1.0)
    # the axes do not move between the looks: one candidate search, and only the points
    # with a modelled twig among their candidate edges' ends can count in a look
    cand = candidates if candidates is not None else segment_candidates(graph, xyz)
    ends = np.where(cand.par >= 0, cand.par, cand.node)
    near_twig = (target[cand.node] | target[ends]).any(axis=1)
    cand = SegmentCandidates(
        cand.node[near_twig], cand.par[near_twig], cand.t[near_twig], cand.d[near_twig]
    )
    xyz = xyz[near_twig]

    def look(r: NDArray[np.float64], among) -> dict[int, tuple[NDArray, NDArray]]:
        """Per tree of ``among``: the signed surface distances of the points within one
        radius of its modelled twigs' surfaces, the twigs at radii ``r``, and the radius of
        each point's cylinder."""
        sd, rd, near = surface_distance(graph.with_(radius=r), xyz, candidates=cand)
        sel = (np.abs(sd) <= rd) & target[near]
        tree_of = trees[near]
        out = {}
        for t in among:
            ts = sel & (tree_of == t)
            out[int(t)] = (sd[ts], rd[ts])
        return out

    def read(x: tuple[NDArray, NDArray], debias: bool = False) -> float:
        """A look's reading: the median signed distance, less the noise's (``debias``)."""
        d, rd = x
        m = float(np.median(d)) if d.size else 0.0
        return m - _noise_median(rd, noise) if debias else m

    def apply(offset: dict[int, float]) -> NDArray[np.float64]:
        per_tree = np.zeros(int(trees.max()) + 1)
        per_tree[list(offset)] = list(offset.values())
        nodes = target & np.isin(trees, list(offset))
        out = radius.copy()
        out[nodes] = np.clip(
            radius[nodes] + per_tree[trees[nodes]], 0.5 * radius[nodes], 2 * radius[nodes]
        )
        return _cap_down_slack(graph.parent, graph.order, out, slack_v)

    first = {
        t: x
        for t, x in look(radius, np.unique(trees[target])).items()
        if x[0].size >= TWIG_MIN_POINTS
    }
    if not first:
        return radius, info
    among = list(first)
    # the raw looks, each on the model thickened by the looks before it
    looks = {t: [read(x)] for t, x in first.items()}
    for _ in range(TWIG_LOOKS - 1):
        cum = {t: float(np.clip(sum(m), -lim, lim)) for t, m in looks.items()}
        for t, x in look(apply(cum), among).items():
            looks[t].append(read(x))
    bias = {t: read(x) - read(x, debias=True) for t, x in first.items()}
    surface: dict[int, bool] = {}
    for t, x in first.items():
        m = looks[t]
        # standard error of the first look's median: 1.2533 σ / √n, σ = 1.4826 MAD
        d = x[0]
        se = 1.2533 * 1.4826 * float(np.median(np.abs(d - m[0]))) / np.sqrt(d.size)
        # a surface the model can reach: the last look finds less missing than the
        # first, by a share and by more than two standard errors
        surface[t] = abs(m[-1]) < TWIG_SURFACE_RATIO * abs(m[0]) and abs(m[0]) - abs(m[-1]) > 2 * se
    # the offset, on surfaces: the looks summed (without noise, the raw ones); with the
    # scan's noise, as many looks again, each read against it
    kept = {t: float(np.clip(sum(looks[t]), -lim, lim)) for t in first if surface[t]}
    if noise > 0 and kept:
        kept = {t: float(np.clip(looks[t][0] - bias[t], -lim, lim)) for t in kept}
        for _ in range(TWIG_LOOKS - 1):
            nxt = look(apply(kept), list(kept))
            kept = {t: float(np.clip(o + read(nxt[t], True), -lim, lim)) for t, o in kept.items()}
    for t, x in first.items():
        info[t] = {
            "points": int(x[0].size),
            "offset": kept.get(t, 0.0),
            "looks": looks[t],
            "noise": noise,
            "bias": bias[t],
            "surface": bool(surface[t]),
            "nodes": int((target & (trees == t)).sum()),
        }
    return (apply(kept) if kept else radius), info


def twig_surface(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    measured: NDArray[np.bool_],
    spacing: float,
    *,
    candidates: SegmentCandidates | None = None,
) -> tuple[bool, dict[int, dict]]:
    """Do the points about the modelled twigs behave as a surface the model can reach (a
    scanned twig's bark) rather than an envelope it never reaches (needles, leaves)? The
    raw looks of :func:`twig_offset` and its test, per tree; pooled over the trees by
    their points (the majority decides). Returns the answer and :func:`twig_offset`'s
    record; False where no tree has :data:`TWIG_MIN_POINTS` points about its twigs."""
    _, info = twig_offset(graph, xyz, measured, spacing, candidates=candidates)
    pts = sum(v["points"] for v in info.values())
    on = sum(v["points"] for v in info.values() if v["surface"])
    return bool(pts and 2 * on > pts), info


#: a scan's scatter about a surface per direction, from the mean absolute residual of its
#: stem circles (which see only the radial part): range noise of spread σ along rays
#: meeting a cylinder at uniform incidence has an RMS of σ/√2 both radially and
#: tangentially, and a mean absolute radial residual of about 0.8 × that RMS
NOISE_PER_MAD = 1.25


def surface_scatter(graph: BranchGraph, fit: RadiusFit) -> float:
    """The scan's surface scatter (m): the median mean-absolute residual of the reliable
    circle fits on the stems' lower halves (of all reliable fits with fewer than three
    there); 0 without three reliable fits."""
    if fit.mad is None or fit.ok.size != graph.n_nodes:
        return 0.0
    carried = np.maximum(graph.subtree_length() + graph.edge_length, 1e-6)
    return _scatter(fit, *_reliable_fits(graph, fit, carried))


def _scatter(fit: RadiusFit, reliable: NDArray[np.bool_], stem: NDArray[np.bool_]) -> float:
    """:func:`surface_scatter` from the reliable fits and stem mask already found."""
    if fit.mad is None:
        return 0.0
    pool = reliable & stem if (reliable & stem).sum() >= 3 else reliable
    return float(np.median(fit.mad[pool])) if pool.sum() >= 3 else 0.0


#: :func:`_noise_median` draws this many simulated points at most (a median of 50,000
#: draws is within 0.5 % of its spread of the exact one; a 10⁶-point cloud's look holds
#: 160,000 points, 16 draws each took a second over the twig offset's looks)
NOISE_DRAWS = 50_000


@functools.lru_cache(maxsize=1)
def _standard_normals() -> NDArray[np.float64]:
    """:data:`NOISE_DRAWS` pairs of standard normal draws of seed 0 (read-only): each look
    of :func:`twig_offset` reads its noise from them instead of drawing them again."""
    z = np.random.default_rng(0).standard_normal((NOISE_DRAWS, 2))
    z.flags.writeable = False
    return z


def _noise_median(rd: NDArray[np.float64], noise: float, reps: int = 16) -> float:
    """The median signed surface distance a look would read at cylinders of radii ``rd``
    if the model were exact and the scan scattered its points by ``noise`` (mean absolute
    residual, :data:`NOISE_PER_MAD`): points about a thin cylinder lie farther from its
    axis than its radius on average (a tangential error lengthens the distance whichever
    way it goes), and the look's window (within one radius of the surface) cuts the
    spread asymmetrically. A fixed stream of Gaussian errors (seeded: the same cloud gives
    the same offset), ``reps`` per radius, at most :data:`NOISE_DRAWS` in all (then at
    radii drawn from ``rd``)."""
    if rd.size == 0 or noise <= 0:
        return 0.0
    if rd.size * reps <= NOISE_DRAWS:
        r = np.repeat(rd, reps)
        # the stream's first draws: the same values as drawing them afresh
        e = NOISE_PER_MAD * noise * _standard_normals()[: r.size]
    else:
        rng = np.random.default_rng(0)
        r = rd[rng.integers(0, rd.size, NOISE_DRAWS)]
        e = rng.normal(0.0, NOISE_PER_MAD * noise, (r.size, 2))
    sd = np.hypot(r + e[:, 0], e[:, 1]) - r
    keep = np.abs(sd) <= r
    return float(np.median(sd[keep])) if keep.any() else 0.0


# --------------------------------------------------------------- taper model (issue 13)


def _cap_down_slack(parent, order, r, slack):
    """:func:`biomorph.core.treeops.cap_down` with a per-node ``slack``."""
    return treeops.cap_down(parent, r, slack, order)


def _shortest_half(v: NDArray) -> NDArray[np.bool_]:
    """The values in the shortest interval holding half of ``v`` (Rousseeuw's shorth)."""
    o = np.sort(v)
    h = max(o.size // 2, 1)
    i = int(np.argmin(o[h - 1 :] - o[: o.size - h + 1]))
    return (v >= o[i]) & (v <= o[i + h - 1])


def _robust_line(
    x: NDArray, y: NDArray, slope: float | None, *, start: NDArray[np.bool_] | None = None
) -> tuple[float, float, float]:
    """``y ≈ a + b x`` by least squares with two rounds of 3-MAD trimming; returns
    ``(a, b, scatter)`` (scatter = 1.4826 MAD of the kept residuals). ``slope`` fixes b;
    ``start``: the points the first round is fitted on (default all)."""
    keep = np.ones(x.size, dtype=bool) if start is None else start.copy()
    a, b = float(np.median(y)), slope or 0.0
    for _ in range(3):
        if slope is None:
            b, a = np.polyfit(x[keep], y[keep], 1)
        else:
            a = float(np.median(y[keep] - slope * x[keep]))
        res = y - (a + b * x)
        mad = 1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep]))))
        new = np.abs(res) <= 3 * max(mad, 1e-3)
        if new.sum() < 3 or (new == keep).all():
            break
        keep = new
    return float(a), float(b), max(mad, 1e-3)


#: a tree whose own stem fits put it more than this factor above the pooled model of all
#: the trees' stems (the pipe rule's level for the wood it carries) takes the pooled model:
#: its "stem" is not one. On the TreeLS pine plot the 16 measured pines lie within
#: 0.49-1.39x of the pool; at a quarter of the TreeLS spruce's points (`bench/tree.py
#: --only density`, session 17) a needle clump of its ground-reaching crown passed the
#: breast-height stem test as a 1.8 m tree, and its circles (needle envelopes, 34 cm) put
#: it 27x above the pool: 937 L, twice the spruce
STEM_POOL_RATIO = 3.0


#: under this share of the stem path's nodes on the tracked stem (within two of its radii
#: of its axis) the path runs mostly off the stem, and its fits are mostly not the stem's:
#: the full real clouds' paths hold 0.68-1.0 of their nodes on it, a quarter of the TreeLS
#: spruce's 0.32-0.60 (its path circles through the whorls)
STEM_PATH_ON_TRACK = 0.5


def _tree_anchor(cum, y, rm, sm_, pooled, shift: float, track=None) -> tuple[float, float, str]:
    """One tree's taper-model level ``a``, its scatter and where it came from
    (:func:`taper_radii`, step 3): its stem's reliable fits (``sm_``), unless they lie over
    :data:`STEM_POOL_RATIO` above the ``pooled`` line of all trees' stems (shifted by
    ``shift`` for the wood this tree carries); without three stem fits the pooled line,
    else the tree's own reliable fits (``rm``), else 1 cm at the root.

    The stem followed through the points section by section (``track()``: its nodes and
    model ordinates, :func:`biomorph.tree.stem.stem_tracks`) anchors the model instead
    where the stem path's fits put it above the band in which the tracked stem's own
    model keeps a fit as measured (step 4: 3 of its scatters, at most
    :data:`KEEP_MAX_RATIO`): those fits are needle envelopes or junctions, however
    consistently (a sparse spruce's stem path through its whorls), or where they scatter
    wider than :data:`KEEP_MAX_RATIO` (the factor that tells an artefact from a
    measurement: two populations, the trimmed median between them). Without a track
    the trimming then starts from the densest half of the fits. Where the levels agree but
    under :data:`STEM_PATH_ON_TRACK` of the stem path's nodes lie on the tracked stem, the
    scatter (the band of :func:`taper_radii`, step 4) is the lesser of the two. Before
    either test, the stem path's fits at the nodes the track covers that lie more than its
    band above the track's radius there are left out as envelopes (the source then reads
    ``"stem (fits on the track)"``)."""
    if sm_.sum() >= 3:  # anchored on the stem: its sections are the best seen
        own = sm_  # the stem fits the level is read from
        a, _, sc = _robust_line(cum[own], y[own], 1.0)
        src = "stem"
        wide = np.log(KEEP_MAX_RATIO)
        got = track() if track is not None else None
        if got is not None:
            nodes, yt, share = got
            at, _, st = _robust_line(cum[nodes], yt, 1.0)
            band = min(3 * st, wide)
            if st <= wide:
                # the stem path's fits where the track measured the stem: one above the
                # track's band there is an envelope (needles round the stem), not a section
                over = np.zeros(sm_.size, dtype=bool)
                over[nodes] = y[nodes] - yt > band
                if (own & over).any() and (own & ~over).sum() >= 3:
                    own = own & ~over
                    a, _, sc = _robust_line(cum[own], y[own], 1.0)
                    src = "stem (fits on the track)"
                if a - at > band or sc > wide:
                    a, sc, src = at, st, "stem (tracked)"
                elif share < STEM_PATH_ON_TRACK:
                    # the level agrees, but the stem path runs mostly off the stem (through
                    # a sparse spruce's whorls): its fits' scatter is the envelopes', not
                    # the stem's, and the band of fits kept above the model takes the track's
                    sc = min(sc, st)
        if src != "stem (tracked)" and sc > wide:
            a, _, sc = _robust_line(cum[own], y[own], 1.0, start=_shortest_half(y[own] - cum[own]))
        if pooled is None or a <= pooled[0] + shift + np.log(STEM_POOL_RATIO):
            return a, sc, src
        return pooled[0] + shift, pooled[2], "all trees (own stem fits too thick)"
    if pooled is not None:  # a fragment without a measured stem: the plot's stems
        return pooled[0] + shift, pooled[2], "all trees"
    if rm.sum() >= 3:
        a, _, sc = _robust_line(cum[rm], y[rm], 1.0)
        return a, sc, "tree"
    return float(np.log(0.01)), 1.0, "none"  # no fit at all: 1 cm at the root


def _lazy_tracks(stems, graph, fit, stem, reliable, floor: float):
    """Per tree label its tracked stem as the taper model's anchor reads it (nodes, model
    ordinates ``log(r - floor)``, the share of the stem path on it), every tree tracked by
    ``stems`` once, on first use."""

    @functools.cache
    def tracked() -> dict:
        if stems is None:
            return {}
        return {
            int(k): (nodes, np.log(np.maximum(rt - floor, 0.5 * rt)), share)
            for k, (nodes, rt, share) in stems(graph, fit, stem, reliable).items()
        }

    return lambda t: tracked().get(t)


def taper_radii(
    graph: BranchGraph,
    fit: RadiusFit,
    *,
    min_radius: float = MIN_RADIUS,
    exponent: float = PIPE_EXPONENT,
    decay: float = 0.1,
    support: str = "length",
    slack: float = 1.1,
    within: bool = True,
    segments: SegmentFit | None = None,
    trusted: NDArray[np.bool_] | None = None,
    stems: StemTracker | None = None,
) -> tuple[NDArray[np.float64], RadiusFit]:
    """Final radii: reliable circle fits where the scan measured the cross-section, a
    taper (pipe) model fitted on them elsewhere.

    ``stems``: called as ``stems(graph, fit, stem, reliable)``, per tree label the stem
    followed through the points (:func:`biomorph.tree.stem.stem_tracks`: stem nodes, the
    track's radii there, the share of the stem path on it), which anchors the model of a
    tree whose stem path's own fits are envelopes, and narrows its band where the path
    runs mostly off the stem (step 3, :func:`_tree_anchor`).

    ``trusted``: nodes whose reliable fits are their radii whatever the model says, the
    nodes between them filled from the nearest such fit along the tree (limbs turned round,
    :mod:`biomorph.tree.limbs`: their fits were checked consistent over three diameters,
    while the model under them still lacks the wood the skeleton hangs elsewhere).

    1. **Fit quality**: a fit is *reliable* when usable (``fit.ok``), covering at least
       :data:`RELIABLE_COVERAGE` of the circumference and scattering by at most
       :data:`RELIABLE_MAD` of its radius.
    2. **Branches**: each fork continues into the child carrying the most length
       (:func:`branch_ids`); the other children start branches of their own.
    3. **Taper model** per tree, in log space of the supported length ``L`` (the length of
       wood a node carries, its subtree plus its own edge), as rTwig / SimpleForest /
       TreeQSM model radius on growth length, with two slopes:

       * *at a fork* a side branch starts at ``r_parent (L_child / L_parent)^(1/e)``, the
         pipe rule with ``e = exponent`` (:data:`PIPE_EXPONENT` = 2, da Vinci's
         area-preserving rule; reported as ``b``);
       * *along a branch* the radius falls as ``L^b_w``. ``b_w`` is fitted on the reliable
         fits of all branches and orders with one free level per branch (the variation of
         radius *within* each branch; between branches the levels differ, which a single
         line through all fits confounds — free slopes 0.06–0.54 on the synthetic scans,
         ``b_free``), robustly (3-MAD trimming) and clipped to
         :data:`WITHIN_SLOPE_BOUNDS`; with fewer than three branches of three fits (or
         ``within=False``) ``b_w = 1/e``. A branch with reliable fits of its own spanning
         a factor 2 in ``L`` uses its own slope, shrunk towards ``b_w``
         (:data:`BRANCH_PRIOR_FITS`). The synthetic presets' branches (linear taper to a
         4 mm tip) give ``b_w`` 0.5–1, the real clouds 0.33–0.39: both are what their own
         cross-sections say, where a fixed 1/2 made the outer halves of the presets'
         branches 1.2–1.7× too thick and the real ones thinner than measured.

       The scale is fitted robustly on the reliable fits of the lower half of the stem (the
       best-seen sections of every scan; on a needled spruce, fits on branches are needle
       envelopes and anchoring on all fits made the stem 0.9 m thick). A tree with fewer
       than three stem fits (an understorey fragment of a plot, a branch the voxel
       skeleton left apart) takes the model of all trees' stems, its level set by the pipe
       rule across trees — each tree's base scaled by ``(its whole length)^b`` (its own
       fits — stumps, ground bumps — gave a 1.4 m fragment 1.7 m³; the stems' base level
       unscaled gave four 0.7–1.1 m branch pieces of a noisy conifer the stem's 18 cm),
       then its own reliable fits, then 1 cm at L = 1 m. So does a tree whose own stem
       fits lie more than :data:`STEM_POOL_RATIO` above that pooled level (a needle clump
       taken for a stem, :func:`_tree_anchor`).
    4. **Blend**: reliable fits up to 3 model scatters *above* the model, and every
       reliable fit below it, are kept (one-sided: the artefacts of a circle fit — needle
       envelopes, neighbouring twigs in the slab, junctions — inflate it; a well-covered,
       tight circle thinner than the model is the scan's measurement, e.g. where the
       skeleton's stem path runs through a side branch: the conifer preset's stem model
       on 1.2 m of a 4 cm branch gave its > 20 cm class 180 %); their
       log-ratio to the model is spread along the graph (:func:`smooth_log_ratio` with a
       pull ``decay`` over about ``1/sqrt(decay)`` ≈ 3 nodes). The pull is not towards the
       model but towards the ratio of the nearest measured cross-section *upstream* (the
       pipe model flows from the base to the tips: a limb measured 30 % thinner than the
       stem's model carries that to its twigs, where no circle can be fitted); nodes with
       no measured ancestor take the model. A fit above that limit is still kept as its
       node's radius where it belongs to a *run* (:data:`RUN_DIAMETERS`: consistent fits
       along three of their diameters, off the stem's lower half, outside every other
       branch's cylinder, at most :data:`KEEP_MAX_RATIO` × the nearest kept fit at or
       above its fork): there the scan measured the wood and the model, which follows the
       skeleton's routing, is wrong; its ratio is not passed on downstream.
    5. **Tips and the pipe rule**: the model describes ``r − min_radius``: the radius tends
       to ``min_radius`` at the tips (rTwig's twig radius; :data:`MIN_RADIUS` by default)
       instead of to zero, and reliable fits are kept as measured. A branch leaving a fork
       is never thicker than its parent node (the continuation at most ``slack`` × it, as
       :func:`cap_down`). ``support="tips"`` models the radius on the number of tips
       carried instead (Shinozaki's pipe model, slope 1/2 at forks and along branches).

    Returns the radii and ``fit`` with ``reliable`` and ``model`` (per tree ``a``, ``b``,
    ``b_within``, ``branch_slopes``, ``scatter``, ``fits``) filled in.
    """
    n = graph.n_nodes
    carried = np.maximum(graph.subtree_length() + graph.edge_length, 1e-6)
    reliable, stem = _reliable_fits(graph, fit, carried)
    if support == "tips":
        x = np.log(graph.subtree_sum((graph.n_children == 0).astype(float)))
        exponent = 2.0
        within = False
    else:
        x = np.log(carried)
    floor, r_fit = float(min_radius), np.maximum(fit.radius, 1e-12)
    # the model describes r - floor; a fit barely above the floor keeps half its radius
    y = np.log(np.maximum(r_fit - floor, 0.5 * r_fit))
    bid, cont = branch_ids(graph, carried)
    par = graph.parent
    trees = graph.trees
    uniq = np.unique(trees)
    b_fork = 1.0 / exponent
    ch = np.flatnonzero(par >= 0)
    info: dict = {}
    tree_bw = _tree_slopes(x, y, bid, trees, reliable, b_fork, within)
    bw_node = np.array([tree_bw[int(t)][0] for t in uniq])[np.searchsorted(uniq, trees)]
    x_top = treeops.per_label(trees, x)  # log of each tree's whole length, per node
    # the stem is anchored on its own fits (lower half) and tapered once chosen: runs
    # there are left to that
    run = _fit_runs(graph, r_fit, reliable) & ~stem
    track_of = _lazy_tracks(stems, graph, fit, stem, reliable, floor)

    def scaled(own: dict[int, float]) -> tuple[NDArray, NDArray, NDArray, dict]:
        """The model with the given per-branch slopes, its scale fitted per tree, and the
        reliable fits it keeps."""
        b_edge = bw_node.copy()
        for b, sb in own.items():
            b_edge[bid == b] = sb
        step = np.zeros(n)
        step[ch] = np.where(cont[ch], b_edge[ch], b_fork) * (x[ch] - x[par[ch]])
        cum = treeops.accumulate_down(par, step, graph.order)  # up to the tree's scale
        model = np.zeros(n)
        keep = np.zeros(n, dtype=bool)
        pooled = None
        pool = reliable & stem if (reliable & stem).sum() >= 3 else reliable
        if pool.sum() >= 3:
            # across trees the pipe rule scales each tree's base with the wood it carries:
            # the pooled level is that of a tree carrying 1 m, shifted per tree by
            # b_fork x log(its total length)
            pooled = _robust_line(cum[pool] + b_fork * x_top[pool], y[pool], 1.0)
        scale: dict = {}
        for t in uniq:
            m = trees == t
            rm = m & reliable
            sm_ = rm & stem
            a, sc, src = _tree_anchor(
                cum,
                y,
                rm,
                sm_,
                pooled,
                b_fork * float(x_top[m][0]),
                functools.partial(track_of, int(t)),
            )
            model[m] = a + cum[m]
            # one-sided: a reliable fit thinner than the model is kept (artefacts — needle
            # envelopes, neighbouring twigs in the slab, junctions — inflate circles)
            keep[rm] = y[rm] - model[rm] <= min(3 * sc, np.log(KEEP_MAX_RATIO))
            tr = track_of(int(t)) if src == "stem (tracked)" else None
            scale[int(t)] = (a, sc, src, int(sm_.sum()) if tr is None else tr[0].size)
        return model, keep, cum, scale

    # first the tree slopes alone, to tell which fits the model keeps; then each branch's own
    # slope from its kept fits (a needle-clump branch must not set its own taper)
    model, keep, _, scale = scaled({})
    own = _branch_slopes(x, y, bid, keep, bw_node) if within else {}
    if own:
        model, keep, _, scale = scaled(own)
    for t in uniq:
        m = trees == t
        rm = m & reliable
        a, sc, src, nstem = scale[int(t)]
        bw, raw, nb = tree_bw[int(t)]
        info[int(t)] = {
            "a": a,
            "b": b_fork,
            "b_within": bw,
            "b_within_raw": raw,
            "branches_fitted": nb,
            "branch_slopes": int(np.isin(np.unique(bid[m]), list(own)).sum()),
            "scatter": sc,
            "fits": int(rm.sum()),
            "stem_fits": nstem,
            "kept": int(keep[rm].sum()),
            "anchor": src,
            "b_free": _free_slope(x[rm], y[rm]),
        }
    seg_keep = np.zeros(n, dtype=bool)
    if segments is not None:
        # a run's cylinder where no circle was kept: the same one-sided test as a fit
        sc_node = np.array([scale[int(t)][1] for t in uniq])[np.searchsorted(uniq, trees)]
        rs = np.maximum(segments.radius, 1e-12)
        ys = np.log(np.maximum(rs - floor, 0.5 * rs))
        seg_keep = segments.ok & ~reliable & ~stem
        seg_keep &= ys - model <= np.minimum(3 * sc_node, np.log(KEEP_MAX_RATIO))
        if segments.bound is not None:  # too thin for the scan's noise: an upper bound
            seg_keep &= ~segments.bound | (ys <= model)
        y = np.where(seg_keep, ys, y)
        for t in uniq:
            info[int(t)]["segments"] = int(seg_keep[trees == t].sum())
    measured = keep | seg_keep
    delta = np.where(measured, y - model, 0.0)
    near = _smooth_with_decay(graph, delta, measured, decay)
    anc = _kept_ancestor(graph.parent, graph.order, measured)
    upstream = np.where(anc >= 0, near[np.maximum(anc, 0)], 0.0)
    sm = _smooth_with_decay(graph, delta, measured, decay, prior=upstream)
    radius = floor + np.exp(model + sm)
    # a run's fits are its own radii (measured), without passing their ratio to the
    # model on: the model under a run is wrong where the run is, not downstream of it
    run = _plausible_runs(graph, run & ~measured, r_fit, radius, bid, cont, anc)
    radius[run] = r_fit[run]
    keep |= run
    if trusted is not None and trusted.any():
        keep |= _own_fits(graph, radius, r_fit, reliable, trusted)
    slack_v = np.where(cont, float(slack), 1.0)
    radius = _cap_down_slack(par, graph.order, radius, slack_v)
    return radius, dataclasses.replace(
        fit,
        reliable=reliable & keep,
        model=info,
        segment=seg_keep,
        segment_centre=_segment_centres(segments, seg_keep),
    )


def _segment_centres(segments: SegmentFit | None, kept: NDArray[np.bool_]) -> NDArray | None:
    """Where a run measured the radius (``kept``), its axis is the branch's: the feet of
    those nodes on it (NaN elsewhere; a run that only bounds the radius is no measurement
    of the axis either)."""
    if segments is None or segments.centre is None:
        return None
    moved = kept & ~segments.bound if segments.bound is not None else kept
    return np.where(moved[:, None], segments.centre, np.nan)


@numba.njit(cache=True)
def _branch_kernel(parent, order, heavy):
    n = parent.size
    bid = np.full(n, -1, dtype=np.int64)
    nb = 0
    for k in range(order.size):  # parents first
        v = order[k]
        p = parent[v]
        if p >= 0 and heavy[p] == v:
            bid[v] = bid[p]
        else:
            bid[v] = nb
            nb += 1
    return bid


def branch_ids(
    graph: BranchGraph, carried: NDArray | None = None
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Branch label per node and the mask of nodes continuing their parent's branch: at
    every fork the child carrying the most length (``carried``, default the supported
    length) continues, the others start branches of their own (as the order rule
    ``supported`` and TreeQSM's branch segmentation)."""
    n = graph.n_nodes
    par = graph.parent
    if carried is None:
        carried = graph.subtree_length() + graph.edge_length
    ch = np.flatnonzero(par >= 0)
    heavy = np.full(n, -1, dtype=np.int64)
    if ch.size:
        oc = ch[np.lexsort((carried[ch], par[ch]))]  # by parent, heaviest last
        heavy[par[oc]] = oc
    bid = _branch_kernel(
        np.asarray(par, dtype=np.int64), np.asarray(graph.order, dtype=np.int64), heavy
    )
    cont = np.zeros(n, dtype=bool)
    cont[ch] = heavy[par[ch]] == ch
    return bid, cont


def _within_slope(
    x: NDArray, y: NDArray, group: NDArray, min_fits: int = 3, min_groups: int = 3
) -> tuple[float | None, int]:
    """Common slope of ``y`` on ``x`` with one free level per group (fixed effects), by least
    squares on the group-centred values with two rounds of 3-MAD trimming. Groups with
    fewer than ``min_fits`` points do not count; None with fewer than ``min_groups``
    groups or less than a factor e of spread in ``x``. Returns ``(slope, groups used)``."""
    keep = np.ones(x.size, dtype=bool)
    b = None
    ng = 0
    for _ in range(3):
        _, inv, cnt = np.unique(group[keep], return_inverse=True, return_counts=True)
        use = cnt[inv] >= min_fits
        ng = int((cnt >= min_fits).sum())
        if ng < min_groups:
            return None, ng
        gi = np.unique(inv[use], return_inverse=True)[1]
        xs, ys = x[keep][use], y[keep][use]
        w = np.bincount(gi)
        dx = xs - (np.bincount(gi, xs) / w)[gi]
        dy = ys - (np.bincount(gi, ys) / w)[gi]
        sxx = float(dx @ dx)
        if np.ptp(dx) < 1.0 or sxx <= 0:
            return None, ng
        b = float(dx @ dy) / sxx
        res = dy - b * dx
        mad = 1.4826 * float(np.median(np.abs(res)))
        idx = np.flatnonzero(keep)[use]
        new = keep.copy()
        new[idx[np.abs(res) > 3 * max(mad, 1e-3)]] = False
        if (new == keep).all():
            break
        keep = new
    return b, ng


def _branch_slopes(
    x: NDArray, y: NDArray, bid: NDArray, reliable: NDArray, prior: NDArray
) -> dict[int, float]:
    """A branch's own taper slope where it holds at least three reliable fits spanning a
    factor 2 in ``x``: its least-squares slope, shrunk towards the tree's ``prior`` as if
    that were :data:`BRANCH_PRIOR_FITS` more fits, clipped to :data:`WITHIN_SLOPE_BOUNDS`."""
    out: dict[int, float] = {}
    ids = bid[reliable]
    if ids.size == 0:
        return out
    order = np.argsort(ids, kind="stable")
    idx = np.flatnonzero(reliable)[order]
    ids = ids[order]
    cuts = np.flatnonzero(np.diff(ids)) + 1
    for grp in np.split(idx, cuts):
        if grp.size < 3 or np.ptp(x[grp]) < np.log(2.0):
            continue
        own = float(np.polyfit(x[grp], y[grp], 1)[0])
        pri = float(prior[grp[0]])
        k = grp.size
        out[int(bid[grp[0]])] = float(
            np.clip(
                (k * own + BRANCH_PRIOR_FITS * pri) / (k + BRANCH_PRIOR_FITS), *WITHIN_SLOPE_BOUNDS
            )
        )
    return out


def _tree_slopes(
    x: NDArray,
    y: NDArray,
    bid: NDArray,
    trees: NDArray,
    reliable: NDArray,
    b_fork: float,
    within: bool,
) -> dict[int, tuple[float, float | None, int]]:
    """Per tree ``(b_w, raw fitted slope or None, branches used)``: the within-branch slope
    (:func:`_within_slope` clipped to :data:`WITHIN_SLOPE_BOUNDS`), else ``b_fork``."""
    out: dict[int, tuple[float, float | None, int]] = {}
    for t in np.unique(trees):
        rm = (trees == t) & reliable
        bw, raw, nb = b_fork, None, 0
        if within:
            raw, nb = _within_slope(x[rm], y[rm], bid[rm])
            if raw is not None:
                bw = float(np.clip(raw, *WITHIN_SLOPE_BOUNDS))
        out[int(t)] = (bw, raw, nb)
    return out


def _plausible_runs(
    graph: BranchGraph,
    run: NDArray[np.bool_],
    r_fit: NDArray,
    radius: NDArray,
    bid: NDArray,
    cont: NDArray,
    anc: NDArray,
) -> NDArray[np.bool_]:
    """The nodes of ``run`` whose fits are kept as their radii (:func:`taper_radii`, step
    4): at most :data:`KEEP_MAX_RATIO` × the wood their branch leaves, as measured there
    (the nearest kept fit ``anc`` at or above the fork; the skeleton may have hung the
    branch from a twig) -- a side branch thicker than that is a needle clump or a
    neighbour's wood in the slab -- and not inside another branch's cylinder: a branch's
    first nodes running inside the stem fit the stem's circle there (consistent, tight,
    thick), the same wood twice."""
    run = run.copy()
    if not run.any():
        return run
    first = np.flatnonzero(~cont)  # each branch's first node (``branch_ids``)
    fork = np.full(int(bid.max()) + 1, -1, dtype=np.int64)
    fork[bid[first]] = graph.parent[first]
    fp = fork[bid]
    ka = np.where(fp >= 0, anc[np.maximum(fp, 0)], -1)
    bound = np.where(ka >= 0, r_fit[np.maximum(ka, 0)], radius[np.maximum(fp, 0)])
    run &= (fp >= 0) & (r_fit <= KEEP_MAX_RATIO * bound)
    other = np.flatnonzero(~run)
    if not run.any() or other.size == 0:
        return run
    # each other node's cylinder (its radius around it) against the run nodes: one query
    cand = np.flatnonzero(run)
    hits = cKDTree(graph.position[cand]).query_ball_point(graph.position[other], radius[other])
    lens = np.fromiter((len(h) for h in hits), dtype=np.int64, count=other.size)
    if lens.sum():
        i = cand[np.concatenate([h for h in hits if h]).astype(np.int64)]
        j = np.repeat(other, lens)
        run[i[bid[j] != bid[i]]] = False
    return run


def _fit_runs(graph: BranchGraph, r_fit: NDArray, reliable: NDArray) -> NDArray[np.bool_]:
    """Reliable fits in runs (:data:`RUN_DIAMETERS`): linked to their parent where both
    are reliable and within :data:`RUN_STEP` of each other; a run's length is the sum of
    its links' edges, compared with its median fitted diameter."""
    from scipy.ndimage import median
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    par = graph.parent
    n = graph.n_nodes
    if n == 0 or not reliable.any():
        return np.zeros(n, dtype=bool)
    pp = np.maximum(par, 0)
    link = (
        (par >= 0)
        & reliable
        & reliable[pp]
        & (np.abs(np.log(r_fit / r_fit[pp])) <= np.log(RUN_STEP))
    )
    i = np.flatnonzero(link)
    _, lab = connected_components(coo_matrix((np.ones(i.size), (i, par[i])), shape=(n, n)))
    k = int(lab.max()) + 1
    length = np.bincount(lab, weights=np.where(link, graph.edge_length, 0.0), minlength=k)
    rmed = np.asarray(median(r_fit, lab, np.arange(k)), dtype=float)
    return reliable & (length[lab] >= RUN_DIAMETERS * 2 * rmed[lab])


def well_covered(fit: RadiusFit) -> NDArray[np.bool_]:
    """Usable circle fits covering at least :data:`RELIABLE_COVERAGE` of the circumference
    and scattering by at most :data:`RELIABLE_MAD` of their radius (the quality test of
    :func:`taper_radii`, step 1, before its stem-envelope test)."""
    mad = fit.mad if fit.mad is not None else np.zeros(fit.radius.size)
    return (
        fit.ok
        & (fit.coverage >= RELIABLE_COVERAGE)
        & (mad <= RELIABLE_MAD * np.maximum(fit.radius, 1e-12))
    )


def _reliable_fits(
    graph: BranchGraph, fit: RadiusFit, carried: NDArray
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """The reliable circle fits (:func:`taper_radii`, step 1) and the stem mask
    (:func:`_stem_mask`)."""
    stem = _stem_mask(graph, carried)
    # a stem circle with points inside it is an envelope
    return well_covered(fit) & (~stem | _not_envelope(fit)), stem


def _not_envelope(fit: RadiusFit) -> NDArray[np.bool_]:
    """Circles with at most :data:`STEM_INSIDE` of their inliers' count of points well
    inside them (a scanner sees a stem's surface, never its inside); all true without
    that count."""
    if fit.inside is None:
        return np.ones(fit.radius.size, dtype=bool)
    return fit.inside <= STEM_INSIDE * fit.inliers


def _stem_mask(graph: BranchGraph, carried: NDArray) -> NDArray[np.bool_]:
    """Nodes on the lower half (by height above the base) of each tree's stem, the path
    from the root always into the child carrying the most length."""
    indptr, idx = graph.children_csr
    stem = np.zeros(graph.n_nodes, dtype=bool)
    pos = graph.position
    for root in graph.roots:
        path = [int(root)]
        v = int(root)
        while indptr[v + 1] > indptr[v]:
            kids = idx[indptr[v] : indptr[v + 1]]
            v = int(kids[np.argmax(carried[kids])])
            path.append(v)
        p = np.asarray(path)
        z = pos[p, 2]
        stem[p[z <= z[0] + 0.5 * (z.max() - z[0])]] = True
    return stem


def _smooth_with_decay(
    graph: BranchGraph,
    values: NDArray,
    ok: NDArray,
    decay: float,
    prior: NDArray | None = None,
) -> NDArray:
    """Minimise ``Σ_ok (x − values)² + Σ_edges (x_v − x_p)² + decay Σ (x − prior)²``
    exactly (prior 0 by default)."""
    par = graph.parent
    ch = par >= 0
    lam = np.where(ch, 1.0, 0.0)
    diag = ok.astype(float) + lam + decay
    np.add.at(diag, par[ch], lam[ch])
    rhs = np.where(ok, values, 0.0)
    if prior is not None:
        rhs = rhs + decay * prior
    return solve_tree_system(par, diag, -lam, rhs, graph.order)


@numba.njit(cache=True)
def _kept_ancestor_kernel(parent, order, keep):
    out = np.full(parent.size, -1, dtype=np.int64)
    for k in range(order.size):  # parents first
        v = order[k]
        if keep[v]:
            out[v] = v
        elif parent[v] >= 0:
            out[v] = out[parent[v]]
    return out


def _own_fits(
    graph: BranchGraph, radius: NDArray, r_fit: NDArray, reliable: NDArray, trusted: NDArray
) -> NDArray[np.bool_]:
    """``radius`` of the ``trusted`` nodes set to their reliable fits, the others among
    them filled along the tree (:func:`_fill_along`); returns the fits now kept."""
    own = _fill_along(graph, np.where(trusted & reliable, r_fit, np.nan), trusted)
    take = trusted & np.isfinite(own)
    radius[take] = own[take]
    return trusted & reliable


def _fill_along(graph: BranchGraph, values: NDArray, mask: NDArray) -> NDArray[np.float64]:
    """``values`` (NaN = unknown) filled within ``mask`` from the nearest known value
    towards the root, else from a child's (parents first, then children first)."""
    out = np.array(values, dtype=float)
    par, order = graph.parent, graph.order
    order = order[mask[order]]
    for v in order:
        p = par[v]
        if mask[v] and np.isnan(out[v]) and p >= 0 and mask[p]:
            out[v] = out[p]
    for v in order[::-1]:
        p = par[v]
        if p >= 0 and mask[p] and mask[v] and np.isnan(out[p]):
            out[p] = out[v]
    return out


def _kept_ancestor(parent: NDArray, order: NDArray, keep: NDArray) -> NDArray[np.int64]:
    """The nearest node on the path to the root (the node itself included) in ``keep``;
    -1 where there is none."""
    return _kept_ancestor_kernel(
        np.asarray(parent, dtype=np.int64), np.asarray(order, dtype=np.int64), keep
    )


def _free_slope(x: NDArray, y: NDArray) -> float | None:
    """The slope of a robust free line through the reliable fits (diagnostic only)."""
    if x.size < 10 or np.ptp(x) < 1.0:
        return None
    return _robust_line(x, y, None)[1]
