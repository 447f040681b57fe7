"""Plastic transformations: local, length-conserving edits of a leaf (wind, gravity, damage).

Operators act on the **angle form** of the midrib, ``phi(s)`` (tangent angle above the
horizontal). Changing the angle on an interval ``[s0, s1]`` and rotating the distal part
rigidly changes the curvature ``dphi/ds`` only inside the interval, and because the midrib
is rebuilt by integrating unit tangents, its length is conserved exactly. Width operators
scale ``r(s)`` on an interval. Operators compose (:func:`apply_ops`), never mutate the input
leaf, and also edit the leaf's ``N(age, s)`` collection so growing leaves feel them too.

================  ==========================================================================
operator          effect on [s0, s1]
================  ==========================================================================
``bend``          adds ``angle`` radians of bending, spread evenly (positive bends *down*)
``curvature``     multiplies the existing curvature by ``factor`` (0 straightens, 2 doubles)
``scale_width``   multiplies the width by ``factor`` (0 = torn away, 0.5 = damaged margin)
================  ==========================================================================
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.leaf.shape import LeafShape


@dataclass(frozen=True)
class PlasticOp:
    """One operator: ``kind`` in {"bend", "curvature", "scale_width"}, interval, value."""

    kind: str
    s0: float
    s1: float
    value: float

    def __post_init__(self) -> None:
        if self.kind not in ("bend", "curvature", "scale_width"):
            raise ParameterError(
                f"plastic operator {self.kind!r} unknown; expected bend, curvature or scale_width"
            )
        if not (0.0 <= self.s0 < self.s1 <= 1.0):
            raise ParameterError(f"interval [{self.s0}, {self.s1}] must satisfy 0 <= s0 < s1 <= 1")
        if not np.isfinite(self.value):
            raise ParameterError(f"{self.kind} value {self.value!r} must be finite")
        if self.kind in ("curvature", "scale_width") and self.value < 0:
            raise ParameterError(f"{self.kind} factor {self.value!r} must be >= 0")


def bend(s0: float, s1: float, angle: float) -> PlasticOp:
    """Add ``angle`` radians of bending on ``[s0, s1]`` (wind/gravity; negative lifts)."""
    return PlasticOp("bend", s0, s1, angle)


def curvature(s0: float, s1: float, factor: float) -> PlasticOp:
    """Scale the curvature on ``[s0, s1]`` by ``factor`` (0 = straight there)."""
    return PlasticOp("curvature", s0, s1, factor)


def scale_width(s0: float, s1: float, factor: float) -> PlasticOp:
    """Scale the width on ``[s0, s1]`` by ``factor`` (damage, growth defects)."""
    return PlasticOp("scale_width", s0, s1, factor)


def _with_knots(s: Array, extra: Sequence[float]) -> Array:
    return np.unique(np.concatenate([s, np.asarray(extra, float)]))


def _angle_delta(s: Array, phi: Array, op: PlasticOp) -> Array:
    """Angle change at knots ``s`` (which contain s0 and s1)."""
    if op.kind == "bend":
        ramp = np.clip((s - op.s0) / (op.s1 - op.s0), 0.0, 1.0)
        return -op.value * ramp
    # curvature: phi' = phi(s0) + f (phi − phi(s0)) inside, distal part rotated rigidly
    p0 = np.interp(op.s0, s, phi)
    p1 = np.interp(op.s1, s, phi)
    inside = (s >= op.s0) & (s <= op.s1)
    delta = np.where(inside, (op.value - 1.0) * (phi - p0), 0.0)
    return np.where(s > op.s1, (op.value - 1.0) * (p1 - p0), delta)


def _apply_angles(s: Array, phi: Array, op: PlasticOp) -> tuple[Array, Array]:
    s_new = _with_knots(s, (op.s0, op.s1))
    phi_new = np.interp(s_new, s, phi)
    return s_new, phi_new + _angle_delta(s_new, phi_new, op)


def apply_op(shape: LeafShape, op: PlasticOp) -> LeafShape:
    """A new leaf with ``op`` applied (the input is unchanged)."""
    if op.kind == "scale_width":
        eps = 1e-9 * (op.s1 - op.s0)
        knots = [op.s0, op.s1] + [k for k in (op.s0 - eps, op.s1 + eps) if 0 <= k <= 1]
        sr = _with_knots(shape.s_r, knots)
        r = np.interp(sr, shape.s_r, shape.r)
        inside = (sr >= op.s0) & (sr <= op.s1)
        r = np.where(inside, r * op.value, r)
        if r.max() <= 0:
            raise ParameterError("scale_width removed the whole blade (width 0 everywhere)")
        peak = r.max()
        # keep absolute widths: relative profile renormalised, maximal width rescaled
        return shape.with_(s_r=sr, r=r / peak, width=shape.width * peak)
    s, phi = _apply_angles(shape.s, shape.phi, op)
    coll = shape.collection
    if coll is not None:
        rows = [_apply_angles(coll.s, row, op) for row in coll.phi]
        coll = coll.with_phi(rows[0][0], np.array([r[1] for r in rows]))
    return shape.with_(s=s, phi=phi, collection=coll)


def apply_ops(shape: LeafShape, ops: Sequence[PlasticOp]) -> LeafShape:
    """Compose operators left to right."""
    for op in ops:
        shape = apply_op(shape, op)
    return shape


__all__ = ["PlasticOp", "apply_op", "apply_ops", "bend", "curvature", "scale_width"]
