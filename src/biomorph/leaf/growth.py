"""Dynamics of a growing leaf (Fournier & Pradal 2012, "dynamic" part).

State of a leaf at a time: normalised physiological age ``a ∈ [0, 1]``, current length
``l`` (m, up to the final length ``L``), visible length ``h`` (the part above the sheath),
a width factor (integral of ``dr/d(age)``) and an extra bending angle (integral of
``dθ/d(age)``).

Geometry of a growing leaf (see :func:`biomorph.leaf.mesh.leaf_profile`):

* midrib — the collection ``N(age, s)`` interpolated **by age** at run time (angle form,
  so unit length is kept); the current leaf is the part of that curve whose arc length is
  ``l/L`` (the model's constraint ``∫_0^h |N'(t)| dt − l/L = 0``), i.e. the visible
  midrib has length exactly ``h``;
* width — ``r(s + l − h) · R / r_max``: the visible part shows the distal (tip) portion of
  the mature width profile, because grass leaves grow from a basal meristem and the tip
  emerges first;
* twist and undulation follow the tissue (tip-relative coordinates) like the width.

Time stepping integrates the four user rates ``d(age)/dt``, ``dl/dt``, ``dr/d(age)``,
``dθ/d(age)`` (numbers or callables) by explicit Euler on a fine step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from biomorph.errors import ParameterError
from biomorph.leaf.age import (
    EXTENSION_END,
    MIN_RELATIVE_LENGTH,
    LeafState,
    ShapeLike,
    relative_length,
    state_at_age,
    visible_area,
)
from biomorph.leaf.mesh import LeafBatch, mesh_batch

Rate = float | Callable[[float], float]


def _rate(value: Rate, x: float) -> float:
    return float(value(x)) if callable(value) else float(value)


@dataclass(frozen=True)
class GrowthRates:
    """The four user rates of the model (constants or callables).

    age_rate : d(age)/dt (1/s), called with the time t (s).
    length_rate : dl/dt (m/s), called with t; ``None`` → the length follows the age via
        :func:`relative_length`.
    width_rate : d(width factor)/d(age) (1 per unit age), called with the age.
    bend_rate : dθ/d(age) (radians of extra bending at the tip per unit age), called with
        the age; positive bends the leaf down.
    """

    age_rate: Rate = 1.0
    length_rate: Rate | None = None
    width_rate: Rate = 0.0
    bend_rate: Rate = 0.0


class LeafTimeline:
    """States and meshes of a growing leaf over ``[0, duration]`` seconds.

    Example
    -------
    >>> from biomorph.leaf.growth import GrowthRates, LeafTimeline
    >>> from biomorph.leaf.shape import LeafShape
    >>> tl = LeafTimeline(LeafShape.from_preset("wheat"), GrowthRates(age_rate=0.1), 10.0)
    >>> m = tl.mesh(5.0)        # mesh at t = 5 s
    """

    def __init__(
        self,
        shape: ShapeLike,
        rates: GrowthRates | None = None,
        duration: float = 1.0,
        dt: float | None = None,
        initial: LeafState | None = None,
        hidden: float = 0.0,
        extension_end: float | None = None,
    ) -> None:
        if not np.isfinite(duration) or duration <= 0:
            raise ParameterError(f"duration {duration!r} must be > 0 s")
        self.shape = shape
        self.rates = rates or GrowthRates(age_rate=1.0 / duration)
        self.duration = float(duration)
        self.hidden = float(hidden)
        self.extension_end = float(
            getattr(shape, "extension_end", EXTENSION_END)
            if extension_end is None
            else extension_end
        )
        steps = 400 if dt is None else max(1, int(np.ceil(duration / dt)))
        self.times = np.linspace(0.0, self.duration, steps + 1)
        s0 = initial or state_at_age(shape, 0.0, self.extension_end, hidden)
        self._states = self._integrate(s0)

    def _integrate(self, s0: LeafState) -> NDArray[np.float64]:
        r = self.rates
        out = np.empty((self.times.size, 4))  # age, length, width factor, bend
        a, l_cur, wf, bend = s0.age, s0.length, s0.width_factor, s0.bend
        out[0] = a, l_cur, wf, bend
        L = self.shape.length
        for i in range(1, self.times.size):
            t, dt = self.times[i - 1], self.times[i] - self.times[i - 1]
            da = _rate(r.age_rate, t) * dt
            a_new = float(np.clip(a + da, 0.0, 1.0))
            da = a_new - a
            if r.length_rate is None:
                l_cur = L * relative_length(a_new, self.extension_end)
            else:
                l_cur = float(np.clip(l_cur + _rate(r.length_rate, t) * dt, 0.0, L))
            wf = max(0.0, wf + _rate(r.width_rate, a) * da)
            bend = bend + _rate(r.bend_rate, a) * da
            a = a_new
            out[i] = a, l_cur, wf, bend
        return out

    def state(self, t: float) -> LeafState:
        """State at time ``t`` (s), linearly interpolated between integration steps."""
        if not 0.0 <= t <= self.duration:
            raise ParameterError(f"time {t!r} is outside [0, {self.duration}] s")
        vals = [float(np.interp(t, self.times, self._states[:, c])) for c in range(4)]
        a, l_cur, wf, bend = vals
        return LeafState(min(max(a, 0.0), 1.0), l_cur, max(l_cur - self.hidden, 0.0), wf, bend)

    def mesh(self, t: float, n_s: int = 40, n_u: int = 3, drop_degenerate: bool = True, **kwargs):
        """Mesh of the visible leaf at time ``t`` (a :class:`~biomorph.core.mesh.Mesh`)."""
        batch = LeafBatch.from_shapes(
            [self.shape], states=[self.state(t)], s=np.linspace(0, 1, n_s), **kwargs
        )
        return mesh_batch(batch, n_u, drop_degenerate=drop_degenerate)

    def frames(self, n: int, **kwargs) -> list:
        """``n`` meshes at equally spaced times from 0 to ``duration``, all with the same
        topology (usable as morph targets)."""
        if n < 1:
            raise ParameterError(f"frames={n}: expected at least 1")
        kwargs.setdefault("drop_degenerate", False)
        return [self.mesh(float(t), **kwargs) for t in np.linspace(0, self.duration, n)]

    def visible_area(self, t: float) -> float:
        """Exact visible blade area (m²) at time ``t`` (flat leaf)."""
        return visible_area(self.shape, self.state(t))


def with_state(state: LeafState, **changes) -> LeafState:
    """A copy of ``state`` with fields replaced."""
    return replace(state, **changes)


__all__ = [
    "EXTENSION_END",
    "MIN_RELATIVE_LENGTH",
    "GrowthRates",
    "LeafState",
    "LeafTimeline",
    "relative_length",
    "state_at_age",
    "visible_area",
    "with_state",
]
