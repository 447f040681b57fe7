"""The spine: three cubic Béziers (neck, back, tail), the seed's C1 fix, arc-length sampling.

Control points are ten 2-D points in the seed's order: neck p0 (head end) … p3 (shoulder),
back p3 … p6 (hip), tail p6 … p9 (tip). Coordinates are whatever the caller uses (px in the
annotation frame, or metres in the creature's sagittal plane).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core.curves import bezier_derivative, bezier_eval

#: Regions of the spine in order.
REGIONS = ("neck", "back", "tail")
_EPS = 1e-9


def curves(points: ArrayLike) -> NDArray[np.float64]:
    """Control polygons ``(3, 4, 2)`` of neck, back and tail from the ten points."""
    p = np.asarray(points, dtype=float).reshape(10, 2)
    return np.stack([p[0:4], p[3:7], p[6:10]])


def _rotate_about(p: NDArray, c: NDArray, ang: float) -> NDArray:
    ca, sa = np.cos(ang), np.sin(ang)
    d = p - c
    return c + np.array([ca * d[0] - sa * d[1], sa * d[0] + ca * d[1]])


def c1_fix(points: ArrayLike) -> NDArray[np.float64]:
    """Make the spine C1 at the shoulder (p3) and hip (p6) joins (seed §6.6.2).

    The control point before the join and the one after it are rotated about the join by
    equal and opposite angles (half the angle between the two tangents each) so both curves
    leave the join in the same direction; their distances to the join are kept. A join next
    to a degenerate (zero-length) neck or tail is left alone: there is no second tangent.
    """
    p = np.array(points, dtype=float).reshape(10, 2)
    for before, join, after in ((2, 3, 4), (5, 6, 7)):
        j = p[join]
        d_in = j - p[before]
        d_out = p[after] - j
        if np.hypot(*d_in) < _EPS or np.hypot(*d_out) < _EPS:
            continue
        a_in = np.arctan2(d_in[1], d_in[0])
        a_out = np.arctan2(d_out[1], d_out[0])
        phi = (a_out - a_in + np.pi) % (2 * np.pi) - np.pi  # signed angle in -> out
        p[before] = _rotate_about(p[before], j, phi / 2)
        p[after] = _rotate_about(p[after], j, -phi / 2)
    return p


def join_angles(points: ArrayLike) -> NDArray[np.float64]:
    """Angles (rad) between the incoming and outgoing tangents at shoulder and hip; NaN where a
    neighbouring curve is degenerate."""
    c = curves(points)
    out = np.full(2, np.nan)
    for k, (a, b) in enumerate(((0, 1), (1, 2))):
        t_in = bezier_derivative(c[a], 1.0)
        t_out = bezier_derivative(c[b], 0.0)
        if np.linalg.norm(t_in) < _EPS or np.linalg.norm(t_out) < _EPS:
            continue
        cross = t_in[0] * t_out[1] - t_in[1] * t_out[0]
        out[k] = float(abs(np.arctan2(cross, t_in @ t_out)))
    return out


_CACHE: dict[bytes, tuple] = {}


def sample(
    points: ArrayLike, per_curve: int = 24
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Dense polyline along the whole spine, head end to tail tip.

    Returns ``(xy (m, 2), s (m,) cumulative arc length, region (m,) 0/1/2)``; degenerate
    curves contribute no length. Results are memoised (read-only arrays) because every
    generation step samples the same spine.
    """
    p = np.ascontiguousarray(points, dtype=float)
    key = p.tobytes() + per_curve.to_bytes(2, "little")
    hit = _CACHE.get(key)
    if hit is not None:
        return hit
    out = _sample(p, per_curve)
    for a in out:
        a.setflags(write=False)
    if len(_CACHE) > 256:
        _CACHE.clear()
    _CACHE[key] = out
    return out


_BASIS: dict[int, NDArray] = {}


def _sample(points: NDArray, per_curve: int) -> tuple:
    c = curves(points)
    basis = _BASIS.get(per_curve)
    if basis is None:  # the Bernstein basis at the samples (bezier_eval of the identity)
        basis = bezier_eval(np.eye(4), np.linspace(0.0, 1.0, per_curve + 1))
        _BASIS[per_curve] = basis
    pts = np.einsum("mk,...kd->...md", basis, c)  # bezier_eval(c, t): (3, per_curve+1, 2)
    xy = np.concatenate([pts[0], pts[1, 1:], pts[2, 1:]])
    region = np.concatenate(
        [
            np.zeros(per_curve + 1, np.int64),
            np.ones(per_curve, np.int64),
            np.full(per_curve, 2, np.int64),
        ]
    )
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return xy, s, region


def region_lengths(s: NDArray, region: NDArray) -> NDArray[np.float64]:
    """Arc lengths of neck, back and tail from :func:`sample` output."""
    per = len(region) // 3
    # boundaries: end of neck at index per, end of back at 2*per, end at -1
    return np.array([s[per], s[2 * per] - s[per], s[-1] - s[2 * per]])


def point_at(xy: NDArray, s: NDArray, at: ArrayLike) -> NDArray[np.float64]:
    """Points at arc lengths ``at`` (clamped) along a dense polyline."""
    a = np.clip(np.asarray(at, dtype=float), 0.0, s[-1])
    return np.stack([np.interp(a, s, xy[:, 0]), np.interp(a, s, xy[:, 1])], axis=-1)


def tangent_at(
    xy: NDArray, s: NDArray, at: ArrayLike, h: float | None = None
) -> NDArray[np.float64]:
    """Unit tangents (head→tail direction) at arc lengths ``at`` by central differences."""
    h = max(s[-1] * 1e-3, 1e-9) if h is None else h
    a = np.asarray(at, dtype=float)
    d = point_at(xy, s, a + h) - point_at(xy, s, a - h)
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    return d / np.where(n > 0, n, 1.0)
