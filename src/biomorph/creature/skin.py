"""The body envelope: an implicit surface over bones and muscles, skinned with smooth weights.

Field: each bone contributes two tapered capsules from its joint to its far end whose radius
is the bone's own half-width plus a thin layer of tissue at the ends (the bony landmarks:
joints, the skull, the tips of the spines) and the soft-tissue half-width of its mass box
(``Creature.mass_size``) in the middle; trunk vertebrae add one sphere at the centre of
their soft-tissue mass (``mass_center``) so the belly hangs below the spine; every muscle
adds capsules along its swept volume. The signed field ``max_i (r_i − d_i(p))`` is
computed on a grid by Euclidean distance transforms to the sampled capsule axes,
smoothed with a Gaussian
of 0.9 cells, which blends the spheres into one skin, and contoured at 0 with
``skimage.measure.marching_cubes``. Grid cell: the median capsule radius / 1.2, kept
between ``RES_MAX[lod]`` and ``RESOLUTION[lod]`` cells along the creature's longest side.

Weights: each envelope vertex is bound to the four bone segments nearest to it, with
weights ``1 / (d + h)²`` normalised (``h`` the grid cell: no vertex lies on a single bone
with weight 1 unless it is far from every other), so joints bend smoothly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.creature.bones.cage import trunk_sections
from biomorph.creature.creature import Creature

#: grid cells along the longest side per level of detail
RESOLUTION = (40, 64, 96)
#: finest grid (cells along the longest side) per level of detail
RES_MAX = (56, 96, 160)
#: tissue over bone at the bony landmarks, as a share of the bone's half-width
LANDMARK_TISSUE = 0.35
#: smoothing of the field (grid cells)
SMOOTH = 0.9


@dataclass(frozen=True)
class Body:
    """Envelope mesh (world, normals set), its per-vertex joints/weights ``(k, 4)``, and the
    muscles (list and mesh)."""

    envelope: Mesh
    joints: NDArray[np.int64]
    weights: NDArray[np.float64]
    muscles: Mesh | None
    muscle_list: list


def _capsules(c: Creature, ms: list) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Tapered capsules of the field: start/end points ``(s, 3)`` and radii ``(s,)``."""
    a_s, b_s, ra_s, rb_s = [], [], [], []
    ends = c.bone_ends
    pos = c.joint_positions
    for j in np.flatnonzero(c.bone_length > 1e-9).tolist():
        bone_hw = 0.5 * max(c.box_size[j, 0], c.box_size[j, 2])
        soft_hw = 0.25 * (c.mass_size[j, 0] + c.mass_size[j, 2])
        end_r = bone_hw * (1 + LANDMARK_TISSUE)
        if c.kind[j] == "skull":  # thin tissue over the skull: its narrower half-width
            end_r = mid_r = 0.5 * min(c.box_size[j, 0], c.box_size[j, 2]) * (1 + LANDMARK_TISSUE)
        elif c.kind[j] == "spine":
            mid_r = end_r
        else:
            mid_r = max(end_r, 0.8 * soft_hw)
        mid = 0.5 * (pos[j] + ends[j])
        a_s += [pos[j], mid]
        b_s += [mid, ends[j]]
        ra_s += [end_r, mid_r]
        rb_s += [mid_r, end_r]
    # the trunk's soft tissue: one sphere per trunk section (the rib cage is built round
    # the same sections, :mod:`biomorph.creature.bones.cage`)
    _, centre, radius = trunk_sections(c)
    a_s.extend(centre)
    b_s.extend(centre)
    ra_s.extend(radius)
    rb_s.extend(radius)
    for m in ms:  # every second path point is enough for the smoothed field
        keep = np.unique(np.r_[np.arange(0, len(m.path), 2), len(m.path) - 1])
        path, rad = m.path[keep], m.radius[keep]
        a_s.extend(path[:-1])
        b_s.extend(path[1:])
        ra_s.extend(rad[:-1])
        rb_s.extend(rad[1:])
    return np.array(a_s), np.array(b_s), np.array(ra_s), np.array(rb_s)


def _field(
    caps: tuple[NDArray, NDArray, NDArray, NDArray], lo: NDArray, h: float, shape: tuple[int, ...]
) -> NDArray:
    """``max_i (r_i(t) - |p - segment_i(t)|)`` on the grid (cells beyond every capsule's
    radius + 2 cells hold the floor of -2 cells): exact at every cell centre, each capsule
    visiting only the cells of its own bounding box (:func:`_capsule_field`)."""
    a, b, ra, rb = (np.ascontiguousarray(x, np.float64) for x in caps)
    field = np.full(shape, -2.0 * h, np.float32)
    _capsule_field(field, np.asarray(lo, np.float64), float(h), a, b, ra, rb)
    return field


@numba.njit(cache=True, nogil=True)
def _capsule_field(field, lo, h, a, b, ra, rb):  # pragma: no cover - compiled
    nx, ny, nz = field.shape
    for s in range(a.shape[0]):
        r_max = max(ra[s], rb[s]) + 2.0 * h
        lo_i = np.empty(3, np.int64)
        hi_i = np.empty(3, np.int64)
        dims = (nx, ny, nz)
        for k in range(3):
            m = min(a[s, k], b[s, k]) - r_max
            M = max(a[s, k], b[s, k]) + r_max
            lo_i[k] = max(int(np.floor((m - lo[k]) / h)), 0)
            hi_i[k] = min(int(np.ceil((M - lo[k]) / h)) + 1, dims[k])
        d0, d1, d2 = b[s, 0] - a[s, 0], b[s, 1] - a[s, 1], b[s, 2] - a[s, 2]
        l2 = d0 * d0 + d1 * d1 + d2 * d2
        inv = 1.0 / l2 if l2 > 1e-30 else 0.0
        for i in range(lo_i[0], hi_i[0]):
            px = lo[0] + i * h - a[s, 0]
            for j in range(lo_i[1], hi_i[1]):
                py = lo[1] + j * h - a[s, 1]
                for k in range(lo_i[2], hi_i[2]):
                    pz = lo[2] + k * h - a[s, 2]
                    t = (px * d0 + py * d1 + pz * d2) * inv
                    t = min(max(t, 0.0), 1.0)
                    ex, ey, ez = px - t * d0, py - t * d1, pz - t * d2
                    v = ra[s] + t * (rb[s] - ra[s]) - np.sqrt(ex * ex + ey * ey + ez * ez)
                    if v > field[i, j, k]:
                        field[i, j, k] = v


def _weights(c: Creature, v: NDArray, h: float) -> tuple[NDArray, NDArray]:
    """Four nearest bone segments per vertex, inverse-square distance weights. Candidate
    bones come from a k-d tree over points sampled along every bone (8 nearest samples),
    exact point-to-segment distances are taken only for those."""
    from scipy.spatial import cKDTree

    bones = np.flatnonzero(c.bone_length > 1e-9)
    a = c.joint_positions[bones]
    ab = c.bone_ends[bones] - a
    u = np.linspace(0.0, 1.0, 5)
    samples = (a[:, None, :] + u[None, :, None] * ab[:, None, :]).reshape(-1, 3)
    owner = np.repeat(np.arange(len(bones)), len(u))
    kq = min(8, len(samples))
    _, idx = cKDTree(samples).query(v, k=kq)
    cand = owner[np.atleast_2d(idx).reshape(len(v), kq)]  # (k, kq) bone numbers
    ca, cab = a[cand], ab[cand]
    L2 = np.maximum((cab**2).sum(axis=2), 1e-18)
    tt = np.clip(((v[:, None, :] - ca) * cab).sum(axis=2) / L2, 0, 1)
    d = np.linalg.norm(v[:, None, :] - (ca + tt[..., None] * cab), axis=2)
    # the same bone may appear several times among the candidates: keep it once
    order = np.argsort(d, axis=1, kind="stable")
    cs = np.take_along_axis(cand, order, axis=1)
    ds = np.take_along_axis(d, order, axis=1)
    dup = np.zeros_like(cs, bool)
    for k in range(1, kq):
        dup[:, k] = (cs[:, :k] == cs[:, k : k + 1]).any(axis=1)
    ds = np.where(dup, np.inf, ds)
    order = np.argsort(ds, axis=1, kind="stable")[:, :4]
    near = np.take_along_axis(cs, order, axis=1)
    dn = np.take_along_axis(ds, order, axis=1)
    w = np.where(np.isfinite(dn), 1.0 / (np.where(np.isfinite(dn), dn, 0) + h) ** 2, 0.0)
    w /= w.sum(axis=1, keepdims=True)
    return bones[near], w


def envelope(c: Creature, ms: list | None = None, lod: int = 1) -> tuple[Mesh, float]:
    """The envelope mesh over bones (and muscles ``ms``) and the grid cell size (m)."""
    from skimage.measure import marching_cubes

    grid, lo, h = envelope_field(c, ms, lod)
    verts, faces, _, _ = marching_cubes(grid, level=0.0, spacing=(h, h, h))
    verts = verts + lo
    faces = faces.astype(np.int64)
    tri = verts[faces]
    if (tri[:, 0] * np.cross(tri[:, 1], tri[:, 2])).sum() < 0:  # wind the faces outwards
        faces = faces[:, ::-1]
    return Mesh(verts, faces).compute_normals(), h


def envelope_field(
    c: Creature, ms: list | None = None, lod: int = 1
) -> tuple[NDArray, NDArray, float]:
    """The smoothed signed field whose 0-level is the envelope (positive inside), the world
    position of its cell ``(0, 0, 0)`` and the cell size (m)."""
    from scipy.ndimage import gaussian_filter

    caps = _capsules(c, ms or [])
    a, b, ra, rb = caps
    r = np.maximum(ra, rb)[:, None]
    lo = np.minimum(a - r, b - r).min(axis=0)
    hi = np.maximum(a + r, b + r).max(axis=0)
    ext = float((hi - lo).max())
    # cell: fine enough that the median limb/bone capsule spans ~2.4 cells, within the
    # RESOLUTION range for this level of detail
    fine, coarse = ext / RES_MAX[lod], ext / RESOLUTION[lod]
    h = float(np.clip(np.median(np.minimum(ra, rb)) / 1.2, fine, coarse))
    # thin capsules would vanish between grid points: keep each at least a cell wide
    ra, rb = np.maximum(ra, 1.4 * h), np.maximum(rb, 1.4 * h)
    # the Gaussian moves a convex surface of radius r inwards by about sigma^2 / r (the
    # field's Laplacian 2 / r times sigma^2 / 2): each capsule is grown by that first, so
    # the smoothed skin keeps the radii its rules give (the rib cage relies on it)
    sig2 = (SMOOTH * h) ** 2
    caps = (a, b, ra + sig2 / ra, rb + sig2 / rb)
    lo = lo - 3 * h
    shape = tuple((np.ceil((hi + 3 * h - lo) / h)).astype(int) + 1)
    return gaussian_filter(_field(caps, lo, h, shape), SMOOTH), lo, h


def body(c: Creature, lod: int = 1, with_muscles: bool = True) -> Body:
    """Muscles, envelope and skin weights of ``c``."""
    from biomorph.creature.muscles import muscle_mesh, muscles

    ms = muscles(c, lod) if with_muscles else []
    env, h = envelope(c, ms, lod)
    joints, weights = _weights(c, env.vertices, h)
    return Body(env, joints, weights, muscle_mesh(ms, lod), ms)
