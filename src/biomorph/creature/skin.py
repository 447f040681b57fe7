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

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.creature.creature import Creature

#: grid cells along the longest side per level of detail
RESOLUTION = (40, 64, 96)
#: finest grid (cells along the longest side) per level of detail
RES_MAX = (56, 96, 160)
#: tissue over bone at the bony landmarks, as a share of the bone's half-width
LANDMARK_TISSUE = 0.35
#: radius classes of the distance-transform field (see :func:`_field`)
RADIUS_CLASSES = 3
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
        if c.kind[j] == "spine" and c.region[j] in ("back", "neck", "tail"):
            # the trunk's soft tissue: from the vertebra to the centre of its mass
            r = 0.42 * 0.5 * (c.mass_size[j, 0] + c.mass_size[j, 2])
            a_s.append(c.mass_center[j])
            b_s.append(c.mass_center[j])
            ra_s.append(r)
            rb_s.append(r)
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
    """``max_i (r_i(t) - |p - segment_i(t)|)`` on the grid, by Euclidean distance transforms:
    every capsule axis is sampled every half cell and marked in its grid cell with its
    radius; one ``distance_transform_edt`` per radius class (``RADIUS_CLASSES`` geometric
    bins, so a thick trunk capsule is never hidden by a thin spine axis running beside it)
    gives each cell its nearest axis cell, and the field is ``r(nearest) - distance``,
    maximised over the classes. Exact for spheres centred on cells, within half a cell
    otherwise; the Gaussian smoothing that follows is wider than that."""
    from scipy.ndimage import distance_transform_edt

    a, b, ra, rb = caps
    length = np.linalg.norm(b - a, axis=1)
    n = np.maximum(np.ceil(length / (0.5 * h)).astype(int), 1) + 1
    seg = np.repeat(np.arange(len(a)), n)
    start = np.repeat(np.cumsum(n) - n, n)
    u = (np.arange(len(seg)) - start) / (n[seg] - 1)
    pts = a[seg] + (b - a)[seg] * u[:, None]
    rad = ra[seg] + (rb - ra)[seg] * u
    cell = np.clip(np.rint((pts - lo) / h).astype(int), 0, np.array(shape) - 1)
    edges = np.geomspace(rad.min(), rad.max() * 1.0001, RADIUS_CLASSES + 1)
    cls = np.clip(np.searchsorted(edges, rad, side="right") - 1, 0, RADIUS_CLASSES - 1)
    field = np.full(shape, -2.0 * h, np.float32)
    dims = np.array(shape)
    for k in range(RADIUS_CLASSES):
        sel = cls == k
        if not sel.any():
            continue
        # only the class's own box matters: beyond its largest radius + 2 cells the field
        # is below the floor of -2 cells anyway
        reach = int(np.ceil(rad[sel].max() / h)) + 3
        lo_c = np.maximum(cell[sel].min(axis=0) - reach, 0)
        hi_c = np.minimum(cell[sel].max(axis=0) + reach + 1, dims)
        box = tuple(slice(a, b) for a, b in zip(lo_c, hi_c, strict=True))
        r_grid = np.zeros(tuple(hi_c - lo_c), np.float32)
        np.maximum.at(r_grid, tuple((cell[sel] - lo_c).T), rad[sel].astype(np.float32))
        dist, (ix, iy, iz) = distance_transform_edt(r_grid <= 0, sampling=h, return_indices=True)
        sub = field[box]
        np.maximum(sub, r_grid[ix, iy, iz] - dist.astype(np.float32), out=sub)
    return field


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
    from scipy.ndimage import gaussian_filter
    from skimage.measure import marching_cubes

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
    caps = (a, b, np.maximum(ra, 1.4 * h), np.maximum(rb, 1.4 * h))
    lo = lo - 3 * h
    shape = tuple((np.ceil((hi + 3 * h - lo) / h)).astype(int) + 1)
    grid = gaussian_filter(_field(caps, lo, h, shape), SMOOTH)
    verts, faces, _, _ = marching_cubes(grid, level=0.0, spacing=(h, h, h))
    verts = verts + lo
    faces = faces.astype(np.int64)
    tri = verts[faces]
    if (tri[:, 0] * np.cross(tri[:, 1], tri[:, 2])).sum() < 0:  # wind the faces outwards
        faces = faces[:, ::-1]
    return Mesh(verts, faces).compute_normals(), h


def body(c: Creature, lod: int = 1, with_muscles: bool = True) -> Body:
    """Muscles, envelope and skin weights of ``c``."""
    from biomorph.creature.muscles import muscle_mesh, muscles

    ms = muscles(c, lod) if with_muscles else []
    env, h = envelope(c, ms, lod)
    joints, weights = _weights(c, env.vertices, h)
    return Body(env, joints, weights, muscle_mesh(ms, lod), ms)
