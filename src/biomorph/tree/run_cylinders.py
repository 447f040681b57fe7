"""Cylinders fitted to runs of nodes along a branch: radii where a single slab is too thin.

A circle fit (:func:`biomorph.tree.radius.fit_circles`) looks at one slab about half an
edge high. On a branch a couple of centimetres thick, sampled at about a centimetre, such
a slab holds a handful of points: too few for a circle (the birch preset at 60,000 points:
4 % of its 1.25–3.5 cm nodes get any fit, under 1 % a reliable one), so the radius there
is the taper model's alone. TreeQSM fits its cylinders to *segments* several cover sets
long for the same reason. Here each branch (:func:`~biomorph.tree.radius.branch_ids`) is cut
into consecutive runs of nodes holding at least :data:`SEGMENT_POINTS` points and at
least :data:`SEGMENT_MIN_DIAMETERS` diameters long (at most
:data:`SEGMENT_MAX_DIAMETERS`, so a curved branch stays close to a straight cylinder), and
one cylinder — axis point, axis direction and radius, five parameters — is fitted to the
run's points by iteratively reweighted Gauss–Newton on the geometric distance
``‖(x − c) − ((x − c)·a) a‖ − r`` (Huber weights at 1.345 robust standard deviations).

The outward bias of the noise across the surface, ``s²/(2r)``, is taken off. A run's fit
is *usable* (``ok``) when its inliers cover at least
:data:`~biomorph.tree.radius.RELIABLE_COVERAGE` of the circumference, its radius is
determined to :data:`SEGMENT_SE` of itself (``1.4826 · MAD / √n``, the standard error of
a mean distance), the inliers' median absolute residual is at most
:data:`SEGMENT_MAX_MAD` of it, its axis turns by at most :data:`SEGMENT_MAX_TILT` from the
run's chord and stays within the search radius of the skeleton. A run thinner than
:data:`SEGMENT_NOISE_RADII` times the scan's surface scatter is an upper bound only
(``bound``). :func:`biomorph.tree.radius.segment_radii` hands usable runs to the taper
model (:func:`~biomorph.tree.radius.taper_radii`) as measured cross-sections where no
circle fit is reliable, under the same one-sided test as circle fits; the pipeline does
so once, on the final skeleton, with ``--run-cylinders`` (session 18, opt-in).

``bench/tree.py --only runs`` checks the fit against pytlidar's TreeQSM least-squares
cylinder on the same synthetic runs; ``--only truth --methods graph graph+runs`` the
whole pipeline against the presets' truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph

__all__ = [
    "SegmentFit",
    "RunCylinders",
    "fit_run_cylinders",
    "fit_segments",
    "segment_runs",
    "SEGMENT_POINTS",
    "SEGMENT_MAX_POINTS",
    "SEGMENT_MIN_DIAMETERS",
    "SEGMENT_MAX_DIAMETERS",
    "SEGMENT_SE",
    "SEGMENT_MAX_MAD",
    "SEGMENT_NOISE_RADII",
    "SEGMENT_MAX_TILT",
]

#: points a run needs before it may close: five parameters and a robust scale; with 12
#: points the standard error of the radius is about a third of the noise
SEGMENT_POINTS = 12
#: a run's cylinder is fitted to at most this many of its points (evenly spread): the
#: radius' standard error is then a ninth of the noise, and a thick branch's thousands of
#: points cost no more than a twig's
SEGMENT_MAX_POINTS = 48
#: a run closes only once it is this many (estimated) diameters long: shorter, the axis
#: direction is poorly determined from one side of a branch
SEGMENT_MIN_DIAMETERS = 2.0
#: and at the latest at this many diameters (with too few points it is then not fitted):
#: over ten diameters a branch bends little (the presets' branches turn by 0.2–0.35 rad
#: over their whole length, a few hundred diameters)
SEGMENT_MAX_DIAMETERS = 10.0
#: a radius is kept when its standard error is at most this share of it
SEGMENT_SE = 0.1
#: largest median absolute residual of a run's inliers, as a share of its radius: where
#: the noise is comparable to the radius the distances to the axis spread asymmetrically
#: (a Rice distribution) and the fitted radius grows with the noise whatever the count; at
#: 0.2 the bias s^2/(2r) taken off is under 5 % (it drops a fifth of the birch preset's
#: thin runs at 8 mm noise; range noise that fits a larger circle tightly is left to
#: SEGMENT_NOISE_RADII)
SEGMENT_MAX_MAD = 0.2
#: a run's radius is a measurement when at least this many times the scan's surface
#: scatter (the mean absolute residual of the stem's reliable circles, which sees the range
#: noise where the radius dwarfs it): range noise along the rays smears a thin branch's
#: section into a cross the fitted circle outgrows (the presets at 8 mm noise: twigs of
#: 0.5-1.2 cm fitted at 1.36x their radius, 1.2-3.5 cm at 0.98x; the stems' scatter 3.6 mm
#: there, 1.2 mm clean); below it the run only bounds the radius from above (the taper
#: model takes it where it is thinner than the model, which on those twigs said up to 2x)
SEGMENT_NOISE_RADII = 4.0
#: largest angle (rad) between the fitted axis and the run's chord
SEGMENT_MAX_TILT = np.radians(30.0)


@dataclass(frozen=True)
class SegmentFit:
    """Per node: ``radius`` of its run's cylinder (m, -1 where the node is in no fitted
    run), ``ok`` where that fit is usable, ``run`` the run id (-1: none); per run:
    ``run_radius``, ``run_points`` (inliers), ``run_coverage``, ``run_se`` (standard error of
    the radius, m), ``run_tilt`` (rad); per node ``bound``: the run is too thin for the
    scan's noise and bounds the radius from above only; ``centre``: the node moved onto
    its run's fitted axis (the foot of the perpendicular; NaN where the node is in no
    fitted run)."""

    radius: NDArray[np.float64]
    ok: NDArray[np.bool_]
    run: NDArray[np.int64]
    run_radius: NDArray[np.float64]
    run_points: NDArray[np.int64]
    run_coverage: NDArray[np.float64]
    run_se: NDArray[np.float64]
    run_tilt: NDArray[np.float64]
    bound: NDArray[np.bool_] | None = None
    centre: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class RunCylinders:
    """Per run: fitted ``radius`` (m, -1 = no fit), ``inliers`` count, angular
    ``coverage`` (0–1), ``mad`` (median absolute residual of the inliers, m), ``se``
    (standard error of the radius, m), ``tilt`` of the axis from the start axis (rad),
    ``shift`` of the axis from the start point across it (m); the fitted axis as a
    ``centre`` point on it (m) and unit ``axis`` direction (NaN where not fitted)."""

    radius: NDArray[np.float64]
    inliers: NDArray[np.int64]
    coverage: NDArray[np.float64]
    mad: NDArray[np.float64]
    se: NDArray[np.float64]
    tilt: NDArray[np.float64]
    shift: NDArray[np.float64]
    centre: NDArray[np.float64]
    axis: NDArray[np.float64]

    def usable(self, min_coverage: float) -> NDArray[np.bool_]:
        """The fits that pass the quality tests of the module doc that need no skeleton:
        count, coverage, standard error, scatter and tilt."""
        r = self.radius
        return (
            (r > 0)
            & (self.inliers >= SEGMENT_POINTS)
            & (self.coverage >= min_coverage)
            & (self.se <= SEGMENT_SE * r)
            & (self.mad <= SEGMENT_MAX_MAD * r)
            & (self.tilt <= SEGMENT_MAX_TILT)
        )


@numba.njit(cache=True)
def _runs_kernel(order, parent, bid, length, count, radius, min_points, min_diam, max_diam):
    n = order.size
    run = np.full(parent.size, -1, dtype=np.int64)
    cur = np.full(parent.size, -1, dtype=np.int64)  # per branch: its open run
    acc_len = np.zeros(parent.size)
    acc_cnt = np.zeros(parent.size, dtype=np.int64)
    nr = 0
    for k in range(n):
        v = order[k]
        b = bid[v]
        if parent[v] < 0:
            continue  # a root carries no edge
        if cur[b] < 0:
            cur[b] = nr
            acc_len[b] = 0.0
            acc_cnt[b] = 0
            nr += 1
        run[v] = cur[b]
        acc_len[b] += length[v]
        acc_cnt[b] += count[v]
        d = 2.0 * radius[v]
        if (acc_cnt[b] >= min_points and acc_len[b] >= min_diam * d) or acc_len[b] >= max_diam * d:
            cur[b] = -1
    return run, nr


def segment_runs(
    graph: BranchGraph, bid: NDArray, count: NDArray, radius: NDArray
) -> tuple[NDArray[np.int64], int]:
    """Run id per node (-1 at roots) and the number of runs: consecutive nodes of one
    branch (``bid``), closed once they hold :data:`SEGMENT_POINTS` points (``count`` per
    node) over :data:`SEGMENT_MIN_DIAMETERS` diameters (``radius`` per node, an estimate),
    or at :data:`SEGMENT_MAX_DIAMETERS` diameters."""
    return _runs_kernel(
        np.asarray(graph.order, dtype=np.int64),
        np.asarray(graph.parent, dtype=np.int64),
        np.asarray(bid, dtype=np.int64),
        np.asarray(graph.edge_length, dtype=np.float64),
        np.asarray(count, dtype=np.int64),
        np.asarray(radius, dtype=np.float64),
        SEGMENT_POINTS,
        SEGMENT_MIN_DIAMETERS,
        SEGMENT_MAX_DIAMETERS,
    )


@numba.njit(cache=True)
def _frame(a):
    # two unit vectors perpendicular to ``a``
    if abs(a[2]) < 0.9:
        e1 = np.cross(a, np.array([0.0, 0.0, 1.0]))
    else:
        e1 = np.cross(a, np.array([1.0, 0.0, 0.0]))
    e1 /= np.sqrt(np.sum(e1 * e1))
    e2 = np.cross(a, e1)
    return e1, e2


@numba.njit(cache=True)
def _residuals(x, p, a0, e1, e2, out):
    # distance of each point to the axis minus the radius, for parameters p (centre offset
    # along e1, e2; axis tilt along e1, e2; radius); returns the axis
    c = p[0] * e1 + p[1] * e2
    a = a0 + p[2] * e1 + p[3] * e2
    a /= np.sqrt(np.sum(a * a))
    for i in range(x.shape[0]):  # scalars: no temporary array per point
        d0 = x[i, 0] - c[0]
        d1 = x[i, 1] - c[1]
        d2 = x[i, 2] - c[2]
        t = d0 * a[0] + d1 * a[1] + d2 * a[2]
        q0 = d0 - t * a[0]
        q1 = d1 - t * a[1]
        q2 = d2 - t * a[2]
        out[i] = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2) - p[4]
    return a


@numba.njit(cache=True)
def _median(v):
    return np.median(v) if v.size else 0.0


@numba.njit(cache=True)
def _fit_cylinder(x, a0, r0, iters):
    """Robust Gauss–Newton cylinder fit of points ``x`` (centred on the run's chord
    midpoint) from axis ``a0`` and radius ``r0``: parameters, final residuals, axis."""
    e1, e2 = _frame(a0)
    m = x.shape[0]
    p = np.zeros(5)
    p[4] = r0
    res = np.empty(m)
    trial = np.empty(m)
    jac = np.empty((m, 5))
    lam = 1e-3
    _residuals(x, p, a0, e1, e2, res)
    for _ in range(iters):
        s = 1.4826 * _median(np.abs(res - _median(res)))
        k = 1.345 * max(s, 1e-5)
        w = np.ones(m)
        for i in range(m):
            if abs(res[i]) > k:
                w[i] = k / abs(res[i])
        cost = np.sum(w * res * res)
        for j in range(5):
            h = 1e-6 if j != 4 else 1e-7
            q = p.copy()
            q[j] += h
            _residuals(x, q, a0, e1, e2, trial)
            jac[:, j] = (trial - res) / h
        jw = jac * w[:, None]
        lhs = jw.T @ jac
        rhs = -(jw.T @ res)
        improved = False
        for _t in range(6):
            a_mat = lhs.copy()
            for j in range(5):
                a_mat[j, j] += lam * (lhs[j, j] + 1e-12)
            step = np.linalg.solve(a_mat, rhs)
            q = p + step
            _residuals(x, q, a0, e1, e2, trial)
            if np.sum(w * trial * trial) < cost:
                p = q
                res[:] = trial
                lam = max(lam * 0.3, 1e-7)
                improved = True
                break
            lam *= 10.0
        if not improved or np.sqrt(np.sum(step * step)) < 1e-3 * max(abs(p[4]), 1e-4):
            break
    a = _residuals(x, p, a0, e1, e2, res)
    return p, res, a, e1, e2


@numba.njit(cache=True)
def _segments_kernel(
    xyz,
    indptr,
    order_pts,
    mid,
    a0s,
    r0s,
    out_r,
    out_n,
    out_cov,
    out_mad,
    out_tilt,
    out_shift,
    out_centre,
    out_axis,
    max_points,
):
    nr = indptr.size - 1
    for k in range(nr):
        lo = indptr[k]
        hi = indptr[k + 1]
        out_r[k] = -1.0
        total = hi - lo
        if total < 6:
            continue
        # at most SEGMENT_MAX_POINTS, evenly through the run's points
        m = min(total, max_points)
        x = np.empty((m, 3))
        for i in range(m):
            x[i] = xyz[order_pts[lo + (i * total) // m]] - mid[k]
        a0 = a0s[k]
        p, res, a, e1, e2 = _fit_cylinder(x, a0, r0s[k], 12)
        r = p[4]
        if not np.isfinite(r) or r <= 0:
            continue
        # inliers: within 3 robust deviations (and at least a third of the radius)
        s = 1.4826 * _median(np.abs(res))
        band = max(3.0 * s, r / 3.0)
        c = p[0] * e1 + p[1] * e2
        b1 = e1 - (e1[0] * a[0] + e1[1] * a[1] + e1[2] * a[2]) * a
        b1 /= np.sqrt(np.sum(b1 * b1))
        b2 = np.cross(a, b1)
        occ = np.zeros(12, dtype=np.bool_)
        n_in = 0
        dev = np.empty(m)
        for i in range(m):
            if abs(res[i]) <= band:
                d0 = x[i, 0] - c[0]
                d1 = x[i, 1] - c[1]
                d2 = x[i, 2] - c[2]
                ang = np.arctan2(
                    d0 * b2[0] + d1 * b2[1] + d2 * b2[2], d0 * b1[0] + d1 * b1[1] + d2 * b1[2]
                )
                occ[int((ang + np.pi) / (2 * np.pi) * 12) % 12] = True
                dev[n_in] = abs(res[i])
                n_in += 1
        mad = _median(dev[:n_in]) if n_in else 0.0
        # the noise across the surface lengthens every point's distance to the axis by
        # about s^2 / (2 r) (its tangential part): taken off
        s_in = 1.4826 * mad
        r = max(r - s_in * s_in / (2.0 * r), 0.5 * r)
        out_r[k] = r
        out_n[k] = n_in
        out_cov[k] = occ.sum() / 12.0
        out_mad[k] = mad
        cosang = abs(np.sum(a * a0))
        out_tilt[k] = np.arccos(min(cosang, 1.0))
        # the axis' distance from the chord midpoint, across the chord
        out_shift[k] = np.sqrt(p[0] * p[0] + p[1] * p[1])
        out_centre[k] = mid[k] + c
        out_axis[k] = a


def fit_run_cylinders(
    xyz: NDArray[np.float64],
    indptr: NDArray[np.int64],
    index: NDArray[np.int64],
    start: NDArray[np.float64],
    axis: NDArray[np.float64],
    radius: NDArray[np.float64],
) -> RunCylinders:
    """One cylinder per run: run ``k`` holds the points ``xyz[index[indptr[k]:indptr[k+1]]]``
    (at most :data:`SEGMENT_MAX_POINTS` of them used, evenly spread); the fit starts from
    the axis through ``start[k]`` along the unit ``axis[k]`` and the radius ``radius[k]``."""
    nr = indptr.size - 1
    out_r = np.full(nr, -1.0)
    out_n = np.zeros(nr, dtype=np.int64)
    out_cov = np.zeros(nr)
    out_mad = np.zeros(nr)
    out_tilt = np.zeros(nr)
    out_shift = np.zeros(nr)
    out_centre = np.full((nr, 3), np.nan)
    out_axis = np.full((nr, 3), np.nan)
    _segments_kernel(
        np.ascontiguousarray(xyz, dtype=np.float64),
        np.ascontiguousarray(indptr, dtype=np.int64),
        np.ascontiguousarray(index, dtype=np.int64),
        np.ascontiguousarray(start, dtype=np.float64),
        np.ascontiguousarray(axis, dtype=np.float64),
        np.ascontiguousarray(radius, dtype=np.float64),
        out_r,
        out_n,
        out_cov,
        out_mad,
        out_tilt,
        out_shift,
        out_centre,
        out_axis,
        SEGMENT_MAX_POINTS,
    )
    # the standard error of a mean distance, sigma = 1.4826 MAD, five parameters fitted
    se = np.where(out_r > 0, 1.4826 * out_mad / np.sqrt(np.maximum(out_n - 5, 1)), np.inf)
    return RunCylinders(
        out_r, out_n, out_cov, out_mad, se, out_tilt, out_shift, out_centre, out_axis
    )


def fit_segments(
    graph: BranchGraph,
    xyz: NDArray[np.float64],
    near: NDArray[np.int64],
    dist: NDArray[np.float64],
    radius: NDArray[np.float64],
    bid: NDArray[np.int64],
    spacing: float,
    min_coverage: float,
    need: NDArray[np.bool_] | None = None,
    noise: float = 0.0,
) -> SegmentFit:
    """Cylinder per run of nodes (:func:`segment_runs`) from the points nearest to its
    nodes (``near``: nearest node per point, ``dist``: its distance to the skeleton, m)
    within ``2 radius + spacing`` of the skeleton (``radius``: the current estimate per
    node, m; ``spacing``: the cloud's point spacing, m). A fit is usable with at least
    ``min_coverage`` of the circumference covered (the circle fits' reliability share).
    ``need``: the nodes that want a segment radius (those without a reliable circle fit,
    off the stem); runs holding none of them are not fitted. ``noise``: the scan's surface
    scatter (m, the mean absolute residual of well-measured stem circles); a run thinner
    than :data:`SEGMENT_NOISE_RADII` times it is only an upper bound (``bound``)."""
    n = graph.n_nodes
    near = np.asarray(near, dtype=np.int64)
    count = np.bincount(near, minlength=n)
    run, nr = segment_runs(graph, bid, count, radius)
    keep_pt = dist <= 2.0 * radius[near] + spacing
    if need is not None:
        wanted = np.zeros(nr + 1, dtype=bool)
        wanted[run[np.asarray(need, dtype=bool) & (run >= 0)]] = True
        keep_pt &= wanted[run[near]]  # run -1 reads the last slot, left False
    pr = np.where(keep_pt, run[near], -1)
    sel = np.flatnonzero(pr >= 0)
    srt = sel[np.argsort(pr[sel], kind="stable")]
    indptr = np.searchsorted(pr[srt], np.arange(nr + 1)).astype(np.int64)
    # the run's chord: from its first node's parent to its last node
    nodes = np.flatnonzero(run >= 0)
    byrun = nodes[np.argsort(run[nodes], kind="stable")]
    first_idx = np.searchsorted(run[byrun], np.arange(nr))  # every run holds a node
    pos = graph.position
    # graph.order is topological: along a branch the first node in order is the lowest
    rank = np.empty(n, dtype=np.int64)
    rank[graph.order] = np.arange(n)
    start = np.zeros(nr, dtype=np.int64)
    end = np.zeros(nr, dtype=np.int64)
    r0 = np.zeros(nr)
    if nr:
        rk = rank[byrun]
        start = graph.order[np.minimum.reduceat(rk, first_idx)]
        end = graph.order[np.maximum.reduceat(rk, first_idx)]
        r0 = np.maximum.reduceat(radius[byrun], first_idx)
    p0 = pos[graph.parent[start]]
    p1 = pos[end]
    chord = p1 - p0
    ln = np.linalg.norm(chord, axis=1)
    a0 = chord / np.maximum(ln, 1e-12)[:, None]
    mid = 0.5 * (p0 + p1)
    fits = fit_run_cylinders(xyz, indptr, srt, mid, a0, r0)
    out_r = fits.radius
    ok_run = (
        fits.usable(min_coverage)
        & (fits.shift <= 2.0 * r0 + spacing)
        & (out_r <= 2.0 * r0 + spacing)
    )
    # noise only lengthens the distances to the axis: a run too thin for the scan's noise
    # still bounds its radius from above
    bound_run = out_r < SEGMENT_NOISE_RADII * noise
    r_node = np.where(run >= 0, out_r[np.maximum(run, 0)], -1.0)
    ok_node = (run >= 0) & ok_run[np.maximum(run, 0)]
    bound = (run >= 0) & bound_run[np.maximum(run, 0)]
    centre = np.full((n, 3), np.nan)
    if nodes.size:
        c, a = fits.centre[run[nodes]], fits.axis[run[nodes]]
        t = np.einsum("ij,ij->i", pos[nodes] - c, a)
        centre[nodes] = c + t[:, None] * a
    return SegmentFit(
        r_node,
        ok_node,
        run,
        out_r,
        fits.inliers,
        fits.coverage,
        fits.se,
        fits.tilt,
        bound,
        centre,
    )
