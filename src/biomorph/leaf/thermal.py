"""One age axis for leaves and plants: thermal time (°Cd) and phyllochrons.

Crop models (ADEL, the ECHAP trajectories) time leaves in **thermal time**: degree-days
above a base temperature, ``TT = Σ max(T_mean − T_base, 0)`` over days, and the
**phyllochron** ``P`` (°Cd between two successive leaves). The Haun stage of a plant is
``HS = TT / P`` and the age of leaf ``rank`` in phyllochrons since its full extension is
``HS − rank`` (the unit of the Tremie12 midrib collection, which spans −2..12).

The normalised leaf age ``a ∈ [0, 1]`` used by the shape, growth and mesh modules maps that
range linearly: ``a = (HS − rank − start) / (end − start)``. With the wheat collection
(start −2, end 12) full extension (``HS − rank = 0``) is ``a = 2/14 = 0.143``, which is the
shape's :attr:`~biomorph.leaf.shape.LeafShape.extension_end`: a leaf at full extension
**equals the mature preset** (its midrib is the preset's plus the collection's change since
full extension, zero there), younger leaves are shorter and straighter, older ones droop as
the measured collection does.

Default parameters (set per preset, all overridable; none is fitted to the shared files):

* wheat: base temperature 0 °C, phyllochron 100 °Cd — the usual winter-wheat values
  (phyllochrons of 90–110 °Cd above 0 °C are typical of field wheat);
* maize: base temperature 8 °C (the usual maize base), phyllochron 50 °Cd above it
  (a typical leaf-tip appearance interval of maize);
* both use the collection's age range (−2..12 phyllochrons) when the preset has one, and
  that range otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core.types import Array
from biomorph.errors import ParameterError

#: (base temperature °C, phyllochron °Cd) per preset; see the module docstring.
DEFAULTS = {"wheat": (0.0, 100.0), "maize": (8.0, 50.0), "grass": (0.0, 100.0)}


@dataclass(frozen=True)
class ThermalTime:
    """Thermal-time axis of one crop (°C, °Cd, phyllochrons)."""

    phyllochron: float = 100.0
    base_temperature: float = 0.0
    age_start: float = -2.0  # leaf age (phyllochrons from full extension) at a = 0
    age_end: float = 12.0  # ... at a = 1 (end of life)

    def __post_init__(self) -> None:
        if not np.isfinite(self.phyllochron) or self.phyllochron <= 0:
            raise ParameterError(f"phyllochron {self.phyllochron!r} must be > 0 °Cd")
        if not np.isfinite(self.base_temperature):
            raise ParameterError(f"base temperature {self.base_temperature!r} must be finite")
        if not self.age_end > self.age_start:
            raise ParameterError(f"leaf age range {self.age_start}..{self.age_end} must increase")

    @classmethod
    def for_preset(
        cls, preset: str, phyllochron: float | None = None, base_temperature: float | None = None
    ) -> ThermalTime:
        """Defaults of ``preset`` (see :data:`DEFAULTS`), age range from its collection."""
        from biomorph.leaf.age import PHYLLOCHRON_RANGE
        from biomorph.leaf.shape import LeafShape

        tb, ph = DEFAULTS.get(preset, DEFAULTS["wheat"])
        coll = LeafShape.from_preset(preset).collection
        lo, hi = PHYLLOCHRON_RANGE if coll is None else (float(coll.ages[0]), float(coll.ages[-1]))
        return cls(
            ph if phyllochron is None else float(phyllochron),
            tb if base_temperature is None else float(base_temperature),
            lo,
            hi,
        )

    def degree_days(self, daily_mean_temperatures: ArrayLike) -> Array:
        """Cumulative thermal time (°Cd) after each day of mean temperatures (°C)."""
        t = np.asarray(daily_mean_temperatures, float).reshape(-1)
        if not np.isfinite(t).all():
            raise ParameterError("daily temperatures must be finite numbers (°C)")
        return np.cumsum(np.maximum(t - self.base_temperature, 0.0))

    def haun_stage(self, thermal_time: ArrayLike) -> Array:
        """Haun stage ``TT / phyllochron`` (leaves)."""
        tt = np.asarray(thermal_time, float)
        if np.any(tt < 0) or not np.isfinite(tt).all():
            raise ParameterError(f"thermal time {thermal_time!r} must be >= 0 °Cd")
        return tt / self.phyllochron

    def leaf_age(self, thermal_time: ArrayLike, rank: ArrayLike) -> Array:
        """Normalised age ``a`` of leaf ``rank`` (1 = first) at ``thermal_time``; may fall
        outside [0, 1] (< 0: not yet emerged, > 1: past its life), see :meth:`emerged`."""
        age = self.haun_stage(thermal_time) - np.asarray(rank, float)
        return (age - self.age_start) / (self.age_end - self.age_start)

    def emerged(self, thermal_time: ArrayLike, rank: ArrayLike) -> NDArray[np.bool_]:
        """Whether leaf ``rank`` has started at ``thermal_time``."""
        return self.leaf_age(thermal_time, rank) >= 0.0

    def thermal_time_of(self, rank: ArrayLike, age: ArrayLike) -> Array:
        """Thermal time (°Cd) at which leaf ``rank`` has normalised ``age`` (inverse)."""
        a = np.asarray(age, float)
        phyl = self.age_start + a * (self.age_end - self.age_start)
        return (phyl + np.asarray(rank, float)) * self.phyllochron

    def full_extension(self) -> float:
        """Normalised age of full extension (0 phyllochrons)."""
        return float(np.clip(-self.age_start / (self.age_end - self.age_start), 0.0, 1.0))


__all__ = ["DEFAULTS", "ThermalTime"]
