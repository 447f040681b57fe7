"""The stem followed through the points, slab by slab, from a measured section.

The skeleton's stem is where the graph's shortest paths ran, and in a needle-clad or sparse
crown they can run out along a whorl's branches and back (a quarter of the TreeLS spruce's
points: the path 0.4-1 m off the stem from 3.3 to 7.5 m), so circles fitted about its nodes
are needle envelopes (20-50 cm round an 11 cm stem) and the taper model anchored on them
was 2-5x too thick. A forester's stem is continuous: from one well-fitted section, the next
slab along the stem's own axis holds a circle of about the same radius within half a
radius of that axis. :func:`track_stem` walks that way up (and down) from a seed section,
as TreeQSM grows its stem from cover sets and SimpleForest its stem from slices, and stops
where the stem has not been seen for :data:`TRACK_GAP_RADII` radii of height.

Constants and where they come from:

* slabs :data:`TRACK_STEP_RADII` of the running radius apart (at least two point
  spacings): a stem's radius and axis change over metres, not centimetres;
* each slab's circle is searched within ``search_factor`` x the running radius of the
  predicted centre (the pipeline's circle search, :func:`biomorph.tree.radius.fit_circles`),
  is kept when it passes the pipeline's quality test (:func:`radius.well_covered`: a third of
  the circumference, scatter under a tenth of the radius; not an envelope:
  :data:`radius.STEM_INSIDE`), lies within half the running radius of the axis (the
  stem test of :func:`biomorph.tree.cleanup._stem_support`) and within
  :data:`TRACK_RATIO` of the last circles' median radius (an envelope or a branch junction
  inflates one slab's circle; the stem tapers by a few per cent over a step);
* the axis is the line through the last circles' centres over :data:`TRACK_AXIS_RADII`
  radii of height, once they span half that, tilted at most 60 degrees from vertical (as
  :func:`biomorph.tree.cleanup.trunk_shortcuts`' lines).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree.radius import RadiusFit, _not_envelope, fit_circles, well_covered

__all__ = ["StemTrack", "track_stem", "stem_tracks", "TRACK_MIN_CIRCLES"]

#: slabs this many running radii apart (at least two point spacings)
TRACK_STEP_RADII = 0.5
#: a slab's circle more than this factor off the median radius of the last
#: :data:`TRACK_MEDIAN` circles is not the stem
TRACK_RATIO = 1.4
TRACK_MEDIAN = 5
#: the stem is given up after this many running radii of height without a circle (a
#: whorl's needles hide a spruce's stem over a few diameters; a fork ends it)
TRACK_GAP_RADII = 10.0
#: the axis from the circles over this many radii of height below the current one
TRACK_AXIS_RADII = 20.0
#: each slab's half-thickness, in running radii (at least a point spacing); the inner
#: search's first slabs take half of it. Thicker slabs gather more of a sparse stem (a
#: quarter of the TreeLS spruce's points holds 0-9 per slab on its shell) and follow it
#: further (0.5 / 1 radius: 59-80 / 107-129 circles where 0.25 finds 7-35), but the
#: quarters' volumes spread as widely (docs/tree.md, session 32)
TRACK_DEPTH_RADII = 0.25
#: slabs predicted and fitted per call of the circle fit
TRACK_BATCH = 8
#: a track shorter than this many circles says nothing about the stem
TRACK_MIN_CIRCLES = 5
#: the steepest axis a stem is followed along (degrees from vertical)
TRACK_MAX_TILT = 60.0


@dataclass(frozen=True)
class StemTrack:
    """Circles along a stem, bottom to top: ``centre`` (m, (k, 3)), ``radius`` (m),
    ``coverage``, ``inliers`` and ``inside`` as :class:`~biomorph.tree.radius.RadiusFit`'s
    (the seed section: NaN, 0, 0)."""

    centre: NDArray[np.float64]
    radius: NDArray[np.float64]
    coverage: NDArray[np.float64]
    inliers: NDArray[np.int64]
    inside: NDArray[np.int64]

    @property
    def n(self) -> int:
        return int(self.radius.size)

    @property
    def height(self) -> float:
        """The height it spans (m)."""
        return float(np.ptp(self.centre[:, 2])) if self.n else 0.0


def _walk(
    xyz: NDArray[np.float64],
    kd: cKDTree,
    spacing: float,
    centre: NDArray[np.float64],
    radius: float,
    direction: float,
    seed: int,
    search_factor: float,
) -> list[tuple[NDArray, float, float, int, int]]:
    """Circles from the section (``centre``, ``radius``) upwards (``direction`` 1) or
    downwards (-1), not including it."""
    up = np.array([0.0, 0.0, direction])
    axis = up.copy()
    c = np.asarray(centre, dtype=float).copy()  # the last circle's centre
    radii = [float(radius)]
    seen = [c.copy()]
    out: list[tuple[NDArray, float, float, int, int]] = []
    missed = 0.0  # the way walked since the last circle
    cos_tilt = float(np.cos(np.radians(TRACK_MAX_TILT)))
    for call in range(100_000):
        r = float(np.median(radii[-TRACK_MEDIAN:]))
        step = max(2.0 * spacing, TRACK_STEP_RADII * r)
        start = c + axis * missed
        nodes = start + axis * step * np.arange(TRACK_BATCH + 1)[:, None]
        f = fit_circles(
            BranchGraph(nodes, np.arange(-1, TRACK_BATCH)),
            xyz,
            np.full(TRACK_BATCH + 1, r),
            search_factor=search_factor,
            search_depth=max(spacing, TRACK_DEPTH_RADII * r),
            spacing=spacing,
            kdtree=kd,
            seed=seed + call,
            axes=np.broadcast_to(axis, nodes.shape),
        )
        good = well_covered(f) & _not_envelope(f)
        inside = f.inside if f.inside is not None else np.zeros(TRACK_BATCH + 1, np.int64)
        for i in range(1, TRACK_BATCH + 1):
            cc, rr = f.centre[i], float(f.radius[i])
            d = cc - c
            along = float(d @ axis)
            off = float(np.linalg.norm(d - along * axis))
            if (
                good[i]
                and along > 0
                and off <= 0.5 * r
                and r / TRACK_RATIO <= rr <= TRACK_RATIO * r
            ):
                out.append((cc.copy(), rr, float(f.coverage[i]), int(f.inliers[i]), int(inside[i])))
                radii.append(rr)
                c = cc.copy()
                seen.append(c)
                missed = 0.0
                axis = _axis(np.asarray(seen), r, up, cos_tilt, axis)
                r = float(np.median(radii[-TRACK_MEDIAN:]))
            else:
                missed += step
                if missed > TRACK_GAP_RADII * r:
                    return out
        # the next batch starts where this one ended: c + axis x missed
    return out


def _axis(seen: NDArray, r: float, up: NDArray, cos_tilt: float, axis: NDArray) -> NDArray:
    """The stem's direction from the centres over :data:`TRACK_AXIS_RADII` radii of height
    (once they span half of it), else as it was."""
    span = TRACK_AXIS_RADII * r
    h = seen @ up
    near = seen[h >= h[-1] - span]
    if near.shape[0] < TRACK_MEDIAN or np.ptp(near @ up) < 0.5 * span:
        return axis
    m = near.mean(axis=0)
    _, _, vt = np.linalg.svd(near - m, full_matrices=False)
    d = vt[0] * np.sign(vt[0] @ up) if vt[0] @ up != 0 else axis
    return d if float(d @ up) >= cos_tilt else axis


def track_stem(
    xyz: NDArray[np.float64],
    spacing: float,
    centre: NDArray[np.float64],
    radius: float,
    *,
    kdtree: cKDTree,
    seed: int = 0,
    search_factor: float = 1.5,
) -> StemTrack:
    """The stem followed up and down from one measured section (``centre``, ``radius``, m)
    through the points ``xyz`` (k-d tree ``kdtree``, point spacing ``spacing``); the seed
    section is included. See the module doc for the rules."""
    if spacing <= 0 or radius <= 0:
        raise ParameterError(f"spacing and radius must be > 0 m, got {spacing}, {radius}")
    c0 = np.asarray(centre, dtype=float)
    ups = _walk(xyz, kdtree, spacing, c0, radius, 1.0, seed, search_factor)
    downs = _walk(xyz, kdtree, spacing, c0, radius, -1.0, seed + 50_000, search_factor)
    rows = [*downs[::-1], (c0.copy(), float(radius), np.nan, 0, 0), *ups]
    return StemTrack(
        np.array([r[0] for r in rows]).reshape(-1, 3),
        np.array([r[1] for r in rows], dtype=float),
        np.array([r[2] for r in rows], dtype=float),
        np.array([r[3] for r in rows], dtype=np.int64),
        np.array([r[4] for r in rows], dtype=np.int64),
    )


#: seed sections tried per tree: the reliable stem fits nearest these multiples of breast
#: height (a third of the height on a tree under 3.9 m); the track with the most circles
#: is kept
SEED_HEIGHTS = (1.0, 0.5, 1.5)


def _covers(track: StemTrack, pos: NDArray[np.float64]) -> int:
    """How many of the points ``pos`` (a tree's stem nodes) lie on the track: within its
    height range and two of its radii of its axis (centres and radii interpolated)."""
    zc = track.centre[:, 2]
    o = np.argsort(zc, kind="stable")
    zc = zc[o]
    inr = (pos[:, 2] >= zc[0]) & (pos[:, 2] <= zc[-1])
    if not inr.any():
        return 0
    z = pos[inr, 2]
    cx = np.interp(z, zc, track.centre[o, 0])
    cy = np.interp(z, zc, track.centre[o, 1])
    r = np.interp(z, zc, track.radius[o])
    return int((np.hypot(pos[inr, 0] - cx, pos[inr, 1] - cy) <= 2 * r).sum())


def stem_tracks(
    graph: BranchGraph,
    fit: RadiusFit,
    stem: NDArray[np.bool_],
    reliable: NDArray[np.bool_],
    xyz: NDArray[np.float64],
    spacing: float,
    *,
    kdtree: cKDTree,
    seed: int = 0,
    cache: list[StemTrack] | None = None,
) -> dict[int, tuple[NDArray[np.int64], NDArray[np.float64], float]]:
    """Per tree label, the stem as tracked, ``(node, radius, share)``: the ``stem`` nodes (the lower
    half of the stem path, :func:`radius._stem_mask`) with a tracked circle within two
    radii of their height, each with the track's radius interpolated at its height (the
    stem's own fits' sampling: circles come every half radius, more per metre up the
    stem), for the taper model's anchor (:func:`radius.taper_radii`), and the share of
    those nodes within two radii of the track's axis (:func:`_covers`: under half, the
    stem path runs mostly off the stem).

    Seeds are the tree's ``reliable`` stem fits nearest :data:`SEED_HEIGHTS` x 1.3 m above
    its lowest node (x a third of its height under 3.9 m); the track with the most circles
    is kept (they come every half radius: a needle envelope round a stem holds fewer per
    metre than the stem), then searched for a stem inside it (:func:`_inner`).

    ``cache``: the tracks of earlier calls on the same points (the radius stage runs
    several times as the skeleton changes; the stem in the points does not): a tree whose
    stem nodes lie on one of them takes the longest such and is not tracked again, and
    new tracks are appended. Trees
    whose track holds fewer than :data:`TRACK_MIN_CIRCLES` circles, or whose stem fits are
    thinner than two point spacings (a stem the scan does not resolve), are left out."""
    out: dict[int, tuple[NDArray[np.int64], NDArray[np.float64], float]] = {}
    if spacing <= 0:
        return out
    cache = [] if cache is None else cache
    pos = graph.position
    z = pos[:, 2]
    for t in np.unique(graph.trees):
        m = graph.trees == t
        sm = np.flatnonzero(m & stem)
        cand = np.flatnonzero(m & stem & reliable & (fit.radius >= 2 * spacing))
        if sm.size == 0 or cand.size == 0:
            continue
        best = _cached(cache, pos[sm])
        if best is None:
            best = _seeded(graph, fit, m, cand, xyz, spacing, kdtree, seed, cache)
        if best is None or best.n < TRACK_MIN_CIRCLES:
            continue
        # the stem's nodes the track covers (a circle within two radii of their height),
        # each with the track's radius at its height: sampled as the stem's own fits are
        zc, rc = best.centre[:, 2], best.radius
        o = np.argsort(zc, kind="stable")
        zc, rc = zc[o], rc[o]
        near = np.abs(z[sm][:, None] - zc[None, :]).min(axis=1)
        node = sm[near <= 2 * float(np.median(rc))]
        if node.size < TRACK_MIN_CIRCLES:
            continue
        share = _covers(best, pos[node]) / node.size
        out[int(t)] = (node.astype(np.int64), np.interp(z[node], zc, rc), share)
    return out


def _cached(cache: list[StemTrack], stem_pos: NDArray[np.float64]) -> StemTrack | None:
    """The longest track of ``cache`` (of :data:`TRACK_MIN_CIRCLES` circles or more) that
    as many of the tree's stem nodes lie on (:func:`_covers`), if any."""
    on = [
        tr
        for tr in cache
        if tr.n >= TRACK_MIN_CIRCLES and _covers(tr, stem_pos) >= TRACK_MIN_CIRCLES
    ]
    return max(on, key=lambda tr: tr.n) if on else None


def _tried(cache: list[StemTrack], centre: NDArray[np.float64], radius: float) -> bool:
    """Whether a seed section lies on a track of ``cache`` (one of its circles within its
    radius, with a radius within :data:`TRACK_RATIO` of its): tracked from there, it would
    follow that track again (the radius stage's later passes move a section by its
    recentring, not to another stem; a tree's seeds on one stem give one track)."""
    for tr in cache:
        near = np.linalg.norm(tr.centre - centre, axis=1) <= radius
        ratio = tr.radius[near] / radius
        if ((ratio >= 1 / TRACK_RATIO) & (ratio <= TRACK_RATIO)).any():
            return True
    return False


def _seeded(graph, fit, m, cand, xyz, spacing, kdtree, seed, cache) -> StemTrack | None:
    """The longest track from the tree's seeds (:func:`stem_tracks`); every track is
    appended to ``cache`` (a short one too: the same seed is not tracked again)."""
    z = graph.position[:, 2]
    base = float(z[m].min())
    height = float(z[m].max()) - base
    bh = min(1.3, height / 3.0)
    seeds: list[int] = []
    for target in SEED_HEIGHTS:
        v = int(cand[np.argmin(np.abs(z[cand] - base - target * bh))])
        if v not in seeds:
            seeds.append(v)
    best: StemTrack | None = None
    for k, v in enumerate(seeds):
        if _tried(cache, fit.centre[v], float(fit.radius[v])):
            continue
        tr = track_stem(
            xyz, spacing, fit.centre[v], float(fit.radius[v]), kdtree=kdtree, seed=seed + k
        )
        cache.append(tr)
        if best is None or tr.n > best.n:
            best = tr
    for level in range(INNER_LEVELS):
        if best is None or best.n < TRACK_MIN_CIRCLES:
            break
        inner = _inner(best, xyz, spacing, kdtree, seed + 100 * (level + 1))
        if inner is None:
            break
        cache.append(inner)
        best = inner
    return best


#: a track is searched for a stem inside it this many times (a needle envelope round the
#: stem is a continuous surface too, a cone up a spruce's crown; the stem is the innermost)
INNER_LEVELS = 2
#: ... a circle at most this share of the track's radius, centred within half of it
INNER_RATIO = 0.75


def _inner(
    track: StemTrack, xyz: NDArray[np.float64], spacing: float, kd: cKDTree, seed: int
) -> StemTrack | None:
    """A track inside ``track`` (:data:`INNER_RATIO`; at least :data:`TRACK_MIN_CIRCLES`
    circles), seeded at its circles nearest its first, middle and last quarter, if any."""
    k = track.n
    best: StemTrack | None = None
    for j, q in enumerate(sorted({k // 4, k // 2, (3 * k) // 4})):
        c, r = track.centre[q], float(track.radius[q])
        if r * 0.5 < 2 * spacing:
            continue
        below = c - np.array([0.0, 0.0, max(2 * spacing, 0.25 * r)])
        f = fit_circles(
            BranchGraph(np.array([below, c]), np.array([-1, 0])),
            xyz,
            np.full(2, 0.5 * r),
            search_factor=1.5,
            search_depth=max(spacing, 0.5 * TRACK_DEPTH_RADII * r),
            spacing=spacing,
            kdtree=kd,
            seed=seed + j,
        )
        ok = well_covered(f) & _not_envelope(f)
        rr = float(f.radius[1])
        if not ok[1] or rr > INNER_RATIO * r or np.hypot(*(f.centre[1] - c)[:2]) > 0.5 * r:
            continue
        tr = track_stem(xyz, spacing, f.centre[1], rr, kdtree=kd, seed=seed + 10 + j)
        if tr.n >= TRACK_MIN_CIRCLES and (best is None or tr.n > best.n):
            best = tr
    return best
