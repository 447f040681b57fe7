"""Leaf shape of a grass leaf: midrib N(s), width r(s), twist θ(s) and margin undulation.

The surface (Fournier & Pradal 2012) is ``S(s, u) = N(s) + r(s) u d(s)`` with ``s ∈ [0, 1]``
the normalised arc length along the midrib (0 = base, 1 = tip) and ``u ∈ [-0.5, 0.5]``
across the blade. The midrib lies in the leaf's local x–z plane (x horizontal away from
the stem, **z up**), so ``N(s) = L·(x(s), 0, z(s))``. ``d(s)`` is the cross-section
direction: the lateral axis ``j = (0, 1, 0)`` turned by the twist angle θ(s) about the
midrib tangent. Margin undulation displaces points along the surface normal by
``A·(2|u|)²·sin(2π σ/λ + φ)·(1 − s)``: zero on the midrib, largest at the margins, fading
to the tip.

Representation
--------------
The midrib is stored in **angle form**: the tangent angle ``phi(s)`` (radians above the
horizontal, piecewise linear between knots). Points are recovered by integrating the unit
tangent with the midpoint rule, so every discretisation of the midrib has length exactly
``L`` — the arc-length constraint of the model holds by construction and the plastic
operators (which edit ``phi``) conserve length. Width is stored relative (max 1) and scaled
by the maximal full width ``width`` (metres); the leaf area is ``L · width · ∫ r_rel ds``.

Digitised data (cm, as in ``../shared/data/leaves``) are converted to metres by the
callers (:func:`fit_leaf` takes a ``scale`` argument, default ``0.01`` m/cm).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from biomorph.core.curves import (
    angles_from_points,
    integrate_angles,
    midrib_arc_length,
    solve_arc_length,
)
from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError
from biomorph.leaf.age import EXTENSION_END, PHYLLOCHRON_RANGE, check_age

PRESET_NAMES = ("maize", "wheat", "grass")


# --------------------------------------------------------------------------- validation
def _as_1d(name: str, values: ArrayLike) -> Array:
    try:
        arr = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numbers; got {values!r}") from exc
    if not np.isfinite(arr).all():
        i = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise InputError(f"{name}[{i}] is {arr[i]}; expected finite numbers")
    return arr


def _check_width_profile(s: ArrayLike, r: ArrayLike) -> tuple[Array, Array]:
    sa, ra = _as_1d("width s", s), _as_1d("width r", r)
    if sa.size != ra.size:
        raise InputError(f"width profile has {sa.size} s values but {ra.size} r values")
    if sa.size < 2:
        raise InputError(f"width profile has {sa.size} point(s); expected at least 2")
    if np.any(np.diff(sa) <= 0):
        i = int(np.flatnonzero(np.diff(sa) <= 0)[0])
        raise InputError(
            f"width profile s must increase strictly; s[{i}]={sa[i]:g} then "
            f"s[{i + 1}]={sa[i + 1]:g}"
        )
    if np.any(ra < 0):
        i = int(np.flatnonzero(ra < 0)[0])
        raise InputError(f"width r[{i}]={ra[i]:g} is negative; expected widths >= 0")
    if ra.max() <= 0:
        raise InputError("width profile is zero everywhere; expected a positive maximum")
    return sa, ra


# --------------------------------------------------------------------------- collection
@dataclass(frozen=True, eq=False)
class MidribCollection:
    """A collection ``N(age, s)`` of unit-length midribs measured at several ages.

    Stored in angle form ``phi[a, k]`` at common knots ``s[k]``; ``ages`` are the stored
    ages in the data's own unit (e.g. phyllochrons), mapped linearly onto the normalised
    age [0, 1]. :meth:`phi_at` interpolates linearly **between** stored ages (the original
    model only picked the nearest one).
    """

    ages: Array
    s: Array
    phi: Array
    source: str = ""
    full_extension_age: float | None = None

    def __post_init__(self) -> None:
        ages = _as_1d("collection ages", self.ages)
        s = _as_1d("collection s", self.s)
        phi = np.asarray(self.phi, dtype=float)
        if phi.shape != (ages.size, s.size):
            raise InputError(
                f"collection phi has shape {phi.shape}; expected ({ages.size}, {s.size})"
            )
        if ages.size < 1 or np.any(np.diff(ages) <= 0):
            raise InputError("collection ages must increase strictly")
        object.__setattr__(self, "ages", ages)
        object.__setattr__(self, "s", s)
        object.__setattr__(self, "phi", phi)

    @classmethod
    def from_curves(
        cls,
        ages: ArrayLike,
        curves: list[tuple[ArrayLike, ArrayLike]],
        n: int = 51,
        source: str = "",
        full_extension_age: float | None = None,
    ) -> MidribCollection:
        """Build from one digitised curve ``(x, y)`` per age (any units, any point count)."""
        s_common = np.linspace(0.0, 1.0, n)
        rows = []
        for x, y in curves:
            s, phi, _ = angles_from_points(x, y)
            rows.append(np.interp(s_common, s, phi))
        return cls(np.asarray(ages, float), s_common, np.array(rows), source, full_extension_age)

    def with_phi(self, s: ArrayLike, phi: ArrayLike) -> MidribCollection:
        """Same ages and metadata, new knots and angles."""
        return MidribCollection(
            self.ages,
            np.asarray(s, float),
            np.asarray(phi, float),
            self.source,
            self.full_extension_age,
        )

    @property
    def extension_end(self) -> float | None:
        """Normalised age of full extension (``full_extension_age`` in data units), or
        ``None`` when the collection does not say."""
        if self.full_extension_age is None or self.ages.size < 2:
            return None
        span = self.ages[-1] - self.ages[0]
        return float(np.clip((self.full_extension_age - self.ages[0]) / span, 0.0, 1.0))

    def data_age(self, age: ArrayLike) -> Array:
        """Stored-age value of normalised ``age`` in [0, 1]."""
        a = np.asarray(age, dtype=float)
        return self.ages[0] + a * (self.ages[-1] - self.ages[0])

    def phi_at(self, age: ArrayLike, s: ArrayLike | None = None) -> Array:
        """Tangent angle at normalised ``age`` (scalar or ``(n,)``), at ``s`` (default: knots).

        Interpolates linearly in age between the two nearest stored curves (angle form:
        the result still has unit length). Returns ``(len(s),)`` or ``(n, len(s))``.
        """
        a = np.asarray(age, dtype=float)
        if np.any((a < 0) | (a > 1)):
            raise ParameterError(f"age {a.min() if a.min() < 0 else a.max()!r} is outside [0, 1]")
        t = self.data_age(a)
        if self.ages.size == 1:
            rows = np.broadcast_to(self.phi[0], a.shape + self.phi.shape[1:])
        else:
            j = np.clip(np.searchsorted(self.ages, t, side="right") - 1, 0, self.ages.size - 2)
            w = (t - self.ages[j]) / (self.ages[j + 1] - self.ages[j])
            w = np.clip(w, 0.0, 1.0)[..., None]
            rows = (1 - w) * self.phi[j] + w * self.phi[j + 1]
        if s is None:
            return np.array(rows)
        sq = np.asarray(s, dtype=float)
        if rows.ndim == 1:
            return np.interp(sq, self.s, rows)
        return np.stack([np.interp(sq, self.s, r) for r in rows])

    def curve_at(self, age: float, n: int | None = None, form: str = "angle") -> Array:
        """Unit-length midrib ``(n, 2)`` at normalised ``age``.

        ``form="angle"`` interpolates the angle θ(age, s) (length exact by construction);
        ``form="curve"`` interpolates the point positions N(age, s) between the two stored
        curves and then solves the arc-length constraint (re-parametrises the interpolated
        polyline by arc length and rescales it to unit length).
        """
        s = self.s if n is None else np.linspace(0, 1, n)
        if form == "angle":
            phi = self.phi_at(age, s)
            mid = 0.5 * (phi[1:] + phi[:-1])
            return integrate_angles(mid, np.diff(s))
        if form != "curve":
            raise ParameterError(f"form {form!r} unknown; expected 'angle' or 'curve'")
        check_age(age)
        t = float(self.data_age(age))
        pts = [integrate_angles(0.5 * (p[1:] + p[:-1]), np.diff(self.s)) for p in self.phi]
        if self.ages.size == 1:
            xy = pts[0]
        else:
            j = int(np.clip(np.searchsorted(self.ages, t, side="right") - 1, 0, self.ages.size - 2))
            w = float(np.clip((t - self.ages[j]) / (self.ages[j + 1] - self.ages[j]), 0, 1))
            xy = (1 - w) * pts[j] + w * pts[j + 1]
        return solve_arc_length(xy, 1.0, s)


# --------------------------------------------------------------------------- leaf shape
@dataclass(frozen=True, eq=False)
class LeafShape:
    """Static shape of one grass leaf (immutable; every method returns new arrays).

    Attributes
    ----------
    s, phi : midrib angle form — knots in [0, 1] and tangent angle (radians above the
        horizontal, in the leaf's x–z plane) at the knots.
    s_r, r : width profile — knots in [0, 1] and relative full width (max 1).
    length : leaf length ``L`` along the midrib (metres).
    width : maximal full width (metres).
    twist : twist angle at the tip (radians); θ(s) = twist · s about the midrib.
    twist_profile : optional ``(s, θ)`` knots (radians) replacing the linear θ(s).
    undulation : margin undulation amplitude (metres, 0 = flat margins).
    wavelength : undulation wavelength along the midrib (metres).
    phase : undulation phase (radians).
    collection : optional ``N(age, s)`` collection used by growing leaves.
    name : label (preset name).
    """

    s: Array
    phi: Array
    s_r: Array
    r: Array
    length: float
    width: float
    twist: float = 0.0
    undulation: float = 0.0
    wavelength: float = 0.05
    phase: float = 0.0
    collection: MidribCollection | None = None
    name: str = "leaf"
    twist_profile: tuple[Array, Array] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        s = _as_1d("midrib s", self.s)
        phi = _as_1d("midrib phi", self.phi)
        if s.size != phi.size or s.size < 2:
            raise InputError(
                f"midrib angle form needs >= 2 matching knots; got {s.size} s and {phi.size} phi"
            )
        if np.any(np.diff(s) <= 0) or s[0] != 0 or s[-1] != 1:
            raise InputError("midrib knots s must increase strictly from 0 to 1")
        sr, rr = _check_width_profile(self.s_r, self.r)
        if sr[0] != 0 or sr[-1] != 1:
            raise InputError("width knots s must run from 0 to 1")
        rr = rr / rr.max()
        for name in ("length", "width"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v <= 0:
                raise ParameterError(f"leaf {name} {v!r} must be a positive number of metres")
            object.__setattr__(self, name, v)
        if float(self.undulation) < 0:
            raise ParameterError(f"undulation amplitude {self.undulation!r} must be >= 0 m")
        if float(self.wavelength) <= 0:
            raise ParameterError(f"undulation wavelength {self.wavelength!r} must be > 0 m")
        for name, arr in (("s", s), ("phi", phi), ("s_r", sr), ("r", rr)):
            arr = arr.copy()
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.twist_profile is not None:
            ts, tv = (
                _as_1d("twist s", self.twist_profile[0]),
                _as_1d("twist theta", self.twist_profile[1]),
            )
            if ts.size != tv.size or ts.size < 2 or np.any(np.diff(ts) <= 0):
                raise InputError("twist_profile needs >= 2 knots with strictly increasing s")
            object.__setattr__(self, "twist_profile", (ts, tv))
        for name in ("twist", "undulation", "wavelength", "phase"):
            object.__setattr__(self, name, float(getattr(self, name)))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_preset(
        cls, name: str, rank_class: str | int | None = None, member: int = 0, **overrides: Any
    ) -> LeafShape:
        """A built-in preset (``maize``, ``wheat``, ``grass``) fitted to real leaves.

        ``rank_class`` picks one of the preset's shape classes (wheat: So99 rank classes
        ``1``..``6``; maize: rank groups such as ``"12"`` or ``"14-16"``; see
        :func:`preset_classes` and :func:`class_of_rank`): its medoid midrib, its width
        profile, its median length and width. ``member`` > 0 picks another leaf of the
        class's member database (ADEL-like draws). Overrides replace fields.
        """
        data = _presets()
        if name not in data:
            raise ParameterError(
                f"unknown leaf preset {name!r}; expected one of {', '.join(sorted(data))}"
            )
        p = data[name]
        coll = None
        if "collection" in p:
            c = p["collection"]
            coll = MidribCollection(
                np.array(c["ages"]),
                np.array(c["s"]),
                np.array(c["phi"]),
                c.get("source", ""),
                c.get("full_extension_age"),
            )
        label = name
        if rank_class is not None:
            key = str(rank_class)
            cp = _class_entry(name, key)
            phis = cp["members_phi"]
            if not 0 <= member < len(phis):
                raise ParameterError(
                    f"member {member} of class {key} of {name!r} is outside 0..{len(phis) - 1}"
                )
            p = {
                **p,
                "s": cp["s"],
                "phi": phis[member],
                "s_r": cp["s_r"],
                "r": cp["r"],
                "length": cp["length"],
                "width": cp["width"],
            }
            label = f"{name} class {key}" + (f" member {member}" if member else "")
        shape = cls(
            np.array(p["s"]),
            np.array(p["phi"]),
            np.array(p["s_r"]),
            np.array(p["r"]),
            p["length"],
            p["width"],
            twist=np.radians(p.get("twist_deg", 0.0)),
            undulation=p.get("undulation", 0.0),
            wavelength=p.get("wavelength", 0.05),
            collection=coll,
            name=label,
            meta={
                "source": p.get("source", ""),
                "preset": name,
                "rank_class": None if rank_class is None else str(rank_class),
                # no collection: full extension where the thermal-time axis puts it
                "full_extension": None
                if coll is not None
                else -PHYLLOCHRON_RANGE[0] / (PHYLLOCHRON_RANGE[1] - PHYLLOCHRON_RANGE[0]),
            },
        )
        return replace(shape, **overrides) if overrides else shape

    @classmethod
    def from_points(
        cls,
        x: ArrayLike,
        y: ArrayLike,
        s_width: ArrayLike,
        r: ArrayLike,
        *,
        width: float | None = None,
        length: float | None = None,
        scale: float = 0.01,
        rounding: float = 0.25,
        **kwargs: Any,
    ) -> LeafShape:
        """Fit a leaf to a digitised midrib ``(x_i, y_i)`` and a width profile ``(s, r)``.

        ``x, y`` are in data units (default cm, ``scale`` converts to metres); the arc
        length is normalised by the total length ``L`` (``length`` overrides it, metres).
        ``s_width`` is normalised to [0, 1] by its own range (maize widths are measured
        along the true leaf, longer than the projected midrib); ``r`` is the full width in
        data units, or relative if ``width`` (metres) is given. ``rounding`` sets how much
        the digitised corners are rounded (see :func:`angles_from_points`; 0 = sharp).
        """
        s, phi, total = angles_from_points(x, y, rounding)
        sw, rw = _check_width_profile(s_width, r)
        sw = (sw - sw[0]) / (sw[-1] - sw[0])
        w = float(rw.max() * scale) if width is None else float(width)
        L = float(total * scale) if length is None else float(length)
        return cls(s, phi, sw, rw / rw.max(), L, w, **kwargs)

    @classmethod
    def parametric(
        cls,
        length: float,
        width: float,
        insertion_deg: float = 60.0,
        bending_deg: float = 90.0,
        base_width: float = 0.6,
        widest_at: float = 0.35,
        tip_power: float = 2.0,
        n: int = 51,
        **kwargs: Any,
    ) -> LeafShape:
        """A leaf from a few numbers instead of digitised data.

        Midrib: insertion angle above the horizontal (degrees) and total bending along the
        leaf (degrees, distributed with curvature growing linearly towards the tip, as in
        grass leaves that droop at the end). Width (relative): ``base_width`` at the base,
        rising as a quarter sine to 1 at ``widest_at``, then ``1 − ((s − s_w)/(1 − s_w))^p``
        to 0 at the tip (``tip_power`` p; 1 = straight taper, 2 = rounded).
        """
        if not 0 < widest_at < 1:
            raise ParameterError(f"widest_at {widest_at!r} must lie in (0, 1)")
        if not 0 <= base_width <= 1:
            raise ParameterError(f"base_width {base_width!r} must lie in [0, 1]")
        if tip_power <= 0:
            raise ParameterError(f"tip_power {tip_power!r} must be > 0")
        s = np.linspace(0.0, 1.0, n)
        phi = np.radians(insertion_deg) - np.radians(bending_deg) * s**2
        rise = base_width + (1 - base_width) * np.sin(0.5 * np.pi * s / widest_at)
        fall = 1 - (np.clip(s - widest_at, 0.0, None) / (1 - widest_at)) ** tip_power
        r = np.where(s <= widest_at, rise, np.clip(fall, 0.0, 1.0))
        return cls(s, phi, s, r, length, width, **kwargs)

    def with_(self, **changes: Any) -> LeafShape:
        """A copy with some fields replaced."""
        return replace(self, **changes)

    # ------------------------------------------------------------------ evaluation
    @property
    def extension_end(self) -> float:
        """Normalised age at which the blade reaches full length: from the collection when
        it records its full-extension age (wheat Tremie12: age 0 of −2..12 phyllochrons →
        2/14 = 0.143), else :data:`~biomorph.leaf.age.EXTENSION_END`."""
        ext = None if self.collection is None else self.collection.extension_end
        if ext is None:
            ext = self.meta.get("full_extension")
        return EXTENSION_END if ext is None else float(ext)

    def phi_at(self, s: ArrayLike, age: float | None = None) -> Array:
        """Tangent angle (radians) at ``s``; at ``age`` when given.

        A growing leaf is the mature shape plus the collection's change of angle since full
        extension, ``φ(s) + N_φ(age, s) − N_φ(a_ext, s)``: at full extension it equals the
        mature shape exactly, younger leaves are straighter, older ones droop as the
        measured collection does. Without a collection the shape does not change with age.
        """
        base = np.interp(np.asarray(s, float), self.s, self.phi)
        if age is None or self.collection is None:
            return base
        c = self.collection
        return base + c.phi_at(check_age(age), s) - c.phi_at(self.extension_end, s)

    def theta_at(self, s: ArrayLike) -> Array:
        """Twist angle θ(s) (radians) about the midrib at mature coordinate ``s``."""
        sa = np.asarray(s, float)
        if self.twist_profile is not None:
            return np.interp(sa, *self.twist_profile)
        return self.twist * sa

    def r_at(self, s: ArrayLike) -> Array:
        """Relative full width (max 1) at ``s``."""
        return np.interp(np.asarray(s, float), self.s_r, self.r)

    def width_at(self, s: ArrayLike) -> Array:
        """Full width (metres) at ``s``."""
        return self.width * self.r_at(s)

    def form_factor(self) -> float:
        """``∫_0^1 r_rel(s) ds`` (exact for the piecewise-linear profile)."""
        return float(np.trapezoid(self.r, self.s_r))

    def area(self) -> float:
        """Analytic blade area ``L · ∫ r(s) ds`` (m²) of the flat, mature leaf."""
        return self.length * self.width * self.form_factor()

    def midrib(self, s: ArrayLike | int = 101, age: float | None = None) -> Array:
        """Midrib points ``(n, 3)`` in metres at ``s`` (or ``n`` equal steps), Z-up.

        The discretised midrib has length exactly ``L`` (midpoint-rule integration of the
        tangent angle).
        """
        sg = np.linspace(0, 1, s) if np.ndim(s) == 0 else np.asarray(s, float)
        mid = 0.5 * (sg[1:] + sg[:-1])
        xz = integrate_angles(self.phi_at(mid, age), np.diff(sg) * self.length)
        return np.stack([xz[:, 0], np.zeros(len(sg)), xz[:, 1]], axis=1)

    def surface(self, s: ArrayLike, u: ArrayLike, age: float | None = None) -> Array:
        """Surface points ``S(s, u)`` on the grid ``s × u``: array ``(len(s), len(u), 3)``."""
        from biomorph.leaf.mesh import LeafBatch, leaf_grid

        sg = np.asarray(s, float)
        batch = LeafBatch.from_shapes([self], ages=None if age is None else [age], s=sg)
        return leaf_grid(batch, np.asarray(u, float))[0]

    def mesh(
        self,
        age: float | None = None,
        triangles: int | None = None,
        n_s: int = 60,
        n_u: int = 3,
        twist: bool = True,
        undulation: bool = True,
    ):
        """Triangle mesh (:class:`biomorph.core.mesh.Mesh`) of this leaf.

        ``triangles`` gives an exact triangle budget (reduced mesh, see
        :mod:`biomorph.leaf.reduction`); otherwise a regular ``n_s × n_u`` grid.
        ``age`` in [0, 1] meshes the growing leaf at that age (see :mod:`biomorph.leaf.growth`).
        """
        from biomorph.leaf.reduction import mesh_leaf

        return mesh_leaf(
            self, age=age, triangles=triangles, n_s=n_s, n_u=n_u, twist=twist, undulation=undulation
        )


# --------------------------------------------------------------------------- presets
@lru_cache(maxsize=1)
def _presets_text() -> str:
    return resources.files("biomorph.leaf").joinpath("presets.json").read_text("utf-8")


def load_presets() -> dict[str, Any]:
    """The preset table (a fresh dict each call; derived by ``bench/derive_leaf_presets.py``)."""
    return json.loads(_presets_text())


@lru_cache(maxsize=1)
def _presets_cached() -> dict[str, Any]:
    return json.loads(_presets_text())


def _presets() -> dict[str, Any]:
    """The parsed preset table shared by the readers in this module (do not mutate)."""
    return _presets_cached()


def _preset_entry(name: str) -> dict[str, Any]:
    data = _presets()
    if name not in data:
        raise ParameterError(
            f"unknown leaf preset {name!r}; expected one of {', '.join(sorted(data))}"
        )
    return data[name]


def _class_entry(name: str, key: str) -> dict[str, Any]:
    """Class ``key`` of a preset with its shape fields resolved: a rank class (maize)
    names the shape class of its digitised leaves and carries its own length and width;
    a shape class key (``shape_classes``) is accepted too."""
    p = _preset_entry(name)
    classes, shapes = p.get("classes", {}), p.get("shape_classes", {})
    if key in classes:
        cp = classes[key]
        if "shape_class" in cp:
            own = {f: cp[f] for f in ("length", "width") if f in cp}
            cp = {**shapes[cp["shape_class"]], **cp, **own}
        return cp
    if key in shapes:
        return shapes[key]
    raise ParameterError(
        f"preset {name!r} has no shape class {key!r}; expected one of "
        f"{', '.join([*classes, *shapes]) or '(none)'}"
    )


def _summary(c: dict[str, Any]) -> dict[str, Any]:
    return {
        **{f: v for f, v in c.items() if f not in ("members_phi", "phi", "s", "r", "s_r")},
        "n_members": len(c["members_phi"]),
    }


def preset_classes(name: str) -> dict[str, dict[str, Any]]:
    """Classes a plant picks by rank (:func:`class_of_rank`): ``{key: {n_leaves,
    median_maxdist, spread, ranks, length, width, n_members...}}``. Wheat: the So99 shape
    classes; maize: one class per rank of the mature plant, each naming its
    ``shape_class`` (see :func:`shape_classes`)."""
    p = _preset_entry(name)
    return {k: _summary(_class_entry(name, k)) for k in p.get("classes", {})}


def shape_classes(name: str) -> dict[str, dict[str, Any]]:
    """Shape classes fitted to the digitised leaves (medoid + member database each):
    wheat the So99 classes, maize the rank groups of ``leaves_db``."""
    p = _preset_entry(name)
    src = p.get("shape_classes", p.get("classes", {}))
    return {k: _summary(c) for k, c in src.items()}


def class_of_rank(name: str, rank: int, n_ranks: int) -> str | None:
    """Class of leaf ``rank`` (1 = lowest) on a main stem of ``n_ranks`` leaves.

    * wheat (``rank_from_top``): ADEL's rule (``geoLeaf`` ``Lindex = nf − n + 1``): class 1
      is the flag leaf, 2 the leaf below…; leaves lower than the last class share it (ADEL
      takes the closest index of a too-small database);
    * maize (``rank_table``): the rank class of the mature plant's table (16 ranks); a
      stem with another leaf count maps rank ``r`` to ``round(1 + (r − 1)·15/(n − 1))``,
      i.e. the profile is read on the normalised rank.
    Returns ``None`` for presets without classes.
    """
    p = _presets().get(name, {})
    classes = p.get("classes")
    if not classes:
        return None
    if rank < 1 or n_ranks < 1 or rank > n_ranks:
        raise ParameterError(f"leaf rank {rank} is outside 1..{n_ranks}")
    keys = list(classes)
    if p.get("class_rule") == "rank_from_top":
        return keys[min(n_ranks - rank, len(keys) - 1)]
    m = len(keys)
    q = 1 + (rank - 1) * (m - 1) / max(n_ranks - 1, 1) if n_ranks > 1 else m
    return keys[int(np.clip(np.floor(q + 0.5), 1, m)) - 1]


__all__ = [
    "LeafShape",
    "MidribCollection",
    "PRESET_NAMES",
    "angles_from_points",
    "check_age",
    "class_of_rank",
    "integrate_angles",
    "load_presets",
    "midrib_arc_length",
    "preset_classes",
    "shape_classes",
    "solve_arc_length",
]
