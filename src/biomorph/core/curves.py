"""Curves: cubic Béziers, polylines by arc length, and interpolating splines.

All functions are vectorised: control polygons may carry leading batch axes
``(..., 4, d)`` and parameters are arrays. Splines wrap scipy's well-kept interpolators
(natural cubic, PCHIP) and add a Catmull–Rom spline (cubic Hermite with centred tangents),
input validation with clear errors, and an ``extrapolate`` policy (``"clamp"`` holds the end
values, which is what editing curves — blend weights, speed keys — want).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import CubicHermiteSpline, CubicSpline, PchipInterpolator

from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError

# 16-point Gauss–Legendre rule on [0, 1] for arc-length integrals of cubic segments
_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W


# --------------------------------------------------------------------------- Bézier
def _bernstein(t: Array) -> Array:
    mt = 1.0 - t
    return np.stack([mt**3, 3 * mt**2 * t, 3 * mt * t**2, t**3], axis=-1)


def _check_ctrl(ctrl: ArrayLike) -> Array:
    c = np.asarray(ctrl, dtype=float)
    if c.ndim < 2 or c.shape[-2] != 4:
        raise ParameterError(
            f"cubic Bézier control points have shape {c.shape}; expected (..., 4, d)"
        )
    return c


def bezier_eval(ctrl: ArrayLike, t: ArrayLike) -> Array:
    """Points of cubic Béziers ``ctrl (..., 4, d)`` at parameters ``t``.

    Scalar ``t`` gives ``(..., d)``; ``t`` of shape ``(m,)`` gives ``(..., m, d)``.
    """
    c = _check_ctrl(ctrl)
    t_arr = np.asarray(t, dtype=float)
    basis = _bernstein(np.atleast_1d(t_arr))  # (m, 4)
    out = np.einsum("mk,...kd->...md", basis, c)
    return out[..., 0, :] if t_arr.ndim == 0 else out


def bezier_derivative(ctrl: ArrayLike, t: ArrayLike, order: int = 1) -> Array:
    """Derivative of order 1, 2 or 3 with respect to ``t`` (same shapes as :func:`bezier_eval`)."""
    c = _check_ctrl(ctrl)
    t_arr = np.asarray(t, dtype=float)
    tt = np.atleast_1d(t_arr)
    if order == 1:
        d = 3.0 * np.diff(c, axis=-2)  # (...,3,d) quadratic
        mt = 1.0 - tt
        basis = np.stack([mt**2, 2 * mt * tt, tt**2], axis=-1)
    elif order == 2:
        d = 6.0 * np.diff(c, n=2, axis=-2)  # (...,2,d) linear
        basis = np.stack([1.0 - tt, tt], axis=-1)
    elif order == 3:
        d = 6.0 * np.diff(c, n=3, axis=-2)
        basis = np.ones((tt.size, 1))
    else:
        raise ParameterError(f"derivative order {order} not in 1, 2, 3")
    out = np.einsum("mk,...kd->...md", basis, d)
    return out[..., 0, :] if t_arr.ndim == 0 else out


def bezier_split(ctrl: ArrayLike, t: float) -> tuple[Array, Array]:
    """Split at ``t`` by de Casteljau: two control polygons covering [0, t] and [t, 1]."""
    c = _check_ctrl(ctrl)
    p01 = (1 - t) * c[..., 0, :] + t * c[..., 1, :]
    p12 = (1 - t) * c[..., 1, :] + t * c[..., 2, :]
    p23 = (1 - t) * c[..., 2, :] + t * c[..., 3, :]
    p012 = (1 - t) * p01 + t * p12
    p123 = (1 - t) * p12 + t * p23
    mid = (1 - t) * p012 + t * p123
    left = np.stack([c[..., 0, :], p01, p012, mid], axis=-2)
    right = np.stack([mid, p123, p23, c[..., 3, :]], axis=-2)
    return left, right


def bezier_arc_length(
    ctrl: ArrayLike, t0: float = 0.0, t1: float = 1.0, segments: int = 8
) -> Array:
    """Arc length of cubic Béziers between ``t0`` and ``t1`` (Gauss–Legendre, piecewise).

    Returns shape ``(...)``. Accurate to ~1e-10 relative for well-behaved curves.
    """
    edges = np.linspace(t0, t1, segments + 1)
    h = np.diff(edges)
    nodes = (edges[:-1, None] + h[:, None] * _GL_X[None, :]).ravel()
    weights = (h[:, None] * _GL_W[None, :]).ravel()
    speed = np.linalg.norm(bezier_derivative(ctrl, nodes), axis=-1)
    return speed @ weights


def bezier_arclength_params(ctrl: ArrayLike, n: int, samples: int = 256) -> Array:
    """Parameters ``t`` of ``n`` points spaced equally by arc length (ends included).

    Works on batches: ``ctrl (..., 4, d)`` gives ``(..., n)``. The arc-length function is
    tabulated at ``samples`` parameters (trapezoid on the speed) and inverted linearly.
    """
    if n < 2:
        raise ParameterError(f"need at least 2 points along the curve, got n={n}")
    c = _check_ctrl(ctrl)
    tt = np.linspace(0.0, 1.0, samples)
    speed = np.linalg.norm(bezier_derivative(c, tt), axis=-1)  # (..., samples)
    cum = np.concatenate(
        [
            np.zeros(speed.shape[:-1] + (1,)),
            np.cumsum(0.5 * (speed[..., 1:] + speed[..., :-1]) * np.diff(tt), axis=-1),
        ],
        axis=-1,
    )
    total = cum[..., -1:]
    flat = cum.reshape(-1, samples)
    tot = flat[:, -1:]
    # normalise each curve's table to [0, 1] and offset rows by 2 so one searchsorted
    # over the flattened tables inverts every curve at once
    u = np.where(tot > 0, flat / np.where(tot > 0, tot, 1.0), tt[None, :])
    rows = np.arange(flat.shape[0])[:, None] * 2.0
    table = (u + rows).ravel()
    query = (np.linspace(0.0, 1.0, n)[None, :] + rows).ravel()
    j = np.clip(np.searchsorted(table, query, side="right") - 1, 0, table.size - 2)
    j = np.minimum(
        j, (np.arange(flat.shape[0])[:, None] * samples + samples - 2).repeat(n, axis=1).ravel()
    )
    t_all = np.tile(tt, flat.shape[0])
    du = table[j + 1] - table[j]
    frac = np.where(du > 0, (query - table[j]) / np.where(du > 0, du, 1.0), 0.0)
    out = t_all[j] + frac * (t_all[j + 1] - t_all[j])
    out = out.reshape(flat.shape[0], n)
    out[:, 0], out[:, -1] = 0.0, 1.0
    target_shape = total.shape[:-1] + (n,)
    return out.reshape(target_shape)


# --------------------------------------------------------------------------- polylines
def segment_projection(p: ArrayLike, a: ArrayLike, b: ArrayLike) -> tuple[Array, Array]:
    """For points ``p`` and segments ``a → b`` (all broadcast over the leading axes, the
    last one the coordinates): the parameter ``t`` in [0, 1] of the segment's point nearest
    to ``p``, and the distance to it. A zero-length segment gives ``t = 0``."""
    p, a, b = (np.asarray(v, dtype=float) for v in (p, a, b))
    ab = b - a
    ap = p - a
    den = np.maximum(np.einsum("...k,...k->...", ab, ab), 1e-300)
    t = np.clip(np.einsum("...k,...k->...", ap, ab) / den, 0.0, 1.0)
    return t, np.linalg.norm(ap - t[..., None] * ab, axis=-1)


def kasa_circle(xy: ArrayLike) -> tuple[Array, Array, float]:
    """The algebraic (Kåsa) least-squares circle through 2-D points ``(n, 2)``, fitted about
    their mean: returns the points less their mean, the circle's centre in those
    coordinates and its squared radius (≤ 0 when no circle fits)."""
    u = np.asarray(xy, dtype=float)
    u = u - u.mean(axis=0)
    a = np.column_stack([u, np.ones(u.shape[0])])
    sol, *_ = np.linalg.lstsq(a, (u**2).sum(axis=1), rcond=None)
    cx, cy = sol[0] / 2, sol[1] / 2
    return u, np.array([cx, cy]), float(sol[2] + cx * cx + cy * cy)


def polyline_arc_length(points: ArrayLike) -> Array:
    """Cumulative arc length ``s`` (starting at 0) along a polyline ``(..., n, d)``."""
    p = np.asarray(points, dtype=float)
    seg = np.linalg.norm(np.diff(p, axis=-2), axis=-1)
    return np.concatenate([np.zeros(seg.shape[:-1] + (1,)), np.cumsum(seg, axis=-1)], axis=-1)


def resample_polyline(points: ArrayLike, n: int | None = None, s: ArrayLike | None = None) -> Array:
    """Points along a polyline ``(n_in, d)`` at ``n`` equal arc-length steps or at arc
    lengths ``s`` (metres from the start, clamped to the length)."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[0] < 2:
        raise ParameterError(f"polyline needs shape (n>=2, d), got {p.shape}")
    cum = polyline_arc_length(p)
    if (n is None) == (s is None):
        raise ParameterError("give exactly one of n (point count) or s (arc lengths)")
    if n is not None:
        if n < 2:
            raise ParameterError(f"resample needs n >= 2, got {n}")
        s_new = np.linspace(0.0, cum[-1], n)
    else:
        s_new = np.clip(np.asarray(s, dtype=float), 0.0, cum[-1])
    # drop zero-length steps so np.interp sees strictly increasing abscissae
    keep = np.concatenate([[True], np.diff(cum) > 0])
    if keep.sum() < 2:
        return np.repeat(p[:1], len(s_new), axis=0)
    return np.stack([np.interp(s_new, cum[keep], p[keep, k]) for k in range(p.shape[1])], axis=-1)


# --------------------------------------------------------------------------- splines
Extrapolate = Literal["clamp", "extrapolate"]


def _check_knots(x: ArrayLike, y: ArrayLike, name: str, minimum: int = 2) -> tuple[Array, Array]:
    xa = np.asarray(x, dtype=float).reshape(-1)
    ya = np.asarray(y, dtype=float)
    if xa.size < minimum:
        raise ParameterError(f"{name} needs at least {minimum} keys, got {xa.size}")
    if ya.shape[0] != xa.size:
        raise ParameterError(f"{name}: {xa.size} key positions but {ya.shape[0]} key values")
    if not (np.isfinite(xa).all() and np.isfinite(ya).all()):
        raise ParameterError(f"{name}: keys hold NaN or inf")
    if np.any(np.diff(xa) <= 0):
        i = int(np.flatnonzero(np.diff(xa) <= 0)[0])
        raise ParameterError(
            f"{name}: key positions must increase strictly; "
            f"x[{i}]={xa[i]:g} then x[{i + 1}]={xa[i + 1]:g}"
        )
    return xa, ya


class _Spline:
    """Common evaluation with an extrapolation policy."""

    def __init__(self, x: Array, impl, extrapolate: Extrapolate) -> None:
        if extrapolate not in ("clamp", "extrapolate"):
            raise ParameterError(
                f"extrapolate must be 'clamp' or 'extrapolate', got {extrapolate!r}"
            )
        self.x = x
        self._impl = impl
        self.extrapolate = extrapolate

    def __call__(self, t: ArrayLike) -> Array:
        t = np.asarray(t, dtype=float)
        if self.extrapolate == "clamp":
            t = np.clip(t, self.x[0], self.x[-1])
        return self._impl(t)

    def derivative(self, order: int = 1):
        """The derivative as a callable (zero outside the keys when clamped)."""
        d = self._impl.derivative(order)
        x0, x1, clamp = self.x[0], self.x[-1], self.extrapolate == "clamp"

        def f(t: ArrayLike) -> Array:
            t = np.asarray(t, dtype=float)
            out = d(np.clip(t, x0, x1) if clamp else t)
            if clamp:
                outside = (t < x0) | (t > x1)
                out = np.where(
                    outside.reshape(outside.shape + (1,) * (out.ndim - t.ndim)), 0.0, out
                )
            return out

        return f

    def integral(self, a: float, b: float) -> Array:
        """Integral from ``a`` to ``b`` (inside the keys)."""
        return self._impl.integrate(a, b)


class NaturalCubicSpline(_Spline):
    """C2 interpolating cubic with zero second derivative at both ends.

    ``y`` may be ``(n,)`` or ``(n, d)``. Two keys give a straight line.
    """

    def __init__(self, x: ArrayLike, y: ArrayLike, extrapolate: Extrapolate = "clamp") -> None:
        xa, ya = _check_knots(x, y, "natural cubic spline")
        super().__init__(xa, CubicSpline(xa, ya, bc_type="natural", axis=0), extrapolate)


class MonotoneSpline(_Spline):
    """Shape-preserving C1 cubic (PCHIP, Fritsch–Carlson): no overshoot between keys,
    monotone data stay monotone."""

    def __init__(self, x: ArrayLike, y: ArrayLike, extrapolate: Extrapolate = "clamp") -> None:
        xa, ya = _check_knots(x, y, "monotone spline")
        super().__init__(xa, PchipInterpolator(xa, ya, axis=0), extrapolate)


class CatmullRomSpline(_Spline):
    """C1 cubic Hermite through the keys with centred (Catmull–Rom) tangents
    ``(y[i+1] - y[i-1]) / (x[i+1] - x[i-1])`` and one-sided tangents at the ends."""

    def __init__(self, x: ArrayLike, y: ArrayLike, extrapolate: Extrapolate = "clamp") -> None:
        xa, ya = _check_knots(x, y, "Catmull-Rom spline")
        dydx = np.empty_like(ya)
        dydx[1:-1] = (ya[2:] - ya[:-2]) / (xa[2:] - xa[:-2]).reshape((-1,) + (1,) * (ya.ndim - 1))
        dydx[0] = (ya[1] - ya[0]) / (xa[1] - xa[0])
        dydx[-1] = (ya[-1] - ya[-2]) / (xa[-1] - xa[-2])
        super().__init__(xa, CubicHermiteSpline(xa, ya, dydx, axis=0), extrapolate)


# --------------------------------------------------------------------------- angle form
# Plane curves stored as a tangent angle phi(s) over normalised arc length (leaf midribs):
# every discretisation keeps its length exactly, and editing phi conserves length.
def _finite_1d(name: str, values: ArrayLike) -> Array:
    try:
        arr = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numbers; got {values!r}") from exc
    if not np.isfinite(arr).all():
        i = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise InputError(f"{name}[{i}] is {arr[i]}; expected finite numbers")
    return arr


def midrib_arc_length(x: ArrayLike, y: ArrayLike) -> Array:
    """Cumulative arc length ``s_i = Σ √(Δx² + Δy²)`` of digitised plane-curve points.

    Raises :class:`~biomorph.errors.InputError` for fewer than 2 points, non-finite values
    or duplicate consecutive points (zero-length segments, i.e. non-increasing arc length).
    """
    xa, ya = _finite_1d("midrib x", x), _finite_1d("midrib y", y)
    if xa.size != ya.size:
        raise InputError(f"midrib has {xa.size} x values but {ya.size} y values")
    if xa.size < 2:
        raise InputError(f"midrib has {xa.size} point(s); expected at least 2 (base and tip)")
    seg = np.hypot(np.diff(xa), np.diff(ya))
    if np.any(seg <= 0):
        i = int(np.flatnonzero(seg <= 0)[0])
        raise InputError(
            f"midrib points {i} and {i + 1} are duplicates ({xa[i]:g}, {ya[i]:g});"
            " expected strictly increasing arc length"
        )
    return np.concatenate([[0.0], np.cumsum(seg)])


def angles_from_points(
    x: ArrayLike, y: ArrayLike, rounding: float = 0.25
) -> tuple[Array, Array, float]:
    """Angle form of a digitised plane curve.

    Returns ``(s, phi, length)``: knots ``s`` in [0, 1] and the unwrapped tangent angle
    ``phi`` (radians above +x) at the knots, piecewise linear between them; ``length`` is the
    polyline length in the input units. Each data segment keeps its direction; at every
    digitised corner the angle turns linearly over a window of ``±rounding`` times the
    shorter adjacent segment, centred on the corner, so the rounded curve stays on the
    digitised points to second order (no drift along the curve). ``rounding=0`` keeps the
    polyline's sharp corners.
    """
    cum = midrib_arc_length(x, y)
    xa, ya = np.asarray(x, float).reshape(-1), np.asarray(y, float).reshape(-1)
    total = float(cum[-1])
    seg_phi = np.unwrap(np.arctan2(np.diff(ya), np.diff(xa)))
    seg_len = np.diff(cum) / total
    si = cum / total
    if seg_phi.size == 1:
        return np.array([0.0, 1.0]), np.array([seg_phi[0], seg_phi[0]]), total
    w = np.clip(rounding, 1e-6, 0.49) * np.minimum(seg_len[:-1], seg_len[1:])  # per corner
    corner = si[1:-1]
    s = np.concatenate([[0.0], np.ravel(np.column_stack([corner - w, corner + w])), [1.0]])
    phi = np.concatenate(
        [[seg_phi[0]], np.ravel(np.column_stack([seg_phi[:-1], seg_phi[1:]])), [seg_phi[-1]]]
    )
    keep = np.concatenate([[True], np.diff(s) > 0])
    return s[keep], phi[keep], total


def integrate_angles(phi_seg: Array, seg_len: Array) -> Array:
    """Plane-curve points from segment angles (midpoint rule), vectorised over leading axes.

    ``phi_seg (..., k-1)`` radians, ``seg_len (..., k-1)`` lengths → ``(..., k, 2)`` points
    (horizontal, vertical) starting at the origin; every segment has exactly its length.
    """
    dx = seg_len * np.cos(phi_seg)
    dz = seg_len * np.sin(phi_seg)
    shape = phi_seg.shape[:-1] + (1,)
    x = np.concatenate([np.zeros(shape), np.cumsum(dx, axis=-1)], axis=-1)
    z = np.concatenate([np.zeros(shape), np.cumsum(dz, axis=-1)], axis=-1)
    return np.stack([x, z], axis=-1)


def solve_arc_length(points: ArrayLike, target: float, s: ArrayLike) -> Array:
    """Re-parametrise a polyline by arc length and scale it so its length equals ``target``.

    Points are returned at arc-length fractions ``s`` (in [0, 1]) of the scaled curve,
    shifted so the first one is the origin.
    """
    p = np.asarray(points, dtype=float)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 0:
        raise InputError("curve has zero length; cannot solve the arc-length constraint")
    keep = np.concatenate([[True], seg > 0])
    q = np.asarray(s, float) * cum[-1]
    out = np.stack([np.interp(q, cum[keep], p[keep, k]) for k in range(p.shape[1])], axis=-1)
    return (out - out[0]) * (target / cum[-1])


__all__ = [
    "bezier_eval",
    "bezier_derivative",
    "bezier_split",
    "bezier_arc_length",
    "bezier_arclength_params",
    "polyline_arc_length",
    "resample_polyline",
    "segment_projection",
    "kasa_circle",
    "NaturalCubicSpline",
    "MonotoneSpline",
    "CatmullRomSpline",
    "angles_from_points",
    "integrate_angles",
    "midrib_arc_length",
    "solve_arc_length",
]
