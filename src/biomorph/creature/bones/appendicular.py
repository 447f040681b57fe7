"""Limb bone models: scapula, clavicle, pelvis (ilium, ischium, pubis), long bones with shaft
and epiphyses (paired radius+ulna / tibia+fibula), hands and feet (metapodials, phalanges,
claws/hooves/nails), wing hands with digits, fin radials and rays.

Unit models use the limb joint's box as a unit cube: y along the bone in [0, 1], z the
flexion axis (lateral for legs), x the remaining axis; girdle boxes are thin in z, so the
scapula and ilium blades lie in x-y. Pieces that reach outside their box (the pubis and
ischium meeting at the midline, the clavicle to the sternum) are built in metres from the
joint's world frame. Digit counts per class follow the usual vertebrate formulae (mammal
and reptile hands and feet five digits, bird feet four, bird wings three reduced digits,
bat wings five; hooved mammals bear on one or two) and sizes are shares of the segment.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numpy.typing import NDArray

from biomorph.creature.bones.prim import SIDES, Parts, box, ellipsoid, torus, tube, unit

#: digits (count, spread of the fan in radians, end shape) per (class, limb role)
DIGITS = {
    ("mammal", "hand"): (5, 0.35, "claw"),
    ("mammal", "foot"): (5, 0.3, "claw"),
    ("bird", "foot"): (4, 0.9, "claw"),
    ("reptile", "hand"): (5, 0.7, "claw"),
    ("reptile", "foot"): (5, 0.6, "claw"),
    ("amphibian", "hand"): (4, 0.8, "nail"),
    ("amphibian", "foot"): (5, 0.8, "nail"),
    ("bird", "hand"): (3, 0.2, "nail"),
    ("mammal", "wing"): (5, 1.4, "nail"),
    ("bird", "wing"): (3, 0.15, "nail"),
}
#: hooved mammals (unguligrade stance): cattle and deer bear on two digits ending in hooves
#: (the cloven default); a horse on one (:func:`ungulate` follows ``hoof_digits``)
UNGULATE = (2, 0.18, "hoof")


def ungulate(hoof_digits: int) -> tuple[int, float, str]:
    """Autopod of a hooved foot with ``hoof_digits`` hooves (horse 1, others 2): digits,
    fan spread (none for a single centred digit) and end."""
    n = max(1, int(hoof_digits))
    return (n, UNGULATE[1] if n > 1 else 0.0, UNGULATE[2])


def _freeze(vf: tuple[NDArray, NDArray]) -> tuple[NDArray, NDArray, NDArray]:
    return unit(vf)


@cache
def long_bone(kind: str, lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """Unit long bone: ``single`` (humerus, femur, metapodial: shaft, proximal head,
    distal condyles) or ``paired`` (radius+ulna, tibia+fibula: two shafts sharing ends)."""
    s = SIDES[lod]
    parts = Parts()
    k = 5 + 2 * lod
    y = np.linspace(0.04, 0.96, k)
    # shaft waist: thick epiphyses (0.5 of the box half-width), slim diaphysis (0.22)
    prof = 0.22 + 0.2 * (np.abs(y - 0.5) / 0.46) ** 4
    if kind == "paired":
        main = np.stack([np.zeros(k), y, np.full(k, -0.12)], axis=1)
        parts.add(tube(main, prof * 0.9, s, ref=[1.0, 0, 0]))
        minor = np.stack([np.full(k, 0.05), y, np.full(k, 0.22)], axis=1)
        parts.add(tube(minor, prof * 0.45, max(4, s // 2), ref=[1.0, 0, 0]))
        parts.add(ellipsoid([0.0, 0.05, 0.02], [0.4, 0.07, 0.48], s))
        parts.add(ellipsoid([0.0, 0.95, 0.02], [0.36, 0.06, 0.46], s))
        parts.add(ellipsoid([-0.25, 0.02, -0.1], [0.18, 0.08, 0.15], max(4, s // 2)))
    elif kind == "phalanx":  # short bone: shaft between two knobbed ends
        path = np.stack([np.zeros(k), y, np.zeros(k)], axis=1)
        parts.add(tube(path, 0.5 * prof + 0.12, s, ref=[1.0, 0, 0]))
    else:
        path = np.stack([np.zeros(k), y, np.zeros(k)], axis=1)
        parts.add(tube(path, prof, s, ref=[1.0, 0, 0]))
        parts.add(ellipsoid([0.14, 0.1, 0.0], [0.3, 0.1, 0.3], s))  # head
        parts.add(ellipsoid([-0.2, 0.12, 0.1], [0.16, 0.12, 0.18], max(4, s // 2)))
        for z in (-0.2, 0.2):  # condyles
            parts.add(ellipsoid([0.0, 0.92, z], [0.3, 0.08, 0.2], max(4, s // 2 + 1)))
    return _freeze(parts.mesh())


@cache
def scapula(lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """Unit shoulder blade: a flat plate (x across it, z its thickness) widest at the dorsal
    border (y = 0) and narrowing to the neck, a ridge (the scapular spine) standing out of
    its lateral face (+z) down the middle, and the glenoid cup at y = 1."""
    s = SIDES[lod]
    parts = Parts()
    k = 4 + lod
    y = np.linspace(0.02, 0.86, k)
    width = 0.5 - 0.38 * (y / 0.86) ** 0.8  # broad dorsal border, narrow neck
    path = np.stack([0.04 * np.sin(np.pi * y), y, np.zeros(k)], axis=1)
    parts.add(tube(path, width, s, radius2=np.full(k, 0.08), ref=[1.0, 0, 0]))
    ridge = np.stack([np.zeros(k), y * 0.95 + 0.03, 0.08 + 0.22 * np.sin(np.pi * y * 0.9)], 1)
    parts.add(tube(ridge, 0.04, max(4, s // 2), radius2=0.06, ref=[0, 0, 1.0]))
    parts.add(ellipsoid([0.0, 0.93, 0.0], [0.16, 0.08, 0.3], s))
    return _freeze(parts.mesh())


@cache
def ilium(lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """Unit ilium: a blade from the sacrum (y = 0) to the acetabulum (y = 1) with its rim."""
    s = SIDES[lod]
    parts = Parts()
    path = np.array([[0.0, 0.04, 0.0], [0.0, 0.45, 0.0], [0.0, 0.8, 0.0]])
    parts.add(tube(path, [0.5, 0.32, 0.16], s, radius2=[0.45, 0.4, 0.4], ref=[1.0, 0, 0]))
    parts.add(torus([0.0, 0.94, 0.0], 1, 0.14, 0.05, s))
    parts.add(ellipsoid([0.0, 0.92, 0.0], [0.17, 0.07, 0.4], s))
    return _freeze(parts.mesh())


@cache
def _unit_rod(lod: int) -> tuple[NDArray, NDArray, NDArray]:
    k = 3 + lod
    y = np.linspace(0, 1, k)
    path = np.stack([np.zeros(k), y, np.zeros(k)], axis=1)
    return _freeze(
        tube(path, 1.0 - 0.3 * np.sin(np.pi * y), max(4, SIDES[lod] // 2), ref=[1.0, 0, 0])
    )


def rod(a: NDArray, b: NDArray, radius: float, lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """A bone rod from ``a`` to ``b`` (metres), waisted in the middle:
    ``(vertices, normals, faces)`` from one cached unit rod."""
    v0, n0, f = _unit_rod(lod)
    d = np.asarray(b, float) - np.asarray(a, float)
    L = float(np.linalg.norm(d))
    d = d / L if L > 0 else np.array([0.0, 1.0, 0.0])
    helper = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 0, 1.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    w = np.cross(u, d)
    frame = np.stack([u, d, w], axis=1)  # columns: unit x, y, z -> world
    s = np.array([radius, max(L, 1e-12), radius])
    return v0 * s @ frame.T + a, (n0 / s) @ frame.T, f


@cache
def autopod(
    n_digits: int, spread: float, end: str, lod: int, digits_from: float
) -> tuple[NDArray, NDArray, NDArray]:
    """Unit hand/foot/wing-hand: ``n_digits`` metapodials side by side from y = 0 to
    ``digits_from`` and a fan of phalanges (three per digit, shortening) beyond it, ending
    in ``end`` (``claw`` curved cone, ``hoof`` wedge, ``nail`` flat tip); the fan opens in
    the x-y plane (away from the flexion axis z)."""
    s = max(4, SIDES[lod] // 2 + 1)
    parts = Parts()
    n = max(1, n_digits)
    zs = np.linspace(-0.32, 0.32, n) if n > 1 else np.zeros(1)
    r_meta = 0.42 / n if n > 1 else 0.3
    for i, z in enumerate(zs):
        a = np.array([0.0, 0.02, z * 0.6])
        b = np.array([0.0, digits_from, z])
        parts.add(
            tube(
                np.stack([a, 0.5 * (a + b), b]),
                [r_meta * 1.2, r_meta, r_meta * 1.2],
                s,
                ref=[1.0, 0, 0],
            )
        )
        ang = (i / (n - 1) - 0.5) * spread if n > 1 else 0.0
        d = np.array([np.sin(ang), np.cos(ang), 0.0])
        rest = 1.0 - digits_from
        lens = rest * np.array([0.45, 0.3, 0.25])
        p = b.copy()
        r = r_meta * 0.9
        for k, L in enumerate(lens[:-1] if end != "nail" else lens):
            q = p + d * L
            parts.add(tube(np.stack([p, q]), [r, r * 0.85], s, ref=[1.0, 0, 0]))
            p = q
            r *= 0.8
            if k == 0:
                d = d + np.array([-0.08, 0, 0])
                d /= np.linalg.norm(d)
        tip = p + d * lens[-1]
        if end == "claw":  # curved cone, bending ventrally (-x)
            mid = 0.5 * (p + tip) + np.array([0.04, 0, 0])
            parts.add(
                tube(
                    np.stack([p, mid, tip + np.array([-0.06, 0, 0])]),
                    [r * 1.1, r * 0.6, 0.004],
                    s,
                    ref=[0, 0, 1.0],
                )
            )
        elif end == "hoof":  # wedge: wide at the sole, closing at the toe
            parts.add(
                tube(
                    np.stack([p, tip]),
                    [r * 1.8, r * 0.5],
                    s,
                    radius2=[r * 1.4, r * 0.9],
                    ref=[1.0, 0, 0],
                )
            )
    return _freeze(parts.mesh())


@cache
def fin(n_rays: int, spread: float, lod: int, base: bool) -> tuple[NDArray, NDArray, NDArray]:
    """Unit fin: ``base`` radials (short parallel rods) or a fan of thin ``n_rays`` rays in
    the x-y plane."""
    s = max(3, SIDES[lod] // 2)
    parts = Parts()
    if base:
        for x in np.linspace(-0.35, 0.35, 4):
            parts.add(
                tube(np.array([[x * 0.6, 0.02, 0.0], [x, 0.98, 0.0]]), 0.1, s, ref=[0, 0, 1.0])
            )
        return _freeze(parts.mesh())
    for a in np.linspace(-spread / 2, spread / 2, n_rays):
        d = np.array([0.5 * np.sin(a) / max(np.sin(spread / 2), 1e-9) * 0.9, np.cos(a), 0.0])
        tip = d / max(np.linalg.norm(d), 1e-9)
        tip[1] = max(tip[1], 0.6)
        parts.add(
            tube(
                np.array([[0.0, 0.0, 0.0], [tip[0] * 0.5, 0.5 * tip[1], 0.0], tip]),
                [0.06, 0.04, 0.015],
                s,
                ref=[0, 0, 1.0],
            )
        )
    return _freeze(parts.mesh())


@cache
def digit_end(end: str, lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """Unit phalanx (``phalanx``) or end phalanx with its horn (``claw``/``hoof``/``nail``)."""
    s = max(4, SIDES[lod] // 2 + 1)
    if end == "claw":
        return _freeze(
            tube(
                np.array([[0.0, 0.16, 0.0], [0.1, 0.55, 0.0], [-0.3, 0.98, 0.0]]),
                [0.45, 0.3, 0.03],
                s,
                radius2=[0.4, 0.25, 0.03],
                ref=[0, 0, 1.0],
            )
        )
    if end == "hoof":
        return _freeze(
            tube(
                np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                [0.5, 0.2],
                s,
                radius2=[0.5, 0.45],
                ref=[1.0, 0, 0],
            )
        )
    if end == "nail":
        return _freeze(
            tube(
                np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                [0.35, 0.1],
                s,
                radius2=[0.45, 0.4],
                ref=[1.0, 0, 0],
            )
        )
    return long_bone("phalanx", lod)


@cache
def unit_box_model() -> tuple[NDArray, NDArray, NDArray]:
    """The seed's box (unit cube, y from 0 to 1)."""
    return _freeze(box([-0.5, 0.0, -0.5], [0.5, 1.0, 0.5]))


__all__ = [
    "long_bone",
    "scapula",
    "ilium",
    "rod",
    "autopod",
    "fin",
    "digit_end",
    "unit_box_model",
    "DIGITS",
    "UNGULATE",
    "ungulate",
    "ellipsoid",
    "torus",
]
