"""Vertebrae placed along the spine by arc length with class-dependent counts.

Counts per region (cervical, trunk = thoracic + lumbar + sacral, caudal) come from the species
the sample resembles (inverse-distance weighted over its nearest dataset species) scaled by
the ratio of region lengths, then clamped to class ranges (mammals 6–9 cervical, birds 10–26,
…; the seed: mammals usually 7, 6–31 possible, birds 10–31).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

#: (min, max) vertebrae per region and class: cervical, trunk, caudal.
COUNT_RANGES = {
    "mammal": ((6, 9), (12, 40), (0, 50)),
    "bird": ((10, 26), (8, 20), (4, 25)),
    "reptile": ((0, 76), (8, 260), (0, 160)),
    "amphibian": ((1, 2), (6, 40), (0, 60)),
    "fish": ((0, 0), (8, 60), (6, 60)),
}

_COUNT_LIMITS = {k: tuple(np.array(v, float).T) for k, v in COUNT_RANGES.items()}


def region_counts(
    cls: str,
    neighbour_counts: ArrayLike,
    weights: ArrayLike,
    lengths: ArrayLike,
    neighbour_lengths: ArrayLike,
    max_total: int = 160,
) -> NDArray[np.int64]:
    """Vertebra counts ``(3,)`` for a sample.

    ``neighbour_counts (k, 3)`` and ``neighbour_lengths (k, 3)`` are the counts and region arc
    lengths of the nearest species, ``weights (k,)`` their weights; ``lengths (3,)`` the
    sample's region arc lengths (same units). A region of (near) zero length gets 0.
    """
    nc = np.asarray(neighbour_counts, dtype=float)
    nl = np.asarray(neighbour_lengths, dtype=float)
    w = np.asarray(weights, dtype=float)
    L = np.asarray(lengths, dtype=float)
    # vertebra length per region from the neighbours, then count = length / vertebra length
    per = np.where(nc > 0, nl / np.maximum(nc, 1), np.nan)
    # per region: nansum(w * per) / sum(w where per is a number) — the same sums (the NaNs
    # zeroed in place, the weights compressed) without nansum's per-call overhead
    wp = w[:, None] * per
    wp[np.isnan(wp)] = 0.0
    ok = ~np.isnan(per)
    seg = np.full(3, np.nan)
    for r in range(3):
        okr = ok[:, r]
        if okr.any():
            seg[r] = wp[:, r].sum() / max(w[okr].sum(), 1e-12)
    base = w @ nc
    counts = np.where(np.isfinite(seg) & (seg > 0), L / np.where(seg > 0, seg, 1), base)
    # blend ratio-based and neighbour counts so counts stay near the vertebral formula
    counts = 0.5 * counts + 0.5 * base
    lo, hi = _COUNT_LIMITS.get(cls, _COUNT_LIMITS["mammal"])
    counts = np.minimum(np.maximum(np.rint(counts), lo), hi)
    if cls == "mammal":
        counts[0] = 7 if counts[0] else 0  # mammals: almost always seven
    total_len = max(L.sum(), 1e-12)
    counts = np.where(L < 0.02 * total_len, 0, counts)
    counts[1] = max(counts[1], 2)
    if counts.sum() > max_total:
        counts = np.maximum(np.floor(counts * max_total / counts.sum()), np.minimum(counts, 1))
    return counts.astype(np.int64)


def boundaries(region_len: ArrayLike, counts: ArrayLike) -> tuple[NDArray, NDArray]:
    """Arc-length positions of vertebra boundaries and the region of each vertebra.

    Vertebrae of one region are equally long. A neck or tail with no vertebrae (count 0) is
    covered by the trunk vertebrae instead, so the chain always spans head end to tail tip.
    Returns ``(edges (m+1,), region (m,))`` measured from the head end.
    """
    L = np.ascontiguousarray(region_len, dtype=float)
    c = np.asarray(counts, dtype=np.int64).copy()
    c[1] = max(c[1], 1)
    return _boundaries_kernel(L, c)


@numba.njit(cache=True)
def _boundaries_kernel(L, c):  # pragma: no cover - compiled
    """:func:`boundaries` compiled: per region ``np.linspace(a[r], a[r + 1], c[r] + 1)[1:]``
    with NumPy's formula (``i * step + start``, ``(i / div) * delta + start`` for a zero step,
    the last point ``stop`` exactly)."""
    a = np.array([0.0, L[0], L[0] + L[1], (L[0] + L[1]) + L[2]])
    if c[0] <= 0:
        a[1] = 0.0
    if c[2] <= 0:
        a[2] = a[3]
    total = 0
    for r in range(3):
        if c[r] > 0:
            total += c[r]
    edges = np.empty(total + 1)
    reg = np.empty(total, np.int64)
    edges[0] = a[0]
    k = 1
    for r in range(3):
        div = c[r]
        if div <= 0:
            continue
        start, stop = a[r], a[r + 1]
        delta = stop - start
        step = delta / div
        for i in range(1, div + 1):
            if i == div:
                v = stop
            elif step == 0:
                v = (i / div) * delta + start
            else:
                v = i * step + start
            edges[k] = v
            reg[k - 1] = r
            k += 1
    return edges, reg
