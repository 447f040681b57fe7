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
    """Tapered capsules of the field: start/end points ``(s, 3)`` and radii ``(s,)``: two
    per bone (joint to mid-bone, mid-bone to end), one sphere per trunk section, and the
    muscles' swept paths."""
    js = np.flatnonzero(c.bone_length > 1e-9)
    box, mass = c.box_size[js], c.mass_size[js]
    kind = np.asarray(c.kind, dtype=object)[js]
    bone_hw = 0.5 * np.maximum(box[:, 0], box[:, 2])
    soft_hw = 0.25 * (mass[:, 0] + mass[:, 2])
    end_r = bone_hw * (1 + LANDMARK_TISSUE)
    mid_r = np.where(kind == "spine", end_r, np.maximum(end_r, 0.8 * soft_hw))
    skull = kind == "skull"  # thin tissue over the skull: its narrower half-width
    end_r[skull] = mid_r[skull] = (
        0.5 * np.minimum(box[skull, 0], box[skull, 2]) * (1 + LANDMARK_TISSUE)
    )
    pos, ends = c.joint_positions[js], c.bone_ends[js]
    mid = 0.5 * (pos + ends)
    a_s = [np.stack([pos, mid], 1).reshape(-1, 3)]
    b_s = [np.stack([mid, ends], 1).reshape(-1, 3)]
    ra_s = [np.stack([end_r, mid_r], 1).reshape(-1)]
    rb_s = [np.stack([mid_r, end_r], 1).reshape(-1)]
    # the trunk's soft tissue: one sphere per trunk section (the rib cage is built round
    # the same sections, :mod:`biomorph.creature.bones.cage`)
    _, centre, radius = trunk_sections(c)
    a_s.append(centre)
    b_s.append(centre)
    ra_s.append(radius)
    rb_s.append(radius)
    for m in ms:  # every second path point is enough for the smoothed field
        keep = np.unique(np.r_[np.arange(0, len(m.path), 2), len(m.path) - 1])
        path, rad = m.path[keep], m.radius[keep]
        a_s.append(path[:-1])
        b_s.append(path[1:])
        ra_s.append(rad[:-1])
        rb_s.append(rad[1:])
    return np.concatenate(a_s), np.concatenate(b_s), np.concatenate(ra_s), np.concatenate(rb_s)


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
    """Four nearest bone segments per vertex (exact point-to-segment distances to every
    bone, :func:`_nearest_segments`), inverse-square distance weights ``1 / (d + h)²``
    normalised."""
    bones = np.flatnonzero(c.bone_length > 1e-9)
    a = np.ascontiguousarray(c.joint_positions[bones], np.float64)
    ab = np.ascontiguousarray(c.bone_ends[bones] - a, np.float64)
    near, dn = _nearest_segments(np.ascontiguousarray(v, np.float64), a, ab)
    w = np.where(np.isfinite(dn), 1.0 / (np.where(np.isfinite(dn), dn, 0) + h) ** 2, 0.0)
    w /= w.sum(axis=1, keepdims=True)
    return bones[near], w


@numba.njit(cache=True, nogil=True)
def _nearest_segments(v, a, ab):  # pragma: no cover - compiled
    """Indices ``(k, 4)`` and distances of the four segments ``a + t·ab`` nearest to each
    point (ascending; ``inf`` and index 0 where there are fewer than four)."""
    k, m = v.shape[0], a.shape[0]
    idx = np.zeros((k, 4), np.int64)
    dist = np.full((k, 4), np.inf)
    l2 = np.empty(m)
    for b in range(m):
        l2[b] = max(ab[b, 0] ** 2 + ab[b, 1] ** 2 + ab[b, 2] ** 2, 1e-18)
    for i in range(k):
        for b in range(m):
            px, py, pz = v[i, 0] - a[b, 0], v[i, 1] - a[b, 1], v[i, 2] - a[b, 2]
            t = (px * ab[b, 0] + py * ab[b, 1] + pz * ab[b, 2]) / l2[b]
            t = min(max(t, 0.0), 1.0)
            ex, ey, ez = px - t * ab[b, 0], py - t * ab[b, 1], pz - t * ab[b, 2]
            d = np.sqrt(ex * ex + ey * ey + ez * ez)
            if d >= dist[i, 3]:
                continue
            s = 3
            while s > 0 and dist[i, s - 1] > d:
                dist[i, s] = dist[i, s - 1]
                idx[i, s] = idx[i, s - 1]
                s -= 1
            dist[i, s] = d
            idx[i, s] = b
    return idx, dist


def envelope(c: Creature, ms: list | None = None, lod: int = 1) -> tuple[Mesh, float]:
    """The envelope mesh over bones (and muscles ``ms``) and the grid cell size (m)."""
    from skimage.measure import marching_cubes

    grid, lo, h = envelope_field(c, ms, lod)
    # normals: the field's gradient at each vertex (pointing down the field, outwards)
    verts, faces, normals, _ = marching_cubes(grid, level=0.0, spacing=(h, h, h))
    verts = verts + lo
    faces = faces.astype(np.int64)
    tri = verts[faces]
    if (tri[:, 0] * np.cross(tri[:, 1], tri[:, 2])).sum() < 0:  # wind the faces outwards
        faces = faces[:, ::-1]
    normals = normals.astype(np.float64)
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, norm, out=np.zeros_like(normals), where=norm > 0)
    return Mesh(verts, faces, normals=normals), h


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
