"""Leaf age: the normalised physiological age and its thermal-time axis.

A leaf's age ``a ∈ [0, 1]`` is normalised (0 = just initiated, 1 = end of its life). This
module holds the age check and the growing-leaf state shared by the shape, growth, mesh
and reduction modules, so that none of them needs to import another one upwards (the leaf
modules form a chain: ``age < mesh < reduction < shape``, ``age < mesh < growth``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from biomorph.errors import ParameterError


class ShapeLike(Protocol):
    """What the state helpers need of a :class:`~biomorph.leaf.shape.LeafShape`."""

    length: float
    width: float
    s_r: Any

    def r_at(self, s: Any) -> Any: ...

    def area(self) -> float: ...


def check_age(age: float) -> float:
    """Return ``age`` as float if it lies in [0, 1] (normalised physiological age)."""
    a = float(age)
    if not np.isfinite(a) or a < 0.0 or a > 1.0:
        raise ParameterError(
            f"age {age!r} is outside [0, 1]; the leaf age is normalised "
            "(0 = just initiated, 1 = mature and senescent)"
        )
    return a


#: Normalised age at which the blade reaches its final length (default extension phase of
#: a bare shape; preset leaves use their thermal-time axis, see :data:`PHYLLOCHRON_RANGE`).
EXTENSION_END = 0.5
#: Leaf life on the thermal-time axis in phyllochrons from full extension, mapped onto the
#: normalised age [0, 1] (the wheat Tremie12 collection's range; used for presets without a
#: collection too): full extension at ``a = 2/14``.
PHYLLOCHRON_RANGE = (-2.0, 12.0)
#: Smallest relative length of a leaf (age 0): a just-visible tip.
MIN_RELATIVE_LENGTH = 0.02


@dataclass(frozen=True)
class LeafState:
    """State of a growing leaf. Lengths in metres, angles in radians."""

    age: float
    length: float
    visible: float
    width_factor: float = 1.0
    bend: float = 0.0


def relative_length(age: float, extension_end: float = EXTENSION_END) -> float:
    """``l / L`` of a leaf of normalised ``age``: linear extension until ``extension_end``."""
    a = check_age(age)
    frac = 1.0 if extension_end <= 0 else min(1.0, a / extension_end)
    return MIN_RELATIVE_LENGTH + (1.0 - MIN_RELATIVE_LENGTH) * frac


def state_at_age(
    shape: ShapeLike,
    age: float,
    extension_end: float | None = None,
    hidden: float = 0.0,
    width_factor: float = 1.0,
    bend: float = 0.0,
) -> LeafState:
    """Default state of ``shape`` at ``age`` (length from :func:`relative_length`; the
    extension ends at ``extension_end``, default the shape's own ``extension_end``)."""
    if extension_end is None:
        extension_end = float(getattr(shape, "extension_end", EXTENSION_END))
    l_cur = shape.length * relative_length(age, extension_end)
    return LeafState(check_age(age), l_cur, max(l_cur - hidden, 0.0), width_factor, bend)


def visible_area(shape: ShapeLike, state: LeafState | None = None) -> float:
    """Exact flat area (m²) of the visible part: the width is piecewise linear in the arc
    length, so the trapezoid rule over the width knots is exact."""
    L = shape.length
    if state is None:
        return shape.area()
    lo, hi = state.length - state.visible, state.length
    if hi <= lo:
        return 0.0
    knots = shape.s_r * L - (L - state.length)  # width knots in current-leaf metres
    sigma = np.unique(np.concatenate([[lo, hi], knots[(knots > lo) & (knots < hi)]]))
    shat = np.clip(1.0 - (state.length - sigma) / L, 0, 1)
    w = shape.width * state.width_factor * shape.r_at(shat)
    return float(np.trapezoid(w, sigma))


__all__ = [
    "EXTENSION_END",
    "PHYLLOCHRON_RANGE",
    "MIN_RELATIVE_LENGTH",
    "LeafState",
    "ShapeLike",
    "check_age",
    "relative_length",
    "state_at_age",
    "visible_area",
]
