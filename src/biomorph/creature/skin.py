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
from biomorph.creature import fins as fn
from biomorph.creature.bones.cage import trunk_sections
from biomorph.creature.creature import Creature

#: grid cells along the longest side per level of detail
RESOLUTION = (40, 64, 96)
#: finest grid (cells along the longest side) per level of detail
RES_MAX = (64, 96, 160)
#: tissue over bone at the bony landmarks, as a share of the bone's half-width
LANDMARK_TISSUE = 0.35
#: grid cell = the thinnest limb's skin radius / LIMB_CELLS (creatures without legs or
#: arms: the median capsule radius / H_DIV), within the RESOLUTION .. RES_MAX range
LIMB_CELLS = 2.5
H_DIV = 1.2
#: smoothing of the field (grid cells)
SMOOTH = 0.9
#: the cone from a girdle's trunk section to its limb socket starts at this share of the
#: section's radius
GIRDLE_FILL = 0.85
#: tissue over the shoulder blade's faces (share of its length; the plate is 0.1 thick)
BLADE_TISSUE = 0.09
#: the head's skin at the snout tip as a share of its width at the braincase
SNOUT = {"bird": 0.3, "mammal": 0.6, "reptile": 0.5, "amphibian": 0.6, "fish": 0.5}


@dataclass(frozen=True)
class Body:
    """Envelope mesh (world, normals set), its per-vertex joints/weights ``(k, 4)``, and the
    muscles (list and mesh)."""

    envelope: Mesh
    joints: NDArray[np.int64]
    weights: NDArray[np.float64]
    muscles: Mesh | None
    muscle_list: list


def _capsules(c: Creature, ms: list) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """Tapered capsules of the field: start/end points ``(s, 3)``, radii ``(s,)`` and each
    one's least radius in grid cells ``(s,)``: two per bone (joint to mid-bone, mid-bone
    to end; the wing beyond the elbow excepted), one sphere per trunk section joined to
    its parent's, a cone from each girdle's section to its limb socket, the shoulder
    blades, and the muscles' swept paths (no least radius: a thin muscle lies over bone)."""
    js = np.flatnonzero(c.bone_length > 1e-9)
    # built as explicit tubes and sheets: the wings beyond the elbow, the fins
    js = js[~np.isin(js, np.r_[_wing_hand(c), fn.fin_joints(c)])]
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
    tip_r = end_r.copy()  # the head narrows to the snout (a beak to a point)
    tip_r[skull] *= SNOUT.get(str(c.params.get("class", "mammal")), 0.55)
    pos, ends = c.joint_positions[js], c.bone_ends[js]
    mid = 0.5 * (pos + ends)
    a_s = [np.stack([pos, mid], 1).reshape(-1, 3)]
    b_s = [np.stack([mid, ends], 1).reshape(-1, 3)]
    ra_s = [np.stack([end_r, mid_r], 1).reshape(-1)]
    rb_s = [np.stack([mid_r, tip_r], 1).reshape(-1)]
    # the trunk's soft tissue: one sphere per trunk section (the rib cage is built round
    # the same sections, :mod:`biomorph.creature.bones.cage`), joined to its parent
    # vertebra's section by a tapered capsule (spheres alone beaded the neck and tail)
    sec, centre, radius = trunk_sections(c)
    row = {int(j): k for k, j in enumerate(sec)}
    link = [(k, row.get(int(c.skeleton.parent[j]), -1)) for k, j in enumerate(sec)]
    link = np.asarray([(k, p) for k, p in link if p >= 0 and p != k] or [], np.int64)
    link = link.reshape(-1, 2)
    alone = np.setdiff1d(np.arange(len(sec)), link.reshape(-1))  # a link holds its ends
    a_s.append(centre[alone])
    b_s.append(centre[alone])
    ra_s.append(radius[alone])
    rb_s.append(radius[alone])
    a_s.append(centre[link[:, 0]])
    b_s.append(centre[link[:, 1]])
    ra_s.append(radius[link[:, 0]])
    rb_s.append(radius[link[:, 1]])
    # shoulders and hips: a cone from the girdle's trunk section to the limb's socket, so
    # the shoulder (glenoid, scapula and the spinati over it) and the hip blend into the
    # trunk instead of standing out of its round section as a knob
    kid_r = {}
    for k, j in enumerate(js.tolist()):
        p = int(c.skeleton.parent[j])
        kid_r.setdefault(p, max(float(end_r[k]), 0.6 * float(mid_r[k])))
    for j in range(len(c)):
        p = int(c.skeleton.parent[j])
        if c.kind[j] != "girdle" or p not in row or j not in kid_r:
            continue
        k = row[p]
        a_s.append(centre[k][None])
        b_s.append(c.bone_ends[j][None])
        ra_s.append(np.array([GIRDLE_FILL * radius[k]]))
        rb_s.append(np.array([kid_r[j]]))
    # each shoulder blade: three rows along the plate (dorsal border to glenoid), thin
    # tissue over its faces; kept at least 0.8 cells thick so the plate stays under the
    # skin where a wide-set shoulder puts it beside a narrower chest
    n_bone = sum(len(x) for x in a_s)
    from biomorph.creature.bones.cage import SCAPULA_WIDTH, scapula_frame
    from biomorph.creature.bones.fit import parts_of

    parts = parts_of(c) if any(k == "girdle" for k in c.kind) else ()
    cls = str(c.params.get("class", "mammal"))
    for j in range(len(c)):
        if not parts or parts[j] != "scapula":
            continue
        fr = scapula_frame(c, j, cls)
        if fr is None:
            continue
        frame, d_pt, ls = fr
        # from just above the dorsal border's corners to just past the glenoid's rim (the
        # smoothing rounds a thin capsule's ends off)
        top = d_pt - frame[:, 1] * (0.05 * ls)
        glen = d_pt + frame[:, 1] * (1.05 * ls)
        for share in (-0.95, 0.0, 0.95):
            across = share * 0.5 * SCAPULA_WIDTH * ls * frame[:, 0]
            a_s.append((top + across)[None])
            b_s.append((glen + 0.3 * across)[None])
            ra_s.append(np.array([BLADE_TISSUE * ls]))
            rb_s.append(np.array([BLADE_TISSUE * ls]))
    n_fixed = sum(len(x) for x in a_s)
    hand = set(_wing_hand(c).tolist())
    for m in ms:  # every second path point is enough for the smoothed field
        if m.origin_joint in hand:  # the wing's forearm flexors: an explicit tube
            continue
        keep = np.unique(np.r_[np.arange(0, len(m.path), 2), len(m.path) - 1])
        path, rad = m.path[keep], m.radius[keep]
        a_s.append(path[:-1])
        b_s.append(path[1:])
        ra_s.append(rad[:-1])
        rb_s.append(rad[1:])
    a, b = np.concatenate(a_s), np.concatenate(b_s)
    k = np.arange(len(a))
    floor = np.where(k < n_bone, 1.4, np.where(k < n_fixed, 0.8, 0.0))
    return a, b, np.concatenate(ra_s), np.concatenate(rb_s), floor


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
    """The envelope mesh over bones (and muscles ``ms``) and the grid cell size (m): the
    implicit body surface (marching cubes, Taubin-smoothed) plus the wings' and fins'
    explicit thin tubes and sheets (:func:`explicit_skin`), one mesh with area-weighted
    vertex normals."""
    from skimage.measure import marching_cubes

    grid, lo, h = envelope_field(c, ms, lod)
    verts, faces, _, _ = marching_cubes(grid, level=0.0, spacing=(h, h, h))
    verts = verts.astype(np.float64) + lo
    faces = faces.astype(np.int64)
    tri = verts[faces]
    if (tri[:, 0] * np.cross(tri[:, 1], tri[:, 2])).sum() < 0:  # wind the faces outwards
        faces = faces[:, ::-1]
    verts = taubin(verts, faces, TAUBIN_STEPS)
    wv, wf = explicit_skin(c, ms, lod)
    if len(wv):
        faces = np.concatenate([faces, wf + len(verts)])
        verts = np.concatenate([verts, wv])
    return Mesh(verts, faces, normals=_normals(verts, faces)), h


@numba.njit(cache=True, nogil=True)
def _normals(v, f):  # pragma: no cover - compiled
    """Area-weighted unit vertex normals (as :func:`~biomorph.creature.bones.prim.
    vertex_normals`, compiled)."""
    n = np.zeros((v.shape[0], 3))
    for t in range(f.shape[0]):
        a, b, c = f[t, 0], f[t, 1], f[t, 2]
        ux, uy, uz = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        wx, wy, wz = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
        cx, cy, cz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
        for i in (a, b, c):
            n[i, 0] += cx
            n[i, 1] += cy
            n[i, 2] += cz
    for i in range(v.shape[0]):
        ln = np.sqrt(n[i, 0] ** 2 + n[i, 1] ** 2 + n[i, 2] ** 2)
        if ln > 0:
            n[i, 0] /= ln
            n[i, 1] /= ln
            n[i, 2] /= ln
    return n


#: Taubin smoothing passes (each a shrink step λ and an inflate step μ) over the marching
#: cubes surface: removes the grid's terracing without shrinking the body
TAUBIN_STEPS = 8
TAUBIN = (0.5, -0.53)


def taubin(v: NDArray, f: NDArray, steps: int = TAUBIN_STEPS) -> NDArray:
    """Taubin's λ|μ smoothing of the closed mesh ``(v, f)`` (umbrella Laplacian over its
    edges): a low-pass filter without the shrinkage of plain Laplacian smoothing (Taubin
    1995)."""
    if not len(f) or steps <= 0:
        return v
    out = np.array(v, np.float64)
    _taubin(out, np.ascontiguousarray(f, np.int64), int(steps), *TAUBIN)
    return out


@numba.njit(cache=True, nogil=True)
def _taubin(v, f, steps, lam, mu):  # pragma: no cover - compiled
    n = v.shape[0]
    # each edge once: a closed mesh meets it as (a, b) in one face and (b, a) in the other
    m = 0
    ea = np.empty(3 * f.shape[0], np.int64)
    eb = np.empty(3 * f.shape[0], np.int64)
    for t in range(f.shape[0]):
        for e in range(3):
            a, b = f[t, e], f[t, (e + 1) % 3]
            if a < b:
                ea[m] = a
                eb[m] = b
                m += 1
    deg = np.zeros(n)
    for q in range(m):
        deg[ea[q]] += 1.0
        deg[eb[q]] += 1.0
    for i in range(n):
        deg[i] = 1.0 / deg[i] if deg[i] > 0 else 0.0
    acc = np.empty((n, 3))
    for _ in range(steps):
        for factor in (lam, mu):
            acc[:] = 0.0
            for q in range(m):
                a, b = ea[q], eb[q]
                for k in range(3):
                    acc[a, k] += v[b, k]
                    acc[b, k] += v[a, k]
            for i in range(n):
                if deg[i] > 0:
                    for k in range(3):
                        v[i, k] += factor * (acc[i, k] * deg[i] - v[i, k])


def _limb_radius(c: Creature) -> float:
    """The skin radius at the middle of the thinnest long bone of a leg or arm (as
    :func:`_capsules` gives it), 0 without legs or arms."""
    from biomorph.creature.bones.fit import parts_of

    parts = parts_of(c)
    js = [
        j
        for j in range(len(c))
        if c.kind[j] in ("leg", "arm")
        and parts[j] in ("humerus", "femur", "radius", "tibia")
        and c.bone_length[j] > 1e-9
    ]
    if not js:
        return 0.0
    box, mass = c.box_size[js], c.mass_size[js]
    bone = 0.5 * np.maximum(box[:, 0], box[:, 2]) * (1 + LANDMARK_TISSUE)
    return float(np.maximum(bone, 0.8 * 0.25 * (mass[:, 0] + mass[:, 2])).min())


def envelope_field(
    c: Creature, ms: list | None = None, lod: int = 1
) -> tuple[NDArray, NDArray, float]:
    """The smoothed signed field whose 0-level is the envelope (positive inside), the world
    position of its cell ``(0, 0, 0)`` and the cell size (m)."""
    from scipy.ndimage import gaussian_filter

    a, b, ra, rb, floor = _capsules(c, ms or [])
    r = np.maximum(ra, rb)[:, None]
    lo = np.minimum(a - r, b - r).min(axis=0)
    hi = np.maximum(a + r, b + r).max(axis=0)
    ext = float((hi - lo).max())
    # cell: fine enough that the thinnest leg or arm (its long bones' skin radius) spans
    # LIMB_CELLS cells (a thin limb on a coarse grid is a faceted stick), within the
    # RESOLUTION .. RES_MAX range for this level of detail
    fine, coarse = ext / RES_MAX[lod], ext / RESOLUTION[lod]
    r_limb = _limb_radius(c)
    want = r_limb / LIMB_CELLS if r_limb > 0 else float(np.median(np.minimum(ra, rb))) / H_DIV
    h = float(np.clip(want, fine, coarse))
    # thin bones would vanish between grid points: keep each at least a cell wide. Not the
    # muscles: they lie over bones that keep the skin there, and a thin sheet (the spinati
    # over the scapula) grown to 1.4 cells stood out of the shoulder as a box
    ra, rb = np.maximum(ra, floor * h), np.maximum(rb, floor * h)
    # the Gaussian moves a convex surface of radius r inwards by about sigma^2 / r (the
    # field's Laplacian 2 / r times sigma^2 / 2): each capsule is grown by that first, so
    # the smoothed skin keeps the radii its rules give (the rib cage relies on it)
    sig2 = (SMOOTH * h) ** 2
    grow_a, grow_b = sig2 / np.maximum(ra, 1.4 * h), sig2 / np.maximum(rb, 1.4 * h)
    caps = (a, b, ra + grow_a, rb + grow_b)
    lo = lo - 3 * h
    shape = tuple((np.ceil((hi + 3 * h - lo) / h)).astype(int) + 1)
    return gaussian_filter(_field(caps, lo, h, shape), SMOOTH), lo, h


def body(c: Creature, lod: int = 1, with_muscles: bool = True) -> Body:
    """Muscles, envelope and skin weights of ``c``."""
    from biomorph.creature.muscles import muscle_mesh, muscles

    ms = muscles(c, lod) if with_muscles else []
    env, h = envelope(c, ms, lod)
    joints, weights = _weights(c, env.vertices, h)
    fj = fin_skin_joints(c, lod)
    if len(fj):  # the fin skin (the envelope's last vertices) rides on its fin joints
        joints[-len(fj) :] = fj[:, None]
        weights[-len(fj) :] = (1.0, 0.0, 0.0, 0.0)
    return Body(env, joints, weights, muscle_mesh(ms, lod), ms)


# --------------------------------------------------------------------------- wings
#: membrane thickness as a share of the mean digit bone width (a bat's patagium is a
#: double layer of skin, far thinner than the finger bones it spans)
MEMBRANE = 0.3
#: the free edge between two fingers (and from the last finger to the leg) is drawn in by
#: this share of the patch's length at its middle (the scalloped trailing edge of a bat)
SCALLOP = 0.22
#: a bird's wing envelope (no feathers): chord at the shoulder as a share of the humerus,
#: narrowing to TIP_CHORD of it at the wing tip
ROOT_CHORD = 0.55
TIP_CHORD = 0.12
#: the arm bones lie this far back along the chord (the thick part of the aerofoil)
ARM_AT = 0.22


@dataclass(frozen=True)
class _Wing:
    upper: int
    lower: int
    distal: int
    digits: list[list[int]]  # each a chain of joints from the knuckle to the tip


def _wings(c: Creature) -> list[_Wing]:
    """Each wing's humerus, forearm and hand bone joints and its digit chains (ordered by
    digit number: the thumb first, the trailing finger last)."""
    par = c.skeleton.parent
    out = []
    for up in range(len(c)):
        if c.kind[up] != "wing" or par[up] < 0 or c.kind[int(par[up])] == "wing":
            continue
        chain = [up]
        while len(chain) < 3:
            kids = [int(k) for k in np.flatnonzero(par == chain[-1]) if c.kind[k] == "wing"]
            if not kids:
                break
            chain.append(kids[0])
        if len(chain) < 3:
            continue
        digits = []
        for k in sorted(np.flatnonzero(par == chain[2]).tolist(), key=lambda k: c.names[k]):
            d = [int(k)]
            while True:
                kids = np.flatnonzero(par == d[-1])
                if not kids.size:
                    break
                d.append(int(kids[0]))
            digits.append([j for j in d if c.bone_length[j] > 1e-9])
        out.append(_Wing(chain[0], chain[1], chain[2], [d for d in digits if d]))
    return out


def _wing_hand(c: Creature) -> NDArray[np.int64]:
    """Wing joints beyond the elbow (forearm, hand, digits): skinned by explicit thin tubes
    and sheets instead of the implicit field (whose grid cannot hold a membrane, and whose
    soft tissue made sausages of the fingers)."""
    out = []
    for w in _wings(c):
        out += [w.lower, w.distal] + [j for d in w.digits for j in d]
    return np.asarray(out, np.int64)


def _resample(poly: NDArray, n: int) -> NDArray:
    """``n`` points evenly spaced by arc length along the polyline ``poly (k, 3)``."""
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    if s[-1] <= 1e-12:
        return np.repeat(poly[:1], n, axis=0)
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, poly[:, k]) for k in range(3)], axis=1)


def _ray_tubes(fins, radii: list[NDArray], sides: int) -> tuple[NDArray, NDArray]:
    """The rays of ``fins`` (all of one shape) as one batch of tubes: ``radii`` per fin,
    thickened by the landmark tissue, each tube's cross-section referenced to its fin's
    normal."""
    from biomorph.creature.bones.prim import tubes

    return tubes(
        np.concatenate([fin.rays for fin in fins]),
        np.concatenate(radii) * (1 + LANDMARK_TISSUE),
        sides,
        ref=np.concatenate([np.tile(fin.normal, (len(fin.rays), 1)) for fin in fins]),
    )


def _slab(mid: NDArray, thick: NDArray, up: NDArray) -> tuple[NDArray, NDArray]:
    """A closed thin sheet round the mid-surface grid ``mid (r, k, 3)``: two faces
    ``±thick/2`` along the surface normal (turned towards ``up``) stitched along the rim;
    faces wound outwards."""
    r, k = mid.shape[:2]
    du = np.gradient(mid, axis=0)
    dv = np.gradient(mid, axis=1)
    n = np.cross(du, dv)
    nn = np.linalg.norm(n, axis=2, keepdims=True)
    mean = n.sum(axis=(0, 1))
    if float(mean @ up) < 0:
        n, mean = -n, -mean
    fallback = mean / max(float(np.linalg.norm(mean)), 1e-12)
    n = np.where(nn > 1e-12, n / np.maximum(nn, 1e-12), fallback)
    off = 0.5 * thick[..., None] * n
    top, bot = (mid + off).reshape(-1, 3), (mid - off).reshape(-1, 3)
    v = np.concatenate([top, bot])
    idx = np.arange(r * k).reshape(r, k)
    a, b, cc, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    quads = np.stack([a, b, cc, d], -1).reshape(-1, 4)
    tri = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    rim = np.r_[idx[0, :], idx[1:, -1], idx[-1, -2::-1], idx[-2:0:-1, 0]]
    nxt = np.roll(rim, -1)
    off_b = r * k
    side = np.concatenate(
        [np.stack([rim, nxt, nxt + off_b], 1), np.stack([rim, nxt + off_b, rim + off_b], 1)]
    )
    f = np.concatenate([tri, tri[:, ::-1] + off_b, side])
    vol = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum()
    if vol < 0:
        f = f[:, ::-1]
    return v, f


def _loft(a: NDArray, b: NDArray, rows: int, scallop: float) -> NDArray:
    """Grid ``(rows, k, 3)`` between the polylines ``a`` and ``b`` (both ``(k, 3)``, resampled
    alike): row ``i`` at ``s = i / (rows - 1)`` from ``a`` to ``b``; the far ends are pulled
    in by ``scallop`` of the length at the middle (a concave free edge)."""
    k = len(a)
    s = np.linspace(0.0, 1.0, rows)[:, None]
    u = np.linspace(0.0, 1.0, k)[None, :]
    uu = u * (1.0 - scallop * np.sin(np.pi * s))  # (rows, k)
    grid_u = np.linspace(0.0, 1.0, k)
    out = np.empty((rows, k, 3))
    for i in range(rows):
        pa = np.stack([np.interp(uu[i], grid_u, a[:, q]) for q in range(3)], 1)
        pb = np.stack([np.interp(uu[i], grid_u, b[:, q]) for q in range(3)], 1)
        out[i] = (1 - s[i, 0]) * pa + s[i, 0] * pb
    return out


def _poly(c: Creature, chain: list[int], start: NDArray | None = None) -> NDArray:
    pts = [c.joint_positions[j] for j in chain] + [c.bone_ends[chain[-1]]]
    if start is not None:
        pts = [start, *pts]
    return np.asarray(pts, float)


def _hind_anchor(c: Creature, side: float) -> NDArray | None:
    """Where a bat's wing membrane meets the hind limb on ``side``: the hip, knee and
    ankle of the most caudal leg on that side (None without one)."""
    best, best_x = None, np.inf
    par = c.skeleton.parent
    for j in range(len(c)):
        if c.kind[j] != "leg" or par[j] < 0 or c.kind[int(par[j])] == "leg":
            continue
        if np.sign(c.side[j]) != np.sign(side):
            continue
        x = float(c.joint_positions[j, 0])
        if x < best_x:
            best, best_x = j, x
    if best is None:
        return None
    chain = [best]
    while len(chain) < 3:
        kids = [int(k) for k in np.flatnonzero(par == chain[-1]) if c.kind[k] == "leg"]
        if not kids:
            break
        chain.append(kids[0])
    # hip, knee, ankle: the membrane's body edge runs along the flank and down the leg
    return np.asarray([c.joint_positions[j] for j in chain] + [c.bone_ends[chain[-1]]], float)


def wing_skin(c: Creature, ms: list | None = None, lod: int = 1) -> tuple[NDArray, NDArray]:
    """Explicit skin of the wings beyond the elbow (world ``(vertices, faces)``, closed
    pieces): thin tubes round the forearm, hand and digit bones (bone half-width plus the
    landmark tissue) and the forearm flexors; for membrane wings (bats; any non-bird) a
    thin patagium between consecutive long fingers, from the trailing finger to the ankle
    (plagiopatagium) and from the shoulder to the wrist (propatagium); for birds a flat,
    slightly cambered aerofoil sheet from the arm bones backwards."""
    from biomorph.creature.bones.prim import tubes

    wings = _wings(c)
    if not wings:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    cls = str(c.params.get("class", "mammal"))
    up = np.array([0.0, 1.0, 0.0])
    back = np.array([-1.0, 0.0, 0.0])
    sides = (6, 8, 12)[lod]
    n_along, n_rows = (10, 14, 20)[lod], (4, 6, 9)[lod]
    vs, fs = [], []
    base = 0

    def add(piece: tuple[NDArray, NDArray]) -> None:
        nonlocal base
        vs.append(piece[0])
        fs.append(piece[1] + base)
        base += len(piece[0])

    # tubes round the bones beyond the elbow and round the forearm flexors
    hand = _wing_hand(c)
    a, b = c.joint_positions[hand], c.bone_ends[hand]
    r = 0.5 * np.maximum(c.box_size[hand, 0], c.box_size[hand, 2]) * (1 + LANDMARK_TISSUE)
    u = np.linspace(0.0, 1.0, 5)[None, :, None]
    paths = a[:, None, :] + (b - a)[:, None, :] * u
    rad = np.repeat(r[:, None], 5, axis=1) * np.array([0.8, 1.0, 0.9, 1.0, 0.8])[None, :]
    add(tubes(paths, rad, sides, ref=np.tile([[0.0, 1.0, 0.0]], (len(hand), 1))))
    hand_set = set(hand.tolist())
    for m in ms or []:
        if m.origin_joint in hand_set:
            add(tubes(m.path[None], 1.1 * m.radius[None], sides, ref=np.array([[0.0, 1, 0]])))
    for w in wings:
        S, E = c.joint_positions[w.upper], c.joint_positions[w.lower]
        W, K = c.joint_positions[w.distal], c.bone_ends[w.distal]
        side = float(np.sign(c.side[w.upper]) or 1.0)
        if cls == "bird":
            add(_bird_sheet(c, w, up, back, n_along, n_rows))
            continue
        lengths = [float(c.bone_length[d].sum()) for d in w.digits]
        longest = max(lengths) if lengths else 0.0
        fingers = [d for d, ln in zip(w.digits, lengths, strict=True) if ln > 0.5 * longest]
        if not fingers:
            continue
        width = float(np.mean([c.box_size[j, 0] for d in fingers for j in d]))
        t = MEMBRANE * width
        polys = [_resample(_poly(c, d), n_along) for d in fingers]
        # chiropatagium: between consecutive fingers (the free edge scalloped)
        for pa, pb in zip(polys[:-1], polys[1:], strict=True):
            grid = _loft(pa, pb, n_rows, SCALLOP)[:, 1:]  # off the shared knuckle
            add(_slab(grid, np.full(grid.shape[:2], t), up))
        # plagiopatagium: the arm and the trailing finger to the flank and the ankle
        leg = _hind_anchor(c, side)
        arm = np.concatenate([[S, E, W, K], _poly(c, fingers[-1])[1:]])
        if leg is None:  # no hind leg on this side: to the flank a wing's length back
            flank = np.asarray([S, S + 0.8 * back * float(np.linalg.norm(K - S))])
        else:  # along the flank to the hip, then down the thigh and shank to the ankle
            flank = np.concatenate([[S], leg[1:] if len(leg) > 2 else leg])
        pa, pb = _resample(arm, n_along + 4), _resample(flank, n_along + 4)
        grid = _loft(pa, pb, n_rows + 2, SCALLOP * 0.6)[:, 1:]
        add(_slab(grid, np.full(grid.shape[:2], t), up))
        # propatagium: shoulder to wrist in front of the elbow
        lead = _resample(np.asarray([S, W]), 6)
        arm_l = _resample(np.asarray([S, E, W]), 6)
        grid = _loft(lead, arm_l, 3, 0.0)[:, 1:-1]
        if float(np.linalg.norm(grid[0] - grid[-1], axis=1).max()) > 1e-6:
            add(_slab(grid, np.full(grid.shape[:2], t), up))
    return np.concatenate(vs), np.concatenate(fs)


#: sides of the fin rays' skin tubes per level of detail
_FIN_SIDES = (3, 4, 6)


def fin_skin(c: Creature, lod: int = 1) -> tuple[NDArray, NDArray]:
    """Explicit skin of the fins (world ``(vertices, faces)``, closed pieces): a thin tube
    round each fin ray (:func:`biomorph.creature.fins.ray_radii` plus the landmark tissue)
    and the fin membrane between the rays, a closed slab :data:`fins.MEMBRANE` of the
    first ray's diameter thick — the paired fins, then a fish's median fins (dorsal, anal,
    caudal: :func:`biomorph.creature.fins.build_median`) alike."""
    built = fn.build(c, *fn.DETAIL[lod])
    median = fn.build_median(c, *fn.MEDIAN_DETAIL[lod])
    if not built and not median:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    sides = _FIN_SIDES[lod]  # thin rays: few sides
    vs, fs, base = [], [], 0
    pieces = [
        _slab(
            fn.membrane_grid(fin), np.full(fin.rays.shape[:2], fn.MEMBRANE * fin.width), fin.normal
        )
        for fin in built
    ]
    # rays of fins of one shape in one batch (the median fins share theirs)
    same = len({fin.rays.shape for fin in built}) == 1
    for group in [built] if same else [[fin] for fin in built]:
        pieces.append(_ray_tubes(group, [fn.ray_radii(fin) for fin in group], sides))
    pieces += [
        _slab(fin.rays, np.full(fin.rays.shape[:2], fn.MEMBRANE * fin.width), fin.normal)
        for fin in median
    ]
    if median:
        pieces.append(_ray_tubes(median, [fn.median_radii(fin) for fin in median], sides))
    for v, f in pieces:
        vs.append(v)
        fs.append(f + base)
        base += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def fin_skin_joints(c: Creature, lod: int = 1) -> NDArray[np.int64]:
    """The joint of each :func:`fin_skin` vertex, in its order: the fin joint whose bone the
    vertex's ray sample lies along (slabs: both faces row by row; tubes: ring by ring, then
    the two caps); a median fin's vertices ride on the spine joint of their ray."""
    built = fn.build(c, *fn.DETAIL[lod])
    median = fn.build_median(c, *fn.MEDIAN_DETAIL[lod])
    sides = _FIN_SIDES[lod]
    out = [np.tile(np.tile(fin.joint_of, len(fin.rays)), 2) for fin in built]
    for fin in built:
        jo = fin.joint_of
        tube = np.concatenate([np.repeat(jo, sides), jo[:1], jo[-1:]])
        out.append(np.tile(tube, len(fin.rays)))
    out += [np.tile(fin.joint_of.reshape(-1), 2) for fin in median]
    for fin in median:
        for jo in fin.joint_of:
            out.append(np.concatenate([np.repeat(jo, sides), jo[:1], jo[-1:]]))
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


def explicit_skin(c: Creature, ms: list | None = None, lod: int = 1) -> tuple[NDArray, NDArray]:
    """The envelope's explicit pieces: :func:`wing_skin` then :func:`fin_skin`."""
    wv, wf = wing_skin(c, ms, lod)
    fv, ff = fin_skin(c, lod)
    return np.concatenate([wv, fv]), np.concatenate([wf, ff + len(wv)]).astype(np.int64)


def _bird_sheet(
    c: Creature, w: _Wing, up: NDArray, back: NDArray, n_along: int, n_rows: int
) -> tuple[NDArray, NDArray]:
    """A bird's wing envelope without feathers: a flat, slightly cambered sheet from the
    arm bones (shoulder → elbow → wrist → the longest digit's tip) backwards, thick round
    the bones (ARM_AT of the chord) and thin at the trailing edge."""
    S, E = c.joint_positions[w.upper], c.joint_positions[w.lower]
    W, K = c.joint_positions[w.distal], c.bone_ends[w.distal]
    major = max(w.digits, key=lambda d: float(c.bone_length[d].sum())) if w.digits else []
    arm = np.asarray([S, E, W, K] + ([*_poly(c, major)[1:]] if major else []), float)
    lead = _resample(arm, n_along + 4)[1:]  # off the shoulder (inside the body)
    k = len(lead)
    u = np.linspace(0.0, 1.0, k + 1)[1:]
    tan = np.gradient(lead, axis=0)
    tan /= np.maximum(np.linalg.norm(tan, axis=1, keepdims=True), 1e-12)
    chord_dir = back - (tan @ back)[:, None] * tan
    cn = np.linalg.norm(chord_dir, axis=1, keepdims=True)
    chord_dir = np.where(cn > 1e-6, chord_dir / np.maximum(cn, 1e-12), -up)
    hum = float(c.bone_length[w.upper])
    chord = hum * (ROOT_CHORD + (TIP_CHORD - ROOT_CHORD) * u) * np.sqrt(1 - u**6 + 1e-9)
    chord = np.maximum(chord, 0.02 * hum)
    bone_t = (2.0 * 0.5 * float(np.max(c.box_size[[w.upper, w.lower, w.distal], 0]))) * (
        1 + LANDMARK_TISSUE
    )
    x = np.linspace(0.0, 1.0, n_rows + 3)  # chord fraction from the leading edge
    # NACA-style half-thickness profile (0 at both edges, maximal near 0.3)
    prof = 0.2969 * np.sqrt(x) - 0.126 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4
    prof /= prof.max()
    camber_n = np.cross(tan, chord_dir)
    camber_n *= np.where((camber_n @ up) < 0, -1.0, 1.0)[:, None]
    mid = (
        lead[None, :, :]
        + ((x[:, None] - ARM_AT) * chord[None, :])[..., None] * chord_dir[None]
        + (0.04 * np.sin(np.pi * x)[:, None] * chord[None, :])[..., None] * camber_n[None]
    )
    t_max = np.maximum(bone_t * (1.0 - 0.6 * u), 0.06 * chord)
    thick = np.maximum(prof[:, None] * t_max[None, :], 0.05 * bone_t)
    return _slab(mid, thick, up)
