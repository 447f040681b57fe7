"""Fins as fin-ray sheets (issue 14): thin bony rays radiating from the fin's base, a
membrane between them — the way a ray-finned fish's fins are built (bony rays,
lepidotrichia, fanning from the fin's base and webbed by a thin membrane; Alben, Madden &
Lauder 2007, *J. R. Soc. Interface* 4:243) — instead of the implicit field's tubes round
the fin's three bones.

A fin is the chain of ``fin`` joints of one limb pair's side (base, proximal and distal
ray bones). Its skeleton chain is the *first ray*; the other rays are that polyline
turned about the fin's base, in the plane through the chain nearest the horizontal
(paired fins spread sideways), away from the body's midline, up to :data:`SPREAD`, and
shortened towards the outer edge (:data:`OUTER`: a rounded fin). With the generator's fins
swept back along the flank, the chain is the fin's inner (posterior) edge and the fan opens
outwards and forwards; a real pectoral fin's longest rays lead, which would need fins
posed out from the body. Their roots lie
on the fin's base, :data:`BASE` of the fin's length across the rays, each ray's further
along it the more it is turned (so no two rays cross). Each ray's samples are
assigned to the fin joint whose bone they lie along (the joints' arc-length spans along
the chain), so the bone models bend with the joints.

A fish also has median fins (:func:`build_median`): a dorsal fin on the trunk, an anal
fin behind the vent and a forked caudal fin at the tail's end, rays in the sagittal plane
on the vertebrae they stand on, sized from the creature's trunk sections (see the section
comment below for where each size comes from).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from biomorph.creature.creature import Creature

#: angle (rad) between the first (the skeleton's) and the outermost ray at the fin's base
SPREAD = 0.7
#: length of the outermost ray as a share of the first ray's (rays between: a smooth,
#: rounded margin, ``1 - (1 - OUTER) u^2`` at the share ``u`` of the way out)
OUTER = 0.45
#: the fin base's length (across the rays at their roots), a share of the fin's length
BASE = 0.2
#: ray diameter at the tip as a share of its diameter at the base (rays taper)
RAY_TIP = 0.35
#: membrane thickness as a share of the first ray's diameter (a double layer of skin)
MEMBRANE = 0.3
#: (rays, samples per fin bone) at each level of detail — skin and bone models alike
DETAIL = ((5, 3), (7, 4), (9, 6))


@dataclass(frozen=True)
class Fin:
    """One fin: its joints (base to tip), its rays ``(r, k, 3)`` (world, the chain's ray first,
    each from the base to the margin), each sample's joint ``(k,)`` (boundary samples end
    one joint's piece and start the next's) and the first ray's diameter at the base."""

    joints: tuple[int, ...]
    rays: NDArray[np.float64]
    joint_of: NDArray[np.int64]
    seg_of: NDArray[np.int64]  # index into ``joints`` of each sample (its segment)
    width: float
    normal: NDArray[np.float64]  # the fin plane's normal (pointing up)


def chains(c: Creature) -> list[tuple[int, ...]]:
    """Each side's chain of ``fin`` joints with a bone, from the girdle outwards."""
    par = c.skeleton.parent
    out = []
    for j in range(len(c)):
        if c.kind[j] != "fin" or (par[j] >= 0 and c.kind[int(par[j])] == "fin"):
            continue
        chain = [j]
        while True:
            kids = [int(k) for k in np.flatnonzero(par == chain[-1]) if c.kind[k] == "fin"]
            if not kids:
                break
            chain.append(kids[0])
        chain = [k for k in chain if c.bone_length[k] > 1e-9]
        if chain:
            out.append(tuple(chain))
    return out


def fin_joints(c: Creature) -> NDArray[np.int64]:
    """Every joint of every fin chain (built as explicit sheets, not as field capsules)."""
    return np.asarray([j for ch in chains(c) for j in ch], np.int64)


def build(c: Creature, n_rays: int = 7, per_bone: int = 4) -> list[Fin]:
    """The fins of ``c`` with ``n_rays`` rays each, ``per_bone`` samples per fin bone."""
    up = np.array([0.0, 1.0, 0.0])
    out = []
    for chain in chains(c):
        a = c.joint_positions[list(chain)]
        b = c.bone_ends[list(chain)]
        t = np.linspace(0.0, 1.0, per_bone + 1)
        pts, seg = [a[0][None]], [0]
        for m in range(len(chain)):
            pts.append(a[m] + np.outer(t[1:], b[m] - a[m]))
            seg += [m] * per_bone
        lead = np.concatenate(pts)  # (k, 3), joint boundaries on samples
        seg_of = np.asarray(seg, np.int64)
        rel = lead - lead[0]
        length = float(np.linalg.norm(np.diff(lead, axis=0), axis=1).sum())
        axis = rel[-1] / max(float(np.linalg.norm(rel[-1])), 1e-12)
        # the fin's plane: through the chain, as near the horizontal as it can lie
        n = up - (up @ axis) * axis
        if float(np.linalg.norm(n)) < 0.2:  # a fin pointing up or down: a vertical plane
            n = np.array([0.0, 0.0, 1.0]) - axis[2] * axis
        n /= max(float(np.linalg.norm(n)), 1e-12)
        if n[1] < 0:
            n = -n
        # the rays open away from the midline (outwards; a midline fin: downwards)
        side = float(np.sign(c.side[chain[0]]))
        outward = np.array([0.0, 0.0, side]) if side else -up
        e = np.cross(n, axis)
        sign = 1.0 if float(e @ outward) >= 0 else -1.0
        # the base runs across the rays, from the first ray's root to the outer side
        # (rays turned further start further along it, so no two cross)
        base_dir = sign * e / max(float(np.linalg.norm(e)), 1e-12)
        # each ray: the first ray turned about the fin's normal (Rodrigues, all at once)
        u = np.linspace(0.0, 1.0, n_rays) if n_rays > 1 else np.zeros(1)
        ang = sign * SPREAD * u
        cs, sn = np.cos(ang)[:, None, None], np.sin(ang)[:, None, None]
        nxr = np.cross(n, rel)[None]
        along_n = (rel @ n)[None, :, None] * n
        turned = rel[None] * cs + nxr * sn + along_n * (1.0 - cs)
        scale = (1.0 - (1.0 - OUTER) * u * u)[:, None, None]
        roots = lead[0] + (u * BASE * length)[:, None] * base_dir
        rays = roots[:, None, :] + turned * scale
        width = float(np.max(c.box_size[list(chain), 0]))
        out.append(Fin(chain, rays, np.asarray(chain)[seg_of], seg_of, width, n))
    return out


def ray_radii(fin: Fin) -> NDArray[np.float64]:
    """Radius ``(r, k)`` of each ray along it: the first ray's half-width at the base,
    tapering to :data:`RAY_TIP` of it at the margin; the later rays slimmer (0.7)."""
    r, k = fin.rays.shape[:2]
    along = np.linspace(1.0, RAY_TIP, k)[None, :]
    lead = np.where(np.arange(r) == 0, 1.0, 0.7)[:, None]
    return 0.5 * fin.width * along * lead


def membrane_grid(fin: Fin) -> NDArray[np.float64]:
    """The membrane's mid-surface ``(r, k, 3)``: the rays themselves (rows), so it spans
    the fin from the first to the outermost ray and from the base to the margin."""
    return fin.rays


# --------------------------------------------------------------------------- median fins
# A ray-finned fish's median (unpaired) fins stand in its sagittal plane: the dorsal fin on
# the back, the anal fin on the belly behind the vent and the caudal fin at the tail's end
# (the hypural plate). The skeleton has no joints for them: their rays ride on the spine
# joints they stand on (each ray on the vertebra at its root), so they bend with the spine
# in a rigged GLB. Every size is read off the creature's own skeleton:
#
# * landmarks — the trunk is the spine's ``back`` region (shoulder girdle to hip girdle);
#   the vent, where a fish's tail region begins (trunk | tail boundary), is the first
#   ``tail`` vertebra; the caudal fin's base is the last vertebra's end;
# * body depth — at every vertebra, the trunk section the skin and rib cage are built round
#   (:func:`biomorph.creature.bones.cage.trunk_sections`: centre and radius), so each ray
#   leaves the body where the skin is; ``D`` is the deepest section's diameter;
# * rays — as thick as the creature's paired fin rays (the thickest fin bone's box), else
#   a share of the last vertebra's width; each ray starts inside the body at its vertebra's
#   dorsal (ventral) edge — the pterygiophore reaching down between the neural (haemal)
#   spines — and leaves the skin at the section's surface.
#
# The shares below shape a generalised teleost (perch- or carp-like silhouette: one dorsal
# fin over the middle of the trunk, an anal fin just behind the vent, a forked tail about
# as tall as the body is deep); they are chosen for that silhouette, not fitted to
# specimens, and scale with the landmarks and ``D`` above.

#: the dorsal fin's base: from/to these shares of the trunk's length (head to hip)
DORSAL_BASE = (0.3, 0.8)
#: the dorsal fin's longest (leading) ray beyond the skin, a share of the body depth ``D``
DORSAL_HEIGHT = 0.55
#: the anal fin's base: from the vent over this share of the tail's length
ANAL_BASE = (0.0, 0.3)
#: the anal fin's longest ray beyond the skin, a share of ``D``
ANAL_HEIGHT = 0.45
#: the dorsal and anal rays rake back from the body's dorsal/ventral direction (rad)
RAKE = 0.6
#: the caudal fin: tip-to-tip height of its two lobes, a share of ``D``
CAUDAL_SPAN = 1.0
#: the caudal rays fan ± this angle (rad) about the tail's axis
CAUDAL_FAN = 0.6
#: the fork: the middle caudal ray's length as a share of the lobes' (1 = a square tail)
CAUDAL_FORK = 0.55
#: the caudal rays' roots span this share of the tail end's section depth (hypural plate)
CAUDAL_ROOTS = 0.8
#: (rays, samples along each ray) per level of detail — one shape for all three fins
MEDIAN_DETAIL = ((7, 4), (9, 5), (13, 7))
#: the median fins, in the order :func:`build_median` returns them
MEDIAN = ("dorsal", "anal", "caudal")


@dataclass(frozen=True)
class MedianFin:
    """One median fin: its name (``dorsal | anal | caudal``), its rays ``(r, k, 3)``
    (world, front/top ray first, each from inside the body to the margin), the spine joint
    each ray sample rides on ``(r, k)``, where each ray leaves the skin ``(r, 3)``, the
    rays' diameter at the base and the fin plane's normal (the creature's right, +z)."""

    name: str
    rays: NDArray[np.float64]
    joint_of: NDArray[np.int64]
    surface: NDArray[np.float64]
    width: float
    normal: NDArray[np.float64]

    @property
    def joints(self) -> tuple[int, ...]:
        return tuple(int(j) for j in np.unique(self.joint_of))


@dataclass(frozen=True)
class _Spine:
    """The spine joints head to tail with their sections: joint, arc start along the spine
    (m), bone length, head end, towards-tail unit, dorsal unit, section centre and radius,
    the ``back`` and ``tail`` regions' arc ranges."""

    joint: NDArray[np.int64]
    s0: NDArray[np.float64]
    length: NDArray[np.float64]
    head_end: NDArray[np.float64]
    back: NDArray[np.float64]
    dorsal: NDArray[np.float64]
    centre: NDArray[np.float64]
    radius: NDArray[np.float64]
    trunk: tuple[float, float]
    tail: tuple[float, float]

    def at(self, s: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        """At arc positions ``s``: the row of the joint there, the spine point, its
        towards-tail and dorsal units and the distances from the spine point to the
        section's dorsal and ventral surface."""
        k = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)
        t = np.clip(s - self.s0[k], 0.0, self.length[k])[:, None]
        p = self.head_end[k] + t * self.back[k]
        d = self.dorsal[k]
        off = ((self.centre[k] - p) * d).sum(axis=1)
        return k, p, self.back[k], d, np.stack([self.radius[k] + off, self.radius[k] - off], 1)


def _spine(c: Creature) -> _Spine | None:
    """The spine head to tail (:class:`_Spine`), ``None`` without vertebrae."""
    from biomorph.creature.bones.cage import _headward, _section_frames, trunk_sections

    idx, centre, radius = trunk_sections(c)
    if len(idx) < 2:
        return None
    # order: the tree distance from the skull (head to tail)
    par = c.skeleton.parent
    d = np.full(len(c), -1, np.int64)
    j = c.kind.index("skull") if "skull" in c.kind else int(idx[0])
    k = 0
    while j >= 0:
        d[j] = k
        k += 1
        j = int(par[j])
    for i in range(len(c)):
        if d[i] < 0:
            d[i] = d[par[i]] + 1 if par[i] >= 0 else 0
    order = np.argsort(d[idx], kind="stable")
    idx, centre, radius = idx[order], centre[order], radius[order]
    t, _, dorsal = _section_frames(c, idx, centre)  # t: headward
    head = _headward(c)[idx]
    P, E = c.joint_positions[idx], c.bone_ends[idx]
    head_end = np.where(head[:, None], E, P)
    length = c.bone_length[idx].astype(float)
    s0 = np.r_[0.0, np.cumsum(length)[:-1]]
    regions = np.asarray([c.region[j] for j in idx])

    def span(region: str) -> tuple[float, float]:
        rows = np.flatnonzero(regions == region)
        if not len(rows):
            return (0.0, 0.0)
        return float(s0[rows[0]]), float(s0[rows[-1]] + length[rows[-1]])

    return _Spine(idx, s0, length, head_end, -t, dorsal, centre, radius, span("back"), span("tail"))


def _ray_width(c: Creature) -> float:
    """The median fins' ray diameter at the base: the paired fins' thickest bone, else a
    tenth of the last vertebra's width."""
    paired = fin_joints(c)
    if len(paired):
        return float(np.max(c.box_size[paired, 0]))
    spine = [j for j in range(len(c)) if c.kind[j] == "spine" and c.bone_length[j] > 1e-9]
    return 0.1 * float(c.box_size[spine[-1], 2]) if spine else 0.0


def _along_back(
    sp: _Spine, c: Creature, s: NDArray, height: float, side: int, n_samples: int
) -> tuple[NDArray, NDArray, NDArray]:
    """Rays standing on the back (``side`` +1) or belly (-1) at arc positions ``s`` (front
    to back): from the vertebra's edge through the skin, raked back by :data:`RAKE`, the
    leading ray ``height`` beyond the skin and the later ones shorter (a rounded margin as
    the paired fins', :data:`OUTER` at the last). Returns rays, joints, surface points."""
    k, p, back, dorsal, depth = sp.at(s)
    n = len(s)
    u = np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(1)
    out = side * dorsal
    edge = p + (0.5 * c.box_size[sp.joint[k], 0])[:, None] * out  # the vertebra's edge
    skin = p + depth[:, 0 if side > 0 else 1][:, None] * out
    direction = np.cos(RAKE) * out + np.sin(RAKE) * back
    h = height * (1.0 - (1.0 - OUTER) * u * u)
    tip = skin + h[:, None] * direction
    # sample 0 inside the body at the vertebra's edge, then from the skin to the margin
    w = np.linspace(0.0, 1.0, n_samples - 1)[None, :, None]
    rays = np.concatenate([edge[:, None], skin[:, None] + (tip - skin)[:, None] * w], axis=1)
    joints = np.repeat(sp.joint[k][:, None], n_samples, axis=1)
    return rays, joints, skin


def _caudal(sp: _Spine, span: float, n: int, n_samples: int) -> tuple[NDArray, NDArray, NDArray]:
    """The caudal fin's rays at the last vertebra's end: roots spread over
    :data:`CAUDAL_ROOTS` of that section's depth (the hypural plate), fanned top to bottom
    over ± :data:`CAUDAL_FAN` about the tail's axis, the lobes' tips ``span`` apart and the
    middle ray :data:`CAUDAL_FORK` of the lobes' length (a forked tail)."""
    last = len(sp.joint) - 1
    end = sp.head_end[last] + sp.length[last] * sp.back[last]
    back, dorsal = sp.back[last], sp.dorsal[last]
    r = float(sp.radius[last])
    u = np.linspace(0.0, 1.0, n) if n > 1 else np.full(1, 0.5)
    a = 1.0 - 2.0 * u  # +1 the upper lobe's edge, -1 the lower's
    phi = CAUDAL_FAN * a
    lobe = 0.5 * span / np.sin(CAUDAL_FAN)
    length = lobe * (CAUDAL_FORK + (1.0 - CAUDAL_FORK) * np.abs(a))
    # each root half a vertebra inside the tail, so the fin's base sits in its skin
    root = end - 0.5 * sp.length[last] * back + (CAUDAL_ROOTS * r * a)[:, None] * dorsal
    direction = np.cos(phi)[:, None] * back + np.sin(phi)[:, None] * dorsal
    skin = end + (CAUDAL_ROOTS * r * a)[:, None] * dorsal
    tip = skin + length[:, None] * direction
    w = np.linspace(0.0, 1.0, n_samples - 1)[None, :, None]
    rays = np.concatenate([root[:, None], skin[:, None] + (tip - skin)[:, None] * w], axis=1)
    joints = np.full((n, n_samples), sp.joint[last], np.int64)
    return rays, joints, skin


def build_median(c: Creature, n_rays: int = 9, n_samples: int = 5) -> list[MedianFin]:
    """The median fins of a fish (:data:`MEDIAN`; ``[]`` for other classes): ``n_rays``
    rays each, ``n_samples`` samples per ray (the first inside the body)."""
    if str(c.params.get("class", "")) != "fish":
        return []
    sp = _spine(c)
    if sp is None:
        return []
    depth = 2.0 * float(sp.radius.max())  # D: the deepest section's diameter
    width = _ray_width(c)
    normal = np.array([0.0, 0.0, 1.0])
    out = []
    (t0, t1), (a0, a1) = sp.trunk, sp.tail
    if t1 > t0:
        s = t0 + (t1 - t0) * np.linspace(*DORSAL_BASE, n_rays)
        rays, jo, skin = _along_back(sp, c, s, DORSAL_HEIGHT * depth, 1, n_samples)
        out.append(MedianFin("dorsal", rays, jo, skin, width, normal))
    if a1 > a0:
        s = a0 + (a1 - a0) * np.linspace(*ANAL_BASE, n_rays)
        rays, jo, skin = _along_back(sp, c, s, ANAL_HEIGHT * depth, -1, n_samples)
        out.append(MedianFin("anal", rays, jo, skin, width, normal))
    rays, jo, skin = _caudal(sp, CAUDAL_SPAN * depth, n_rays, n_samples)
    out.append(MedianFin("caudal", rays, jo, skin, width, normal))
    return out


def median_radii(fin: MedianFin) -> NDArray[np.float64]:
    """Radius ``(r, k)`` of each median fin ray: half its base width, tapering from the
    skin to :data:`RAY_TIP` of it at the margin (as :func:`ray_radii`)."""
    r, k = fin.rays.shape[:2]
    along = np.r_[1.0, np.linspace(1.0, RAY_TIP, k - 1)][None, :]
    return np.broadcast_to(0.5 * fin.width * along, (r, k)).copy()
