"""Shape classes fitted to digitised leaves, and the distance used to judge them.

Distance between two leaves: both midribs are scaled to unit length and sampled at the
same 101 arc-length fractions; the distance is the **maximum** Euclidean distance between
corresponding points, in units of the leaf length ``L`` (so 0.1 means "never further than a
tenth of the leaf length apart"). This is the figure ``bench/leaf.py`` reports per class.

A class's shape is its **medoid**: the digitised leaf whose median distance to the other
leaves of the class is smallest. Unlike a median of tangent angles (which averages two
families of arching and erect leaves into a shape that belongs to neither), the medoid is a
real leaf of the class and minimises the median distance among real shapes. The spread of
a class is the median pairwise distance between its leaves; a fitted shape is *within the
spread* when its median distance to the class is below that.

ADEL (openalea.adel) does not use one shape per class: it draws a leaf at random from the
class database. :func:`class_members` keeps the ``k`` greedy medoids of a class (k chosen
so the median distance of the class to its nearest member is at most ``target``), which
plants then draw from with their seed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from biomorph.core.curves import integrate_angles
from biomorph.core.types import Array

#: Arc-length fractions at which midribs are compared.
COMPARE_S = np.linspace(0.0, 1.0, 101)


def unit_curve(phi_at, s: Array = COMPARE_S) -> Array:
    """Unit-length midrib ``(len(s), 2)`` of a tangent-angle function ``phi_at(s)``."""
    mid = 0.5 * (s[1:] + s[:-1])
    return integrate_angles(np.asarray(phi_at(mid), float), np.diff(s))


def curves_of(shapes: Sequence) -> Array:
    """Unit midribs ``(n, 101, 2)`` of leaf shapes (objects with ``phi_at``)."""
    return np.array([unit_curve(sh.phi_at) for sh in shapes])


def max_distances(curves: Array, ref: Array) -> Array:
    """Max point distance (units of L) of each curve ``(n, k, 2)`` to ``ref`` ``(k, 2)``."""
    return np.linalg.norm(curves - ref[None], axis=-1).max(axis=-1)


def pairwise(curves: Array) -> Array:
    """Matrix of max point distances between all curves ``(n, n)``."""
    n = curves.shape[0]
    out = np.zeros((n, n))
    for i in range(n):
        out[i] = max_distances(curves, curves[i])
    return out


def medoid(curves: Array, dist: Array | None = None) -> int:
    """Index of the curve with the smallest median distance to the others."""
    d = pairwise(curves) if dist is None else dist
    return int(np.argmin(np.median(d, axis=1)))


def class_members(
    curves: Array, target: float = 0.1, k_max: int = 12, dist: Array | None = None
) -> list[int]:
    """Greedy medoids: start from :func:`medoid`, add the curve that lowers the median
    nearest-member distance most, until it is ``<= target`` or ``k_max`` members."""
    d = pairwise(curves) if dist is None else dist
    members = [medoid(curves, d)]
    while len(members) < min(k_max, len(curves)):
        near = d[:, members].min(axis=1)
        if np.median(near) <= target:
            break
        scores = np.median(np.minimum(near[:, None], d), axis=0)
        scores[members] = np.inf
        members.append(int(np.argmin(scores)))
    return members


#: Insertion angles (radians) tried when a shape is aligned to a leaf: a 2° grid over
#: ±90°, then a 0.05° grid around the best one.
_COARSE = np.radians(np.arange(-90.0, 90.0 + 1e-9, 2.0))
_FINE = np.radians(np.arange(-2.0, 2.0 + 1e-9, 0.05))


def aligned_distances(curves: Array, ref: Array) -> tuple[Array, Array]:
    """Max point distance (units of L) of each curve to ``ref`` once ``ref`` is turned
    about the leaf base by the insertion angle that fits that curve best, and that angle
    (radians, counter-clockwise; adding it to ``ref``'s tangent angles gives the fitted
    midrib). The insertion angle is a separate per-leaf parameter of a plant (ADEL's
    ``incline_leaf``/``Linc``), so this compares the *shape* (curvature) of the midribs."""
    cur = np.asarray(curves, float)
    cz = cur[..., 0] + 1j * cur[..., 1]  # (N, K)
    rz = ref[:, 0] + 1j * ref[:, 1]  # (K,)
    i = np.arange(len(cz))
    # coarse grid shared by all curves
    d = np.abs(cz[:, None, :] - np.exp(1j * _COARSE)[None, :, None] * rz).max(-1)  # (N, A)
    a0 = _COARSE[d.argmin(1)]
    a = a0[:, None] + _FINE[None, :]  # (N, F)
    d = np.abs(cz[:, None, :] - np.exp(1j * a)[:, :, None] * rz).max(-1)
    j = d.argmin(1)
    return d[i, j], a[i, j]


def aligned_pairwise(curves: Array) -> Array:
    """Symmetrised matrix of :func:`aligned_distances` between all curves ``(n, n)``."""
    n = curves.shape[0]
    out = np.zeros((n, n))
    for i in range(n):
        out[:, i] = aligned_distances(curves, curves[i])[0]
    return np.minimum(out, out.T)


def class_figures(
    curves: Array, ref: Array, dist: Array | None = None, aligned: bool = False
) -> dict[str, float]:
    """Median / 90th percentile distance of the class to ``ref`` and the class spread
    (median pairwise distance); ``aligned``: with one fitted insertion angle per leaf
    (:func:`aligned_distances`), else as digitised (:func:`max_distances`)."""
    if dist is None:
        dist = aligned_pairwise(curves) if aligned else pairwise(curves)
    e = aligned_distances(curves, ref)[0] if aligned else max_distances(curves, ref)
    iu = np.triu_indices(len(curves), 1)
    return {
        "n": int(len(curves)),
        "median_maxdist": float(np.median(e)),
        "p90_maxdist": float(np.percentile(e, 90)),
        "spread": float(np.median(dist[iu])) if iu[0].size else 0.0,
        "chord_deg": float(np.degrees(np.arctan2(ref[-1, 1], ref[-1, 0]))),
    }


def kmedoids(dist: Array, k: int, iters: int = 100) -> tuple[list[int], Array]:
    """k-medoids (alternating assignment / medoid update, deterministic greedy start:
    the overall medoid, then the leaf that lowers the summed distance most) on a distance
    matrix; returns the medoid indices and each item's family label."""
    n = len(dist)
    med = [int(np.argmin(dist.sum(0)))]
    while len(med) < min(k, n):
        near = dist[:, med].min(1)
        gain = np.maximum(near[:, None] - dist, 0.0).sum(0)
        gain[med] = -1.0
        med.append(int(np.argmax(gain)))
    for _ in range(iters):
        lab = np.argmin(dist[:, med], 1)
        new = []
        for j in range(len(med)):
            idx = np.flatnonzero(lab == j)
            new.append(int(idx[np.argmin(dist[np.ix_(idx, idx)].sum(0))]) if idx.size else med[j])
        if new == med:
            break
        med = new
    return med, np.argmin(dist[:, med], 1)


def shape_families(
    dist: Array, target: float = 0.1, k_max: int = 4
) -> tuple[list[int], Array, list[float]]:
    """Fewest k-medoids families (k <= ``k_max``) whose members' median distance to
    their family medoid is ``<= target`` each (the last k tried when none reaches it):
    medoids, labels, per-family medians."""
    for k in range(1, k_max + 1):
        med, lab = kmedoids(dist, k)
        meds = [float(np.median(dist[lab == j, m])) for j, m in enumerate(med)]
        if max(meds) <= target:
            break
    return med, lab, meds


__all__ = [
    "COMPARE_S",
    "aligned_distances",
    "aligned_pairwise",
    "class_figures",
    "class_members",
    "kmedoids",
    "shape_families",
    "curves_of",
    "max_distances",
    "medoid",
    "pairwise",
    "unit_curve",
]
