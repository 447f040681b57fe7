"""Major muscles as swept volumes between attachment points on the bone models.

Attachment points are given on a bone's unit model (its box normalised to a unit cube:
x across the bone, y along it from 0 to 1, z the flexion axis for limbs, lateral for the
axial skeleton) and scaled into the joint's box, so they sit on the model's surface. Each
muscle runs from an *origin* on one bone to an *insertion* on another, as a tube whose
radius rises from the tendons (10 % of the belly) to the belly in the middle; the belly
radius is a share of the soft-tissue box of the bone it lies along (``mass_size``), so
muscles scale with the mass model, not with absolute constants.

First set (the seed's section 3.2 asks for "the major muscles"):

* per limb: a girdle muscle over the upper bone (deltoid / gluteus), front and back of the
  upper bone acting on the middle joint (biceps–triceps / quadriceps–hamstrings) and the
  back of the lower bone to the distal one (forearm flexors / gastrocnemius);
* along the spine: the epaxial muscles (longissimus) above the trunk and tail vertebrae, the
  neck's dorsal muscles above the cervical vertebrae;
* the jaw closers, where the jaw is its own joint: the temporalis from the braincase's
  temporal fossa to the coronoid process and the masseter from the zygomatic arch to the
  mandible's angle (the points of :mod:`biomorph.creature.bones.skull`'s models);
* per standing limb with a metapodial: the digital flexors down the back of the lower bone
  to the far end of the metapodial;
* over each shoulder blade (:func:`biomorph.creature.bones.cage.scapula_frame`): the
  supraspinatus and infraspinatus as one volume from the dorsal border to the shoulder,
  as wide as the blade, so the skin covers the scapula as muscle does.

Left out: the wing membranes (a patagium is a skin fold, not a swept muscle) and the
intrinsic muscles of hands and feet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.creature.creature import Creature

#: the back's epaxial bellies lie this far either side of the spine (share of the
#: soft-tissue half-width)
EPAXIAL_OFFSET = 0.36
#: tendon radius as a share of the belly radius
TENDON = 0.1
#: belly radius as a share of the soft-tissue half-width of the bone it lies along
BELLY = {
    "girdle": 0.55,
    "front": 0.45,
    "back": 0.5,
    "distal": 0.4,
    "epaxial": 0.4,
    "caudal": 0.22,
    "neck": 0.3,
    "temporalis": 0.35,
    "masseter": 0.25,
    "flexor": 0.22,
}


@dataclass(frozen=True)
class Muscle:
    """One muscle: name, origin and insertion joints and points (world, metres), the path
    of its swept volume ``(k, 3)`` and radii ``(k,)``."""

    name: str
    origin_joint: int
    insertion_joint: int
    origin: NDArray
    insertion: NDArray
    path: NDArray
    radius: NDArray


def attachment(c: Creature, j: int, unit: tuple[float, float, float]) -> NDArray:
    """World position of the unit-model point ``unit`` (x, y, z) of joint ``j``'s bone."""
    s = np.array([c.box_size[j, 0], c.bone_length[j], c.box_size[j, 2]])
    return c.world[j, :3, :3] @ (np.asarray(unit, float) * s) + c.world[j, :3, 3]


def _sweep(a: NDArray, b: NDArray, bulge: NDArray, belly: float, k: int) -> tuple[NDArray, NDArray]:
    u = np.linspace(0.0, 1.0, k)[:, None]
    path = a + (b - a) * u + np.sin(np.pi * u) * bulge
    r = belly * (TENDON + (1 - TENDON) * np.sin(np.pi * u[:, 0]) ** 0.8)
    return path, r


def _half_width(c: Creature, j: int) -> float:
    return 0.25 * float(c.mass_size[j, 0] + c.mass_size[j, 2])


def _limb_chains(c: Creature) -> list[list[int]]:
    par = c.skeleton.parent
    out = []
    for g in (j for j in range(len(c)) if c.kind[j] == "girdle"):
        chain = [g]
        while len(chain) < 4:
            kids = [
                int(k) for k in np.flatnonzero(par == chain[-1]) if c.kind[k] not in ("girdle",)
            ]
            if not kids:
                break
            chain.append(kids[0])
        if len(chain) == 4:
            out.append(chain)
    return out


def muscles(c: Creature, lod: int = 1) -> list[Muscle]:
    """The first set of major muscles of ``c`` (see the module docstring)."""
    k = 6 + 2 * lod
    out: list[Muscle] = []
    for g, up, lo, di in _limb_chains(c):
        if c.kind[up] == "fin":
            continue
        tag = c.names[up].rsplit("_", 2)[0] + ("_l" if c.side[up] < 0 else "_r")
        # side normal of the limb's bending plane (away from the body: the flexion axis)
        specs = [
            ("girdle", g, (0.3, 0.4, 0.0), up, (0.3, 0.35, 0.0), (0.35, 0.0)),
            ("front", up, (0.45, 0.15, 0.0), lo, (0.4, 0.1, 0.0), (0.45, 0.0)),
            ("back", up, (-0.45, 0.1, 0.0), lo, (-0.45, 0.12, 0.0), (-0.5, 0.0)),
            ("distal", lo, (-0.45, 0.05, 0.0), di, (-0.4, 0.1, 0.0), (-0.45, 0.0)),
        ]
        for role, oj, ou, ij, iu, (bx, _) in specs:
            a, b = attachment(c, oj, ou), attachment(c, ij, iu)
            along = up if role in ("girdle", "front", "back") else lo
            belly = BELLY[role] * _half_width(c, along)
            bulge = c.world[along, :3, 0] * bx * belly * 1.2
            path, r = _sweep(a, b, bulge, belly, k)
            out.append(Muscle(f"{tag}_{role}", oj, ij, a, b, path, r))
        if c.kind[up] == "leg" and c.bone_length[di] > 1e-9:  # digital flexors
            a, b = attachment(c, lo, (-0.45, 0.55, 0.0)), attachment(c, di, (-0.45, 0.92, 0.0))
            belly = BELLY["flexor"] * _half_width(c, lo)
            bulge = c.world[lo, :3, 0] * -0.5 * belly
            path, r = _sweep(a, b, bulge, belly, k)
            out.append(Muscle(f"{tag}_flexor", lo, di, a, b, path, r))
    out.extend(_axial(c, k))
    out.extend(_jaw(c, k))
    out.extend(_scapular(c, k))
    return out


def _scapular(c: Creature, k: int) -> list[Muscle]:
    """Supra- and infraspinatus over each scapula: a volume along the blade from its
    dorsal border to the glenoid, its radius the blade's half-width (the plate narrows to
    the neck), lying on the blade's outer face."""
    from biomorph.creature.bones.cage import SCAPULA_WIDTH, scapula_frame
    from biomorph.creature.bones.fit import parts_of

    cls = str(c.params.get("class", "mammal"))
    parts = parts_of(c)
    out = []
    for j in range(len(c)):
        if parts[j] != "scapula":
            continue
        fr = scapula_frame(c, j, cls)
        if fr is None:
            continue
        frame, d_pt, ls = fr
        u = np.linspace(0.0, 1.0, k)
        # a flat sheet: three bellies side by side across the blade (the blade narrows to
        # the neck), each about a tenth of the blade's length thick
        half = 0.5 * SCAPULA_WIDTH * ls * (1.0 - 0.7 * u**0.8)
        # thin at the dorsal border (the blade's cartilage lies under the skin there), full
        # over the fossae, narrowing to the neck: a blunt full-thickness start made a box
        # on the shoulder's skin
        rise = np.sin(0.5 * np.pi * np.clip(u / 0.35, 0.0, 1.0))
        thick = (0.1 * (1.0 - 0.4 * u) + 0.02) * ls * (0.45 + 0.55 * rise)
        ins = int(np.flatnonzero(c.skeleton.parent == j)[0])
        # a dome across the blade: the middle belly (over the spine) the thickest
        for n_sheet, (share, t_share) in enumerate(((-0.6, 0.65), (0.0, 1.0), (0.6, 0.65))):
            path = (
                d_pt
                + np.outer(u * 0.95, frame[:, 1] * ls)
                + np.outer(share * half, frame[:, 0])
                + np.outer(0.4 * t_share * thick, frame[:, 2])
            )
            out.append(
                Muscle(
                    f"{c.names[j]}_spinati{n_sheet}",
                    j,
                    ins,
                    path[0],
                    path[-1],
                    path,
                    t_share * thick,
                )
            )
    return out


def _jaw(c: Creature, k: int) -> list[Muscle]:
    """Temporalis and masseter on both sides (skull and jaw unit models have x dorsal and
    are mirrored into their joints' frames, whose local X is ventral)."""
    if "skull" not in c.kind or "jaw" not in c.names:
        return []
    s, j = c.kind.index("skull"), c.names.index("jaw")
    if c.bone_length[s] <= 1e-9 or c.bone_length[j] <= 1e-9:
        return []
    hw = 0.5 * float(min(c.box_size[s, 0], c.box_size[s, 2]))
    out = []
    for side, tag in ((1.0, "r"), (-1.0, "l")):
        for name, o, ins in (  # (x dorsal, y, z) on the skull / the jaw
            ("temporalis", (0.44, 0.1, 0.22), (1.6, 0.12, 0.42)),  # from the crown
            ("masseter", (-0.14, 0.3, 0.47), (-0.4, 0.1, 0.44)),  # arch to angle
        ):
            a = attachment(c, s, (-o[0], o[1], side * o[2]))
            b = attachment(c, j, (-ins[0], ins[1], side * ins[2]))
            belly = BELLY[name] * hw
            path, r = _sweep(a, b, np.zeros(3), belly, k)
            out.append(Muscle(f"{name}_{tag}", s, j, a, b, path, r))
    return out


def _axial(c: Creature, k: int) -> list[Muscle]:
    """Epaxial muscles: one swept volume over consecutive runs of trunk/tail vertebrae and
    one over the neck, on top of the neural spines."""
    out = []
    par = c.skeleton.parent
    for region, role in (("back", "epaxial"), ("tail", "epaxial"), ("neck", "neck")):
        idx = [
            j
            for j in range(len(c))
            if c.kind[j] == "spine" and c.region[j] == region and c.bone_length[j] > 1e-9
        ]
        if len(idx) < 2:
            continue
        runs = _chains(par, idx)
        for n_run, run in enumerate(runs):
            if len(run) < 2:
                continue
            dorsal = [_dorsal_point(c, j) for j in run]
            path = np.array(dorsal)
            hw = np.array([_half_width(c, j) for j in run])
            u = np.linspace(0, 1, len(run))
            taper = TENDON + (1 - TENDON) * np.sin(np.pi * (0.1 + 0.8 * u)) ** 0.5
            if region != "back":
                belly = BELLY["caudal" if region == "tail" else role] * hw
                out.append(
                    Muscle(
                        f"{region}_{role}_{n_run}",
                        run[0],
                        run[-1],
                        path[0],
                        path[-1],
                        path,
                        belly * taper,
                    )
                )
                continue
            # the back: longissimus and iliocostalis as a broad mass either side of the
            # spinous processes, between them and the ribs' angles (a dog's back is about as
            # wide as its chest at the withers; one thin midline tube left the scapula's
            # dorsal border standing out of a narrow back)
            lat = np.array([_lateral(c, j) for j in run])
            spine = c.joint_positions[run] + 0.5 * c.bone_length[run][:, None] * c.world[run, :3, 1]
            low = spine + 0.3 * (path - spine)
            taper = TENDON + (1 - TENDON) * np.sin(np.pi * (0.05 + 0.9 * u)) ** 0.35
            for tag, sgn in (("r", 1.0), ("l", -1.0)):
                side_path = low + sgn * (EPAXIAL_OFFSET * hw)[:, None] * lat
                out.append(
                    Muscle(
                        f"{region}_{role}_{n_run}_{tag}",
                        run[0],
                        run[-1],
                        side_path[0],
                        side_path[-1],
                        side_path,
                        BELLY["epaxial"] * hw * taper,
                    )
                )
    return out


def _chains(par: NDArray, idx: list[int]) -> list[list[int]]:
    """The joints ``idx`` as runs along the skeleton: each connected piece (by parent
    links within ``idx``) walked from one end to the other, through the root where the
    root sits mid-back (its head- and tail-side children are both in ``idx``). A piece
    that branches is split at the branch. (Sorting by depth from the root used to
    interleave the two sides of a mid-back root into runs of one joint each: the back's
    epaxial muscle was a stub over the root vertebra, a box on the spine.)"""
    members = set(idx)
    nbr: dict[int, list[int]] = {j: [] for j in idx}
    for j in idx:
        p = int(par[j])
        if p in members:
            nbr[j].append(p)
            nbr[p].append(j)
    seen: set[int] = set()
    runs: list[list[int]] = []
    # start at the ends (degree 1) first, then any branch point or leftover
    for start in sorted(idx, key=lambda j: (len(nbr[j]) != 1, len(nbr[j]) == 0, j)):
        if start in seen:
            continue
        run, prev, j = [start], -1, start
        seen.add(start)
        while True:
            nxt = [k for k in nbr[j] if k != prev and k not in seen]
            if len(nbr[j]) > 2 and j != start or len(nxt) != 1:
                break
            prev, j = j, nxt[0]
            run.append(j)
            seen.add(j)
        runs.append(run)
    return runs


def _lateral(c: Creature, j: int) -> NDArray:
    """Joint ``j``'s right-hand direction across the spine (world, unit, ⟂ the bone)."""
    y = c.world[j, :3, 1]
    z = np.array([0.0, 0.0, 1.0])
    lat = z - (z @ y) * y
    n = float(np.linalg.norm(lat))
    return lat / n if n > 1e-9 else c.world[j, :3, 2]


def _dorsal_point(c: Creature, j: int) -> NDArray:
    """The top of joint ``j``'s vertebra (world): the box's dorsal face at mid-length."""
    w = c.world[j]
    x = w[:3, 0]
    up = np.array([0.0, 1.0, 0.0])
    sign = 1.0 if x @ up >= 0 else -1.0
    mid = w[:3, 3] + w[:3, 1] * 0.5 * c.bone_length[j]
    return mid + sign * x * 0.45 * c.box_size[j, 0]


def muscle_mesh(ms: list[Muscle], lod: int = 1) -> Mesh | None:
    """All muscles as one closed mesh (world), faces labelled ``face_ids["muscle"]``: the
    muscles with the same number of path points swept in one batch."""
    from biomorph.creature.bones.prim import SIDES, tubes

    if not ms:
        return None
    vs, fs, ids = [], [], []
    base = 0
    groups: dict[int, list[int]] = {}
    for i, m in enumerate(ms):
        groups.setdefault(len(m.path), []).append(i)
    for members in groups.values():
        paths = np.stack([ms[i].path for i in members])
        radii = np.stack([ms[i].radius for i in members])
        v, f = tubes(paths, radii, SIDES[lod], ref=_ring_refs(paths))
        per_f = len(f) // len(members)
        vs.append(v)
        fs.append(f + base)
        ids.append(np.repeat(np.asarray(members), per_f))
        base += len(v)
    ids_all = np.concatenate(ids)
    mesh = Mesh(np.concatenate(vs), np.concatenate(fs), face_ids={"muscle": ids_all})
    return mesh.compute_normals()


def _ring_refs(paths: NDArray) -> NDArray:
    """Per path the ring reference of :func:`~biomorph.creature.bones.prim.tube` (x unless
    the path runs mostly along x, then z)."""
    t = np.gradient(paths, axis=1)
    t /= np.maximum(np.linalg.norm(t, axis=2, keepdims=True), 1e-12)
    mean = t.mean(axis=1)
    along_x = np.abs(mean[:, 0]) >= 0.8 * np.linalg.norm(mean, axis=1) + 1e-9
    return np.where(along_x[:, None], [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
