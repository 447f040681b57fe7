"""Grass plants and fields of them, meshed in one vectorised pass.

Plant (:class:`PlantSpec`): a vertical stem with ``leaves`` leaves in **distichous**
phyllotaxy — successive leaves alternate by 180° in azimuth (plus Gaussian jitter) — at
insertion heights that grow with the stem; leaf ``i`` (0 = lowest) appears at plant age
``i · appearance`` and then ages over ``lifespan`` of the plant's life, so lower leaves are
older (longer, more bent) and upper leaves younger; blade lengths follow a bell-shaped
profile along the stem (longest in the middle, as in ``Wheat_dimension_profiles.csv``);
each leaf's insertion angle is jittered by rotating its midrib in its own plane.

Field (:class:`FieldSpec`): plants in ``rows`` rows ``row_spacing`` apart, ``plant_spacing``
apart within a row, positions jittered; the leaf area index is the one-sided leaf area over
the ground area ``rows·row_spacing × plants_per_row·plant_spacing``.

Every random choice comes from ``np.random.default_rng(seed)``: the same seed gives the same
canopy. All leaves of a field are evaluated as arrays ``(n_leaves, K)`` and meshed with
:func:`biomorph.leaf.mesh.mesh_batch`; leaves of one field share a level of detail chosen by
the reduction algorithm for the preset (``triangles_per_leaf``).

Face ids: ``plant`` (0-based plant index), ``leaf`` (1-based leaf rank on its plant; 0 =
stem, as CARIBU expects).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.leaf.age import MIN_RELATIVE_LENGTH
from biomorph.leaf.mesh import LeafBatch, concat_batches, mesh_batch, rest_on_soil
from biomorph.leaf.shape import LeafShape, check_age


@dataclass(frozen=True)
class PlantSpec:
    """Parameters of one grass plant (metres, degrees for jitters)."""

    preset: str = "wheat"
    leaves: int = 6
    age: float = 0.8
    # default: maize, the mature stem's internodes (data.mature_maize_stem, the same
    # profile `leaf plant` uses); other presets 2.5 × the preset leaf length
    stem_height: float | None = None
    stem_radius: float = 0.002
    appearance: float = 0.1  # plant-age interval between two leaves
    lifespan: float = 0.5  # leaf life as a fraction of the plant's life
    azimuth_jitter_deg: float = 15.0
    insertion_jitter_deg: float = 8.0
    length_jitter: float = 0.08  # relative standard deviation
    shape_overrides: dict = field(default_factory=dict)
    shape_classes: bool = True  # per-rank shape classes of the preset (if any)
    draw_members: bool = False  # draw each leaf from its class database (ADEL)
    soil: bool = True  # bend leaves at the soil plane z = 0
    thermal_time: float | None = None  # °Cd since emergence: leaf ages from phyllochrons
    phyllochron: float | None = None  # °Cd per leaf (default per preset, see thermal)

    def validate(self) -> None:
        check_age(self.age)
        if self.thermal_time is not None and not self.thermal_time >= 0:
            raise ParameterError(f"thermal time {self.thermal_time!r} must be >= 0 °Cd")
        if self.phyllochron is not None and not self.phyllochron > 0:
            raise ParameterError(f"phyllochron {self.phyllochron!r} must be > 0 °Cd")
        if self.leaves < 1:
            raise ParameterError(f"leaves per plant {self.leaves} must be >= 1")
        for name in ("appearance", "lifespan", "stem_radius"):
            if getattr(self, name) <= 0:
                raise ParameterError(f"{name} {getattr(self, name)!r} must be > 0")
        if self.stem_height is not None and self.stem_height <= 0:
            raise ParameterError(f"stem_height {self.stem_height!r} must be > 0 m")


@dataclass(frozen=True)
class FieldSpec:
    """A field: ``plants`` plants in ``rows`` rows (metres)."""

    plants: int = 20
    rows: int = 4
    row_spacing: float = 0.15
    plant_spacing: float | None = None  # default: from density, else row_spacing / 3
    position_jitter: float = 0.01
    density: float | None = None  # plants per m²; sets plant_spacing
    plant: PlantSpec = field(default_factory=PlantSpec)

    def validate(self) -> None:
        if self.plants < 1 or self.rows < 1:
            raise ParameterError(
                f"need at least 1 plant and 1 row; got plants={self.plants}, rows={self.rows}"
            )
        if self.rows > self.plants:
            raise ParameterError(f"rows={self.rows} exceeds plants={self.plants}")
        if self.row_spacing <= 0 or (self.plant_spacing is not None and self.plant_spacing <= 0):
            raise ParameterError(f"spacing must be > 0 m; got row spacing {self.row_spacing}")
        if self.density is not None and self.density <= 0:
            raise ParameterError(f"density {self.density!r} must be > 0 plants/m²")
        if self.position_jitter < 0:
            raise ParameterError(f"position_jitter {self.position_jitter} must be >= 0 m")
        self.plant.validate()


@dataclass(frozen=True, eq=False)
class Field:
    """Leaves of a field as arrays (one row per leaf) plus plant positions."""

    shape: LeafShape
    plant_pos: Array  # (P, 3) stem base positions
    stem_height: Array  # (P,) current stem height
    stem_radius: float
    plant: NDArray[np.int64]  # (N,) plant index per leaf
    rank: NDArray[np.int64]  # (N,) 1-based leaf rank
    age: Array  # (N,) leaf age in [0, 1]
    length_scale: Array  # (N,) final length / preset length
    incline: Array  # (N,) insertion-angle offset (radians, + = more erect)
    azimuth: Array  # (N,)
    origin: Array  # (N, 3) insertion point
    ground_area: float
    shapes: tuple = ()  # per-leaf shapes by ``shape_id`` (empty: ``shape`` for all)
    shape_id: NDArray[np.int64] | None = None
    soil: bool = True
    requested_leaves: int = 0  # leaves per plant asked for
    tile: tuple[float, float, float, float] | None = None  # ground rectangle (x0 y0 x1 y1)
    width_scale: Array | None = None  # (N,) extra width factor (plant tables: W_blade)

    @property
    def n_leaves(self) -> int:
        return int(self.plant.size)

    def leaf_shapes(self) -> tuple[tuple, NDArray[np.int64]]:
        """``(shapes, shape_id)``: the distinct leaf shapes and each leaf's index."""
        if self.shapes and self.shape_id is not None:
            return self.shapes, self.shape_id
        return (self.shape,), np.zeros(self.n_leaves, np.int64)

    def missing_leaves(self) -> int:
        """Leaves per plant asked for but not emerged at this age (0 when all are)."""
        if not self.requested_leaves or not self.plant_pos.shape[0]:
            return 0
        per = np.bincount(self.plant, minlength=self.plant_pos.shape[0])
        return int(self.requested_leaves - per.min())


def _plant_leaves(spec: PlantSpec, plant_age: float, plants: int, rng: np.random.Generator):
    """Leaf parameters of ``plants`` plants at once: arrays ``(plants, leaves)``."""
    n = spec.leaves
    i = np.arange(n)
    if spec.thermal_time is not None:
        from biomorph.leaf.thermal import ThermalTime

        tt = ThermalTime.for_preset(spec.preset, spec.phyllochron)
        a_tt = tt.leaf_age(spec.thermal_time, i + 1)
        present = np.broadcast_to(a_tt >= 0.0, (plants, n))
        age = np.broadcast_to(np.clip(a_tt, 0.0, 1.0), (plants, n))
    else:
        emerge = i * spec.appearance
        present = np.broadcast_to(plant_age >= emerge, (plants, n))
        age = np.broadcast_to(np.clip((plant_age - emerge) / spec.lifespan, 0.0, 1.0), (plants, n))
    x = i / max(n - 1, 1)
    profile = 0.55 + 0.45 * np.sin(np.pi * (0.15 + 0.7 * x))
    lscale = profile * np.clip(1 + spec.length_jitter * rng.standard_normal((plants, n)), 0.5, 1.5)
    base_az = rng.uniform(0, 2 * np.pi, size=(plants, 1))
    az = (
        base_az + np.pi * i + np.radians(spec.azimuth_jitter_deg) * rng.standard_normal((plants, n))
    )
    incl = np.radians(spec.insertion_jitter_deg) * rng.standard_normal((plants, n))
    return present, age, lscale, az, incl


def build_plant(
    spec: PlantSpec,
    seed: int | np.random.Generator = 0,
    origin=(0.0, 0.0, 0.0),
    age: float | None = None,
) -> Field:
    """One plant (a one-plant :class:`Field`)."""
    fs = FieldSpec(
        plants=1, rows=1, row_spacing=1.0, plant_spacing=1.0, position_jitter=0.0, plant=spec
    )
    return build_field(fs, seed=seed, origin=origin, age=age)


def _stem_profile(ps: PlantSpec, leaf_length: float) -> tuple[float, Array]:
    """Stem height (m) and each rank's insertion height as a share of it.

    Maize (unless ``stem_height`` is given): the mature stem of
    :func:`biomorph.leaf.data.mature_maize_stem` — leaf ``r`` at the top of internode ``r``,
    so the crown leaves sit near the soil and the canopy is as tall as a ``leaf plant``
    maize plant. Otherwise ``stem_height`` (default 2.5 × the preset leaf length) with
    insertion heights ``(r / n)^1.3``."""
    n = ps.leaves
    if ps.stem_height is None and ps.preset == "maize":
        from biomorph.leaf.data import mature_maize_stem

        nodes = np.cumsum(mature_maize_stem(blade_params={"n_ranks": n})["L_internode"])
        return float(nodes[-1]), nodes / nodes[-1]
    H = ps.stem_height or 2.5 * leaf_length
    return H, ((np.arange(n) + 1) / n) ** 1.3


def build_field(
    spec: FieldSpec,
    seed: int | np.random.Generator = 0,
    origin=(0.0, 0.0, 0.0),
    age: float | None = None,
) -> Field:
    """Place plants in rows and draw every leaf's parameters (deterministic given ``seed``).

    ``age`` overrides the plant age (for growth animation: same seed, same plants).
    """
    spec.validate()
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    ps = spec.plant
    plant_age = check_age(ps.age if age is None else age)
    shape = LeafShape.from_preset(ps.preset, **ps.shape_overrides)
    per_row = int(np.ceil(spec.plants / spec.rows))
    dx = spec.plant_spacing or (
        1.0 / (spec.density * spec.row_spacing) if spec.density else spec.row_spacing / 3.0
    )
    idx = np.arange(spec.plants)
    row, col = idx // per_row, idx % per_row
    pos = np.stack([col * dx, row * spec.row_spacing, np.zeros(spec.plants)], axis=1)
    pos[:, :2] += spec.position_jitter * rng.standard_normal((spec.plants, 2))
    pos += np.asarray(origin, float)
    n = ps.leaves
    H, rel_h = _stem_profile(ps, shape.length)
    elong = np.clip(plant_age / 0.8, 0.1, 1.0)
    if ps.thermal_time is not None:
        from biomorph.leaf.thermal import ThermalTime

        tt = ThermalTime.for_preset(ps.preset, ps.phyllochron)
        elong = float(np.clip(tt.haun_stage(ps.thermal_time) / ps.leaves, 0.1, 1.0))
    stem_h = np.full(spec.plants, H * elong)
    present, a, ls, az, incl = _plant_leaves(ps, plant_age, spec.plants, rng)
    pp, kk = np.nonzero(present)  # plant-major order, ranks ascending
    org = pos[pp].copy()
    org[:, 2] += stem_h[pp] * rel_h[kk]
    cat = {
        "plant": pp,
        "rank": kk + 1,
        "age": a[pp, kk],
        "ls": ls[pp, kk],
        "az": az[pp, kk],
        "incl": incl[pp, kk],
        "org": org,
    }
    ground = spec.rows * spec.row_spacing * per_row * dx
    shapes, shape_id, ls_leaf = _class_shapes(ps, shape, kk, cat["ls"], rng)
    fld = Field(
        shape,
        pos,
        stem_h,
        ps.stem_radius,
        cat["plant"].astype(np.int64),
        cat["rank"].astype(np.int64),
        cat["age"],
        ls_leaf,
        cat["incl"],
        cat["az"],
        cat["org"].reshape(-1, 3),
        float(ground),
        shapes,
        shape_id,
        ps.soil,
        n,
        _tile(origin, dx, spec.row_spacing, per_row, spec.rows),
    )
    missing = fld.missing_leaves()
    if missing:
        when = (
            f"thermal time {ps.thermal_time:g} °Cd"
            if ps.thermal_time is not None
            else f"plant age {plant_age:g} (leaf i emerges at age i × appearance {ps.appearance:g})"
        )
        warnings.warn(
            f"{missing} of the {n} requested leaves per plant have not emerged at "
            f"{when}; the plants have {n - missing} leaves",
            LeafCountWarning,
            stacklevel=3,
        )
    return fld


def _tile(
    origin, dx: float, dy: float, per_row: int, rows: int
) -> tuple[float, float, float, float]:
    """Ground rectangle of the planting pattern: plants sit at cell centres, so the field
    repeats with this tile (the light model's periodic ground)."""
    ox, oy = float(origin[0]), float(origin[1])
    return (ox - dx / 2, oy - dy / 2, ox + per_row * dx - dx / 2, oy + rows * dy - dy / 2)


class LeafCountWarning(UserWarning):
    """A requested number of leaves cannot have emerged by the requested age."""


def _class_shapes(
    ps: PlantSpec, base: LeafShape, kk: NDArray[np.int64], ls: Array, rng: np.random.Generator
):
    """Per-leaf shape classes (by rank) of the preset, and length scales relative to them.

    With classes, each leaf takes its rank class's shape, length and width (the class
    medians of the digitised leaves, so the rank profile is the data's); the length jitter
    is kept. Without, the preset shape and the bell-shaped rank profile."""
    from biomorph.leaf.shape import class_of_rank, preset_classes

    classes = preset_classes(ps.preset) if ps.shape_classes else None
    if not classes or ps.shape_overrides:
        return (), None, ls
    n = ps.leaves
    i = np.arange(n)
    profile = 0.55 + 0.45 * np.sin(np.pi * (0.15 + 0.7 * i / max(n - 1, 1)))
    jitter = ls / profile[kk]  # undo the bell profile, keep the jitter
    keys = [class_of_rank(ps.preset, int(k) + 1, n) for k in kk]
    members = (
        [int(rng.integers(classes[k]["n_members"])) for k in keys]
        if ps.draw_members
        else [0] * len(keys)
    )
    index: dict[tuple[str, int], int] = {}
    shapes: list[LeafShape] = []
    sid = np.empty(len(keys), np.int64)
    for j, km in enumerate(zip(keys, members, strict=True)):
        if km not in index:
            index[km] = len(shapes)
            shapes.append(LeafShape.from_preset(ps.preset, rank_class=km[0], member=km[1]))
        sid[j] = index[km]
    lengths = np.array([sh.length for sh in shapes])[sid]
    return tuple(shapes), sid, jitter * lengths / base.length


def _interp_rows(knots: Array, rows: Array, q: Array) -> Array:
    """Linear interpolation of many rows sharing ``knots``: rows ``(N, M)``, q ``(N, K)``."""
    j = np.clip(np.searchsorted(knots, q, side="right") - 1, 0, knots.size - 2)
    w = np.clip((q - knots[j]) / (knots[j + 1] - knots[j]), 0.0, 1.0)
    a = np.take_along_axis(rows, j, axis=1)
    b = np.take_along_axis(rows, j + 1, axis=1)
    return (1 - w) * a + w * b


def batch_from_field(
    fld: Field, s: Array, twist: bool = True, undulation: bool = True
) -> LeafBatch:
    """Vectorised profiles of every leaf of ``fld`` at visible fractions ``s`` ``(K,)``
    (one vectorised pass per distinct leaf shape), bent at the soil when ``fld.soil``."""
    shapes, sid = fld.leaf_shapes()
    sg = np.asarray(s, float)
    if len(shapes) == 1:
        batch = _batch_one_shape(fld, shapes[0], np.arange(fld.n_leaves), sg, twist, undulation)
    else:
        parts, order = [], []
        for k, shape in enumerate(shapes):
            idx = np.flatnonzero(sid == k)
            if idx.size:
                parts.append(_batch_one_shape(fld, shape, idx, sg, twist, undulation))
                order.append(idx)
        batch = concat_batches(parts)
        inv = np.empty(fld.n_leaves, np.int64)
        inv[np.concatenate(order)] = np.arange(fld.n_leaves)
        batch = LeafBatch(*[getattr(batch, f)[inv] for f in _BATCH_FIELDS])
    return rest_on_soil(batch, 0.0) if fld.soil else batch


_BATCH_FIELDS = (
    "phi",
    "seg",
    "width",
    "theta",
    "wave_amp",
    "wave_arg",
    "v",
    "origin",
    "azimuth",
    "plant",
    "leaf",
)


def _batch_one_shape(
    fld: Field, shape: LeafShape, idx: NDArray[np.int64], sg: Array, twist: bool, undulation: bool
) -> LeafBatch:
    """Profiles of the leaves ``idx`` of ``fld`` that share ``shape`` (``length_scale`` is
    relative to the field's base shape)."""
    age = fld.age[idx]
    L = fld.shape.length * fld.length_scale[idx]  # (N,)
    wscale = L / shape.length
    ext = shape.extension_end
    rel = MIN_RELATIVE_LENGTH + (1 - MIN_RELATIVE_LENGTH) * np.clip(age / ext, 0, 1)
    l_cur = L * rel
    sigma = sg[None, :] * l_cur[:, None]  # (N,K) metres
    shat = np.clip(1.0 - (l_cur[:, None] - sigma) / L[:, None], 0, 1)  # exact 1 at the tip
    smid = 0.5 * (sigma[:, 1:] + sigma[:, :-1]) / L[:, None]
    phi = np.interp(smid, shape.s, shape.phi)
    if shape.collection is not None:
        c = shape.collection
        rows = np.atleast_2d(c.phi_at(age)) - c.phi_at(ext)[None, :]  # (N, M) change
        phi = phi + _interp_rows(c.s, rows, smid)
    phi = phi + fld.incline[idx, None]
    seg = np.diff(sg)[None, :] * l_cur[:, None]
    if fld.width_scale is not None:
        wscale = wscale * fld.width_scale[idx]
    width = shape.width * wscale[:, None] * np.interp(shat, shape.s_r, shape.r)
    theta = shape.theta_at(shat) if twist else np.zeros_like(shat)
    if undulation and shape.undulation > 0:
        amp = shape.undulation * (1 - shat)
        arg = 2 * np.pi * shat * L[:, None] / shape.wavelength + shape.phase
    else:
        amp = arg = np.zeros_like(shat)
    v = np.broadcast_to(sg, shat.shape).copy()
    return LeafBatch(
        phi,
        seg,
        width,
        theta,
        amp,
        arg,
        v,
        fld.origin[idx],
        fld.azimuth[idx],
        fld.plant[idx],
        fld.rank[idx],
    )


def lod_samples(shape: LeafShape, triangles: int, age: float = 0.8, reduction=None) -> Array:
    """Sample positions (visible fractions) chosen by the reduction for a leaf of ``shape``
    at ``age`` with about ``triangles`` triangles (strips of 2, closed tip 1)."""
    from biomorph.leaf.reduction import reduce_leaf

    red = reduction or reduce_leaf(shape, 200, age=age)
    triangles = max(int(triangles), red.min_triangles)
    kept = red.kept(red.removed_for_budget(min(triangles, red.full_triangles)))
    return red.s[kept]


def stem_mesh(fld: Field, sides: int = 6) -> Mesh:
    """Prism stems (one per plant) with face ids ``plant`` and ``leaf = 0``."""
    p = fld.plant_pos.shape[0]
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang), np.zeros(sides)], axis=1)  # (S,3)
    bottom = fld.plant_pos[:, None, :] + fld.stem_radius * ring[None]
    top = bottom.copy()
    top[..., 2] += fld.stem_height[:, None]
    verts = np.concatenate([bottom, top], axis=1).reshape(-1, 3)  # (P*2S,3)
    j = np.arange(sides)
    a, b = j, (j + 1) % sides
    quad = np.concatenate([np.stack([a, b, b + sides], 1), np.stack([a, b + sides, a + sides], 1)])
    faces = (quad[None] + (np.arange(p) * 2 * sides)[:, None, None]).reshape(-1, 3)
    normals = np.tile(np.concatenate([ring, ring]), (p, 1))
    uv = np.tile(
        np.concatenate(
            [np.stack([j / sides, np.zeros(sides)], 1), np.stack([j / sides, np.ones(sides)], 1)]
        ),
        (p, 1),
    )
    plant = np.repeat(np.arange(p), 2 * sides)
    return Mesh(
        verts,
        faces,
        normals=normals,
        uv=uv,
        face_ids={"plant": plant, "leaf": np.zeros(plant.size, np.int64)},
    )


def field_mesh(
    fld: Field,
    triangles_per_leaf: int = 20,
    stems: bool = True,
    twist: bool = True,
    undulation: bool = True,
    drop_degenerate: bool = True,
    s: Array | None = None,
) -> Mesh:
    """One mesh of the whole field (leaves, optionally stems)."""
    if triangles_per_leaf < 1:
        raise ParameterError(
            f"triangles per leaf {triangles_per_leaf} is below the minimum mesh (1)"
        )
    sg = lod_samples(fld.shape, triangles_per_leaf) if s is None else s
    leaves = (
        mesh_batch(
            batch_from_field(fld, sg, twist, undulation), n_u=2, drop_degenerate=drop_degenerate
        )
        if fld.n_leaves
        else None
    )
    parts = [m for m in (leaves, stem_mesh(fld) if stems else None) if m is not None]
    return parts[0] if len(parts) == 1 else Mesh.merge(parts)


def leaf_area_index(fld: Field, mesh: Mesh) -> float:
    """One-sided leaf area (stems excluded) over ground area."""
    leaf = mesh.face_ids["leaf"] > 0
    return float(mesh.face_areas()[leaf].sum() / fld.ground_area)


def plant_growth_frames(
    spec: PlantSpec | FieldSpec,
    frames: int,
    seed: int = 0,
    age_start: float = 0.05,
    age_end: float = 1.0,
    triangles_per_leaf: int = 20,
) -> list[Mesh]:
    """Equal-topology meshes of a plant (or field) growing from ``age_start`` to
    ``age_end``: every leaf exists in every frame (zero-size before it appears)."""
    if frames < 1:
        raise ParameterError(f"frames={frames}: expected at least 1")
    fs = (
        spec
        if isinstance(spec, FieldSpec)
        else FieldSpec(
            plants=1, rows=1, row_spacing=1.0, plant_spacing=1.0, position_jitter=0.0, plant=spec
        )
    )
    full = build_field(fs, seed=seed, age=1.0)  # every leaf present
    sg = lod_samples(full.shape, triangles_per_leaf)
    out = []
    ps = fs.plant
    for a in np.linspace(age_start, age_end, frames):
        emerge = (full.rank - 1) * ps.appearance
        leaf_age = np.clip((a - emerge) / ps.lifespan, 0, 1)
        present = a >= emerge
        scale = np.where(present, full.length_scale, 1e-9)
        elong = np.clip(a / 0.8, 0.1, 1.0)
        stem_h = full.stem_height * elong
        org = full.origin.copy()
        org[:, 2] = (
            full.plant_pos[full.plant, 2] + (org[:, 2] - full.plant_pos[full.plant, 2]) * elong
        )
        fr = Field(
            full.shape,
            full.plant_pos,
            stem_h,
            full.stem_radius,
            full.plant,
            full.rank,
            leaf_age,
            scale,
            full.incline,
            full.azimuth,
            org,
            full.ground_area,
            full.shapes,
            full.shape_id,
            full.soil,
            full.requested_leaves,
            full.tile,
            full.width_scale,
        )
        out.append(field_mesh(fr, s=sg, drop_degenerate=False))
    return out


__all__ = [
    "Field",
    "FieldSpec",
    "LeafCountWarning",
    "PlantSpec",
    "batch_from_field",
    "build_field",
    "build_plant",
    "field_mesh",
    "leaf_area_index",
    "lod_samples",
    "plant_growth_frames",
    "stem_mesh",
]
