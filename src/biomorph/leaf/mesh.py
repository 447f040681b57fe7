"""Vectorised meshing of many leaves at once.

A :class:`LeafBatch` holds the evaluated profiles of ``N`` leaves sampled at ``K`` points
along their visible midrib (structure of arrays); :func:`leaf_grid` turns it into surface
points ``(N, K, n_u, 3)`` in one numpy pass and :func:`mesh_batch` into one
:class:`~biomorph.core.mesh.Mesh` with unit vertex normals, UVs (u across the blade, v from
base 0 to tip 1) and per-triangle ``plant`` / ``leaf`` ids.

Frames: each leaf is built in its local frame (midrib in the x–z plane, x away from the
stem, z up), rotated by its azimuth about +z and translated to its origin (metres).
Triangles are counter-clockwise seen from the adaxial (upper) side.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core.curves import integrate_angles
from biomorph.core.mesh import Mesh
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.leaf.age import state_at_age


@dataclass(frozen=True, eq=False)
class LeafBatch:
    """Evaluated profiles of ``N`` leaves, ``K`` samples each (metres, radians).

    phi : ``(N, K-1)`` tangent angle of each midrib segment (above the horizontal).
    seg : ``(N, K-1)`` segment lengths (their sum is the visible length).
    width : ``(N, K)`` full blade width at the samples.
    theta : ``(N, K)`` twist angle about the midrib.
    wave_amp : ``(N, K)`` margin undulation amplitude; wave_arg ``(N, K)`` its phase.
    v : ``(N, K)`` texture coordinate along the leaf (0 base, 1 tip).
    origin : ``(N, 3)`` base position; azimuth ``(N,)`` rotation about +z.
    plant, leaf : ``(N,)`` integer ids written per triangle.
    """

    phi: Array
    seg: Array
    width: Array
    theta: Array
    wave_amp: Array
    wave_arg: Array
    v: Array
    origin: Array
    azimuth: Array
    plant: NDArray[np.int64]
    leaf: NDArray[np.int64]
    ground: float | None = None

    @property
    def n(self) -> int:
        return int(self.width.shape[0])

    @property
    def k(self) -> int:
        return int(self.width.shape[1])

    @classmethod
    def from_shapes(
        cls,
        shapes: Sequence,
        ages: Sequence[float | None] | None = None,
        s: ArrayLike | None = None,
        origin: ArrayLike | None = None,
        azimuth: ArrayLike | None = None,
        plant: ArrayLike | None = None,
        leaf: ArrayLike | None = None,
        twist: bool = True,
        undulation: bool = True,
        states: Sequence | None = None,
    ) -> LeafBatch:
        """Evaluate leaf shapes (optionally growing: ``ages`` or explicit ``states``).

        ``s`` are sample positions in [0, 1] along the visible leaf: ``(K,)`` shared,
        ``(N, K)`` per leaf, or ``None`` for 31 equal steps.
        """
        n = len(shapes)
        if states is None:
            ages_l = [None] * n if ages is None else list(ages)
            states = [
                None if a is None else state_at_age(sh, a)
                for sh, a in zip(shapes, ages_l, strict=True)
            ]
        sg = np.linspace(0, 1, 31) if s is None else np.asarray(s, float)
        sg = np.broadcast_to(sg, (n, sg.shape[-1]))
        rows = [
            leaf_profile(sh, st, sg[i], twist, undulation)
            for i, (sh, st) in enumerate(zip(shapes, states, strict=True))
        ]
        cols = [np.array([r[c] for r in rows]) for c in range(7)]
        return cls(*cols, *_placement(n, origin, azimuth, plant, leaf))


def _placement(n: int, origin, azimuth, plant, leaf):
    o = (
        np.zeros((n, 3))
        if origin is None
        else np.broadcast_to(np.asarray(origin, float), (n, 3)).copy()
    )
    a = np.zeros(n) if azimuth is None else np.broadcast_to(np.asarray(azimuth, float), (n,))
    p = (
        np.zeros(n, np.int64)
        if plant is None
        else np.broadcast_to(np.asarray(plant, np.int64), (n,))
    )
    lf = (
        np.arange(n, dtype=np.int64)
        if leaf is None
        else np.broadcast_to(np.asarray(leaf, np.int64), (n,))
    )
    return o, np.array(a), np.array(p), np.array(lf)


def leaf_profile(shape, state, s: Array, twist: bool = True, undulation: bool = True):
    """Profiles of one leaf (or growing leaf ``state``) at visible fractions ``s``.

    Returns ``(phi, seg, width, theta, wave_amp, wave_arg, v)`` as in :class:`LeafBatch`
    (one row): segment angles and lengths of the visible midrib, full width, twist and
    undulation at the samples, and the texture coordinate ``v = s``."""
    L = shape.length
    if state is None:
        l_cur, h, wf, bend, age = L, L, 1.0, 0.0, None
    else:
        l_cur, h, wf, bend, age = (
            state.length,
            state.visible,
            state.width_factor,
            state.bend,
            state.age,
        )
    sigma = l_cur - (1.0 - s) * h  # metres from the base of the current leaf
    shat = np.clip(1.0 - (l_cur - sigma) / L, 0, 1)  # mature coordinate (tip-fixed, exact 1)
    smid = 0.5 * (sigma[1:] + sigma[:-1]) / L  # base-relative midrib coordinate
    phi = shape.phi_at(smid, age) - bend * smid
    seg = np.diff(s) * h
    width = shape.width * wf * shape.r_at(shat)
    theta = shape.theta_at(shat) if twist else np.zeros_like(s)
    if undulation and shape.undulation > 0:
        amp = shape.undulation * (1.0 - shat)
        arg = 2 * np.pi * shat * L / shape.wavelength + shape.phase
    else:
        amp, arg = np.zeros_like(s), np.zeros_like(s)
    return phi, seg, width, theta, amp, arg, s.copy()


def rest_on_soil(batch: LeafBatch, ground: float = 0.0) -> LeafBatch:
    """Bend every midrib at the soil plane ``z = ground`` as a real leaf does.

    Walking from the base, a segment that would end below the soil is turned so it ends on
    it (same length, so the arc length is kept); from there on the blade lies on the soil
    (twist and undulation are flattened where the midrib touches it) and later segments
    may only rise or run along it. Meshes of the result also clamp margin vertices to the
    soil (``ground`` is kept on the batch), so no vertex is below ground.
    """
    phi = batch.phi.copy()
    theta = batch.theta.copy()
    amp = batch.wave_amp.copy()
    z = batch.origin[:, 2].astype(float).copy()
    dz = batch.seg * np.sin(phi)
    for k in range(batch.k - 1):
        low = z + dz[:, k] < ground
        if low.any():
            new_dz = np.minimum(ground - z[low], 0.0)
            ratio = np.divide(
                new_dz, batch.seg[low, k], out=np.zeros_like(new_dz), where=batch.seg[low, k] > 0
            )
            phi[low, k] = np.arcsin(np.clip(ratio, -1.0, 1.0))
            theta[low, k + 1] = 0.0
            amp[low, k + 1] = 0.0
            z[low] += new_dz
        z[~low] += dz[~low, k]
    return LeafBatch(
        phi,
        batch.seg,
        batch.width,
        theta,
        amp,
        batch.wave_arg,
        batch.v,
        batch.origin,
        batch.azimuth,
        batch.plant,
        batch.leaf,
        float(ground),
    )


def concat_batches(batches: Sequence[LeafBatch]) -> LeafBatch:
    """One batch from several with the same ``K``."""
    ks = {b.k for b in batches}
    if len(ks) != 1:
        raise ParameterError(f"batches have different sample counts {sorted(ks)}")
    names = (
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
    grounds = {b.ground for b in batches}
    ground = (
        grounds.pop()
        if len(grounds) == 1
        else min((g for g in grounds if g is not None), default=None)
    )
    return LeafBatch(
        *[np.concatenate([getattr(b, f) for b in batches]) for f in names], ground=ground
    )


def leaf_grid(batch: LeafBatch, u: ArrayLike, with_normals: bool = False):
    """Surface points ``(N, K, n_u, 3)`` (metres, world frame) at cross positions ``u``.

    With ``with_normals`` also returns unit normals of the same shape: the analytic blade
    normal ``m = cosθ·n − sinθ·j`` when there is no undulation (exact for untwisted blades,
    tilted by ≈ atan(u·w·dθ/ds) otherwise), finite differences of the surface otherwise.
    """
    ua = np.asarray(u, float)
    xz = integrate_angles(batch.phi, batch.seg)  # (N,K,2)
    ph = batch.phi
    phv = np.concatenate([ph[:, :1], 0.5 * (ph[:, 1:] + ph[:, :-1]), ph[:, -1:]], axis=1)
    c, sn = np.cos(phv), np.sin(phv)
    ct, st = np.cos(batch.theta), np.sin(batch.theta)
    ca, sa = np.cos(batch.azimuth)[:, None], np.sin(batch.azimuth)[:, None]

    def rot(vx, vy, vz):
        """Rotate local (x, y, z) components (N,K) about +z by the azimuth → (N,K,3)."""
        out = np.empty(vx.shape + (3,))
        out[..., 0] = ca * vx - sa * vy
        out[..., 1] = sa * vx + ca * vy
        out[..., 2] = vz
        return out

    # cross-section direction d = cosθ j + sinθ n, blade normal m = cosθ n − sinθ j,
    # with in-plane normal n = (−sinφ, 0, cosφ) and lateral axis j = (0, 1, 0)
    d = rot(-st * sn, ct, st * c)
    m = rot(-ct * sn, -st, ct * c)
    base = rot(xz[..., 0], np.zeros_like(xz[..., 0]), xz[..., 1])
    base += batch.origin[:, None, :]
    pts = base[:, :, None, :] + (batch.width[..., None] * ua)[..., None] * d[:, :, None, :]
    waves = bool(np.any(batch.wave_amp))
    if waves:
        side = np.where(ua < 0, 0.5 * np.pi, 0.0)
        wave = batch.wave_amp[..., None] * (2 * ua) ** 2 * np.sin(batch.wave_arg[..., None] + side)
        pts += wave[..., None] * m[:, :, None, :]
    if batch.ground is not None:
        np.maximum(pts[..., 2], batch.ground, out=pts[..., 2])
    if not with_normals:
        return pts
    if waves:
        return pts, _grid_normals(pts)
    return pts, np.broadcast_to(m[:, :, None, :], pts.shape)


def _grid_faces(k: int, nu: int) -> NDArray[np.int64]:
    """Face template ``(k-1, nu-1, 2, 3)`` of one leaf grid (row-major vertex index)."""
    kk, jj = np.meshgrid(np.arange(k - 1), np.arange(nu - 1), indexing="ij")
    a = kk * nu + jj
    b = a + 1
    d = a + nu
    c = d + 1
    t1 = np.stack([a, d, c], axis=-1)  # dropped when the upper row has zero width
    t2 = np.stack([a, c, b], axis=-1)  # dropped when the lower row has zero width
    return np.stack([t1, t2], axis=2)


def mesh_batch(
    batch: LeafBatch, n_u: int = 3, normals: bool = True, drop_degenerate: bool = True
) -> Mesh:
    """One mesh of all leaves in ``batch`` with ``n_u`` (>= 2) vertices across each blade.

    Degenerate triangles at zero-width ends (closed tips/bases) are dropped, so a closed
    tip strip yields ``n_u − 1`` triangles instead of ``2(n_u − 1)``. Pass
    ``drop_degenerate=False`` to keep a fixed topology (animation frames, morph targets).
    """
    if n_u < 2:
        raise ParameterError(f"n_u={n_u}: a leaf needs at least 2 vertices across")
    u = np.linspace(-0.5, 0.5, n_u)
    pts, nrm = leaf_grid(batch, u, with_normals=True)  # (N,K,U,3)
    n, k = batch.n, batch.k
    per = k * n_u
    tmpl = _grid_faces(k, n_u)  # (K-1,U-1,2,3)
    w = batch.width
    keep = np.stack([w[:, 1:] > 0, w[:, :-1] > 0], axis=-1)  # (N,K-1,2)
    if not drop_degenerate:
        keep = np.ones_like(keep)
    keep = np.broadcast_to(keep[:, :, None, :], (n, k - 1, n_u - 1, 2))
    if n and (keep == keep[:1]).all():
        # same zero-width pattern on every leaf (the usual case): filter the template once
        one = tmpl[keep[0]]  # (f, 3)
        faces = (one[None] + (np.arange(n, dtype=np.int64) * per)[:, None, None]).reshape(-1, 3)
        leaf_of_face = np.repeat(np.arange(n), one.shape[0])
    else:
        faces = tmpl[None] + (np.arange(n, dtype=np.int64) * per)[:, None, None, None, None]
        faces = faces[keep]
        leaf_of_face = np.broadcast_to(np.arange(n)[:, None, None, None], keep.shape)[keep]
    verts = pts.reshape(-1, 3)
    nrm = nrm.reshape(-1, 3) if normals else None
    uv = np.empty((n, k, n_u, 2))
    uv[..., 0] = u + 0.5
    uv[..., 1] = batch.v[:, :, None]
    return Mesh(
        verts,
        faces,
        normals=nrm,
        uv=uv.reshape(-1, 2),
        face_ids={"plant": batch.plant[leaf_of_face], "leaf": batch.leaf[leaf_of_face]},
    )


def _grid_normals(pts: Array) -> Array:
    """Unit surface normals ``S_s × S_u`` from finite differences on the grid."""
    ds = np.gradient(pts, axis=1)
    du = np.gradient(pts, axis=2)
    nrm = np.cross(ds, du)
    length = np.linalg.norm(nrm, axis=-1, keepdims=True)
    bad = length[..., 0] < 1e-14
    if bad.any():
        # zero-width rows (closed tip/base): borrow the neighbouring row's normal
        nb = np.where(np.arange(pts.shape[1]) == 0, 1, np.arange(pts.shape[1]) - 1)
        nrm = np.where(bad[..., None], nrm[:, nb], nrm)
        length = np.linalg.norm(nrm, axis=-1, keepdims=True)
    out = np.divide(nrm, length, out=np.zeros_like(nrm), where=length > 0)
    out[~np.isfinite(out).all(axis=-1)] = 0.0
    # fall back to +z for any remaining zero normal
    zero = np.linalg.norm(out, axis=-1) == 0
    out[zero] = (0.0, 0.0, 1.0)
    return out


def leaf_areas(mesh: Mesh, key: str = "leaf") -> Array:
    """Area (m²) per id of ``mesh.face_ids[key]`` (index = id)."""
    ids = mesh.face_ids[key]
    return np.bincount(
        ids, weights=mesh.face_areas(), minlength=int(ids.max()) + 1 if ids.size else 0
    )


def split_boundary_edge(mesh: Mesh, face: int | None = None, edge: int | None = None) -> Mesh:
    """Add exactly one triangle by splitting a boundary (margin) edge at its midpoint.

    Without ``face``/``edge`` the largest face owning a boundary edge is chosen. The two new
    triangles lie in the plane of the old one, so area is unchanged and no T-junction
    appears (the split edge belongs to a single face).
    """
    f = np.asarray(mesh.faces)
    if face is None or edge is None:
        n = np.int64(max(mesh.n_vertices, 1))
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        key = np.minimum(e[:, 0], e[:, 1]) * n + np.maximum(e[:, 0], e[:, 1])
        _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
        boundary = (cnt[inv] == 1).reshape(3, -1).T  # (m,3) per face edge
        cand = np.flatnonzero(boundary.any(axis=1))
        if cand.size == 0:
            raise ParameterError("mesh has no boundary edge to split")
        areas = mesh.face_areas()
        face = int(cand[np.argmax(areas[cand])])
        edge = int(np.flatnonzero(boundary[face])[0])
    a, b, c = f[face, edge], f[face, (edge + 1) % 3], f[face, (edge + 2) % 3]
    v = np.asarray(mesh.vertices)
    mid_idx = len(v)
    verts = np.vstack([v, 0.5 * (v[a] + v[b])])
    extra: dict = {}
    if mesh.normals is not None:
        nm = np.asarray(mesh.normals[a]) + np.asarray(mesh.normals[b])
        nm = nm / (np.linalg.norm(nm) or 1.0)
        extra["normals"] = np.vstack([mesh.normals, nm])
    if mesh.uv is not None:
        extra["uv"] = np.vstack([mesh.uv, 0.5 * (mesh.uv[a] + mesh.uv[b])])
    new_faces = np.vstack([f, [[mid_idx, b, c]]])
    new_faces[face] = (a, mid_idx, c)
    ids = {k: np.append(val, val[face]) for k, val in mesh.face_ids.items()}
    return Mesh(verts, new_faces, face_ids=ids, **extra)


__all__ = [
    "LeafBatch",
    "concat_batches",
    "leaf_areas",
    "leaf_grid",
    "leaf_profile",
    "mesh_batch",
    "rest_on_soil",
    "split_boundary_edge",
]
