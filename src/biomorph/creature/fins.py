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
