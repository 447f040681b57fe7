"""Mesh building blocks for bone models: swept tubes, ellipsoids, boxes, tori, and a parts
list that concatenates them.

Everything is plain ``(vertices (n, 3), faces (m, 3))`` numpy arrays with outward,
counter-clockwise faces; a :class:`Parts` collects pieces and returns one pair. ``sides``
(ring resolution) comes from the level of detail (:data:`SIDES`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: ring resolution per level of detail: 0 low (game LOD), 1 medium (default), 2 high
SIDES = (5, 8, 14)


def _ring_faces(n_rings: int, sides: int, start: int = 0) -> NDArray[np.int64]:
    k = np.arange(n_rings - 1)[:, None] * sides
    j = np.arange(sides)[None, :]
    a0 = start + k + j
    a1 = start + k + (j + 1) % sides
    b0, b1 = a0 + sides, a1 + sides
    f = np.stack([np.stack([a0, b1, a1], -1), np.stack([a0, b0, b1], -1)], axis=2)
    return f.reshape(-1, 3)


def _cap(center: int, ring_start: int, sides: int, flip: bool) -> NDArray[np.int64]:
    j = np.arange(sides)
    a, b = ring_start + j, ring_start + (j + 1) % sides
    c = np.full(sides, center)
    return np.stack([c, a, b] if flip else [c, b, a], axis=1)


def _frames(path: NDArray, ref: NDArray | None) -> tuple[NDArray, NDArray, NDArray]:
    t = np.gradient(path, axis=0) if len(path) > 1 else np.array([[0.0, 1.0, 0.0]])
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    if ref is None:
        mean = t.mean(axis=0)
        ref = (
            np.array([1.0, 0, 0])
            if abs(mean[0]) < 0.8 * np.linalg.norm(mean) + 1e-9
            else np.array([0, 0, 1.0])
        )
    ref = np.broadcast_to(np.asarray(ref, float), t.shape)
    n = ref - (ref * t).sum(axis=1, keepdims=True) * t
    bad = np.linalg.norm(n, axis=1) < 1e-6
    if bad.any():
        alt = np.where(np.abs(t[bad, 1:2]) < 0.9, [[0.0, 1, 0]], [[1.0, 0, 0]])
        n[bad] = alt - (alt * t[bad]).sum(axis=1, keepdims=True) * t[bad]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return t, n, np.cross(t, n)


def tube(
    path: ArrayLike,
    radius: ArrayLike,
    sides: int,
    *,
    radius2: ArrayLike | None = None,
    ref: ArrayLike | None = None,
    caps: bool = True,
) -> tuple[NDArray, NDArray]:
    """A tube swept along ``path (k, 3)`` with elliptical rings: ``radius`` along the ring's
    normal (towards ``ref``), ``radius2`` (default ``radius``) along the binormal."""
    p = np.asarray(path, float)
    r1 = np.broadcast_to(np.asarray(radius, float), (len(p),))
    r2 = r1 if radius2 is None else np.broadcast_to(np.asarray(radius2, float), (len(p),))
    t, n, b = _frames(p, None if ref is None else np.asarray(ref, float))
    a = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    ca, sa = np.cos(a), np.sin(a)
    rings = (
        p[:, None, :]
        + (r1[:, None, None] * ca[None, :, None]) * n[:, None, :]
        + (r2[:, None, None] * sa[None, :, None]) * b[:, None, :]
    )
    v = rings.reshape(-1, 3)
    f = _ring_faces(len(p), sides)
    if caps:
        base = len(v)
        v = np.concatenate([v, p[:1], p[-1:]])
        f = np.concatenate(
            [
                f,
                _cap(base, 0, sides, flip=True),
                _cap(base + 1, (len(p) - 1) * sides, sides, flip=False),
            ]
        )
    return v, f[:, ::-1]  # rings run n -> b with b = t x n: reversed winding faces out


def ellipsoid(center: ArrayLike, radii: ArrayLike, sides: int) -> tuple[NDArray, NDArray]:
    """An ellipsoid with ``sides`` meridians and ``max(3, sides // 2)`` parallels."""
    c, r = np.asarray(center, float), np.asarray(radii, float)
    n_lat = max(3, sides // 2 + 1)
    th = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    # rings stacked along -y .. +y so the ring order matches tube()'s (+y sweep)
    y = -np.cos(th)
    s = np.sin(th)
    ring = np.stack(
        [np.outer(s, np.cos(ph)), np.repeat(y[:, None], sides, 1), -np.outer(s, np.sin(ph))],
        axis=-1,
    )
    v = ring.reshape(-1, 3)
    f = _ring_faces(len(th), sides)
    base = len(v)
    v = np.concatenate([v, [[0, -1.0, 0], [0, 1.0, 0]]])
    f = np.concatenate(
        [
            f,
            _cap(base, 0, sides, flip=True),
            _cap(base + 1, (len(th) - 1) * sides, sides, flip=False),
        ]
    )
    return v * r + c, f[:, ::-1]


def box(lo: ArrayLike, hi: ArrayLike) -> tuple[NDArray, NDArray]:
    """An axis-aligned box from corner ``lo`` to ``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    u = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1], [0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]],
        float,
    )
    f = np.array(
        [
            [0, 1, 2],
            [0, 2, 3],
            [4, 6, 5],
            [4, 7, 6],
            [0, 4, 5],
            [0, 5, 1],
            [1, 5, 6],
            [1, 6, 2],
            [2, 6, 7],
            [2, 7, 3],
            [3, 7, 4],
            [3, 4, 0],
        ]
    )
    return lo + u * (hi - lo), f


def torus(
    center: ArrayLike, axis: int, radius: float, thickness: float, sides: int
) -> tuple[NDArray, NDArray]:
    """A ring of ``radius`` around coordinate axis ``axis`` (0, 1, 2) through ``center``."""
    a = np.linspace(0, 2 * np.pi, max(sides, 6) + 1)
    circle = np.zeros((len(a), 3))
    u, w = [k for k in range(3) if k != axis]
    circle[:, u], circle[:, w] = radius * np.cos(a), radius * np.sin(a)
    path = circle[:-1]
    ref = np.zeros(3)
    ref[axis] = 1.0
    v, _ = tube(
        np.concatenate([path, path[:1]]), thickness, max(4, sides // 2), ref=ref, caps=False
    )
    ring = max(4, sides // 2)
    n = len(path)
    f = _ring_faces(n + 1, ring)
    # close the loop: the last ring is the first one again
    v = v[: n * ring]
    f = (f % (n * ring))[:, ::-1]
    return v + np.asarray(center, float), f


class Parts:
    """Collects ``(vertices, faces)`` pieces; :meth:`mesh` concatenates them."""

    def __init__(self) -> None:
        self.v: list[NDArray] = []
        self.f: list[NDArray] = []
        self.n = 0

    def add(self, piece: tuple[NDArray, NDArray]) -> Parts:
        v, f = piece
        self.v.append(np.asarray(v, float))
        self.f.append(np.asarray(f, np.int64) + self.n)
        self.n += len(v)
        return self

    def mirrored(self, piece: tuple[NDArray, NDArray], axis: int) -> Parts:
        """Add ``piece`` and its mirror image across the plane ``coordinate[axis] = 0``."""
        v, f = piece
        self.add(piece)
        m = np.array(v, float)
        m[:, axis] *= -1
        return self.add((m, np.asarray(f)[:, ::-1]))

    def mesh(self) -> tuple[NDArray, NDArray]:
        if not self.v:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
        return np.concatenate(self.v), np.concatenate(self.f)


def vertex_normals(v: NDArray, f: NDArray) -> NDArray:
    """Area-weighted unit vertex normals."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    fn = np.cross(b - a, c - a)
    idx = f.reshape(-1)
    n = len(v)
    acc = np.stack(
        [np.bincount(idx, weights=np.repeat(fn[:, k], 3), minlength=n) for k in range(3)], axis=1
    )
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    return np.divide(acc, norm, out=np.zeros_like(acc), where=norm > 0)


def unit(vf: tuple[NDArray, NDArray]) -> tuple[NDArray, NDArray, NDArray]:
    """A cached unit model: ``(vertices, normals, faces)``, read-only."""
    v, f = np.asarray(vf[0], float), np.asarray(vf[1], np.int64)
    out = (v, vertex_normals(v, f), f)
    for a in out:
        a.setflags(write=False)
    return out


def tubes(
    paths: ArrayLike,
    radius: ArrayLike,
    sides: int,
    *,
    radius2: ArrayLike | None = None,
    ref: ArrayLike,
) -> tuple[NDArray, NDArray]:
    """Many capped tubes at once (the same as :func:`tube` on each): ``paths (r, k, 3)``,
    radii ``(r, k)`` along the ring normal (towards ``ref (r, 3)``, one per tube) and
    ``radius2`` along the binormal; one ``(vertices, faces)`` pair, tubes one after another."""
    p = np.asarray(paths, float)
    n_t, k = p.shape[:2]
    r1 = np.broadcast_to(np.asarray(radius, float), (n_t, k))
    r2 = r1 if radius2 is None else np.broadcast_to(np.asarray(radius2, float), (n_t, k))
    t = np.gradient(p, axis=1)
    t /= np.maximum(np.linalg.norm(t, axis=2, keepdims=True), 1e-12)
    ref_a = np.broadcast_to(np.asarray(ref, float)[:, None, :], t.shape)
    n = ref_a - (ref_a * t).sum(axis=2, keepdims=True) * t
    bad = np.linalg.norm(n, axis=2) < 1e-6
    if bad.any():  # a tangent along the reference: as tube()
        tb = t[bad]
        alt = np.where(np.abs(tb[:, 1:2]) < 0.9, [[0.0, 1, 0]], [[1.0, 0, 0]])
        n[bad] = alt - (alt * tb).sum(axis=1, keepdims=True) * tb
    n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)
    b = np.cross(t, n)
    a = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    ca, sa = np.cos(a), np.sin(a)
    rings = (
        p[:, :, None, :]
        + (r1[..., None, None] * ca[None, None, :, None]) * n[:, :, None, :]
        + (r2[..., None, None] * sa[None, None, :, None]) * b[:, :, None, :]
    ).reshape(n_t, k * sides, 3)
    v = np.concatenate([rings, p[:, :1], p[:, -1:]], axis=1)  # (r, k*sides + 2, 3)
    per = k * sides + 2
    f1 = np.concatenate(
        [
            _ring_faces(k, sides),
            _cap(k * sides, 0, sides, flip=True),
            _cap(k * sides + 1, (k - 1) * sides, sides, flip=False),
        ]
    )[:, ::-1]
    f = (f1[None] + (np.arange(n_t) * per)[:, None, None]).reshape(-1, 3)
    return v.reshape(-1, 3), f
