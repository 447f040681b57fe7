"""Leaf/wood separation by neighbourhood thickness (a step before skeletonisation).

Why: a skeleton method follows every point. Foliage around the twig tips of a leaf-on scan
(or needles, epiphytes, stray returns) grows spurious twigs: on the synthetic presets with
5 % leaf clutter the graph method's tip count (NOB) rose to 170–290 % of the truth and the
total length to 108–125 %, while 8 mm range noise and self-occlusion alone changed neither
by more than 10 % (bench/tree.py, docs/tree.md).

Feature: for every point, the covariance of its ``k`` nearest neighbours (k = 12) and its
eigenvalues ``λ1 ≥ λ2 ≥ λ3``. ``√λ3`` is the **thickness** of the neighbourhood: the RMS
distance of the points from their best-fitting plane. Bark is a surface, so at that
scale it is a thin sheet (or, on a twig, a thin line) whose thickness is the scanner's
range noise; foliage clutter is a volume of points scattered in depth, several times
thicker. Measured on the synthetic scans (8 mm noise): wood median 4–5 mm, foliage median
27–44 mm.

Rule: a point is foliage when its thickness exceeds ``factor`` × the cloud's median
thickness (the median is a wood value as long as wood is most of the cloud, so the
threshold follows the scanner's noise without a parameter in metres). With ``passes = 2``
the features are recomputed on the remaining points once: foliage points that survived
the first pass among other foliage points stand out once their neighbours are gone.
The synthetic foliage is removed to 80–95 %; 0.1–6 % of the wood goes with it, nearly
all on the thinnest twig tips, which are buried in the foliage (their neighbourhoods are
foliage too, no local feature can tell them apart).

Detection (``detect=True``, what ``skeletonize`` does by default): a leafless scan loses
those twig points for nothing, so the split is only applied when the cloud has foliage —
more than 0.3 % of its points thicker than 6 × the median. Measured after ``prepare``
(whose outlier removal already takes the sparsest foliage): the synthetic leafy scans
0.51–3.5 % (the conifer lowest: its foliage sits among dense twigs), the same trees
without leaves ≤ 0.12 %, the real clouds in ``../shared/data/trees`` ≤ 0.01 % except the
pine plot with undergrowth (0.46 %), the 40,000-point demo birch (4 mm noise, no leaves)
0.66 % — so sparse leafless scans can still trigger it (costs ~1.5 % F1 there).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.errors import InputError, ParameterError
from biomorph.tree.neighbours import NeighbourCache, query_blocks, query_workers

__all__ = [
    "neighbourhood_thickness",
    "separate_foliage",
    "FoliageSplit",
    "scatter_ratio",
    "check_not_only_leaves",
    "require_wood",
    "SCATTER_LEAVES",
]

_CHUNK = 200_000  #: points per block of neighbourhood covariances (bounds memory)


def neighbourhood_thickness(
    xyz: NDArray[np.float64],
    k: int = 12,
    kdtree: cKDTree | None = None,
    neighbours: NeighbourCache | None = None,
) -> NDArray[np.float64]:
    """RMS distance (m) of each point's ``k`` nearest neighbours (itself included) from
    their least-squares plane: ``√λ3`` of the neighbourhood covariance. Computed in blocks
    of 200,000 points, so memory stays ~100 MB for any cloud size. ``kdtree``: a k-d tree
    of ``xyz``; ``neighbours``: the :class:`~biomorph.tree.neighbours.NeighbourCache` of
    ``xyz`` (e.g. the outlier filter's), whose lists give the rows they decide (the same
    neighbours, so the same values) and the tree the others."""
    xyz = np.asarray(xyz, dtype=np.float64)
    n = xyz.shape[0]
    if k < 4:
        raise ParameterError(f"foliage neighbourhood k must be >= 4 points, got {k}")
    if n < k:
        return np.zeros(n)
    tree = kdtree if kdtree is not None else cKDTree(xyz)
    out = np.empty(n)
    if neighbours is not None and neighbours.n == n:
        for a in range(0, n, _CHUNK):
            _, idx = neighbours.query(k, tree, xyz, a, a + _CHUNK)
            out[a : a + idx.shape[0]] = _thickness(xyz, idx, k)
        return out
    # blocks in spatial order (the tree's own for its own points): the query and the
    # neighbour gather stay in cache
    own = tree.data is xyz
    for rows, _, idx in query_blocks(tree, None if own else xyz, k, block=_CHUNK):
        out[rows] = _thickness(xyz, idx, k)
    return out


def _thickness(xyz: NDArray[np.float64], idx: NDArray, k: int) -> NDArray[np.float64]:
    """``√λ3`` of the covariance of the points ``xyz[idx[i]]``, per row ``i``."""
    nb = xyz[idx]
    nb -= nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb) / k
    lam = np.linalg.eigvalsh(cov)[:, 0]
    return np.sqrt(np.maximum(lam, 0.0))


@dataclass(frozen=True)
class FoliageSplit:
    """Result of :func:`separate_foliage`.

    wood : boolean mask over the input points (True = kept as wood).
    thickness : first-pass neighbourhood thickness per point (m).
    threshold : thickness limit of each pass (m); empty when nothing was removed because
        no foliage was detected.
    foliage_share : share of points thicker than ``DETECT_FACTOR`` × the median (first pass).
    detected : whether foliage was detected (always True with ``detect=False``).
    """

    wood: NDArray[np.bool_]
    thickness: NDArray[np.float64]
    threshold: tuple[float, ...]
    foliage_share: float = 0.0
    detected: bool = True
    #: the k-d tree of all the input points, if the first pass built one (for a later
    #: query on the same points)
    kdtree: cKDTree | None = field(default=None, repr=False, compare=False)

    @property
    def foliage_fraction(self) -> float:
        return float(1.0 - self.wood.mean()) if self.wood.size else 0.0


DETECT_FACTOR = 6.0  #: "clearly foliage": thicker than this × the median
DETECT_SHARE = 0.003  #: foliage present when more than this share of points is


#: clouds above this many points are first checked for foliage on a seeded sample of this
#: size (the share of thick neighbourhoods is a mean: ±0.05 % at 200,000 samples for the
#: 0.3 % limit); the sample's spacing is coarser, so its neighbourhoods are wider, as in a
#: sparser scan of the same tree
DETECT_SAMPLE = 200_000


def _detected_share(xyz: NDArray[np.float64], k: int) -> float:
    """Share of thick neighbourhoods (> ``DETECT_FACTOR`` × median) on a seeded sample."""
    n = xyz.shape[0]
    pick = np.sort(np.random.default_rng(0).choice(n, size=min(n, DETECT_SAMPLE), replace=False))
    th = neighbourhood_thickness(xyz[pick], k)
    return float(np.mean(th > DETECT_FACTOR * np.median(th)))


def separate_foliage(
    xyz: NDArray[np.float64],
    factor: float = 3.0,
    k: int = 12,
    passes: int = 2,
    detect: bool = False,
    neighbours: NeighbourCache | None = None,
) -> FoliageSplit:
    """Split a tree cloud into wood and foliage by neighbourhood thickness (module doc).

    Parameters
    ----------
    xyz : ``float[n, 3]`` points (m).
    factor : foliage = thickness above ``factor`` × the median thickness of the pass
        (> 1; smaller removes more foliage and more twig tips).
    k : neighbourhood size (points).
    passes : how many times the features are recomputed on the remaining points (≥ 1).
    detect : only split when foliage is detected (module doc); otherwise keep every point.
    neighbours : the :class:`~biomorph.tree.neighbours.NeighbourCache` of ``xyz`` (at
        least ``k`` neighbours per point, e.g. the outlier filter's): the passes take the
        neighbourhoods it decides from it instead of querying them again (same result).
    """
    if not factor > 1:
        raise ParameterError(
            f"foliage factor must be > 1 (a multiple of the median "
            f"neighbourhood thickness), got {factor}"
        )
    if passes < 1:
        raise ParameterError(f"foliage passes must be >= 1, got {passes}")
    xyz = np.asarray(xyz, dtype=np.float64)
    n = xyz.shape[0]
    wood = np.ones(n, dtype=bool)
    first = np.zeros(n)
    share = 0.0
    limits: list[float] = []
    if detect and n > DETECT_SAMPLE:
        # no foliage on a seeded sample: skip the full feature pass (1M points: ~1/3 of
        # the pipeline's CPU); clouds up to DETECT_SAMPLE points are judged on every point
        sampled = _detected_share(xyz, k)
        if sampled <= DETECT_SHARE:
            return FoliageSplit(wood, first, (), sampled, False)
    if neighbours is not None and neighbours.n != n:
        neighbours = None
    kd0 = None  # the first pass's k-d tree (of all the points)
    for it in range(passes):
        idx = np.flatnonzero(wood)
        if idx.size <= 4 * k:
            break
        pts = xyz[idx]
        kd = cKDTree(pts)
        if it == 0:
            kd0 = kd
        elif neighbours is not None:
            neighbours = neighbours.select(idx)
        th = neighbourhood_thickness(pts, k, kdtree=kd, neighbours=neighbours)
        med = float(np.median(th))
        if it == 0:
            first = th
            share = float(np.mean(th > DETECT_FACTOR * med))
            if detect and share <= DETECT_SHARE:
                return FoliageSplit(wood, first, (), share, False, kdtree=kd0)
        limit = factor * med
        limits.append(limit)
        leafy = th > limit
        if not leafy.any():
            break
        wood[idx[leafy]] = False
    return FoliageSplit(wood, first, tuple(limits), share, True, kdtree=kd0)


#: median :func:`scatter_ratio` above which a cloud is a volume of scattered returns, not
#: wood: 0.75 × the ratio of a uniformly filled ball (0.28, k = 12). Measured: the real
#: clouds in ``../shared/data/trees`` 0.12–0.18 (bark is a surface, the ratio is the range
#: noise over the neighbourhood size), the synthetic presets with 8 mm noise and 5 % leaf
#: clutter 0.05–0.15 (2,000 to 240,000 points), their leaf clutter alone 0.25–0.27
SCATTER_LEAVES = 0.21


def _scatter_sample(xyz: NDArray[np.float64], sample: int, seed: int) -> NDArray[np.float64]:
    xyz = np.asarray(xyz, dtype=np.float64)
    n = xyz.shape[0]
    if n > sample:
        xyz = xyz[np.sort(np.random.default_rng(seed).choice(n, size=sample, replace=False))]
    return xyz


def _scatter_ratios(
    xyz: NDArray[np.float64], d: NDArray[np.float64], idx: NDArray, k: int
) -> NDArray[np.float64]:
    """The ratio of every row with a positive ``k``-th distance (rows without one are
    left out, as :func:`scatter_ratio` leaves them out of its median)."""
    nb = xyz[idx]
    nb -= nb.mean(axis=1, keepdims=True)
    lam = np.linalg.eigvalsh(np.einsum("nki,nkj->nij", nb, nb) / k)[:, 0]
    ok = d[:, -1] > 0
    return np.sqrt(np.maximum(lam[ok], 0.0)) / d[ok, -1]


def scatter_ratio(
    xyz: NDArray[np.float64], k: int = 12, sample: int = 20_000, seed: int = 0
) -> float:
    """Median neighbourhood thickness (``√λ3`` of a point's ``k`` nearest neighbours) over
    the distance to the ``k``-th neighbour, on a seeded random subsample of ``sample``
    points: scale-free, small on surfaces and lines (wood), about 0.28 inside a uniformly
    filled volume. The subsample keeps the neighbourhood much wider than the range noise
    whatever the scan density (on the full 240,000-point conifer with 8 mm noise the
    neighbourhoods shrink to a few noise widths and the ratio rises from 0.09 to 0.19)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.shape[0] <= k:
        return 0.0
    xyz = _scatter_sample(xyz, sample, seed)
    d, idx = cKDTree(xyz).query(xyz, k=k, workers=-1)
    r = _scatter_ratios(xyz, d, idx, k)
    if not r.size:
        return 0.0
    return float(np.median(r))


def _leaves_error(source: str, s: float) -> InputError:
    return InputError(
        f"{source}: the points look like foliage only (median neighbourhood "
        f"scatter {s:.2f} > {SCATTER_LEAVES}, a volume of scattered returns; "
        "wood surfaces give 0.07-0.18); expected a scan showing the stem and "
        "branches"
    )


def check_not_only_leaves(xyz: NDArray[np.float64], source: str = "point cloud") -> float:
    """Raise :class:`InputError` when the cloud is foliage only (its median
    :func:`scatter_ratio` exceeds ``SCATTER_LEAVES``): a skeleton through scattered leaf
    returns is a silent wrong model. Returns the ratio."""
    s = scatter_ratio(xyz)
    if s > SCATTER_LEAVES:
        raise _leaves_error(source, s)
    return s


#: :func:`require_wood` looks at the sample in this many interleaved parts
_WOOD_PARTS = 8


def require_wood(xyz: NDArray[np.float64], source: str = "point cloud") -> None:
    """:func:`check_not_only_leaves` without the ratio: the same verdict (and error), but
    the sample's points are looked at in interleaved parts, and the look stops once more
    than half of the sample has a ratio at most ``SCATTER_LEAVES`` — the median can then
    no longer exceed it (on wood, ~70 % of the points do: about a quarter of the
    neighbour queries spared). A foliage cloud is looked at whole, for the message."""
    k = 12
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.shape[0] <= k:
        return
    xyz = _scatter_sample(xyz, 20_000, 0)
    m = xyz.shape[0]
    tree = cKDTree(xyz)
    need = m // 2 + 1  # ratios <= the limit that put the median (of <= m) below it
    low = 0
    parts = []
    for j in range(_WOOD_PARTS):
        rows = np.arange(j, m, _WOOD_PARTS)
        if not rows.size:
            continue
        d, idx = tree.query(xyz[rows], k=k, workers=query_workers(rows.size))
        r = _scatter_ratios(xyz, d, idx, k)
        parts.append(r)
        low += int(np.count_nonzero(r <= SCATTER_LEAVES))
        if low >= need:
            return
    r = np.concatenate(parts)
    s = float(np.median(r)) if r.size else 0.0
    if s > SCATTER_LEAVES:
        raise _leaves_error(source, s)
