"""Display helpers: turn core data types into arrays viser draws (no algorithms here).

All functions are vectorised and cheap enough for interactive redraws.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: Colours by branch order / category (RGB 0..255), cycled.
PALETTE = np.array([
    [120, 72, 40], [214, 96, 77], [244, 165, 62], [120, 180, 60], [44, 160, 160],
    [66, 110, 210], [140, 90, 200], [200, 80, 160], [110, 110, 110],
], dtype=np.uint8)


def palette(index: NDArray[np.integer]) -> NDArray[np.uint8]:
    """RGB colours for integer labels (orders, trees), cycling through :data:`PALETTE`."""
    idx = np.asarray(index, dtype=np.int64)
    return PALETTE[np.mod(np.maximum(idx, 0), len(PALETTE))]


def subsample(points: NDArray[np.float64], max_points: int, seed: int = 0
              ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """At most ``max_points`` of ``points`` (uniform random, reproducible) and their indices."""
    pts = np.asarray(points, dtype=float)
    n = pts.shape[0]
    if n <= max_points:
        return pts, np.arange(n)
    idx = np.sort(np.random.default_rng(seed).choice(n, size=max_points, replace=False))
    return pts[idx], idx


def height_colors(points: NDArray[np.float64], axis: int = 2) -> NDArray[np.uint8]:
    """Greenish-to-brown colours by height along ``axis`` for point clouds."""
    pts = np.asarray(points, dtype=float)
    if pts.size == 0:
        return np.zeros((0, 3), np.uint8)
    h = pts[:, axis]
    t = (h - h.min()) / max(float(np.ptp(h)), 1e-12)
    low = np.array([110.0, 90.0, 70.0])
    high = np.array([90.0, 170.0, 90.0])
    return (low + t[:, None] * (high - low)).astype(np.uint8)


def graph_segments(position: NDArray[np.float64], parent: NDArray[np.integer]
                   ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Segments ``(m, 2, 3)`` parent->child of a forest and the child index of each."""
    par = np.asarray(parent, dtype=np.int64)
    child = np.flatnonzero(par >= 0)
    pos = np.asarray(position, dtype=float)
    return np.stack([pos[par[child]], pos[child]], axis=1), child


def tubes(position: NDArray[np.float64], parent: NDArray[np.integer],
          radius: NDArray[np.float64], sides: int = 8
          ) -> tuple[NDArray[np.float32], NDArray[np.int32], NDArray[np.int64]]:
    """Open cylinders along every edge, each with the radius of its two end nodes.

    Returns ``(vertices, faces, edge_of_face)``; the last maps each face to the child node
    of its edge (for colouring by order).
    """
    seg, child = graph_segments(position, parent)
    if len(child) == 0:
        return (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32),
                np.zeros(0, np.int64))
    r = np.maximum(np.asarray(radius, dtype=float), 0.0)
    r0, r1 = r[np.asarray(parent)[child]], r[child]
    a, b = seg[:, 0], seg[:, 1]
    axis = b - a
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    d = axis / np.maximum(length, 1e-12)
    helper = np.where(np.abs(d[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(d, helper)
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
    v = np.cross(d, u)
    ang = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    ring = np.cos(ang)[None, :, None] * u[:, None, :] + np.sin(ang)[None, :, None] * v[:, None, :]
    bottom = a[:, None, :] + r0[:, None, None] * ring
    top = b[:, None, :] + r1[:, None, None] * ring
    m = len(child)
    verts = np.concatenate([bottom, top], axis=1).reshape(-1, 3)
    k = np.arange(sides)
    k1 = (k + 1) % sides
    base = (np.arange(m) * 2 * sides)[:, None]
    f1 = np.stack([base + k, base + k1, base + sides + k1], axis=-1)
    f2 = np.stack([base + k, base + sides + k1, base + sides + k], axis=-1)
    faces = np.concatenate([f1, f2], axis=1).reshape(-1, 3)
    edge_of_face = np.repeat(child, 2 * sides)
    return verts.astype(np.float32), faces.astype(np.int32), edge_of_face


def polygon_loop(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Segments ``(k, 2, 3)`` closing a polygon given by its ``k`` corners."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) < 2:
        return np.zeros((0, 2, 3))
    return np.stack([pts, np.roll(pts, -1, axis=0)], axis=1)


def fit_camera(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Centre and size of a set of points (for scaling markers and joint sizes)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) == 0:
        return np.zeros(3), 1.0
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (lo + hi) / 2.0, float(max(np.linalg.norm(hi - lo), 1e-6))
