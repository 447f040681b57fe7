"""Fitting bone models into a creature: which model each joint gets and how it is scaled.

Unit models are built in a canonical frame (x dorsal for the axial skeleton, y along the
bone in [0, 1], z lateral) and scaled by the joint's box ``(box_x, length, box_z)``. Spine
and skull joint frames have local X ventral when the bone points towards the head (X = Y ×
Z with Z the creature's right) and dorsal when it points to the tail, so axial models are
mirrored into the joint frame accordingly (faces flipped with the handedness).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

import biomorph.creature.bones.appendicular as ap
import biomorph.creature.bones.axial as ax
import biomorph.creature.bones.cage as cage
import biomorph.creature.bones.prim as prim
import biomorph.creature.bones.skull as sk
from biomorph.core.mesh import Mesh
from biomorph.creature import fins as fn
from biomorph.creature import skulls
from biomorph.creature.anatomy import limb_parts
from biomorph.creature.creature import Creature
from biomorph.errors import ParameterError

SHAPES = ("bone", "box")
LODS = (0, 1, 2)
VERTEBRAE = ("cervical", "thoracic", "lumbar", "sacral", "caudal")
#: share of the thoracic vertebrae (from the front) whose ribs reach the sternum
TRUE_RIBS = cage.TRUE_RIBS
_SEG = {"girdle": 0, "upper": 1, "lower": 2, "distal": 3}


def parts_of(c: Creature) -> tuple[str, ...]:
    """Anatomical part per joint: the creature's labels, else derived from kind/region."""
    if c.part and len(c.part) == len(c):
        return tuple(c.part)
    out = []
    for j, (k, r, n) in enumerate(zip(c.kind, c.region, c.names, strict=True)):
        if k == "skull":
            out.append("skull")
        elif k == "spine":
            out.append({"neck": "cervical", "tail": "caudal"}.get(r, "thoracic"))
        else:
            seg = n.rsplit("_", 2)[-2] if n.count("_") >= 2 else "upper"
            kind = k if k != "girdle" else _child_kind(c, j)
            out.append(limb_parts(kind, r)[_SEG.get(seg, 1)])
    return tuple(out)


def _child_kind(c: Creature, j: int) -> str:
    kids = np.flatnonzero(c.skeleton.parent == j)
    return c.kind[int(kids[0])] if kids.size else "leg"


def _headward(c: Creature) -> NDArray[np.bool_]:
    """Joints whose bone points towards the head (:func:`cage._headward`)."""
    return cage._headward(c)


def _spine_rank(c: Creature, parts: tuple[str, ...]) -> NDArray[np.float64]:
    """Position ``0..1`` of each vertebra within its region, counted from the head."""
    n = len(c)
    d = np.full(n, -1, np.int64)
    j = c.kind.index("skull") if "skull" in c.kind else 0
    k = 0
    while j >= 0:
        d[j] = k
        k += 1
        j = int(c.skeleton.parent[j])
    par = c.skeleton.parent
    for i in range(n):
        if d[i] < 0:
            d[i] = d[par[i]] + 1 if par[i] >= 0 else 0
    t = np.zeros(n)
    for region in VERTEBRAE:
        idx = [i for i in range(n) if parts[i] == region]
        if len(idx) > 1:
            order = np.argsort(d[idx], kind="stable")
            t[np.asarray(idx)[order]] = np.linspace(0, 1, len(idx))
    return t


def _palate(c: Creature) -> float:
    """The top of the lower jaw in the skull's unit cube (x dorsal): where the snout's floor
    (the palate) lies; rounded to 0.02 so the unit models stay cached."""
    default = -0.5 + 1.45 * sk.JAW_SHARE
    if "skull" not in c.kind or "jaw" not in c.names:
        return default
    s, j = c.kind.index("skull"), c.names.index("jaw")
    height = c.box_size[s, 0]
    if height <= 1e-12:
        return default
    ventral = (c.joint_positions[j] - c.joint_positions[s]) @ c.world[s, :3, 0]
    dorsal = -ventral if _headward(c)[s] else ventral
    top = (dorsal + 0.5 * c.box_size[j, 0]) / height
    return float(np.round(np.clip(top, -0.45, 0.1) / 0.02) * 0.02)


class _Context:
    """Per-creature facts the models need (computed once)."""

    def __init__(self, c: Creature, lod: int) -> None:
        self.c = c
        self.lod = lod
        self.parts = parts_of(c)
        self.headward = _headward(c)
        self.rank = _spine_rank(c, self.parts)
        self.cls = str(c.params.get("class", "mammal"))
        self.stance = str(c.params.get("stance", ""))
        self.hoof_digits = int(c.params.get("hoof_digits") or ap.UNGULATE[0])
        self.has_mandible = "mandible" in self.parts
        skull_type = str(c.params.get("skull", skulls.CLASS_SKULL.get(self.cls, "mammal_long")))
        self.taper = round(float(skulls.get(skull_type).taper), 2)
        self.skull_plan = sk.plan_for(skull_type, self.cls)
        self.palate = _palate(c)
        self.n_thoracic = sum(1 for p in self.parts if p == "thoracic")
        thoracic = [j for j, p in enumerate(self.parts) if p == "thoracic"]
        # the rib cage round the trunk's sections (world), one piece per thoracic joint
        self.cage = cage.rib_cage(c, thoracic, lod, pleural=self.cls == "fish")
        # fin rays (world), built once per creature: each fin joint gets its stretch of them
        self.fins = _fin_pieces(c, lod)
        # a fish's median fins (dorsal, anal, caudal): rays on the spine joints they stand on
        self.median = _median_pieces(c, lod)


class _Geometry:
    """Accumulates pieces per joint — cached unit models (with normals) to be scaled,
    shifted and mirrored, and one-off pieces in metres — and transforms them all in a few
    batched array operations at the end (per-piece numpy calls dominated otherwise)."""

    def __init__(self) -> None:
        self.v: list[NDArray] = []
        self.n: list[NDArray | None] = []
        self.f: list[NDArray] = []
        self.j: list[int] = []
        # per piece: scale (3), shift (3), sign (3), flip_y
        self.scale: list[NDArray] = []
        self.shift: list[NDArray] = []
        self.sign: list[NDArray] = []
        self.flip: list[float] = []

    def unit(
        self,
        j: int,
        model: tuple[NDArray, NDArray, NDArray],
        scale: NDArray,
        mirror: NDArray | None = None,
        shift: NDArray | None = None,
        flip_y: float | None = None,
    ) -> None:
        """``model`` scaled by ``scale``, shifted, then mirrored (``mirror``: signs per
        axis) and optionally flipped along y (``y -> flip_y - y``)."""
        self._add(j, model[0], model[1], model[2], scale, mirror, shift, flip_y)

    def raw(
        self,
        j: int,
        piece: tuple[NDArray, ...],
        mirror: NDArray | None = None,
        flip_y: float | None = None,
    ) -> None:
        """A piece in metres: ``(vertices, faces)`` or ``(vertices, normals, faces)``."""
        v, n, f = (piece[0], None, piece[1]) if len(piece) == 2 else piece
        self._add(j, np.asarray(v, float), n, np.asarray(f), _ONE, mirror, None, flip_y)

    def _add(self, j, v, n, f, scale, mirror, shift, flip_y) -> None:
        sign = _ONE if mirror is None else mirror
        if flip_y is not None:
            sign = sign * _MY
        if sign[0] * sign[1] * sign[2] < 0:
            f = f[:, ::-1]
        self.v.append(v)
        self.n.append(n)
        self.f.append(f)
        self.j.append(j)
        self.scale.append(scale)
        self.shift.append(_ZERO if shift is None else shift)
        self.sign.append(sign)
        self.flip.append(0.0 if flip_y is None else flip_y)

    def arrays(self) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """``(vertices, unit normals, joint, faces)`` over all pieces."""
        from biomorph.creature.bones.prim import vertex_normals

        if not self.v:
            return (
                np.zeros((0, 3)),
                np.zeros((0, 3)),
                np.zeros(0, np.int64),
                np.zeros((0, 3), np.int64),
            )
        counts = np.fromiter((len(v) for v in self.v), np.int64, len(self.v))
        base = np.cumsum(counts) - counts
        scale = np.repeat(np.array(self.scale), counts, axis=0)
        shift = np.repeat(np.array(self.shift), counts, axis=0)
        sign = np.repeat(np.array(self.sign), counts, axis=0)
        flip = np.repeat(np.array(self.flip), counts)
        raw = [i for i, n in enumerate(self.n) if n is None]
        if raw:  # one normal pass over every one-off piece (they never share vertices)
            rc = counts[raw]
            rb = np.cumsum(rc) - rc
            rv = np.concatenate([self.v[i] for i in raw])
            rf = np.concatenate([self.f[i] + b for i, b in zip(raw, rb, strict=True)])
            rn = vertex_normals(rv, rf)
            for i, b, c in zip(raw, rb, rc, strict=True):
                self.n[i] = rn[b : b + c]
        f_counts = np.fromiter((len(f) for f in self.f), np.int64, len(self.f))
        faces = np.concatenate(self.f) + np.repeat(base, f_counts)[:, None]
        verts = (np.concatenate(self.v) * scale + shift) * sign
        verts[:, 1] += flip
        normals = np.concatenate(self.n) / np.where(scale > 0, scale, 1.0) * sign
        norm = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, norm, out=np.zeros_like(normals), where=norm > 0)
        joint = np.repeat(np.asarray(self.j, np.int64), counts)
        return verts, normals, joint, faces


_ONE = np.ones(3)
_ZERO = np.zeros(3)
_MY = np.array([1.0, -1.0, 1.0])


def _size(c: Creature, j: int) -> NDArray:
    return np.array([c.box_size[j, 0], c.bone_length[j], c.box_size[j, 2]])


def _axial(g: _Geometry, ctx: _Context, j: int, part: str) -> None:
    c, lod = ctx.c, ctx.lod
    L = float(c.bone_length[j])
    size = _size(c, j)
    if part in ("skull", "mandible"):
        model = (
            sk.skull(ctx.skull_plan, lod, not ctx.has_mandible, ctx.palate)
            if part == "skull"
            else sk.mandible(ctx.skull_plan, lod)
        )
        g.unit(j, model, size, mirror=_MX)
        return
    head = bool(ctx.headward[j])
    mirror, flip = (_MX, None) if head else (None, L)
    t_bin = int(round(ctx.rank[j] * (ax.BINS - 1)))
    g.unit(j, ax.vertebra(part, t_bin, lod), size, mirror, flip_y=flip)
    if part == "thoracic" and j in ctx.cage:
        v, f, _ = ctx.cage[j]
        g.raw(j, (_local(c, j, v), f))
    elif part == "thoracic" and ctx.n_thoracic:
        trunk = np.array([max(c.mass_size[j, 0], size[0]), L, max(c.mass_size[j, 2], size[2])])
        shift = np.array([-0.3 * size[0], 0.0, 0.0])  # ribs start at the centrum
        true = ctx.rank[j] <= TRUE_RIBS
        fish = ctx.cls == "fish"
        g.unit(j, ax.rib_pair(1.0 if true else 0.72, fish, lod), trunk, mirror, shift, flip)
        if true and not fish:
            g.unit(j, ax.sternebra(lod), trunk, mirror, shift, flip)


def _local(c: Creature, j: int, p: NDArray) -> NDArray:
    """World points ``p`` in joint ``j``'s frame."""
    return (p - c.world[j, :3, 3]) @ c.world[j, :3, :3]


_MX = np.array([-1.0, 1.0, 1.0])
_MZ = np.array([1.0, 1.0, -1.0])


def _girdle(g: _Geometry, ctx: _Context, j: int, part: str) -> None:
    c, lod = ctx.c, ctx.lod
    L = float(c.bone_length[j])
    size = _size(c, j)
    R, o = c.world[j, :3, :3], c.world[j, :3, 3]
    end = o + R[:, 1] * L
    r = max(0.2 * size[0], 0.02 * L)

    def local(p: NDArray) -> NDArray:
        return (p - o) @ R

    if part == "pelvis":
        g.unit(j, ap.ilium(lod), size)
        pubis = np.array([end[0] + 0.25 * L, end[1] - 0.35 * L, 0.0])
        ischium = np.array([end[0] - 0.45 * L, end[1] - 0.2 * L, 0.35 * end[2]])
        g.raw(j, ap.rod(local(end), local(pubis), r, lod))
        g.raw(j, ap.rod(local(end), local(ischium), r * 1.1, lod))
        return
    blade = cage.scapula_blade(c, j, ap.scapula(lod), ctx.cls)
    if blade is None:
        g.unit(j, ap.scapula(lod), size)
    else:  # on the rib cage's side, the glenoid at the shoulder joint
        g.raw(j, (local(blade[0]), blade[1]))
    if ctx.cls in ("bird", "reptile") or _child_kind(c, j) in ("arm", "wing"):
        # clavicle (a bird's furcula halves) from the shoulder to the front of the sternum
        manubrium = np.array([end[0] + 0.15 * L, end[1] - 0.3 * L, 0.0])
        g.raw(j, ap.rod(local(end), local(manubrium), 0.6 * r, lod))


def _limb_model(ctx: _Context, j: int, part: str):
    c, lod = ctx.c, ctx.lod
    if part in ("humerus", "femur"):
        return ap.long_bone("single", lod)
    if part in ("radius", "tibia"):
        return ap.long_bone("paired", lod)
    if part in ("phalanx", "hoof", "claw", "nail"):
        return ap.digit_end(part, lod)
    if part in ("metacarpal", "metatarsal", "carpometacarpus"):
        if bool(np.any(c.skeleton.parent == j)):  # the digits are joints of their own
            return ap.long_bone("single", lod)
        kind = c.kind[j]
        role = "wing" if kind == "wing" else "foot" if part == "metatarsal" else "hand"
        n, spread, end = ap.DIGITS.get((ctx.cls, role), (5, 0.4, "claw"))
        if ctx.stance == "unguligrade" and ctx.cls == "mammal" and kind == "leg":
            n, spread, end = ap.ungulate(ctx.hoof_digits)
        digits_from = 0.3 if role == "wing" and ctx.cls == "mammal" else 0.62
        return ap.autopod(n, spread, end, lod, digits_from)
    return None


def _fin_pieces(c: Creature, lod: int) -> dict[int, tuple[NDArray, NDArray]]:
    """The fin rays (:mod:`biomorph.creature.fins`) as bone models: per fin joint, its
    stretch of every ray of its fin — thin tapering rods from the joint's start to its
    bone's end — in the joint's frame (``(vertices, faces)``; all rods in one batch)."""
    fins = fn.build(c, *fn.DETAIL[lod])
    if not fins:
        return {}
    joints, paths, rad, ref = [], [], [], []
    for fin in fins:
        r_all = fn.ray_radii(fin)
        for m, j in enumerate(fin.joints):
            k = np.flatnonzero(fin.seg_of == m)
            if k[0] > 0:
                k = np.r_[k[0] - 1, k]  # from the previous segment's last sample
            joints.append(j)
            paths.append(fin.rays[:, k])
            rad.append(r_all[:, k])
            ref.append(np.tile(fin.normal, (len(fin.rays), 1)))
    if len({p.shape for p in paths}) > 1:  # not one batch: joint by joint
        pieces = [
            prim.tubes(p, r, max(3, prim.SIDES[lod] // 2), ref=f)
            for p, r, f in zip(paths, rad, ref, strict=True)
        ]
    else:
        v, f = prim.tubes(
            np.concatenate(paths),
            np.concatenate(rad),
            max(3, prim.SIDES[lod] // 2),
            ref=np.concatenate(ref),
        )
        nv, nf = len(v) // len(joints), len(f) // len(joints)
        pieces = [
            (v[i * nv : (i + 1) * nv], f[i * nf : (i + 1) * nf] - i * nv)
            for i in range(len(joints))
        ]
    return {j: (_local(c, j, v), f) for j, (v, f) in zip(joints, pieces, strict=True)}


def _median_pieces(c: Creature, lod: int) -> dict[int, tuple[NDArray, NDArray]]:
    """A fish's median fins (:func:`biomorph.creature.fins.build_median`) as bone models:
    each ray a thin tapering rod from inside the body (its pterygiophore) to the fin's
    margin, on the spine joint at its root; per joint its rays in its frame."""
    fins = fn.build_median(c, *fn.MEDIAN_DETAIL[lod])
    if not fins:
        return {}
    paths = np.concatenate([fin.rays for fin in fins])
    joint = np.concatenate([fin.joint_of[:, 0] for fin in fins])
    rad = np.concatenate([fn.median_radii(fin) for fin in fins])
    ref = np.concatenate([np.tile(fin.normal, (len(fin.rays), 1)) for fin in fins])
    v, f = prim.tubes(paths, rad, max(3, prim.SIDES[lod] // 2), ref=ref)
    nv, nf = len(v) // len(paths), len(f) // len(paths)
    out = {}
    for j in np.unique(joint).tolist():
        rows = np.flatnonzero(joint == j)
        vs = np.concatenate([v[i * nv : (i + 1) * nv] for i in rows])
        fs = np.concatenate(
            [f[i * nf : (i + 1) * nf] - i * nv + m * nv for m, i in enumerate(rows)]
        )
        out[j] = (_local(c, j, vs), fs)
    return out


def _fin(g: _Geometry, ctx: _Context, j: int) -> None:
    """Fin joint ``j``'s stretch of its fin's rays (:func:`_fin_pieces`)."""
    g.raw(j, ctx.fins[j])


def _box(g: _Geometry, c: Creature, j: int) -> None:
    L = float(c.bone_length[j])
    if c.kind[j] == "skull":
        g.raw(j, skulls.mesh(skulls.get(c.params.get("skull", "mammal_long")), L))
        return
    g.unit(j, ap.unit_box_model(), _size(c, j))


def geometry(
    creature: Creature, shape: str = "bone", lod: int = 1
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """All bone models as ``(vertices, normals, joint, faces)``: each vertex in the local
    frame of joint ``joint[k]`` (metres) — what :func:`biomorph.io.gltf.write_gltf` takes as
    ``joint_geometry``."""
    if shape not in SHAPES:
        raise ParameterError(f"bone shape {shape!r} unknown; expected one of {', '.join(SHAPES)}")
    if lod not in LODS:
        raise ParameterError(f"bone level of detail {lod!r}; expected one of 0, 1, 2")
    g = _Geometry()
    ctx = _Context(creature, lod) if shape == "bone" else None
    for j in np.flatnonzero(creature.bone_length > 1e-9).tolist():
        if ctx is None:
            _box(g, creature, j)
            continue
        part = ctx.parts[j]
        if part in VERTEBRAE or part in ("skull", "mandible"):
            _axial(g, ctx, j, part)
            if j in ctx.median:  # the median fin rays standing on this vertebra
                g.raw(j, ctx.median[j])
        elif part in ("scapula", "pelvis"):
            _girdle(g, ctx, j, part)
        elif j in ctx.fins:
            _fin(g, ctx, j)
        else:
            model = _limb_model(ctx, j, part)
            if model is None:
                _box(g, creature, j)
            else:
                g.unit(j, model, _size(creature, j), _MZ if creature.side[j] < 0 else None)
    return g.arrays()


def joint_meshes(creature: Creature, shape: str = "bone", lod: int = 1) -> dict[int, Mesh]:
    """One mesh per joint with a bone, in that joint's local frame (metres)."""
    v, n, jnt, f = geometry(creature, shape, lod)
    out: dict[int, Mesh] = {}
    if not len(v):
        return out
    face_joint = jnt[f[:, 0]]
    for j in np.unique(jnt).tolist():
        sel = np.flatnonzero(jnt == j)
        lo = sel[0]
        fs = f[face_joint == j] - lo
        out[j] = Mesh(v[sel], fs, normals=n[sel])
    return out


def world_mesh(creature: Creature, shape: str = "bone", lod: int = 1) -> Mesh:
    """All bone meshes merged in world space, faces labelled ``face_ids["bone"]``."""
    v, n, jnt, f = geometry(creature, shape, lod)
    world = creature.world
    rot, trans = world[jnt, :3, :3], world[jnt, :3, 3]
    pos = np.einsum("kij,kj->ki", rot, v) + trans
    nrm = np.einsum("kij,kj->ki", rot, n)
    return Mesh(pos, f, normals=nrm, face_ids={"bone": jnt[f[:, 0]]})
