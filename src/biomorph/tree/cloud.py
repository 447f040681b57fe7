"""Point-cloud preparation for tree skeletonisation (seed 001, thesis §3.2 and beyond).

Every function is pure: it takes a :class:`~biomorph.core.pointcloud.PointCloud` and returns a
new one. Coordinates are metres, Z up, in the cloud's frame (``xyz``); the original
(possibly georeferenced) frame is ``xyz + offset`` and is never changed by these functions.

Steps, in the order :func:`prepare` applies them:

1. :func:`validate_cloud` -- empty, too few points, NaN/inf, coplanar/collinear clouds fail
   with an :class:`~biomorph.errors.InputError` naming the cloud's source.
2. :func:`centre` -- bottom centre of the bounding box to the origin; ``offset`` accumulates
   (on the cloud's own decimal lattice, :func:`coordinate_lattice`, where it has one);
   :func:`canonical_order` -- the points sorted by position, so the file's order is moot.
3. :func:`filter_attribute` -- keep points whose attribute (e.g. LAS ``Deviation``) lies in
   a range.
4. :func:`downsample` -- random ratio, random per voxel (thesis) or voxel centroid.
5. :func:`remove_outliers` -- statistical outlier removal on the k-NN mean distance.
6. ground removal (:mod:`biomorph.tree.ground`) so the ground is never skeletonised.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError
from biomorph.tree.neighbours import (
    NeighbourCache,
    morton_codes,
    query_blocks,
    query_ordered,
    smooth_median,
)
from biomorph.tree.options import UNITS, UP_AXES

__all__ = [
    "validate_cloud",
    "UNITS",
    "MAX_TREE_HEIGHT",
    "to_metres",
    "check_units",
    "to_z_up",
    "duplicate_points",
    "LAS_NOISE",
    "flagged_points",
    "centre",
    "canonical_order",
    "coordinate_lattice",
    "filter_attribute",
    "downsample",
    "remove_outliers",
    "point_spacing",
    "prepare",
    "PreparedCloud",
    "has_ground",
]

#: Minimum number of points a cloud needs to be skeletonised.
MIN_POINTS = 10


def _name(cloud: PointCloud) -> str:
    return cloud.source or "point cloud"


#: no tree stands this tall (the tallest measured, a coast redwood, about 116 m) and no
#: forest plot spans this much height of trees and terrain: a cloud taller than this,
#: read as metres, is in other units (plant scanners, photogrammetry and CloudCompare
#: exports write centimetres or millimetres)
MAX_TREE_HEIGHT = 200.0


def to_metres(cloud: PointCloud, units: str) -> PointCloud:
    """The cloud with its coordinates (and offset, and the LAS scales and offsets kept for
    writing it back) converted from ``units`` (a key of :data:`UNITS`) to metres."""
    if units not in UNITS:
        raise ParameterError(f"units {units!r}; expected one of {', '.join(UNITS)}")
    s = UNITS[units]
    if s == 1.0:
        return cloud
    meta = dict(cloud.meta)
    for key in ("scales", "offsets"):
        if meta.get(key) is not None:
            meta[key] = np.asarray(meta[key], dtype=np.float64) * s
    return PointCloud(cloud.xyz * s, dict(cloud.attributes), cloud.offset * s, meta, cloud.source)


#: Y-up -> Z-up: (x, y, z) -> (x, -z, y), a rotation of +90 degrees about x (determinant
#: 1: handedness kept, so a tree's spiral phyllotaxis and the model's twist are not mirrored)
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def to_z_up(cloud: PointCloud, up: str) -> PointCloud:
    """The cloud turned so that its ``up`` axis (``"z"`` or ``"y"``) points along +Z: its
    coordinates, its offset and the LAS scales and offsets kept for writing it back (the
    grid permuted with the axes)."""
    if up not in UP_AXES:
        raise ParameterError(f"up axis {up!r}; expected one of {', '.join(UP_AXES)}")
    if up == "z":
        return cloud
    rot = Y_UP_TO_Z_UP
    meta = dict(cloud.meta)
    if meta.get("scales") is not None:
        meta["scales"] = np.abs(rot) @ np.asarray(meta["scales"], dtype=np.float64)
    if meta.get("offsets") is not None:
        meta["offsets"] = rot @ np.asarray(meta["offsets"], dtype=np.float64)
    xyz = cloud.xyz @ rot.T
    return PointCloud(xyz, dict(cloud.attributes), rot @ cloud.offset, meta, cloud.source)


def check_units(cloud: PointCloud) -> None:
    """Raise :class:`InputError` when the cloud, read as metres, is taller than
    :data:`MAX_TREE_HEIGHT` (the 0.1–99.9 percentile range of its heights, so a stray
    point does not count): its coordinates are in other units, and the model would be a
    tree kilometres tall. The message gives the heights it would have in centimetres and
    in millimetres."""
    z = cloud.xyz[:: max(1, cloud.n_points // 200_000), 2]
    z = z[np.isfinite(z)]
    if z.size < MIN_POINTS:
        return  # validate_cloud reports it
    lo, hi = np.percentile(z, [0.1, 99.9])
    h = float(hi - lo)
    if h <= MAX_TREE_HEIGHT:
        return
    readings = [
        f"{u} ({h * UNITS[u]:.3g} m tall)"
        for u in ("cm", "mm")
        if 0.05 <= h * UNITS[u] <= MAX_TREE_HEIGHT
    ]
    guess = " or ".join(readings) if readings else "another unit"
    raise InputError(
        f"{_name(cloud)}: the cloud is {h:,.0f} m tall read as metres, taller than any "
        f"tree ({MAX_TREE_HEIGHT:.0f} m); its coordinates look like {guess}: pass "
        f"--units cm or --units mm (one of {', '.join(UNITS)}; --units m runs it as metres)"
    )


#: odd 64-bit multipliers mixing a point's three coordinates' bit patterns into one key
_HASH = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9], dtype=np.uint64)


def duplicate_points(xyz: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Mask of the points that repeat an earlier point exactly (merged scans that wrote
    their overlap twice, a file concatenated with itself). They carry nothing, but every
    density the pipeline derives its constants from counts them: rTwig's cloud written
    twice had a point spacing of 0 and a node spacing of 7 mm (29 mm once), and five
    times over it modelled 153 L for 22 L. One key per point (its coordinates' bits,
    mixed), sorted; the points sharing a key are then sorted by their coordinates and
    compared, so a collision never drops a distinct point. 0.15 s per 10⁶ points."""
    n = xyz.shape[0]
    dup = np.zeros(n, dtype=bool)
    if n < 2:
        return dup
    bits = np.ascontiguousarray(xyz, dtype=np.float64).view(np.uint64)
    key = (bits * _HASH).sum(axis=1)  # wraps modulo 2^64
    order = np.argsort(key)
    ks = key[order]
    same = np.flatnonzero(ks[1:] == ks[:-1])
    if same.size == 0:
        return dup
    # the points whose key repeats, sorted by their coordinates (then index: the first
    # stays): a copy sits next to its original, a collision does not
    idx = np.unique(np.concatenate([order[same], order[same + 1]]))
    sub = xyz[idx]
    o = np.lexsort((idx, sub[:, 2], sub[:, 1], sub[:, 0]))
    eq = (sub[o[1:]] == sub[o[:-1]]).all(axis=1)
    dup[idx[o[1:][eq]]] = True
    return dup


#: ASPRS LAS classes of noise: 7 (low point) and 18 (high noise, LAS 1.4)
LAS_NOISE = (7, 18)


def flagged_points(cloud: PointCloud) -> NDArray[np.bool_]:
    """Mask of the points the file itself marks as not to be used: classified as noise
    (:data:`LAS_NOISE`) or flagged ``withheld`` (LAS: "to be considered deleted"). A
    processing chain (lidR, PDAL, LAStools, the scanner's software) marks them so; read
    as wood they are outliers the skeleton would chase. All false without those
    attributes."""
    out = np.zeros(cloud.n_points, dtype=bool)
    cls = cloud.attributes.get("classification")
    if cls is not None:
        out |= np.isin(np.asarray(cls), LAS_NOISE)
    held = cloud.attributes.get("withheld")
    if held is not None:
        out |= np.asarray(held).astype(bool)
    return out


def validate_cloud(cloud: PointCloud) -> None:
    """Raise :class:`InputError` if ``cloud`` cannot be skeletonised.

    Checks: at least :data:`MIN_POINTS` points, finite coordinates, and a truly 3-D spread
    (the PCA eigenvalues of the coordinates: the smallest must exceed ``1e-10`` of the
    largest and the second ``1e-10`` of it as well, else the points are coplanar or collinear).
    The message names the cloud's ``source``.
    """
    name = _name(cloud)
    n = cloud.n_points
    if n == 0:
        raise InputError(f"{name} is empty; expected at least {MIN_POINTS} points")
    if n < MIN_POINTS:
        raise InputError(
            f"{name} has {n} point{'s' if n != 1 else ''}; expected at least "
            f"{MIN_POINTS} to skeletonise a tree"
        )
    xyz = cloud.xyz
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise InputError(
            f"{name}: point {bad} has a non-finite coordinate (NaN or inf); "
            f"expected finite numbers ({int((~finite).sum())} bad points)"
        )
    d = xyz - xyz.mean(axis=0)
    ev = np.linalg.eigvalsh(d.T @ d / n)  # ascending
    top = ev[2]
    if top <= 0 or ev[1] <= 1e-10 * top:
        raise InputError(
            f"{name}: all {n} points lie on one line (or coincide); expected a 3-D tree point cloud"
        )
    if ev[0] <= 1e-10 * top:
        raise InputError(
            f"{name}: all {n} points are coplanar; expected a 3-D tree point cloud with volume"
        )


#: decimal steps (m) tried, coarsest first, for the lattice a cloud's coordinates were
#: stored on (a LAS file's scale, a text file's decimals; :func:`coordinate_lattice`)
LATTICE_STEPS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
#: a coordinate lies on a lattice when it is within this share of a step of a node (the
#: round-off of a georeferenced coordinate, ~10⁻⁹ m at 10⁶ m, is 10⁻³ of a 1 µm step; a
#: coordinate off any lattice passes by chance with probability 0.02 per point and axis)
LATTICE_TOLERANCE = 0.01


def coordinate_lattice(cloud: PointCloud) -> NDArray[np.float64]:
    """Per axis the coarsest decimal step of :data:`LATTICE_STEPS` on which every
    coordinate lies, counted from the axis's lowest one (NaN where none fits: float32
    exports, simulated clouds).

    A LAS file stores integers times its scale, a text export a fixed number of decimals:
    the same scan shifted by a georeferencing offset lies on the same lattice, and
    :func:`centre` puts both at the same coordinates, bit for bit."""
    steps = np.full(3, np.nan)
    if cloud.n_points == 0:
        return steps
    rel = cloud.xyz - cloud.xyz.min(axis=0)
    for axis in range(3):
        col = rel[:, axis]
        span = float(col.max())
        for q in LATTICE_STEPS:
            if span / q > 2.0**40:  # float64 no longer holds the step's fraction
                break
            if _on_lattice(col[: min(col.size, 4096)], q) and _on_lattice(col, q):
                steps[axis] = q
                break
    return steps


def _on_lattice(v: NDArray[np.float64], q: float) -> bool:
    s = v / q
    return bool(np.all(np.abs(s - np.rint(s)) <= LATTICE_TOLERANCE))


def centre(cloud: PointCloud, lattice: NDArray[np.float64] | None = None) -> PointCloud:
    """Move the bottom centre of the bounding box to the origin.

    The shift is added to ``offset`` so ``world_xyz`` is unchanged. Coordinates are kept in
    float64 relative to the offset, so georeferenced clouds (~1e6 m) keep sub-micrometre
    precision once centred (round-off of ``world_xyz`` stays below ~1e-9 m at 1e6 m).
    Along an axis stored on a decimal lattice (:func:`coordinate_lattice`) the centred
    coordinates are whole numbers of lattice steps from the lowest one: a copy of the cloud
    moved by any offset (a georeferenced export of a local scan) gets the very same
    centred coordinates, where subtracting floats left round-off of up to 10⁻⁹ m that
    decided exact ties between grid-snapped distances differently (AdTree tree7's volume
    moved by 14 %, docs/tree.md, session 33). ``lattice``: the cloud's
    :func:`coordinate_lattice` if already known.
    """
    lo, hi = cloud.bounds()
    shift = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    xyz = cloud.xyz - shift
    q = coordinate_lattice(cloud) if lattice is None else np.asarray(lattice, dtype=float)
    for axis in np.flatnonzero(np.isfinite(q)):
        steps = np.rint((cloud.xyz[:, axis] - lo[axis]) / q[axis]).astype(np.int64)
        mid = int(steps.max()) // 2 if axis < 2 else 0
        xyz[:, axis] = (steps - mid) * q[axis]
        shift[axis] = lo[axis] + mid * q[axis]
    return cloud.with_(xyz=xyz, offset=cloud.offset + shift)


def canonical_order(cloud: PointCloud) -> PointCloud:
    """The points in an order set by their coordinates alone (attributes with them).

    Every later step that breaks a tie (equal distances on a grid-snapped scan, equal path
    costs, the circle fits' random draws, which index a section's points) then breaks it
    the same way whatever order the file lists its points in: two exports of one scan
    give the same model. The order is the Morton (Z-order) curve through the cloud's
    bounding box at 2^-21 of its largest side, ties by height, y, x: spatially coherent,
    as a scanner's own order is. (Ordered by a hash of the position -- a shuffle -- the
    small aspen test tree's tips came out 1.6x the truth's where the scan's order and the
    Morton order give 1.40 and 1.43: shuffled orders of that scan give 1.47-1.60.)"""
    if cloud.n_points < 2:
        return cloud
    key = morton_codes(cloud.xyz)  # the neighbour queries' spatial order, ties decided
    order = np.lexsort((cloud.xyz[:, 0], cloud.xyz[:, 1], cloud.xyz[:, 2], key))
    return cloud.select(order)


def filter_attribute(
    cloud: PointCloud, name: str, max_value: float | None = None, min_value: float | None = None
) -> PointCloud:
    """Keep the points whose attribute ``name`` lies in ``[min_value, max_value]``.

    Used e.g. with the LAS ``Deviation`` attribute (thesis: drop noisy returns). Raises
    :class:`ParameterError` if the attribute is missing or no bound is given.
    """
    if name not in cloud.attributes:
        have = ", ".join(sorted(cloud.attributes)) or "none"
        raise ParameterError(
            f"{_name(cloud)} has no attribute {name!r} to filter on; available: {have}"
        )
    if max_value is None and min_value is None:
        raise ParameterError("filter_attribute needs max_value and/or min_value")
    v = np.asarray(cloud.attributes[name], dtype=float)
    keep = np.ones(cloud.n_points, dtype=bool)
    if max_value is not None:
        keep &= v <= max_value
    if min_value is not None:
        keep &= v >= min_value
    return cloud.select(keep)


def _voxel_keys(xyz: NDArray[np.float64], voxel_size: float) -> NDArray[np.int64]:
    """Unique-able integer key per point of the voxel it falls into."""
    ijk = np.floor((xyz - xyz.min(axis=0)) / voxel_size).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    return (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]


def downsample(
    cloud: PointCloud,
    method: str = "ratio",
    ratio: float | None = None,
    voxel_size: float | None = None,
    seed: int = 0,
) -> PointCloud:
    """Reduce the number of points.

    Parameters
    ----------
    method : ``"ratio"`` keeps a random fraction ``ratio`` of all points (thesis method 1);
        ``"voxel"`` keeps a random fraction ``ratio`` (default: one point) of the points of
        each cube of edge ``voxel_size`` metres (thesis method 2, spatially even);
        ``"centroid"`` replaces the points of each voxel by their centroid (attributes of one
        point of the voxel are kept).
    ratio : fraction in (0, 1].
    voxel_size : voxel edge in metres (``"voxel"`` and ``"centroid"``).
    seed : random seed; the same seed gives the same subset.
    """
    rng = np.random.default_rng(seed)
    n = cloud.n_points
    if ratio is not None and not (0 < ratio <= 1):
        raise ParameterError(f"downsample ratio must lie in (0, 1]; got {ratio}")
    if method == "ratio":
        if ratio is None:
            raise ParameterError("downsample method 'ratio' needs ratio in (0, 1]")
        k = max(1, int(round(ratio * n)))
        idx = np.sort(rng.choice(n, size=k, replace=False))
        return cloud.select(idx)
    if method not in ("voxel", "centroid"):
        raise ParameterError(
            f"downsample method must be 'ratio', 'voxel' or 'centroid'; got {method!r}"
        )
    if voxel_size is None or not voxel_size > 0:
        raise ParameterError(
            f"downsample method {method!r} needs voxel_size > 0 (metres); got {voxel_size}"
        )
    if n == 0:
        return cloud
    keys = _voxel_keys(cloud.xyz, voxel_size)
    if method == "centroid":
        uniq, first, inv, counts = np.unique(
            keys, return_index=True, return_inverse=True, return_counts=True
        )
        sums = np.zeros((uniq.size, 3))
        np.add.at(sums, inv, cloud.xyz)
        rep = cloud.select(first)
        return rep.with_(xyz=sums / counts[:, None])
    perm = rng.permutation(n)
    k = keys[perm]
    order = np.argsort(k, kind="stable")
    ks = k[order]
    start = np.r_[0, np.flatnonzero(np.diff(ks)) + 1]
    counts = np.diff(np.r_[start, ks.size])
    rank = np.arange(ks.size) - np.repeat(start, counts)
    quota = (
        np.ones_like(counts)
        if ratio is None
        else np.maximum(1, np.round(ratio * counts).astype(np.int64))
    )
    keep = rank < np.repeat(quota, counts)
    idx = np.sort(perm[order[keep]])
    return cloud.select(idx)


#: an outlier of the global statistic is kept when its mean neighbour distance is at most
#: this many times that of its sparser neighbours (the LOCAL_QUANTILE of its neighbours'
#: values; a local density ratio as in Breunig et al. 2000's local outlier factor, whose
#: usual cut is 1.5-2): the global statistic assumes one density, and the points of a twig
#: sampled every 5 cm next to a densely sampled stem fail it although they are evenly
#: spaced among themselves (a synthetic 5 cm scan lost 31 of one twig's 53 points). The
#: quantile (0.9 of 16 neighbours: the second sparsest) lets a twig point beside the stem
#: count its two twig neighbours, while an isolated return, or a pair of them, has only
#: dense neighbours there. Off by default (``None``) until thin-branch radii are right:
#: the twigs it keeps get the taper model's radii, which are still too thick on thin
#: branches (clean synthetic maple, 30,000 points: total volume 104 % → 114 %); 2.0 is
#: the value measured in docs/tree.md (``remove_outliers(local_ratio=2.0)``,
#: ``bench/tree.py --lof``).
LOCAL_RATIO: float | None = None
LOCAL_QUANTILE = 0.9


def remove_outliers(
    cloud: PointCloud,
    k: int = 16,
    std_ratio: float = 2.0,
    *,
    return_mask: bool = False,
    local_ratio: float | None = None,
    return_neighbours: bool = False,
) -> PointCloud | tuple:
    """Statistical outlier removal.

    A point is an outlier when its mean distance to its ``k`` nearest neighbours exceeds
    ``mean + std_ratio * std`` of that statistic over the cloud, and — with
    ``local_ratio`` (default :data:`LOCAL_RATIO`, off) — more than ``local_ratio`` × the
    same statistic of its sparser neighbours (sparse but evenly sampled parts, such as thin
    twigs, stay). With ``return_mask`` the boolean inlier mask is returned as well; with
    ``return_neighbours`` the result is ``(cloud, mask, cache)``, ``cache`` the
    :class:`~biomorph.tree.neighbours.NeighbourCache` of the kept points from the same
    ``k + 1``-neighbour query (None for clouds of at most ``k + 1`` points), so the
    neighbour graph needs no second query.
    """
    if k < 1:
        raise ParameterError(f"remove_outliers k must be >= 1; got {k}")
    n = cloud.n_points
    cache = None
    if n <= k + 1:
        keep = np.ones(n, dtype=bool)
    else:
        tree = cKDTree(cloud.xyz)
        if return_neighbours:
            cache = NeighbourCache.from_query(tree, k + 1)
            md = cache.dist[:, 1:].mean(axis=1)
        else:
            md = np.empty(n)
            for rows, d, _ in query_blocks(tree, None, k + 1):
                md[rows] = d[:, 1:].mean(axis=1)
        out_ = np.flatnonzero(md > md.mean() + std_ratio * md.std())
        lr = LOCAL_RATIO if local_ratio is None else local_ratio
        if out_.size and lr is not None:
            # ... unless the point is about as sparse as its own neighbours (a sparsely
            # sampled twig, not an isolated return): local density ratio, as in LOF
            _, idx = tree.query(cloud.xyz[out_], k=k + 1, workers=-1)
            local = np.quantile(md[idx[:, 1:]], LOCAL_QUANTILE, axis=1)
            out_ = out_[md[out_] > lr * local]
        keep = np.ones(n, dtype=bool)
        keep[out_] = False
    out = cloud.select(keep)
    if return_neighbours:
        return out, keep, None if cache is None else cache.select(keep)
    return (out, keep) if return_mask else out


def point_spacing(cloud: PointCloud, max_samples: int = 200_000, seed: int = 0) -> float:
    """Median nearest-neighbour distance (metres; :func:`~biomorph.tree.neighbours.
    smooth_median`), over at most ``max_samples`` query points.

    Duplicate points (distance 0) are ignored; raises :class:`InputError` for fewer than two
    distinct points.
    """
    xyz = cloud.xyz
    if xyz.shape[0] < 2:
        raise InputError(f"{_name(cloud)} has fewer than 2 points; cannot estimate spacing")
    tree = cKDTree(xyz)
    q = xyz
    if xyz.shape[0] > max_samples:
        q = xyz[np.random.default_rng(seed).choice(xyz.shape[0], max_samples, replace=False)]
    d, _ = query_ordered(tree, q, 4)
    d = d[:, 1:]
    d = np.where(d > 0, d, np.inf).min(axis=1)
    d = d[np.isfinite(d)]
    if d.size == 0:
        raise InputError(f"{_name(cloud)}: all points coincide; cannot estimate spacing")
    return smooth_median(d)


def has_ground(cloud: PointCloud, cell: float | None = None) -> bool:
    """Heuristic: does the cloud contain a ground surface below the tree(s)?

    The XY plane is cut into cells (``cell`` metres; default ``max(0.5, extent/20)``). A cell
    counts as *low* when its lowest point lies less than ``0.5 m + 0.15 * d`` above the lowest
    point of the cloud, ``d`` being the horizontal distance to that point (slopes up to
    ~8.5°). A single segmented tree has low cells only at its stem base; a plot with terrain
    has them almost everywhere. Ground is assumed when more than half the occupied cells are
    low and there are at least 6 of them.
    """
    xyz = cloud.xyz
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    ext = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    c = cell if cell else max(0.5, ext / 20)
    ij = np.floor((xyz[:, :2] - lo[:2]) / c).astype(np.int64)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    uniq, inv = np.unique(key, return_inverse=True)
    zmin = np.full(uniq.size, np.inf)
    np.minimum.at(zmin, inv, xyz[:, 2])
    cent = np.zeros((uniq.size, 2))
    np.add.at(cent, inv, xyz[:, :2])
    cent /= np.bincount(inv, minlength=uniq.size)[:, None]
    i0 = int(np.argmin(xyz[:, 2]))
    dist = np.linalg.norm(cent - xyz[i0, :2], axis=1)
    low = zmin - xyz[i0, 2] < 0.5 + 0.15 * dist
    return bool(low.sum() >= 6 and low.mean() > 0.5)


_centre = centre
_downsample = downsample


@dataclass(frozen=True)
class PreparedCloud:
    """Result of :func:`prepare`.

    ``cloud``: the vegetation points ready for skeletonisation; ``ground``: the removed ground
    points (or ``None``); ``steps``: per step what was done -- ``{"name": {"points_in": ...,
    "points_out": ..., "seconds": ..., **details}}`` in execution order; ``neighbours``: with
    ``prepare(neighbours=True)`` the outlier filter's neighbour lists of ``cloud``
    (:class:`~biomorph.tree.neighbours.NeighbourCache`), or None.
    """

    cloud: PointCloud
    ground: PointCloud | None = None
    steps: dict[str, dict[str, Any]] = field(default_factory=dict)
    neighbours: NeighbourCache | None = field(default=None, repr=False)


def _ground_method(cloud: PointCloud, ground: str) -> tuple[str, bool]:
    """The ground method ``ground`` resolves to, and whether to run it: ``"auto"`` takes
    the file's own ground (ASPRS class 2) where it has one, else the default method where
    :func:`has_ground` finds a ground surface."""
    from biomorph.tree.ground import DEFAULT_METHOD, LAS_GROUND

    if ground != "auto":
        return ground, True
    cls = cloud.attributes.get("classification")
    if cls is not None and np.count_nonzero(np.asarray(cls) == LAS_GROUND) >= MIN_POINTS:
        return "classified", True
    return DEFAULT_METHOD, has_ground(cloud)


def prepare(
    cloud: PointCloud,
    *,
    centre: bool = True,
    filter: dict[str, Any] | tuple | None = None,
    downsample: dict[str, Any] | float | None = None,
    outliers: bool | dict[str, Any] = True,
    ground: str | None = "auto",
    seed: int = 0,
    ground_params: dict[str, Any] | None = None,
    neighbours: bool = False,
) -> PreparedCloud:
    """Validate, centre, filter, downsample, de-noise and remove ground, in that order.

    Parameters
    ----------
    centre : move the bottom centre of the bbox to the origin (offset kept).
    filter : ``{"name": "Deviation", "max_value": 50}`` (or a tuple ``(name, max, min)``).
    downsample : a ratio (float) or keyword arguments of :func:`downsample`.
    outliers : ``True`` for defaults, a dict of :func:`remove_outliers` arguments, or False.
    ground : ``"auto"`` (the file's own ground where it classifies one, ASPRS class 2; else
        the default method of :func:`biomorph.tree.ground.remove_ground`,
        only if :func:`has_ground` detects a ground surface), ``"classified"``, ``"csf"``,
        ``"grid"`` or None. Points the file marks as noise (LAS classes 7 and 18) or
        withheld are dropped first (:func:`flagged_points`).
    seed : random seed of the downsampling.
    neighbours : keep the outlier filter's neighbour lists (``PreparedCloud.neighbours``)
        for a later kNN query on the prepared points (the graph method's neighbour graph).
    """
    steps: dict[str, dict[str, Any]] = {}
    validate_cloud(cloud)
    cur = cloud
    cache: NeighbourCache | None = None

    def record(step: str, before: int, t0: float, **extra: Any) -> None:
        steps[step] = {
            "points_in": before,
            "points_out": cur.n_points,
            "seconds": time.perf_counter() - t0,
            **extra,
        }

    if centre:
        t0 = time.perf_counter()
        n0 = cur.n_points
        lattice = coordinate_lattice(cur)
        cur = _centre(cur, lattice)
        record(
            "centre",
            n0,
            t0,
            offset=[float(v) for v in cur.offset],
            lattice=[float(q) if np.isfinite(q) else None for q in lattice],
        )
    t0 = time.perf_counter()
    n0 = cur.n_points
    cur = canonical_order(cur)
    record("order", n0, t0)
    t0 = time.perf_counter()
    n0 = cur.n_points
    dup = duplicate_points(cur.xyz)
    if dup.any():
        cur = cur.select(~dup)
    record("duplicates", n0, t0)
    flagged = flagged_points(cur)
    if flagged.any():  # the file's own noise classes and withheld points
        t0 = time.perf_counter()
        n0 = cur.n_points
        cur = cur.select(~flagged)
        if cur.n_points < MIN_POINTS:
            raise InputError(
                f"{_name(cloud)}: {n0 - cur.n_points:,} of {n0:,} points are classified as "
                f"noise (LAS classes {', '.join(map(str, LAS_NOISE))}) or withheld; "
                f"expected at least {MIN_POINTS} others"
            )
        record("flagged", n0, t0)
    if filter is not None:
        t0 = time.perf_counter()
        n0 = cur.n_points
        if isinstance(filter, dict):
            cur = filter_attribute(cur, **filter)
            record(
                "filter",
                n0,
                t0,
                attribute=filter.get("name"),
                **{k: v for k, v in filter.items() if k != "name"},
            )
        else:
            cur = filter_attribute(cur, *filter)
            record("filter", n0, t0, args=list(filter))
    if downsample is not None:
        t0 = time.perf_counter()
        n0 = cur.n_points
        kw = (
            {"method": "ratio", "ratio": float(downsample)}
            if isinstance(downsample, (int, float))
            else dict(downsample)
        )
        kw.setdefault("seed", seed)
        cur = _downsample(cur, **kw)
        record("downsample", n0, t0, **kw)
    if outliers:
        t0 = time.perf_counter()
        n0 = cur.n_points
        kw = {} if outliers is True else dict(outliers)
        if neighbours:
            cur, _, cache = remove_outliers(cur, **kw, return_neighbours=True)
        else:
            cur = remove_outliers(cur, **kw)
        record("outliers", n0, t0, **kw)
    ground_cloud = None
    if ground is not None:
        from biomorph.tree.ground import remove_ground

        t0 = time.perf_counter()
        n0 = cur.n_points
        method, run = _ground_method(cur, ground)
        if run:
            veg, mask = remove_ground(cur, method=method, **(ground_params or {}))
            ground_cloud = cur.select(mask)
            cur = veg
            if cache is not None:
                cache = cache.select(~mask)
            record("ground", n0, t0, method=method, ground_points=int(mask.sum()))
        else:
            record("ground", n0, t0, method=None, detail="no ground surface detected")
    validate_cloud(cur)
    return PreparedCloud(cloud=cur, ground=ground_cloud, steps=steps, neighbours=cache)
