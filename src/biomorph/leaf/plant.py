"""Grass plants as ADEL describes them: per-rank dimension and phenology tables, thermal
time, stems and sheaths as tubes, internodes, collars, insertion angles, phyllotaxy,
optional tillers, senescence, and an MTG of the plant.

Tables (see :mod:`biomorph.io.plant_tables` for the CSV schema): ``dimT``-like
``L_blade W_blade L_sheath W_sheath L_internode W_internode`` per rank (metres) and
``phenT``-like ``tip col ssi disp`` per rank (Haun stages). Defaults
(:func:`default_tables`):

* wheat dimensions — ``adel/Wheat_dimension_profiles.csv`` (kept in ``presets.json``),
  interpolated at the ranks of an ``n``-leaf main stem, ``xn = xn_flag − (n − rank)``. The
  table does not say which ``xn`` is the flag leaf; we take the rank above the longest
  blade (``xn = 1``: in wheat the leaf below the flag is usually the longest), the rows
  beyond it are read as ear/peduncle and not used — an assumption, stated here;
* maize dimensions — blade length and width of a **mature** plant (the digitised
  ``leaves_db`` plant is young: blades ≤ 0.56 m): per-rank leaf area from the bell model of
  Yang & Alley (2005), 0.5 m² per plant, the largest leaf (ear leaf) five ranks below the
  top, split into length and width with the data's width allometry (see
  :func:`biomorph.leaf.data.mature_maize_blades` and docs/leaf.md); 16 leaves by default
  (:data:`DEFAULT_LEAVES`); sheaths and internodes from published maize profiles
  (:func:`biomorph.leaf.data.mature_maize_stem`: five short crown internodes, 0.185 m
  internodes around the ear, sheaths longest at the ear; 2.3 m plant), read on the
  normalised rank for other leaf counts;
* phenology (both) — ``tip = rank − 2`` and ``col = rank`` (the Tremie12 midrib collection's
  own axis: it starts 2 phyllochrons before full extension); wheat ``ssi = rank + 4``
  (senescence starts 4 phyllochrons after ligulation — set by hand, the shared files do not
  time it), ``disp = rank + 12`` (the collection's last age); maize ``ssi``/``disp`` from the
  published bilinear course of plant leaf senescence around silking, leaves senescing
  bottom-up (:func:`biomorph.leaf.data.maize_senescence_stages`).

Growth with the Haun stage ``HS = TT / phyllochron`` (:mod:`biomorph.leaf.thermal`): a blade
extends linearly from ``tip`` to ``col`` (then equals its mature class shape, see
:attr:`~biomorph.leaf.shape.LeafShape.extension_end`), its sheath grows with it, the
internode below the next node elongates during the phyllochron after ``col``. Senescence
runs from the tip: the senescent fraction of the blade is ``(HS − ssi)/(disp − ssi)``
(clipped); a leaf past ``disp`` has disappeared. Leaves are inserted at their collar (top
of the sheath), distichous (180° + jitter), with the class shape's own insertion angle
(jittered by the class's insertion spread in the data, ``insertion_sd_deg``). Tiller ``k``
grows in the axil of main-stem leaf ``k`` and starts when the main stem is at Haun stage
``k + 2`` (the usual "tiller n appears with leaf n + 3" rule of grasses, set by hand);
tillers are vertical axes beside the main stem (no tiller lean).

Face ids of the mesh: ``plant``, ``leaf`` (rank, 0 = stem tube), ``axis`` (0 main stem,
k tiller k), ``organ`` (1 blade, 2 sheath, 3 internode); blade vertices are coloured green
or senescent brown.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError
from biomorph.leaf.canopy import Field, LeafCountWarning, batch_from_field, lod_samples
from biomorph.leaf.mesh import mesh_batch
from biomorph.leaf.shape import LeafShape, class_of_rank
from biomorph.leaf.thermal import ThermalTime

Table = dict[str, Array]

GREEN = (62, 130, 45, 255)
SENESCENT = (156, 120, 62, 255)
ORGAN_BLADE, ORGAN_SHEATH, ORGAN_INTERNODE = 1, 2, 3


# --------------------------------------------------------------------------- tables
#: Main-stem leaves of a preset's default plant (maize: the 16 ranks of its mature table).
DEFAULT_LEAVES = {"maize": 16}


def default_leaves(preset: str) -> int:
    """Main-stem leaf count of ``preset``'s default plant (11 unless set in
    :data:`DEFAULT_LEAVES`)."""
    return DEFAULT_LEAVES.get(preset, 11)


def mature_thermal_time(preset: str, leaves: int, phyllochron: float | None = None) -> float:
    """Thermal time (°Cd) at which the last of ``leaves`` main-stem leaves is ligulated
    (fully extended): the plant a crop modeller calls mature (maize at tasselling)."""
    tt = ThermalTime.for_preset(preset, phyllochron)
    return float(tt.thermal_time_of(leaves, tt.full_extension()))


def default_tables(
    preset: str = "wheat", leaves: int = 11, phyllochron: float | None = None
) -> tuple[Table, Table]:
    """Default ``(dimensions, phenology)`` of a ``leaves``-leaf main stem (module docs);
    ``phyllochron`` (°Cd, default per preset) converts maize senescence times to stages."""
    from biomorph.leaf.shape import _presets, preset_classes

    if leaves < 1:
        raise ParameterError(f"leaves {leaves} must be >= 1")
    data = _presets()
    if preset not in data:
        raise ParameterError(
            f"unknown leaf preset {preset!r}; expected one of {', '.join(sorted(data))}"
        )
    wd = data["wheat"]["dimensions"]
    xn = np.asarray(wd["xn"])
    rank = np.arange(1, leaves + 1, dtype=float)
    flag = float(xn[int(np.argmax(wd["L_blade"]))]) + 1.0  # F-1 is the longest blade
    q = flag - (leaves - rank)
    wheat = {
        c: np.interp(q, xn, np.asarray(wd[c]))
        for c in ("L_blade", "W_blade", "L_sheath", "W_sheath", "L_internode", "W_internode")
    }
    if preset == "maize":
        classes = preset_classes("maize")
        keys = [class_of_rank("maize", int(r), leaves) for r in rank]
        dims = {
            "L_blade": np.array([classes[k]["length"] for k in keys]),
            "W_blade": np.array([classes[k]["width"] for k in keys]),
            **_maize_stem(rank),
        }
        ssi, disp = _maize_senescence([classes[k]["area"] for k in keys], phyllochron)
    else:
        dims = wheat
        ssi, disp = rank + 4.0, rank + 12.0
    dims = {"rank": rank, **dims}
    phen = {"rank": rank, "tip": rank - 2.0, "col": rank, "ssi": ssi, "disp": disp}
    return dims, phen


def _maize_stem(rank: Array) -> Table:
    """Mature maize internodes and sheaths (:func:`biomorph.leaf.data.mature_maize_stem`)
    read on the normalised rank of an ``n``-leaf stem, as the blade classes are."""
    from biomorph.leaf.data import mature_maize_stem

    stem = mature_maize_stem()
    m, n = stem["rank"].size, rank.size
    q = 1 + (rank - 1) * (m - 1) / max(n - 1, 1) if n > 1 else np.array([float(m)])
    cols = ("L_sheath", "W_sheath", "L_internode", "W_internode")
    return {c: np.interp(q, stem["rank"], stem[c]) for c in cols}


def _maize_phenology_of(dims: Table, phen: Table, phyllochron: float | None) -> Table:
    """Default maize phenology with senescence timed on a user table's own blade areas
    (``L_blade · W_blade`` × the form factor of each rank's class); rank order as given."""
    from biomorph.leaf.shape import preset_classes

    if np.asarray(dims["rank"]).size != phen["rank"].size:
        return phen  # _check_tables reports the mismatch
    classes = preset_classes("maize")
    order = np.argsort(dims["rank"])
    rank = np.asarray(dims["rank"], float)[order]
    n = rank.size
    ff = []
    for r in rank.astype(int):
        c = classes[class_of_rank("maize", int(np.clip(r, 1, n)), n)]
        ff.append(c["area"] / (c["length"] * c["width"]))
    area = np.asarray(dims["L_blade"], float)[order] * np.asarray(dims["W_blade"], float)[order]
    ssi, disp = _maize_senescence(list(np.maximum(area, 0.0) * np.array(ff)), phyllochron)
    return {**phen, "ssi": ssi, "disp": disp}


def _maize_senescence(areas: list[float], phyllochron: float | None) -> tuple[Array, Array]:
    """Maize senescence stages from the blade areas (data.maize_senescence_stages)."""
    from biomorph.leaf.data import maize_senescence_stages

    ph = ThermalTime.for_preset("maize", phyllochron).phyllochron
    return maize_senescence_stages(np.asarray(areas, float), ph)


def _check_tables(dims: Table, phen: Table) -> None:
    from biomorph.io.plant_tables import check_dimensions, check_phenology

    check_dimensions(dims)
    check_phenology(phen)
    if not np.array_equal(np.sort(dims["rank"]), np.sort(phen["rank"])):
        raise InputError(
            f"dimension table ranks {dims['rank'].astype(int).tolist()} and "
            f"phenology ranks {phen['rank'].astype(int).tolist()} differ"
        )
    r = np.sort(dims["rank"]).astype(int)
    if r[0] != 1 or np.any(np.diff(r) != 1):
        raise InputError(f"missing ranks: tables hold {r.tolist()}; expected 1..{r.max()}")


# --------------------------------------------------------------------------- options
@dataclass(frozen=True)
class PlantOptions:
    """One ADEL-like plant (or a row of them): tables, time, tillers, jitter, seed."""

    preset: str = "wheat"
    leaves: int | None = None  # main-stem leaves (None: default_leaves(preset))
    thermal_time: float | None = None  # °Cd since emergence (None: last leaf ligulated)
    phyllochron: float | None = None  # °Cd (default per preset)
    tillers: int = 0
    dimensions: Table | None = None  # None: default_tables(preset, leaves)
    phenology: Table | None = None
    azimuth_jitter_deg: float = 15.0
    insertion_jitter_deg: float | None = None  # None: the leaf's class spread in the data
    triangles_per_leaf: int = 20
    tube_sides: int = 8
    soil: bool = True
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.leaves is None:
            n = self.dimensions["rank"].size if self.dimensions is not None else None
            object.__setattr__(self, "leaves", int(n or default_leaves(self.preset)))
        if self.thermal_time is None:
            t = mature_thermal_time(self.preset, int(self.leaves), self.phyllochron)
            object.__setattr__(self, "thermal_time", t)

    def tables(self) -> tuple[Table, Table]:
        d0, p0 = default_tables(self.preset, int(self.leaves), self.phyllochron)
        dims = self.dimensions if self.dimensions is not None else d0
        phen = self.phenology if self.phenology is not None else p0
        if self.preset == "maize" and self.phenology is None and self.dimensions is not None:
            phen = _maize_phenology_of(dims, p0, self.phyllochron)
        _check_tables(dims, phen)
        order_d, order_p = np.argsort(dims["rank"]), np.argsort(phen["rank"])
        return (
            {k: np.asarray(v, float)[order_d] for k, v in dims.items()},
            {k: np.asarray(v, float)[order_p] for k, v in phen.items()},
        )

    def validate(self) -> None:
        if not self.thermal_time >= 0:
            raise ParameterError(f"thermal time {self.thermal_time!r} must be >= 0 °Cd")
        if self.phyllochron is not None and not self.phyllochron > 0:
            raise ParameterError(f"phyllochron {self.phyllochron!r} must be > 0 °Cd")
        if self.tillers < 0:
            raise ParameterError(f"tillers {self.tillers} must be >= 0")
        if self.triangles_per_leaf < 1 or self.tube_sides < 3:
            raise ParameterError("triangles per leaf must be >= 1 and tube sides >= 3")


# --------------------------------------------------------------------------- build
@dataclass(frozen=True, eq=False)
class Plant:
    """A built plant: its mesh, per-organ table and per-leaf report."""

    mesh: Mesh
    organs: list[dict[str, Any]]  # one dict per organ (MTG rows)
    leaves: dict[str, Array]  # per visible leaf
    haun_stage: float
    thermal_time: float
    missing: int  # requested main-stem leaves not yet visible

    def summary(self) -> dict[str, Any]:
        lv = self.leaves
        return {
            "haun_stage": self.haun_stage,
            "thermal_time_cd": self.thermal_time,
            "leaves": int(lv["rank"].size),
            "missing_leaves": self.missing,
            "axes": int(len({o["axis"] for o in self.organs})),
            "triangles": self.mesh.n_faces,
            "height_m": float(self.mesh.vertices[:, 2].max()),
            "leaf_area_m2": float(lv["area"].sum()),
            "green_area_m2": float(lv["green_area"].sum()),
            "senescent_area_m2": float((lv["area"] - lv["green_area"]).sum()),
            "below_ground_vertices": int((self.mesh.vertices[:, 2] < 0).sum()),
        }


def _axis_state(dims: Table, phen: Table, hs: float) -> dict[str, Array]:
    """Per-rank current lengths, ages and positions along one vertical axis."""
    tip, col, ssi, disp = (phen[k] for k in ("tip", "col", "ssi", "disp"))
    g_blade = np.clip((hs - tip) / (col - tip), 0.0, 1.0)
    g_int = np.clip(hs - col, 0.0, 1.0)
    internode = dims["L_internode"] * g_int
    sheath = dims["L_sheath"] * g_blade
    node = np.concatenate([[0.0], np.cumsum(internode)])[:-1]
    collar = node + sheath
    sen = np.clip((hs - ssi) / (disp - ssi), 0.0, 1.0)
    visible = (hs >= tip) & (hs < disp)
    return {
        "g_blade": g_blade,
        "internode": internode,
        "sheath": sheath,
        "node": node,
        "collar": collar,
        "sen": sen,
        "visible": visible,
        "phyllochrons": hs - col,
    }


def _leaf_age(st: dict[str, Array], ext: float, tt: ThermalTime) -> Array:
    """Normalised leaf age: extension maps onto [0, ext], then the collection's range."""
    after = ext + (1 - ext) * np.clip(st["phyllochrons"] / tt.age_end, 0, 1)
    return np.where(st["g_blade"] < 1, ext * st["g_blade"], after)


def build_plant_architecture(
    opts: PlantOptions, seed: int = 0, origin=(0.0, 0.0, 0.0), plant_id: int = 0
) -> Plant:
    """Build one plant from its tables at ``opts.thermal_time`` (deterministic per seed)."""
    opts.validate()
    dims, phen = opts.tables()
    rng = np.random.default_rng(seed)
    tt = ThermalTime.for_preset(opts.preset, opts.phyllochron)
    hs_main = float(tt.haun_stage(opts.thermal_time))
    base = LeafShape.from_preset(opts.preset)
    n = int(dims["rank"].size)
    org = np.asarray(origin, float)
    axes = [(0, hs_main, org, rng.uniform(0, 2 * np.pi))]
    for k in range(1, opts.tillers + 1):
        hs_t = hs_main - (k + 2)
        if hs_t <= phen["tip"][0]:
            continue
        ang = np.radians(90 + 137.5 * k)
        off = org + 0.006 * k * np.array([np.cos(ang), np.sin(ang), 0.0])
        axes.append((k, hs_t, off, rng.uniform(0, 2 * np.pi)))
    leaf_rows, tubes, organs = [], [], []
    for axis, hs, pos, az0 in axes:
        st = _axis_state(dims, phen, hs)
        ranks = np.flatnonzero(st["visible"] & (np.arange(n) < (n if axis == 0 else n - axis)))
        for i in range(n if axis == 0 else max(n - axis, 0)):
            if hs < phen["tip"][i]:
                break
            node = pos + [0, 0, st["node"][i]]
            tubes.append(
                (
                    node,
                    node + [0, 0, st["internode"][i]],
                    dims["W_internode"][i] / 2,
                    axis,
                    ORGAN_INTERNODE,
                    i + 1,
                )
            )
            tubes.append(
                (
                    node,
                    node + [0, 0, st["sheath"][i]],
                    dims["W_sheath"][i] / 2,
                    axis,
                    ORGAN_SHEATH,
                    i + 1,
                )
            )
        for i in ranks:
            az = az0 + np.pi * i + np.radians(opts.azimuth_jitter_deg) * rng.standard_normal()
            key = class_of_rank(opts.preset, int(i) + 1, n)
            incl = np.radians(_insertion_sd(opts, key)) * rng.standard_normal()
            leaf_rows.append(
                {
                    "axis": axis,
                    "rank": int(i) + 1,
                    "class": key,
                    "az": az,
                    "incl": incl,
                    "origin": pos + [0, 0, st["collar"][i]],
                    "sen": st["sen"][i],
                    "L": dims["L_blade"][i],
                    "W": dims["W_blade"][i],
                    "hs": hs,
                    "st": st,
                    "i": int(i),
                }
            )
        organs.extend(
            _organ_rows(axis, st, dims, n if axis == 0 else max(n - axis, 0), pos, hs, phen)
        )
    visible_main = sum(1 for r in leaf_rows if r["axis"] == 0)
    missing = int(np.sum(phen["tip"] > hs_main))
    if missing:
        warnings.warn(
            f"{missing} of the {n} main-stem leaves have not emerged at thermal "
            f"time {opts.thermal_time:g} °Cd (Haun stage {hs_main:.2f}); the plant "
            f"shows {visible_main} leaves",
            LeafCountWarning,
            stacklevel=2,
        )
    mesh, leaves = _mesh_plant(opts, base, leaf_rows, tubes, tt, plant_id)
    return Plant(mesh, organs, leaves, hs_main, float(opts.thermal_time), missing)


def _insertion_sd(opts: PlantOptions, key: str | None) -> float:
    """Insertion-angle jitter (degrees): the option, else the spread of the fitted
    insertion angles of the class's digitised leaves (``insertion_sd_deg``; 5° without)."""
    if opts.insertion_jitter_deg is not None:
        return float(opts.insertion_jitter_deg)
    if key is None:
        return 5.0
    from biomorph.leaf.shape import preset_classes

    return float(preset_classes(opts.preset)[key].get("insertion_sd_deg", 5.0))


def _organ_rows(axis, st, dims, n, pos, hs, phen) -> list[dict[str, Any]]:
    rows = []
    for i in range(n):
        if hs < phen["tip"][i]:
            break
        node = pos[2] + st["node"][i]
        rows.append(
            {
                "axis": axis,
                "rank": i + 1,
                "organ": "internode",
                "length": float(st["internode"][i]),
                "diameter": float(dims["W_internode"][i]),
                "top": (float(pos[0]), float(pos[1]), float(node + st["internode"][i])),
            }
        )
        rows.append(
            {
                "axis": axis,
                "rank": i + 1,
                "organ": "sheath",
                "length": float(st["sheath"][i]),
                "diameter": float(dims["W_sheath"][i]),
                "top": (float(pos[0]), float(pos[1]), float(pos[2] + st["collar"][i])),
            }
        )
        if st["visible"][i]:
            rows.append(
                {
                    "axis": axis,
                    "rank": i + 1,
                    "organ": "blade",
                    "length": float(dims["L_blade"][i] * st["g_blade"][i]),
                    "width": float(dims["W_blade"][i]),
                    "senescent_fraction": float(st["sen"][i]),
                    "top": (float(pos[0]), float(pos[1]), float(pos[2] + st["collar"][i])),
                }
            )
    return rows


def _mesh_plant(
    opts: PlantOptions, base: LeafShape, rows, tubes, tt: ThermalTime, plant_id: int
) -> tuple[Mesh, dict[str, Array]]:
    parts = []
    leaves = {
        k: np.zeros(len(rows))
        for k in (
            "rank",
            "axis",
            "length",
            "green_length",
            "area",
            "green_area",
            "insertion_deg",
            "age",
        )
    }
    if rows:
        shapes, index = [], {}
        for r in rows:
            if r["class"] not in index:
                index[r["class"]] = len(shapes)
                shapes.append(
                    LeafShape.from_preset(opts.preset, rank_class=r["class"])
                    if r["class"] is not None
                    else base
                )
        sid = np.array([index[r["class"]] for r in rows], np.int64)
        ext = np.array([shapes[k].extension_end for k in sid])
        age = np.array(
            [
                _leaf_age({k: v[r["i"] : r["i"] + 1] for k, v in r["st"].items()}, e, tt)[0]
                for r, e in zip(rows, ext, strict=True)
            ]
        )
        L = np.array([r["L"] for r in rows])
        W = np.array([r["W"] for r in rows])
        cls_w = np.array([shapes[k].width / shapes[k].length for k in sid])
        fld = Field(
            base,
            np.asarray([rows[0]["origin"]]) * [1, 1, 0],
            np.zeros(1),
            0.001,
            np.full(len(rows), plant_id, np.int64),
            np.array([r["rank"] for r in rows], np.int64),
            age,
            L / base.length,
            np.array([r["incl"] for r in rows]),
            np.array([r["az"] for r in rows]),
            np.array([r["origin"] for r in rows]),
            1.0,
            tuple(shapes),
            sid,
            opts.soil,
            0,
            None,
            W / (cls_w * L),
        )
        s = lod_samples(base, opts.triangles_per_leaf)
        batch = batch_from_field(fld, s)
        blades = mesh_batch(batch, n_u=2)
        sen = np.array([r["sen"] for r in rows])
        leaf_of_face = blades.face_ids["leaf"]
        idx_face = _face_leaf_index(blades, len(rows))
        v_tip = blades.uv[:, 1]
        leaf_of_vertex = np.repeat(np.arange(len(rows)), blades.n_vertices // len(rows))
        brown = v_tip > 1 - sen[leaf_of_vertex] + 1e-12
        colors = np.where(brown[:, None], SENESCENT, GREEN).astype(np.uint8)
        area = blades.face_areas()
        face_v = blades.uv[blades.faces, 1].mean(axis=1)
        green_face = face_v <= 1 - sen[idx_face]
        leaves["rank"] = np.array([r["rank"] for r in rows], float)
        leaves["axis"] = np.array([r["axis"] for r in rows], float)
        vis = batch.seg.sum(axis=1)
        leaves["length"] = vis
        leaves["green_length"] = vis * (1 - sen)
        leaves["area"] = np.bincount(idx_face, weights=area, minlength=len(rows))
        leaves["green_area"] = np.bincount(idx_face, weights=area * green_face, minlength=len(rows))
        leaves["insertion_deg"] = 90 - np.degrees(batch.phi[:, 0])
        leaves["age"] = age
        parts.append(
            Mesh(
                blades.vertices,
                blades.faces,
                normals=blades.normals,
                uv=blades.uv,
                vertex_colors=colors,
                face_ids={
                    "plant": blades.face_ids["plant"],
                    "leaf": leaf_of_face,
                    "axis": leaves["axis"].astype(np.int64)[idx_face],
                    "organ": np.full(blades.n_faces, ORGAN_BLADE, np.int64),
                },
            )
        )
    tube_mesh = _tubes(tubes, opts.tube_sides, plant_id)
    if tube_mesh is not None:
        parts.append(tube_mesh)
    if not parts:
        raise InputError(
            "the plant has no organ at this thermal time (before the first leaf tip emerges)"
        )
    return (parts[0] if len(parts) == 1 else Mesh.merge(parts)), leaves


def _face_leaf_index(mesh: Mesh, n_leaves: int) -> NDArray[np.int64]:
    """Index (0..n-1) of the leaf owning each face (faces of one leaf share a vertex block)."""
    per = mesh.n_vertices // max(n_leaves, 1)
    return (mesh.faces[:, 0] // per).astype(np.int64)


def _tubes(tubes, sides: int, plant_id: int) -> Mesh | None:
    """Open cylinders ``(p0, p1, radius, axis, organ, rank)``; zero-length ones dropped."""
    keep = [t for t in tubes if t[1][2] - t[0][2] > 1e-9 and t[2] > 0]
    if not keep:
        return None
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang), np.zeros(sides)], axis=1)
    p0 = np.array([t[0] for t in keep])
    p1 = np.array([t[1] for t in keep])
    rad = np.array([t[2] for t in keep])
    bottom = p0[:, None, :] + rad[:, None, None] * ring[None]
    top = p1[:, None, :] + rad[:, None, None] * ring[None]
    verts = np.concatenate([bottom, top], axis=1).reshape(-1, 3)
    j = np.arange(sides)
    a, b = j, (j + 1) % sides
    quad = np.concatenate([np.stack([a, b, b + sides], 1), np.stack([a, b + sides, a + sides], 1)])
    m = len(keep)
    faces = (quad[None] + (np.arange(m) * 2 * sides)[:, None, None]).reshape(-1, 3)
    per = quad.shape[0]
    normals = np.tile(np.concatenate([ring, ring]), (m, 1))
    colors = np.tile(np.array(GREEN, np.uint8), (verts.shape[0], 1))
    ids = {
        "plant": np.full(m * per, plant_id, np.int64),
        "leaf": np.zeros(m * per, np.int64),
        "axis": np.repeat([t[3] for t in keep], per).astype(np.int64),
        "organ": np.repeat([t[4] for t in keep], per).astype(np.int64),
    }
    return Mesh(verts, faces, normals=normals, vertex_colors=colors, face_ids=ids)


def build_plant_stand(
    opts: PlantOptions,
    plants: int,
    rows: int,
    row_spacing: float,
    density: float | None = None,
    seed: int = 0,
    position_jitter: float = 0.01,
) -> tuple[Mesh, list[Plant], tuple[float, float, float, float]]:
    """A stand of ADEL-like plants in rows (each with its own seed-derived draws): the merged
    mesh (``plant`` ids 0..plants-1), the plants, and the ground tile of the planting
    pattern (for :func:`biomorph.leaf.light.intercept`'s periodic ground)."""
    if plants < 1 or rows < 1 or rows > plants:
        raise ParameterError(f"need 1 <= rows <= plants; got plants={plants}, rows={rows}")
    if not row_spacing > 0 or (density is not None and not density > 0):
        raise ParameterError("row spacing and density must be > 0")
    per_row = int(np.ceil(plants / rows))
    dx = 1.0 / (density * row_spacing) if density else row_spacing / 3.0
    rng = np.random.default_rng(seed)
    seeds = rng.integers(0, 2**31 - 1, plants)
    jit = position_jitter * rng.standard_normal((plants, 2))
    built = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LeafCountWarning)
        for k in range(plants):
            pos = (k % per_row * dx + jit[k, 0], k // per_row * row_spacing + jit[k, 1], 0.0)
            built.append(build_plant_architecture(opts, seed=int(seeds[k]), origin=pos, plant_id=k))
    if caught:
        warnings.warn(str(caught[0].message), LeafCountWarning, stacklevel=2)
    tile = (-dx / 2, -row_spacing / 2, per_row * dx - dx / 2, rows * row_spacing - row_spacing / 2)
    return Mesh.merge([b.mesh for b in built]), built, tile


# --------------------------------------------------------------------------- MTG
def write_plant_mtg(path, plant: Plant | list[Plant]) -> Any:
    """Plants as a multiscale MTG: plant (P, scale 1) / axis (A, 2) / metamer (M, 3) /
    organs internode I, sheath S, blade L (scale 4), written with :func:`io.mtg.write_mtg`.

    Features: ``XX YY ZZ`` (organ top: internode top, collar, blade insertion), ``Length``,
    ``Diameter`` (tubes), ``Width`` and ``SenescentFraction`` (blades)."""
    from biomorph.io.mtg import write_mtg

    feats = ["XX", "YY", "ZZ", "Length", "Diameter", "Width", "SenescentFraction"]
    rows: list[tuple[int, str, dict[str, float]]] = []
    for k, one in enumerate(plant if isinstance(plant, list) else [plant]):
        rows.append((0, f"/P{k + 1}", {}))
        _plant_rows(one, rows)
    classes = [("P", 1), ("A", 2), ("M", 3), ("I", 4), ("S", 4), ("L", 4)]
    return write_mtg(path, classes, rows, feats)


def _plant_rows(plant: Plant, rows: list) -> None:
    by_axis: dict[int, dict[int, list[dict[str, Any]]]] = {}
    for o in plant.organs:
        by_axis.setdefault(o["axis"], {}).setdefault(o["rank"], []).append(o)
    symbol = {"internode": "I", "sheath": "S", "blade": "L"}

    def organ_feats(o):
        x, y, z = o["top"]
        return {
            "XX": x,
            "YY": y,
            "ZZ": z,
            "Length": o["length"],
            "Diameter": o.get("diameter"),
            "Width": o.get("width"),
            "SenescentFraction": o.get("senescent_fraction"),
        }

    def axis_rows(axis: int, col: int, first: str) -> None:
        rows.append((col, first, {}))
        metamers = by_axis.get(axis, {})
        for j, rank in enumerate(sorted(metamers)):
            rows.append((col, f"^/M{rank}" if j == 0 else f"^<M{rank}", {}))
            for k, o in enumerate(metamers[rank]):
                code = f"/{symbol[o['organ']]}{rank}" if k == 0 else f"^<{symbol[o['organ']]}{rank}"
                rows.append((col + 1, code, organ_feats(o)))
            tiller = rank if axis == 0 else None
            if tiller is not None and tiller in by_axis and tiller != 0:
                axis_rows(tiller, col + 1, f"+A{tiller + 1}")

    axis_rows(0, 0, "^/A1")


__all__ = [
    "Plant",
    "PlantOptions",
    "build_plant_architecture",
    "build_plant_stand",
    "DEFAULT_LEAVES",
    "default_leaves",
    "default_tables",
    "mature_thermal_time",
    "write_plant_mtg",
]
