"""Display helpers: turn core data types into arrays viser draws (no algorithms here).

All functions are vectorised and cheap enough for interactive redraws.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: Colours by branch order / category (RGB 0..255), cycled.
PALETTE = np.array(
    [
        [120, 72, 40],
        [214, 96, 77],
        [244, 165, 62],
        [120, 180, 60],
        [44, 160, 160],
        [66, 110, 210],
        [140, 90, 200],
        [200, 80, 160],
        [110, 110, 110],
    ],
    dtype=np.uint8,
)


def palette(index: NDArray[np.integer]) -> NDArray[np.uint8]:
    """RGB colours for integer labels (orders, trees), cycling through :data:`PALETTE`."""
    idx = np.asarray(index, dtype=np.int64)
    return PALETTE[np.mod(np.maximum(idx, 0), len(PALETTE))]


def subsample(
    points: NDArray[np.float64], max_points: int, seed: int = 0
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


def graph_segments(
    position: NDArray[np.float64], parent: NDArray[np.integer]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Segments ``(m, 2, 3)`` parent->child of a forest and the child index of each."""
    par = np.asarray(parent, dtype=np.int64)
    child = np.flatnonzero(par >= 0)
    pos = np.asarray(position, dtype=float)
    return np.stack([pos[par[child]], pos[child]], axis=1), child


def hex_colour(rgb: NDArray[np.integer]) -> str:
    """``#rrggbb`` of one RGB colour (viser's markdown shows it as a colour chip)."""
    r, g, b = (int(c) for c in np.asarray(rgb).reshape(3))
    return f"#{r:02x}{g:02x}{b:02x}"


def order_legend(orders: NDArray[np.integer], limit: int = 9) -> str:
    """Markdown legend of the branch-order colours used for ``orders``."""
    present = np.unique(np.asarray(orders, dtype=np.int64))[:limit]
    if present.size == 0:
        return ""
    return "Branch order: " + ", ".join(
        f"{int(o)} `{hex_colour(palette(np.array([o]))[0])}`" for o in present
    )


#: Radius colour ramp (thin -> thick): light yellow-green to dark brown.
RADIUS_RAMP = np.array([[200, 220, 90], [230, 160, 50], [170, 80, 40], [90, 40, 30]], float)


def ramp(t: NDArray[np.float64]) -> NDArray[np.uint8]:
    """Colours of :data:`RADIUS_RAMP` at ``t`` in [0, 1] (piecewise linear)."""
    t = np.clip(np.asarray(t, dtype=float), 0.0, 1.0) * (len(RADIUS_RAMP) - 1)
    i = np.minimum(t.astype(np.int64), len(RADIUS_RAMP) - 2)
    f = (t - i)[..., None]
    return (RADIUS_RAMP[i] * (1 - f) + RADIUS_RAMP[i + 1] * f).astype(np.uint8)


def radius_scale(radius: NDArray[np.float64]) -> tuple[float, float]:
    """Range (m) the radius colours span: logarithmic between the 2nd and 98th
    percentile of the radii shown (twigs and trunk differ by two decades)."""
    r = np.asarray(radius, dtype=float)
    r = r[np.isfinite(r) & (r > 0)]
    if r.size == 0:
        return 0.001, 0.01
    lo, hi = (float(v) for v in np.percentile(r, [2, 98]))
    return lo, max(hi, lo * 1.01)


def radius_colors(radius: NDArray[np.float64], lo: float, hi: float) -> NDArray[np.uint8]:
    """Colours of radii on a log scale from ``lo`` (thin) to ``hi`` (thick)."""
    r = np.maximum(np.asarray(radius, dtype=float), 1e-9)
    t = (np.log(r) - np.log(lo)) / max(np.log(hi) - np.log(lo), 1e-9)
    return ramp(t)


def radius_legend(lo: float, hi: float, steps: int = 4) -> str:
    """Markdown legend of :func:`radius_colors` between ``lo`` and ``hi`` (in cm)."""
    values = np.geomspace(lo, hi, steps)
    chips = ", ".join(
        f"{v * 100:.2g} cm `{hex_colour(radius_colors(np.array([v]), lo, hi)[0])}`" for v in values
    )
    return f"Tube radius (log scale): {chips}"


def polygon_loop(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Segments ``(k, 2, 3)`` closing a polygon given by its ``k`` corners."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) < 2:
        return np.zeros((0, 2, 3))
    return np.stack([pts, np.roll(pts, -1, axis=0)], axis=1)


def fit_camera(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Centre and size (bounding-box diagonal) of a set of points: where the camera looks
    and how far it stands, and the scale of markers and joint sizes."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) == 0:
        return np.zeros(3), 1.0
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (lo + hi) / 2.0, float(max(np.linalg.norm(hi - lo), 1e-6))
