"""Light intercepted by a canopy: direct sun + diffuse sky by ray casting.

Model (first-order interception, no scattering — the "projection" part of CARIBU):

* **Sun** — position from date, time (UTC) and latitude/longitude with the NOAA solar
  equations (fractional-year series of Spencer 1971 for the declination and the equation
  of time; accurate to about 0.1° for the elevation, far below a canopy's leaf scale). A sun
  below the horizon is an error.
* **Sky** — ``N`` directions with weights that sum to 1 (fraction of the diffuse
  horizontal irradiance each carries). ``16``: the turtle sky of CARIBU's
  ``Turtle16soc.light`` (zenith, the five upper icosahedron vertices at atan(1/2) = 26.6°
  and the ten upper face centres at 52.6° and 10.8°); ``46``: rings of 1, 5, 10, 15 and 15
  sectors of equal solid angle (turtle-like: den Dulk's 46-sector sky also has sectors of
  near-equal solid angle). Radiance follows the **standard overcast sky** (Moon & Spencer
  1942) ``L(β) ∝ (1 + 2 sin β)/3``; a sector's weight is ``L · sin β · Ω``.
* **Rays** — for each direction, parallel rays on a jittered square grid whose ground
  points cover the scene's ground rectangle (spacing ``ray_spacing``; default
  ``½·√(median triangle area)``: about four rays per triangle and direction, coarsened so
  one direction casts at most ``max_rays``). Per-triangle values are ray-sampling
  estimates (relative error about 1/√(rays on the triangle)); per-leaf sums are much
  tighter.
  Each ray carries ``E_h · spacing²`` (E_h: that direction's horizontal irradiance), so the
  sum over rays is exactly the energy falling on the ground rectangle. The first triangle
  hit intercepts it; leaves absorb a fraction ``absorptance`` of it. A ray that reaches
  the ground is a gap: the gap fraction of a direction is the fraction of its rays that hit
  nothing.
* **Periodic canopy** — the rectangle is treated as one tile of an infinite field (as crop
  light models do): triangles are copied to the 8 neighbouring tiles where a ray towards
  the rectangle can meet them (a band as wide as the canopy height × tan of the largest
  zenith angle, at most one tile), so fields have no edge effects.

Ray engine: Embree through ``trimesh`` + ``embreex`` (PyPI); without it trimesh's pure
Python engine is used with a warning (much slower).

Units: PAR in µmol m⁻² s⁻¹ (horizontal, above the canopy), energies in µmol s⁻¹, areas m².
Validated (``tests/leaf/test_light.py``, ``bench/leaf.py``) against Beer–Lambert on
random turbid canopies and the exact shadow of a single horizontal leaf.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError

# --------------------------------------------------------------------------- options
ENGINES = ("zbuffer", "embree", "trimesh")


@dataclass(frozen=True)
class LightOptions:
    """Options of :func:`intercept` (angles in degrees, PAR in µmol m⁻² s⁻¹)."""

    when: datetime | None = None  # UTC date and time of the sun (None: sky only)
    latitude: float = 48.8  # degrees north
    longitude: float = 2.3  # degrees east
    sky: int = 46  # 16 or 46 directions; 0: sun only (all PAR direct)
    par: float = 1500.0  # global horizontal PAR above the canopy
    diffuse_fraction: float = 0.3  # part of ``par`` that is diffuse (1 with no sun)
    absorptance: float = 0.85  # leaf PAR absorptance (green leaves absorb ~85 %)
    ray_spacing: float | None = None  # metres between rays (default from triangle size)
    max_rays: int = 300_000  # per direction
    periodic: bool = True
    ground: tuple[float, float, float, float] | None = None  # xmin, ymin, xmax, ymax
    seed: int = 0
    engine: str = "zbuffer"  # zbuffer (numba, both cores), embree (embreex), trimesh

    def validate(self) -> None:
        if not -90 <= self.latitude <= 90:
            raise ParameterError(f"latitude {self.latitude} is outside [-90, 90] degrees")
        if not -180 <= self.longitude <= 360:
            raise ParameterError(f"longitude {self.longitude} is outside [-180, 360] degrees")
        if self.sky not in (0, 16, 46):
            raise ParameterError(f"sky {self.sky}: expected 0, 16 or 46 directions")
        if not self.par > 0:
            raise ParameterError(f"PAR {self.par} must be > 0 µmol m-2 s-1")
        if not 0 <= self.diffuse_fraction <= 1:
            raise ParameterError(f"diffuse fraction {self.diffuse_fraction} is outside [0, 1]")
        if not 0 < self.absorptance <= 1:
            raise ParameterError(f"absorptance {self.absorptance} is outside (0, 1]")
        if self.ray_spacing is not None and not self.ray_spacing > 0:
            raise ParameterError(f"ray spacing {self.ray_spacing} must be > 0 m")
        if self.max_rays < 1:
            raise ParameterError(f"max rays {self.max_rays} must be >= 1")
        if self.engine not in ENGINES:
            raise ParameterError(
                f"light engine {self.engine!r}: expected one of {', '.join(ENGINES)}"
            )
        if self.when is None and self.sky == 0:
            raise ParameterError("no light: give a sun time or a sky of 16 or 46 directions")


# --------------------------------------------------------------------------- sun and sky
def sun_position(when: datetime, latitude: float, longitude: float) -> tuple[float, float]:
    """Solar (elevation, azimuth) in degrees; azimuth clockwise from north.

    NOAA general solar position equations (fractional year γ, Spencer's series for the
    equation of time and declination). Naive datetimes are taken as UTC.
    """
    t = when if when.tzinfo is not None else when.replace(tzinfo=UTC)
    t = t.astimezone(UTC)
    start = datetime(t.year, 1, 1, tzinfo=UTC)
    days = 366 if (t.year % 4 == 0 and (t.year % 100 != 0 or t.year % 400 == 0)) else 365
    hour = t.hour + t.minute / 60 + t.second / 3600
    g = 2 * np.pi / days * ((t - start).days + (hour - 12) / 24)
    eqtime = 229.18 * (
        0.000075
        + 0.001868 * np.cos(g)
        - 0.032077 * np.sin(g)
        - 0.014615 * np.cos(2 * g)
        - 0.040849 * np.sin(2 * g)
    )
    decl = (
        0.006918
        - 0.399912 * np.cos(g)
        + 0.070257 * np.sin(g)
        - 0.006758 * np.cos(2 * g)
        + 0.000907 * np.sin(2 * g)
        - 0.002697 * np.cos(3 * g)
        + 0.00148 * np.sin(3 * g)
    )
    tst = hour * 60 + eqtime + 4 * longitude  # true solar time, minutes
    ha = np.radians(tst / 4 - 180)
    lat = np.radians(latitude)
    cz = np.sin(lat) * np.sin(decl) + np.cos(lat) * np.cos(decl) * np.cos(ha)
    zen = np.arccos(np.clip(cz, -1, 1))
    az = (
        np.degrees(np.arctan2(np.sin(ha), np.cos(ha) * np.sin(lat) - np.tan(decl) * np.cos(lat)))
        + 180.0
    )
    return float(90 - np.degrees(zen)), float(az % 360)


def direction_from(elevation: float, azimuth: float) -> Array:
    """Unit vector towards a source at (elevation, azimuth clockwise from north), Z-up with
    +y north and +x east."""
    e, a = np.radians(elevation), np.radians(azimuth)
    return np.array([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)])


def _icosahedral_16() -> Array:
    phi = np.radians(np.degrees(np.arctan(0.5)))
    verts = [np.array([0.0, 0.0, 1.0])]
    verts += [
        np.array(
            [
                np.cos(phi) * np.cos(k * 2 * np.pi / 5),
                np.cos(phi) * np.sin(k * 2 * np.pi / 5),
                np.sin(phi),
            ]
        )
        for k in range(5)
    ]
    lower = [
        np.array(
            [
                np.cos(phi) * np.cos((k + 0.5) * 2 * np.pi / 5),
                np.cos(phi) * np.sin((k + 0.5) * 2 * np.pi / 5),
                -np.sin(phi),
            ]
        )
        for k in range(5)
    ]
    dirs = [verts[0]] + verts[1:]
    for k in range(5):  # upper cap faces: pole + two upper vertices
        c = verts[0] + verts[1 + k] + verts[1 + (k + 1) % 5]
        dirs.append(c / np.linalg.norm(c))
    for k in range(5):  # band faces pointing up: two upper vertices + one lower
        c = verts[1 + k] + verts[1 + (k + 1) % 5] + lower[k]
        dirs.append(c / np.linalg.norm(c))
    out = np.array(dirs)
    out[:, :2] *= -1.0  # CARIBU's azimuth origin (its file lists these exactly)
    return out


def _rings_46() -> Array:
    counts = [1, 5, 10, 15, 15]
    n = sum(counts)
    dirs, done = [], 0
    for j, c in enumerate(counts):
        mid = 1 - (done + 0.5 * c) / n  # cos(zenith) at the ring's middle
        sz = np.sqrt(1 - mid * mid)
        for k in range(c):
            a = 2 * np.pi * (k + 0.5 * (j % 2)) / c
            dirs.append([sz * np.cos(a), sz * np.sin(a), mid])
        done += c
    return np.array(dirs)


def sky_directions(n: int) -> tuple[Array, Array]:
    """``(directions (n, 3) towards the sky, weights (n,))`` of the standard overcast sky;
    weights are fractions of the diffuse horizontal irradiance (sum 1)."""
    if n == 16:
        d = _icosahedral_16()
    elif n == 46:
        d = _rings_46()
    else:
        raise ParameterError(f"sky of {n} directions: expected 16 or 46")
    sin_b = d[:, 2]
    w = (1 + 2 * sin_b) / 3 * sin_b  # equal solid angles: L(β) · sin β
    return d, w / w.sum()


# --------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class LightResult:
    """Light intercepted by every triangle, leaf and the ground."""

    energy: Array  # (m,) intercepted µmol s-1 per triangle
    irradiance: Array  # (m,) intercepted µmol m-2 s-1 per triangle
    absorbed: Array  # (m,) absorbed µmol m-2 s-1 per triangle
    leaves: dict[str, Array]  # plant, leaf, area, intercepted, absorbed, fraction
    gap_fraction: float  # of all incident light (sun + sky weighted)
    gap_fraction_sun: float | None
    gap_fraction_sky: float | None
    gap_by_direction: Array  # (d,) gap fraction per cast direction
    directions: Array  # (d, 3) towards the sources
    incident: Array  # (d,) horizontal irradiance per direction
    ground_area: float
    sun: tuple[float, float] | None  # elevation, azimuth (degrees)
    rays: int
    engine: str
    meta: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        lv = self.leaves
        total_in = float(self.incident.sum() * self.ground_area)
        return {
            "triangles": int(self.energy.size),
            "leaves": int(lv["leaf"].size),
            "rays": self.rays,
            "directions": int(self.directions.shape[0]),
            "engine": self.engine,
            "sun_elevation_deg": None if self.sun is None else self.sun[0],
            "sun_azimuth_deg": None if self.sun is None else self.sun[1],
            "ground_area_m2": self.ground_area,
            "incident_umol_s": total_in,
            "intercepted_fraction": float(self.energy.sum() / total_in) if total_in else 0,
            "gap_fraction": self.gap_fraction,
            "gap_fraction_sun": self.gap_fraction_sun,
            "gap_fraction_sky": self.gap_fraction_sky,
            "absorbed_par_umol_s": float(lv["absorbed"].sum()),
            "leaf_area_m2": float(lv["area"].sum()),
            **self.meta,
        }

    def vertex_values(self, mesh: Mesh, values: Array | None = None) -> Array:
        """Per-triangle ``values`` (default absorbed PAR) averaged to vertices by area."""
        v = self.absorbed if values is None else np.asarray(values, float)
        area = mesh.face_areas()
        num = np.zeros(mesh.n_vertices)
        den = np.zeros(mesh.n_vertices)
        for k in range(3):
            num += np.bincount(mesh.faces[:, k], weights=v * area, minlength=mesh.n_vertices)
            den += np.bincount(mesh.faces[:, k], weights=area, minlength=mesh.n_vertices)
        return np.divide(num, den, out=np.zeros_like(num), where=den > 0)


# --------------------------------------------------------------------------- casting
class _Embree:
    """First hits with Embree (embreex) directly: one scene, float32 rays, ``tfar``."""

    def __init__(self, tri: Array) -> None:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcs.EmbreeScene()
        self._mesh = TriangleMesh(scene=self.scene, vertices=tri.astype(np.float32))

    def first(self, origins: Array, direction: Array) -> tuple[NDArray[np.int64], Array]:
        d = np.broadcast_to(direction.astype(np.float32), origins.shape)
        res = self.scene.run(origins.astype(np.float32), np.ascontiguousarray(d), output=1)
        prim = res["primID"].astype(np.int64)
        hit = prim >= 0
        return np.where(hit, prim, -1), np.where(hit, res["tfar"].astype(float), np.inf)


class _Trimesh:
    """trimesh's pure-Python engine (fallback)."""

    def __init__(self, tri: Array) -> None:
        import trimesh
        from trimesh.ray.ray_triangle import RayMeshIntersector

        tm = trimesh.Trimesh(
            tri.reshape(-1, 3), np.arange(tri.shape[0] * 3).reshape(-1, 3), process=False
        )
        self.engine = RayMeshIntersector(tm)

    def first(self, origins: Array, direction: Array) -> tuple[NDArray[np.int64], Array]:
        tri, ray, loc = self.engine.intersects_id(
            origins,
            np.broadcast_to(direction, origins.shape),
            multiple_hits=False,
            return_locations=True,
        )
        prim = np.full(len(origins), -1, np.int64)
        dist = np.full(len(origins), np.inf)
        prim[ray] = tri
        if ray.size:
            dist[ray] = np.einsum("ij,j->i", loc - origins[ray], direction)
        return prim, dist


def _intersector(tri: Array, engine: str = "embree") -> tuple[Any, str]:
    if engine == "embree":
        try:
            return _Embree(tri), "embree"
        except ImportError:
            warnings.warn(
                "embreex is not installed: using trimesh's pure-Python ray engine "
                "(much slower); pip install embreex",
                RuntimeWarning,
                stacklevel=3,
            )
    return _Trimesh(tri), "trimesh"


def _ground_rect(mesh: Mesh, opts: LightOptions) -> tuple[float, float, float, float]:
    if opts.ground is not None:
        x0, y0, x1, y1 = map(float, opts.ground)
    else:
        lo, hi = mesh.vertices[:, :2].min(axis=0), mesh.vertices[:, :2].max(axis=0)
        x0, y0, x1, y1 = float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
    if not (x1 > x0 and y1 > y0):
        raise InputError(f"ground rectangle {x0:g},{y0:g} .. {x1:g},{y1:g} has no area")
    return x0, y0, x1, y1


def _tiled(mesh: Mesh, rect) -> tuple[Array, NDArray[np.int64]]:
    """Triangle corners ``(m', 3, 3)`` of the mesh plus its copies in the 8 neighbouring
    tiles whose bounding box overlaps the rectangle; ``src`` maps copies to originals."""
    x0, y0, x1, y1 = rect
    tri = mesh.vertices[mesh.faces]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    wx, wy = x1 - x0, y1 - y0
    parts, src = [tri], [np.arange(tri.shape[0])]
    for i in (-1, 0, 1):
        for j in (-1, 0, 1):
            if i == 0 and j == 0:
                continue
            keep = np.flatnonzero(
                (hi[:, 0] + i * wx > x0)
                & (lo[:, 0] + i * wx < x1)
                & (hi[:, 1] + j * wy > y0)
                & (lo[:, 1] + j * wy < y1)
            )
            if keep.size:
                parts.append(tri[keep] + np.array([i * wx, j * wy, 0.0]))
                src.append(keep)
    return np.concatenate(parts), np.concatenate(src)


def _cast(
    engine: Any, ground: Array, d: Array, top: float, rect, periodic: bool
) -> NDArray[np.int64]:
    """First triangle hit (or -1) by rays from the sky along ``-d`` to ground points.

    Periodic: the path from the top plane to the ground is cut where it crosses tile
    borders; each piece is cast in the base tile's coordinates (shifted by whole tiles) and
    a hit counts only within that piece, so a ray sees the infinite periodic canopy."""
    n = ground.shape[0]
    t_end = top / d[2]
    start = ground + d[None, :] * t_end  # on the top plane
    direction = -d
    out = np.full(n, -1, np.int64)
    if not periodic:
        return engine.first(start, direction)[0]
    x0, y0, x1, y1 = rect
    w = np.array([x1 - x0, y1 - y0])
    lo = np.array([x0, y0])
    active = np.arange(n)
    t = np.zeros(n)
    while active.size:
        p = start[active] + t[active, None] * direction[None, :]
        # nudge points sitting on a border into the tile the ray is heading to
        q = p[:, :2] + 1e-9 * direction[None, :2]
        shift = np.floor((q - lo) / w)
        local = p.copy()
        local[:, :2] -= shift * w
        # time to leave the tile along x and y
        t_next = np.full(active.size, np.inf)
        for k in range(2):
            v = direction[k]
            if abs(v) > 1e-15:
                edge = lo[k] + (shift[:, k] + (1 if v > 0 else 0)) * w[k]
                t_next = np.minimum(t_next, (edge - p[:, k]) / v)
        seg = np.minimum(t_next, t_end - t[active])
        prim, dist = engine.first(local, direction)
        ok = (prim >= 0) & (dist <= seg + 1e-9)
        out[active[ok]] = prim[ok]
        done = ok.copy()
        t[active] += seg
        done |= t[active] >= t_end - 1e-12
        active = active[~done]
    return out


def intercept(mesh: Mesh, options: LightOptions | None = None, progress=None) -> LightResult:
    """Light intercepted by ``mesh`` (Z-up, metres; face ids ``plant``/``leaf`` optional)."""
    opts = options or LightOptions()
    opts.validate()
    if mesh.n_faces == 0:
        raise InputError("canopy has no triangles; expected a mesh of leaves")
    D, E, n_sun, sun, fd = _sources(opts)
    rect = _ground_rect(mesh, opts)
    face_area = mesh.face_areas()
    nx, ny = _cells(rect, face_area, opts)
    dx, dy = (rect[2] - rect[0]) / nx, (rect[3] - rect[1]) / ny
    area = (rect[2] - rect[0]) * (rect[3] - rect[1])
    energy = np.zeros(mesh.n_faces)
    gaps = np.zeros(len(D))
    hits, name = _engine_hits(mesh, D, rect, (nx, ny), opts)
    for k, hit in hits:
        ok = hit >= 0
        gaps[k] = 1.0 - ok.mean()
        energy += np.bincount(hit[ok], minlength=mesh.n_faces) * (E[k] * dx * dy)
        if progress is not None:
            progress(k + 1, len(D))
    irr = np.divide(energy, face_area, out=np.zeros_like(energy), where=face_area > 0)
    is_leaf = mesh.face_ids["leaf"] > 0 if "leaf" in mesh.face_ids else np.ones(mesh.n_faces, bool)
    absorbed = irr * np.where(is_leaf, opts.absorptance, 1.0)
    w = E / E.sum()
    gap_sun = float(gaps[0]) if n_sun else None
    gap_sky = float(np.dot(gaps[n_sun:], w[n_sun:]) / w[n_sun:].sum()) if len(D) > n_sun else None
    leaves = _per_leaf(mesh, energy, face_area, is_leaf, opts, E.sum() * area)
    return LightResult(
        energy,
        irr,
        absorbed,
        leaves,
        float(np.dot(gaps, w)),
        gap_sun,
        gap_sky,
        gaps,
        D,
        E,
        area,
        sun,
        int(nx * ny * len(D)),
        name,
        {
            "ray_spacing_m": float(np.sqrt(dx * dy)),
            "periodic": opts.periodic,
            "diffuse_fraction": fd,
            "par": opts.par,
        },
    )


def _cells(rect, face_area: Array, opts: LightOptions) -> tuple[int, int]:
    """Ray grid: spacing ``ray_spacing`` or ½·√(median triangle area), coarsened so one
    direction casts at most ``max_rays``."""
    x0, y0, x1, y1 = rect
    area = (x1 - x0) * (y1 - y0)
    spacing = opts.ray_spacing or 0.5 * float(np.sqrt(np.median(face_area[face_area > 0])))
    spacing = max(spacing, float(np.sqrt(area / opts.max_rays)))
    return max(1, int(np.ceil((x1 - x0) / spacing))), max(1, int(np.ceil((y1 - y0) / spacing)))


def _engine_hits(mesh: Mesh, D: Array, rect, cells: tuple[int, int], opts: LightOptions):
    """``(iterator of (direction index, first hit per ray), engine name)``."""
    if opts.engine == "zbuffer":
        return _zbuffer_hits(mesh, D, rect, cells, opts), "zbuffer"
    tri, src = (
        _tiled(mesh, rect)
        if opts.periodic
        else (mesh.vertices[mesh.faces], np.arange(mesh.n_faces))
    )
    engine, name = _intersector(tri, opts.engine)
    return _ray_hits(engine, src, mesh, D, rect, cells, opts), name


def _zbuffer_hits(mesh: Mesh, D: Array, rect, cells: tuple[int, int], opts: LightOptions):
    from biomorph.leaf.raster import first_hits

    tri = mesh.vertices[mesh.faces]
    chunk = 4  # directions per call: both cores busy, progress and Ctrl-C between calls
    for k0 in range(0, len(D), chunk):
        hits = first_hits(tri, D[k0 : k0 + chunk], rect, cells, opts.seed, opts.periodic, k0)
        for k, hit in enumerate(hits):
            yield k0 + k, hit


def _ray_hits(engine, src, mesh: Mesh, D: Array, rect, cells: tuple[int, int], opts):
    """Rays cast one direction at a time from the same jittered ground points as the
    z-buffer's (:func:`biomorph.leaf.raster.jitter`)."""
    from biomorph.leaf.raster import jitter

    x0, y0, x1, y1 = rect
    nx, ny = cells
    dx, dy = (x1 - x0) / nx, (y1 - y0) / ny
    top = float(mesh.vertices[:, 2].max()) + 1e-3 + 1e-6 * max(x1 - x0, y1 - y0)
    gx, gy = np.meshgrid(x0 + (np.arange(nx) + 0.5) * dx, y0 + (np.arange(ny) + 0.5) * dy)
    for k, d in enumerate(D):
        j = jitter(opts.seed, k, nx, ny)
        ground = np.column_stack(
            [gx.ravel() + j[:, 0] * dx, gy.ravel() + j[:, 1] * dy, np.zeros(gx.size)]
        )
        hit = _cast(engine, ground, d, top, rect, opts.periodic)
        yield k, np.where(hit >= 0, src[np.maximum(hit, 0)], -1)


def _sources(opts: LightOptions):
    """Directions towards the sources, their horizontal irradiance, sun count, sun, f_d."""
    sun = None
    dirs, inc = [], []
    fd = opts.diffuse_fraction if opts.when is not None else 1.0
    if opts.sky == 0:
        fd = 0.0  # no sky: all of ``par`` comes from the sun
    if opts.when is not None:
        el, az = sun_position(opts.when, opts.latitude, opts.longitude)
        if el <= 0:
            raise ParameterError(
                f"the sun is below the horizon (elevation {el:.1f}°) at "
                f"{opts.when.isoformat()} UTC, latitude {opts.latitude:g}, "
                f"longitude {opts.longitude:g}; expected a daytime sun"
            )
        sun = (el, az)
        if fd < 1:
            dirs.append(direction_from(el, az))
            inc.append(opts.par * (1 - fd))
    n_sun = len(dirs)
    if opts.sky and fd > 0:
        sd, sw = sky_directions(opts.sky)
        dirs.extend(sd)
        inc.extend(opts.par * fd * sw)
    return np.array(dirs), np.array(inc), n_sun, sun, fd


def _per_leaf(
    mesh: Mesh, energy: Array, face_area: Array, is_leaf, opts: LightOptions, incident_total: float
) -> dict[str, Array]:
    plant = mesh.face_ids.get("plant", np.zeros(mesh.n_faces, np.int64))
    leaf = mesh.face_ids.get("leaf", np.ones(mesh.n_faces, np.int64))
    sel = np.flatnonzero(is_leaf)
    key = plant[sel].astype(np.int64) * (int(leaf.max()) + 1) + leaf[sel]
    uniq, inv = np.unique(key, return_inverse=True)
    e = np.bincount(inv, weights=energy[sel], minlength=uniq.size)
    a = np.bincount(inv, weights=face_area[sel], minlength=uniq.size)
    first = np.zeros(uniq.size, np.int64)
    first[inv] = sel
    return {
        "plant": plant[first],
        "leaf": leaf[first],
        "area": a,
        "intercepted": e,
        "absorbed": e * opts.absorptance,
        "fraction": e / incident_total if incident_total else np.zeros_like(e),
        "absorbed_par": np.divide(e * opts.absorptance, a, out=np.zeros_like(e), where=a > 0),
    }


def turbid_canopy(
    lai: float, size: float = 1.0, leaf: float = 0.03, seed: int = 0, horizontal: bool = True
) -> Mesh:
    """A Poisson turbid medium for validating a light model against Beer–Lambert: square
    leaves of side ``leaf`` (m) at uniform random positions over a ``size`` × ``size`` m tile,
    0.2–1.2 m above the soil, horizontal or uniformly (spherically) oriented, enough of them
    for leaf area index ``lai``. Its gap fraction in direction θ is exp(−G·LAI / cos θ) with
    G = 1 (horizontal) or 0.5 (spherical)."""
    from biomorph.core.transforms import quat_to_matrix

    rng = np.random.default_rng(seed)
    n = int(round(lai * size * size / leaf**2))
    c = np.column_stack(
        [rng.uniform(0, size, n), rng.uniform(0, size, n), rng.uniform(0.2, 1.2, n)]
    )
    sq = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]]) * leaf
    if horizontal:
        rot = np.broadcast_to(np.eye(3), (n, 3, 3))
    else:  # normalised Gaussian 4-vectors are uniform random rotations
        rot = quat_to_matrix(rng.standard_normal((n, 4)))
    v = (np.einsum("nij,kj->nki", rot, sq) + c[:, None]).reshape(-1, 3)
    f = (np.array([[0, 1, 2], [0, 2, 3]])[None] + 4 * np.arange(n)[:, None, None]).reshape(-1, 3)
    return Mesh(v, f)


__all__ = [
    "LightOptions",
    "LightResult",
    "direction_from",
    "intercept",
    "sky_directions",
    "sun_position",
    "turbid_canopy",
]
