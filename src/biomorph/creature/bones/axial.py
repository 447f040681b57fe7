"""Axial bone models: vertebrae by region and the unit rib pair / sternebra (used where a
thoracic vertebra has no trunk section; the rib cage proper is :mod:`.cage`, the skulls
:mod:`.skull`).

Unit models live in the joint's box normalised to a unit cube — x dorsal (+) to ventral
(−) in [−0.5, 0.5], y along the bone in [0, 1], z lateral in [−0.5, 0.5] — and are scaled
per joint by its box (the seed's plan: "models normalised to a unit cube, scaled into each
terminal"). Proportions inside the cube are read off vertebrae of a dog and a horse (centrum
≈ 40 % of the height, neural spine up to 50 %, lumbar transverse processes spanning the
width) and are relative, never metres. Ribs and the sternum reach outside the vertebra's
box: they are sized by the joint's soft-tissue box (``Creature.mass_size``: trunk depth and
width), so the cage wraps the trunk's mass.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numpy.typing import NDArray

from biomorph.creature.bones.prim import SIDES, Parts, ellipsoid, tube, unit

#: neural-spine height (share of the dorsal half), transverse-process span (share of the
#: width), centrum length (share of the bone) per vertebra region, at the region's start and
#: end (linear in between): thoracic spines tallest at the withers, caudal ones fade out
REGION = {
    "cervical": ((0.25, 0.35), (0.75, 0.7), 0.92),
    "thoracic": ((1.0, 0.65), (0.55, 0.6), 0.85),
    "lumbar": ((0.6, 0.55), (1.0, 0.9), 0.9),
    "sacral": ((0.45, 0.35), (0.95, 0.8), 1.0),
    "caudal": ((0.45, 0.0), (0.6, 0.0), 0.88),
}
#: positions along a region are quantised into this many variants (models are cached)
BINS = 5


def _freeze(vf: tuple[NDArray, NDArray]) -> tuple[NDArray, NDArray, NDArray]:
    return unit(vf)


@cache
def vertebra(region: str, t_bin: int, lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """Unit vertebra of ``region`` at position ``t_bin / (BINS - 1)`` along it."""
    s = SIDES[lod]
    t = t_bin / (BINS - 1)
    (h0, h1), (w0, w1), clen = REGION.get(region, REGION["thoracic"])
    spine_h = h0 + (h1 - h0) * t
    span = w0 + (w1 - w0) * t
    y0, y1 = (1 - clen) / 2, (1 + clen) / 2
    parts = Parts()
    # centrum: a spool in the ventral 40 %, slightly waisted
    ys = np.linspace(y0, y1, 4)
    path = np.stack([np.full(4, -0.3), ys, np.zeros(4)], axis=1)
    rc = np.array([0.2, 0.17, 0.17, 0.2])
    parts.add(tube(path, rc, s, radius2=rc * 1.25, ref=[1.0, 0, 0]))
    # neural arch: two pedicles and the lamina over the spinal canal
    ym0, ym1 = 0.5 - 0.3 * clen, 0.5 + 0.3 * clen
    # (rounded: boxes read as boxes on long cervicals; a pedicle is a short column and
    # the lamina a flat arch)
    ya = np.linspace(ym0, ym1, 3)
    ped = np.stack([np.full(3, -0.05), ya, np.full(3, 0.15)], axis=1)
    pr = np.array([0.085, 0.1, 0.085])
    parts.mirrored(tube(ped, pr, max(4, s // 2 + 2), radius2=0.5 * pr, ref=[1.0, 0, 0]), axis=2)
    lam = np.stack([np.full(3, 0.04), ya, np.zeros(3)], axis=1)
    lr = np.array([0.045, 0.05, 0.045])
    parts.add(tube(lam, lr, s, radius2=4.0 * lr, ref=[1.0, 0, 0]))
    if spine_h > 0.02:  # neural spine, leaning caudally (towards y = 0 for headward bones)
        top = 0.08 + 0.42 * spine_h
        sp = np.array([[0.06, 0.5, 0.0], [top, 0.5 - 0.15 * spine_h, 0.0]])
        parts.add(tube(sp, [0.06, 0.03], max(4, s // 2), radius2=[0.035, 0.02], ref=[0, 1.0, 0]))
    if span > 0.02:  # transverse processes
        z1 = 0.5 * span
        tp = np.array([[-0.05, 0.5, 0.12], [-0.02, 0.5 + 0.05 * (region == "lumbar"), z1]])
        parts.mirrored(tube(tp, [0.05, 0.03], max(4, s // 2), ref=[1.0, 0, 0]), axis=2)
    if region == "caudal" and t < 0.7:  # haemal arch (chevron) below the centrum
        ch = np.array([[-0.45, 0.5, 0.0], [-0.5, 0.35, 0.0]])
        parts.add(tube(ch, 0.04, max(4, s // 2), ref=[0, 0, 1.0]))
    return _freeze(parts.mesh())


@cache
def rib_pair(reach: float, pleural: bool, lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """Left and right rib of one vertebra in the trunk's unit box (scaled per joint by the
    trunk depth in x, the vertebra length in y and the trunk width in z; x dorsal, y
    cranial): an arc from the transverse process round the trunk's cross-section to
    ``reach`` of the way to the ventral midline, sloping caudally by 0.8 vertebra lengths;
    fish ribs (``pleural``) are straight and point down, out and back."""
    s = max(4, SIDES[lod] // 2)
    k = 4 + 2 * lod
    parts = Parts()
    if pleural:
        u = np.linspace(0, 1, k)
        path = np.stack([-0.1 - 0.5 * u, 0.5 - 1.2 * u, 0.15 + 0.2 * u], axis=1)
    else:
        a = np.linspace(0.08 * np.pi, reach * np.pi, k)
        path = np.stack([-0.5 + 0.5 * np.cos(a), 0.5 - 0.8 * a / np.pi, 0.5 * np.sin(a)], axis=1)
    parts.mirrored(tube(path, 0.09, s, radius2=0.012, ref=[0, 1.0, 0]), axis=2)
    return _freeze(parts.mesh())


@cache
def sternebra(lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """One segment of the sternum at the ventral midline below the vertebra (trunk unit
    box as for :func:`rib_pair`)."""
    return _freeze(ellipsoid([-1.0, -0.3, 0.0], [0.03, 0.5, 0.05], SIDES[lod]))
