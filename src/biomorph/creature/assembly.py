"""Assembly: the steps' states → joint arrays (creature px) → a :class:`Creature` (metres).

Vertebrae and skull are built as whole arrays, limbs per pair (right side, then the exact
mirror image for the left). The joint arrays travel as one dict of parallel arrays (names,
parent, world rotation ``W``, position, bone length, box, volume, mass centre, limits …),
reordered depth-first before the conversion to local rest transforms.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.creature import anatomy as an
from biomorph.creature import balance as bal
from biomorph.creature import feet
from biomorph.creature import limbs as lb
from biomorph.creature import mass as ms
from biomorph.creature import skulls as sk
from biomorph.creature import spine as sp
from biomorph.creature import vertebrae as vt
from biomorph.creature.creature import Creature
from biomorph.creature.options import Options
from biomorph.creature.quality import rules_hold
from biomorph.creature.states import LimbsState, SkullState, SpineState

_M = np.diag([1.0, 1.0, -1.0])

#: Share of the distal segment's (hand / foot) soft-tissue volume carried by its digits (a
#: human foot: toes ≈ 0.3 of the foot's mass; a horse's pastern and hoof ≈ 0.3 below the
#: cannon bone).
DIGIT_MASS_SHARE = 0.3

#: Relative joint ranges (degrees, about local x, y, z) for spine/skull/girdle bones.
SPINE_RANGE = {
    "neck": (20, 15, 30),
    "back": (5, 5, 8),
    "tail": (15, 12, 20),
    "head": (25, 20, 40),
    "girdle": (5, 5, 10),
    "jaw": (3, 5, 35),
    "digit": (10, 5, 60),
}


def _frames_from_dirs(d: NDArray) -> NDArray:
    """World rotations ``(m, 3, 3)`` with +Y along each sagittal direction and Z = +z."""
    return _frames_kernel(np.ascontiguousarray(d, dtype=np.float64))


@numba.njit(cache=True)
def _frames_kernel(d: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """:func:`_frames_from_dirs` compiled (the same operations in the same order: a norm is
    ``sqrt((a² + b²) + c²)``; a degenerate direction becomes −x)."""
    m = d.shape[0]
    out = np.empty((m, 3, 3))
    for i in range(m):
        n = np.sqrt((d[i, 0] * d[i, 0] + d[i, 1] * d[i, 1]) + d[i, 2] * d[i, 2])
        if n > 1e-12:
            y0, y1, y2 = d[i, 0] / n, d[i, 1] / n, d[i, 2] / n
        else:
            y0, y1, y2 = -1.0, 0.0, 0.0
        z0 = 0.0 - y2 * y0
        z1 = 0.0 - y2 * y1
        z2 = 1.0 - y2 * y2
        nz = np.sqrt((z0 * z0 + z1 * z1) + z2 * z2)
        z0, z1, z2 = z0 / nz, z1 / nz, z2 / nz
        out[i, 0, 0] = y1 * z2 - y2 * z1
        out[i, 1, 0] = y2 * z0 - y0 * z2
        out[i, 2, 0] = y0 * z1 - y1 * z0
        out[i, 0, 1], out[i, 1, 1], out[i, 2, 1] = y0, y1, y2
        out[i, 0, 2], out[i, 1, 2], out[i, 2, 2] = z0, z1, z2
    return out


_RZ_PI = np.diag([-1.0, -1.0, 1.0])
_RANGES = {k: np.stack([-np.radians(v), np.radians(v)], axis=1) for k, v in SPINE_RANGE.items()}
_REGION_RANGES = np.stack([_RANGES["neck"], _RANGES["back"], _RANGES["tail"]])


def _body(spine: SpineState, pts: NDArray, skull: SkullState) -> _Body:
    """The vertebrae and skull blocks of :func:`assemble` (memoised on their inputs: balance
    repair re-assembles the same spine and skull with shifted legs)."""
    o = np.asarray(skull.origin, float)
    key = (
        np.ascontiguousarray(pts, dtype=float).tobytes(),
        np.asarray(spine.counts).tobytes(),
        float(spine.girth),
        spine.cls,
        spine.legs == 0,
        skull.shape,
        float(skull.length),
        float(skull.angle),
        o.tobytes(),
    )
    hit = _BODY_CACHE.get(key)
    if hit is not None:
        return hit
    out = _body_blocks(spine, pts, skull)
    if len(_BODY_CACHE) > 64:
        _BODY_CACHE.clear()
    _BODY_CACHE[key] = out
    return out


@dataclass(frozen=True, eq=False)
class _Body:
    """Vertebra + skull joint arrays (creature px), in joint order, and what the limbs need
    of the spine (vertebra boundaries, joint index of each vertebra)."""

    m: int
    edges: list[float]
    slot: NDArray[np.int64]
    names: tuple[str, ...]
    kind: tuple[str, ...]
    region: tuple[str, ...]
    part: tuple[str, ...]
    arrays: dict[str, NDArray]


@dataclass(frozen=True, eq=False)
class _Topology:
    """What the vertebra counts fix: joint order (root vertebra first, then towards the head,
    then towards the tail), parents, names, parts, regions, limits."""

    m: int
    root: int
    order: NDArray[np.int64]
    slot: NDArray[np.int64]
    vreg: NDArray[np.int64]
    parent: NDArray[np.int64]
    lim: NDArray[np.float64]
    names: tuple[str, ...]
    kind: tuple[str, ...]
    region: tuple[str, ...]
    part: tuple[str, ...]


@lru_cache(maxsize=256)
def _topology(counts: tuple[int, int, int], cls: str) -> _Topology:
    _, vreg = vt.boundaries(np.ones(3), np.array(counts, np.int64))
    m = len(vreg)
    back_idx = np.flatnonzero(vreg == 1)
    root = int(back_idx[min(int(round(0.65 * (len(back_idx) - 1))), len(back_idx) - 1)])
    order = np.concatenate([[root], np.arange(root - 1, -1, -1), np.arange(root + 1, m)])
    slot = np.empty(m, np.int64)
    slot[order] = np.arange(m)  # joint index of vertebra i
    rname = ("neck", "back", "tail")
    within = np.zeros(m, np.int64)
    for r in range(3):
        sel = vreg == r
        within[sel] = np.arange(1, sel.sum() + 1)
    vl, wl = vreg.tolist(), within.tolist()
    vnames = [f"{rname[vl[i]]}_{wl[i]:02d}" for i in order.tolist()]
    vparts = an.vertebra_parts(vreg, cls)
    vi = order
    ant = order < root
    par_v = np.where(
        vi == root, -1, np.where(ant, slot[np.minimum(vi + 1, m - 1)], slot[np.maximum(vi - 1, 0)])
    )
    out = _Topology(
        m=m,
        root=root,
        order=order,
        slot=slot,
        vreg=vreg,
        parent=np.concatenate([par_v, [slot[0], m]]).astype(np.int64),
        lim=np.concatenate([_REGION_RANGES[vreg[vi]], [_RANGES["head"], _RANGES["jaw"]]]),
        names=tuple(vnames) + ("skull", "jaw"),
        kind=("spine",) * m + ("skull", "skull"),
        region=tuple(rname[r] for r in vreg[vi].tolist()) + ("head", "head"),
        part=tuple(vparts[i] for i in vi.tolist()) + ("skull", "mandible"),
    )
    for a in (out.order, out.slot, out.vreg, out.parent, out.lim):
        a.setflags(write=False)
    return out


def _body_blocks(spine: SpineState, pts: NDArray, skull: SkullState) -> _Body:
    cls = spine.cls
    legless = spine.legs == 0
    xy, s, region = sp.sample(pts)
    rl = sp.region_lengths(s, region)
    shape = sk.get(skull.shape)
    skull_h = shape.height * skull.length
    top = _topology(tuple(int(c) for c in spine.counts), cls)
    edges, _ = vt.boundaries(rl, spine.counts)
    m, root, order, slot = top.m, top.root, top.order, top.slot
    # body slices (volume, centre, owning vertebra), compiled (_slices_kernel)
    h, b, off = ms.profile(s, rl, spine.girth, cls, skull_h, legless)
    P, vmass, vcen, vh, vb = _slices_kernel(xy, s, h, b, off, np.ascontiguousarray(edges), m)
    # vertebra i: joint at the end nearer the root, bone towards the other end
    ant = order < root
    vi = order
    a = np.where(ant[:, None], P[vi + 1], P[vi])
    e = np.where(ant[:, None], P[vi], P[vi + 1])
    d3 = np.concatenate([e - a, np.zeros((m, 1))], axis=1)
    Lv = np.linalg.norm(d3, axis=1)
    # skull and jaw
    ang = skull.angle
    d = np.array([np.cos(ang), np.sin(ang), 0.0])
    org = np.array([skull.origin[0], skull.origin[1], 0.0])
    sbox = sk.box_size(shape, skull.length)
    Wsk = _frames_from_dirs(d[None])
    jaw = sk.jaw(shape, skull.length, Wsk[0], org)
    vsk = ms.ellipsoid_volume(sbox)
    sk_box = np.array([sbox, jaw.box], float)
    arrays = {
        "parent": top.parent,
        "side": np.zeros(m + 2, np.int64),
        "digit": np.zeros(m + 2, np.int64),
        "W": np.concatenate([_frames_from_dirs(d3), Wsk, jaw.W[None]]),
        "pos": np.concatenate(
            [np.concatenate([a, np.zeros((m, 1))], axis=1), np.array([org, jaw.pos], float)]
        ),
        "blen": np.concatenate([Lv, [skull.length, jaw.length]]),
        "box": np.concatenate([np.stack([0.35 * vh[vi], Lv, 0.3 * vb[vi]], axis=1), sk_box]),
        "vol": np.concatenate(
            [vmass[vi], [(1 - sk.JAW_MASS_FRACTION) * vsk, sk.JAW_MASS_FRACTION * vsk]]
        ),
        "mass_c": np.concatenate(
            [
                np.concatenate([vcen[vi], np.zeros((m, 1))], axis=1),
                np.array(
                    [org + d * skull.length / 2, jaw.pos + jaw.W[:, 1] * jaw.length / 2], float
                ),
            ]
        ),
        "mass_sz": np.concatenate(
            [np.stack([vh[vi], np.maximum(Lv, 1e-9), vb[vi]], axis=1), sk_box]
        ),
        "lim": top.lim,
        "anat_a": np.zeros((m + 2, 3)),
        "anat_l": np.zeros((m + 2, 3, 2)),
    }
    for v in arrays.values():
        if v.flags.writeable:
            v.setflags(write=False)
    return _Body(
        m=m,
        edges=edges.tolist(),
        slot=slot,
        names=top.names,
        kind=top.kind,
        region=top.region,
        part=top.part,
        arrays=arrays,
    )


@numba.njit(cache=True)
def _interp1(x, xp, fp):  # pragma: no cover - compiled
    """``np.interp`` at one point (NumPy's formula: the last knot ``xp[j] <= x``, the knot's
    value where ``x`` equals it, the slope form otherwise, its NaN fallback)."""
    n = xp.shape[0]
    if x > xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    lo, hi = 0, n
    while lo < hi:  # upper bound
        mid = lo + ((hi - lo) >> 1)
        if x >= xp[mid]:
            lo = mid + 1
        else:
            hi = mid
    j = lo - 1
    if j == n - 1 or xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    r = slope * (x - xp[j]) + fp[j]
    if np.isnan(r):
        r = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(r) and fp[j] == fp[j + 1]:
            r = fp[j]
    return r


@numba.njit(cache=True)
def _slices_kernel(xy, s, h, b, off, edges, m):  # pragma: no cover - compiled
    """The vertebrae's share of the body slices, the NumPy steps of the assembly compiled
    with the same arithmetic: points at the vertebra boundaries (``sp.point_at``), slice
    volumes (``ms.slice_volumes``) and centres (below the spine along its normal), each
    slice owned by the vertebra its midpoint lies in (volume-weighted centres; a vertebra
    without a slice takes the interpolated centre at its midpoint), heights and widths at
    the vertebra midpoints."""
    n = s.shape[0]
    ne = edges.shape[0]
    P = np.empty((ne, 2))
    for i in range(ne):
        a = min(max(edges[i], 0.0), s[n - 1])
        P[i, 0] = _interp1(a, s, xy[:, 0])
        P[i, 1] = _interp1(a, s, xy[:, 1])
    ns = n - 1
    smid = np.empty(ns)
    cen = np.empty((ns, 2))
    vol = np.empty(ns)
    vmass = np.zeros(m)
    w0 = np.zeros(m)
    w1 = np.zeros(m)
    for i in range(ns):
        ds = s[i + 1] - s[i]
        hm = 0.5 * (h[i + 1] + h[i])
        bm = 0.5 * (b[i + 1] + b[i])
        vol[i] = np.pi / 4.0 * hm * bm * ds
        smid[i] = 0.5 * (s[i + 1] + s[i])
        t0, t1 = xy[i + 1, 0] - xy[i, 0], xy[i + 1, 1] - xy[i, 1]
        nt = max(np.sqrt(t0 * t0 + t1 * t1), 1e-12)
        t0, t1 = t0 / nt, t1 / nt
        n0, n1 = t1, -t0
        if n1 < 0:
            n0, n1 = -n0, -n1
        o = off[i + 1] + off[i]
        cen[i, 0] = 0.5 * (xy[i + 1, 0] + xy[i, 0]) - n0 * 0.5 * o
        cen[i, 1] = 0.5 * (xy[i + 1, 1] + xy[i, 1]) - n1 * 0.5 * o
        lo, hi = 0, ne  # searchsorted(edges, smid, side="right") - 1, clipped
        while lo < hi:
            mid = lo + ((hi - lo) >> 1)
            if smid[i] >= edges[mid]:
                lo = mid + 1
            else:
                hi = mid
        k = min(max(lo - 1, 0), m - 1)
        vmass[k] += vol[i]
        w0[k] += vol[i] * cen[i, 0]
        w1[k] += vol[i] * cen[i, 1]
    vcen = np.empty((m, 2))
    vh = np.empty(m)
    vb = np.empty(m)
    for k in range(m):
        d = max(vmass[k], 1e-30)
        vcen[k, 0] = w0[k] / d
        vcen[k, 1] = w1[k] / d
        emid = 0.5 * (edges[k + 1] + edges[k])
        if vmass[k] <= 0:
            vcen[k, 0] = _interp1(emid, smid, cen[:, 0])
            vcen[k, 1] = _interp1(emid, smid, cen[:, 1])
        vh[k] = _interp1(emid, s, h)
        vb[k] = _interp1(emid, s, b)
    return P, vmass, vcen, vh, vb


_BODY_CACHE: dict[tuple, _Body] = {}
_SEG_NAMES = ("girdle", "upper", "lower", "distal")
_MIRROR3 = np.array([1.0, 1.0, -1.0])
_MIRROR_ANG = np.array([1.0, -1.0, -1.0])
_KEYS = ("parent", "side", "digit", "W", "pos", "blen", "box", "vol", "mass_c", "mass_sz")
_KEYS2 = ("lim", "anat_a", "anat_l")


def assemble(spine: SpineState, limbs: LimbsState, skull: SkullState) -> dict[str, Any]:
    """Joint arrays in creature px (world rotations, positions, masses, contacts).

    Vertebrae and skull are built as whole arrays (memoised, :func:`_body`); limbs per pair
    (right side, then the exact mirror image for the left)."""
    body = _body(spine, limbs.points, skull)
    m, edges, slot = body.m, body.edges, body.slot
    blocks: dict[str, list] = {k: [v] for k, v in body.arrays.items()}
    names, kinds, regions, parts = (
        list(body.names),
        list(body.kind),
        list(body.region),
        list(body.part),
    )
    n_now = m + 2
    pairs: list[tuple[int, int]] = []
    contacts, contact_joint = [], []
    nedge = len(edges)
    for (gname, k, spec, at), (gpt, apt), pose, L3 in zip(
        limbs.places, limbs.attach, limbs.poses, limbs.lengths, strict=True
    ):
        vidx = min(max(bisect.bisect_right(edges, at) - 1, 0), m - 1) if nedge else 0
        tag = f"{gname}{k + 1}"
        gvec = apt - gpt
        gl = float(np.linalg.norm(gvec))
        radius = ms.LIMB_RADIUS[spec.kind] * L3
        rb = ms.BONE_FRACTION * radius
        vols = ms.limb_volume(L3, spec.kind)
        dg = limb_digits(
            pose, L3, spec.kind, gname, spine, limbs.ground if pose.contact is not None else None
        )
        nd = len(dg.name)
        q = 4 + nd
        # right side (4 joints: girdle, upper, lower, distal; then the digits)
        W = np.concatenate(
            [
                _frames_from_dirs(gvec[None]) if gl > 1e-9 else _EYE3,
                pose.rotations @ _RZ_PI,
                dg.W,
            ]
        )
        pos = np.concatenate([gpt[None], pose.points[:3], dg.pos])
        blen = np.concatenate([[gl], L3, dg.length])
        # boxes (bone) and soft-tissue sizes: girdle, the three limb bones, the digits
        box = np.empty((q, 3))
        box[0] = (0.3 * gl, gl, 0.06 * gl)
        box[1:4, 0] = 2 * rb
        box[1:4, 1] = L3
        box[1:4, 2] = box[1:4, 0]
        box[4:, 0] = 2 * dg.radius
        box[4:, 1] = np.maximum(dg.length, 1e-9)
        box[4:, 2] = box[4:, 0]
        vv = np.concatenate([[0.0], vols, np.zeros(nd)])
        if nd:  # the digits carry their share of the hand / foot (mass unchanged in total)
            vv[4:] = DIGIT_MASS_SHARE * vols[2] * dg.length / max(dg.length.sum(), 1e-30)
            vv[3] *= 1.0 - DIGIT_MASS_SHARE
        mc = np.concatenate(
            [
                [0.5 * (gpt + apt)],
                0.5 * (pose.points[:3] + pose.points[1:]),
                dg.pos + dg.W[:, :, 1] * (0.5 * dg.length)[:, None],
            ]
        )
        msz = np.empty((q, 3))
        msz[0] = (0.3 * gl, max(gl, 1e-9), 0.06 * gl)
        msz[1:4, 0] = 2 * radius
        msz[1:4, 1] = np.maximum(L3, 1e-9)
        msz[1:4, 2] = msz[1:4, 0]
        msz[4:] = box[4:]
        lim, aa0, al0 = _limb_consts(nd)
        aa = aa0.copy()
        aa[1:4] = pose.angles
        al = al0.copy()
        al[1:4] = pose.limits
        alm = al.copy()
        alm[:4, 1:] = -al[:4, 1:, ::-1]
        aam = aa.copy()
        aam[:4] *= _MIRROR_ANG
        dpar = np.asarray(dg.parent, np.int64)
        dig = np.concatenate([_ZERO4, np.asarray(dg.digit, np.int64)])
        lparts = list(an.limb_parts(spec.kind, gname)) + list(dg.part)
        lkinds = ["girdle"] + [spec.kind] * (q - 1)
        pairs.append((n_now, q))  # right block, then its mirror image on the left
        cl = np.asarray(dg.contact_local, np.int64)
        for sd, sgn in (("r", 1), ("l", -1)):
            base = n_now
            names += [f"{tag}_{sn}_{sd}" for sn in _SEG_NAMES]
            names += [f"{tag}_{nm}_{sd}" for nm in dg.name]
            kinds += lkinds
            regions += [gname] * q
            parts += lparts
            par = np.empty(q, np.int64)
            par[:4] = (slot[vidx], base, base + 1, base + 2)
            par[4:] = np.where(dpar < 0, base + 3, base + 4 + dpar)
            blocks["parent"].append(par)
            blocks["side"].append(np.full(q, sgn, np.int64))
            blocks["digit"].append(dig)
            blocks["blen"].append(blen)
            blocks["box"].append(box)
            blocks["vol"].append(vv)
            blocks["mass_sz"].append(msz)
            blocks["lim"].append(lim)
            if sgn > 0:
                blocks["W"].append(W)
                blocks["pos"].append(pos)
                blocks["mass_c"].append(mc)
                blocks["anat_a"].append(aa)
                blocks["anat_l"].append(al)
            else:
                blocks["W"].append(_M @ W @ _M)
                blocks["pos"].append(pos * _MIRROR3)
                blocks["mass_c"].append(mc * _MIRROR3)
                blocks["anat_a"].append(aam)
                blocks["anat_l"].append(alm)
            if len(cl):
                contacts.append(dg.contacts * (_MIRROR3 if sgn < 0 else _ONE3))
                contact_joint.append(np.where(cl < 0, base + 3, base + 4 + cl))
            n_now += q
    n = len(names)
    mirror = np.arange(n, dtype=np.int64)  # right ↔ left limb blocks, spine itself
    for start, k in pairs:
        mirror[start : start + k] = np.arange(start + k, start + 2 * k)
        mirror[start + k : start + 2 * k] = np.arange(start, start + k)
    cat = {k: np.concatenate(blocks[k]) for k in _KEYS + _KEYS2}
    con = np.concatenate(contacts) if contacts else np.zeros((0, 3))
    return dict(
        names=names,
        parent=cat["parent"],
        kind=kinds,
        region=regions,
        part=parts,
        digit=cat["digit"],
        side=cat["side"],
        W=cat["W"],
        pos=cat["pos"],
        blen=cat["blen"],
        box=cat["box"],
        vol=cat["vol"],
        mass_c=cat["mass_c"],
        mass_sz=cat["mass_sz"],
        lim=cat["lim"],
        anat_a=cat["anat_a"],
        anat_l=cat["anat_l"],
        mirror=mirror,
        n=n,
        contacts=con,
        contact_joint=(np.concatenate(contact_joint) if contact_joint else np.zeros(0, np.int64)),
        patches=con[:, [0, 2]],
        density=ms.density(spine.cls),
        ground=limbs.ground,
    )


_EYE3 = np.eye(3)[None]
_ZERO4 = np.zeros(4, np.int64)
_ONE3 = np.ones(3)


@lru_cache(maxsize=64)
def _limb_consts(nd: int) -> tuple[NDArray, NDArray, NDArray]:
    """Limits, zero anatomical angles and limits of a limb block with ``nd`` digit joints."""
    lim = np.stack([_RANGES["girdle"]] * 4 + [_RANGES["digit"]] * nd)
    return lim, np.zeros((4 + nd, 3)), np.zeros((4 + nd, 3, 2))


def balance_px(asm: dict, opts: Options) -> bal.BalanceReport:
    vol = asm["vol"]
    com = (vol[:, None] * asm["mass_c"]).sum(axis=0) / max(vol.sum(), 1e-30)
    p = np.concatenate([asm["pos"], asm["pos"] + asm["W"][:, :, 1] * asm["blen"][:, None]])
    return bal.evaluate(
        com,
        float(vol.sum()),
        asm["patches"],
        float(np.ptp(p[:, 0])),
        opts.min_margin_fraction,
        float(com[1] - asm["ground"]),
    )


def limb_digits(
    pose: lb.LimbPose,
    L3: NDArray,
    kind: str,
    girdle: str,
    spine: SpineState,
    ground: float | None,
    frames: bool = True,
) -> feet.Digits:
    """Digit joints (right side, creature px) of one limb; a standing leg's digits lie on
    ``ground`` and carry its contact points (:mod:`biomorph.creature.feet`); ``frames=False``
    when only the contacts are needed (``W`` may then be empty). Memoised on the objects
    (the balance repair's cheap re-check and the final assembly ask for the same legs)."""
    key = (id(pose), id(L3), id(spine), kind, girdle, ground)
    hit = _DIGITS.get(key)
    if (
        hit is not None
        and hit[0] is pose
        and hit[1] is L3
        and hit[2] is spine
        and (hit[3] or not frames)
    ):
        return hit[4]
    dg = _free_digits(pose, L3, kind, girdle, spine) if ground is None and frames else None
    if dg is None:
        dg = _limb_digits(pose, L3, kind, girdle, spine, ground, frames)
    if len(_DIGITS) > 64:
        _DIGITS.clear()
    _DIGITS[key] = (pose, L3, spine, frames, dg)
    return dg


_DIGITS: dict[tuple, tuple] = {}
_FREE: dict[tuple, tuple] = {}


def _free_digits(pose, L3, kind, girdle, spine) -> feet.Digits:
    """A free limb's digits (no ground) memoised on the hand's orientation and size: the
    balance repair of bipeds moves wings rigidly with their attachment, so their digits are
    those of the original pose translated (the same arrays where the hand has not moved)."""
    tip = pose.points[3]
    key = (
        np.ascontiguousarray(pose.rotations[2]).tobytes(),
        np.asarray(L3, float).tobytes(),
        kind,
        girdle,
        spine.cls,
        spine.stance,
        spine.skull,
        spine.hoof_digits,
        bool(pose.foot_flat),
    )
    hit = _FREE.get(key)
    if hit is None:
        dg = _limb_digits(pose, L3, kind, girdle, spine, None, True)
        if len(_FREE) > 64:
            _FREE.clear()
        _FREE[key] = (tip.copy(), dg)
        return dg
    tip0, dg = hit
    d = tip - tip0
    if not d.any():
        return dg
    return replace(dg, pos=dg.pos + d)


def _limb_digits(pose, L3, kind, girdle, spine, ground, frames) -> feet.Digits:
    role = "hind" if girdle == "hip" else "fore"
    plan = feet.digit_plan(
        kind, role, spine.cls, foot_posture(spine, pose), spine.skull, spine.hoof_digits
    )
    if L3[2] <= 1e-6 * max(float(np.sum(L3)), 1e-30):
        plan = ()  # no hand / foot bone to carry digits
    rb = ms.BONE_FRACTION * ms.LIMB_RADIUS[kind] * np.asarray(L3, float)
    width = max(1.5 * rb[2], 0.02 * float(np.sum(L3)))
    heel = pose.points[2] if pose.foot_flat and ground is not None else None
    return feet.build(
        plan,
        pose.rotations[2] @ _RZ_PI,
        pose.points[3],
        float(L3[2]),
        float(rb[2]),
        width,
        ground,
        heel,
        frames,
    )


def foot_posture(spine: SpineState, pose: lb.LimbPose) -> str:
    """The foot posture a leg actually stands in (a plantigrade foot that could not lie flat
    stands on its toes)."""
    if pose.foot_flat:
        return "plantigrade"
    return "unguligrade" if spine.stance == "unguligrade" else "digitigrade"


@numba.njit(cache=True)
def _preorder(par: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Depth-first pre-order of a forest given by parent indices (-1 = root): roots and
    children in index order."""
    n = par.shape[0]
    nkids = np.zeros(n + 1, np.int64)
    for j in range(n):
        if par[j] >= 0:
            nkids[par[j] + 1] += 1
    start = np.cumsum(nkids)  # children of j at kids[start[j]:start[j + 1]]
    kids = np.empty(max(start[n], 1), np.int64)
    fill = start[:n].copy()
    for j in range(n):
        if par[j] >= 0:
            kids[fill[par[j]]] = j
            fill[par[j]] += 1
    stack = np.empty(n, np.int64)
    top = 0
    for j in range(n - 1, -1, -1):
        if par[j] < 0:
            stack[top] = j
            top += 1
    order = np.empty(n, np.int64)
    k = 0
    while top > 0:
        top -= 1
        j = stack[top]
        order[k] = j
        k += 1
        for c in range(start[j + 1] - 1, start[j] - 1, -1):
            stack[top] = kids[c]
            top += 1
    return order


def depth_first(asm: dict) -> dict:
    """Reorder joints depth-first (children after their parent, subtrees contiguous) — the
    order BVH files and most DCC tools use — remapping parent, mirror and contact indices."""
    par = asm["parent"]
    n = asm["n"]
    perm = _preorder(np.asarray(par, np.int64))
    inv = np.empty(n, np.int64)
    inv[perm] = np.arange(n)
    out = dict(asm)
    for k in (
        "W",
        "pos",
        "blen",
        "box",
        "vol",
        "mass_c",
        "mass_sz",
        "lim",
        "anat_a",
        "anat_l",
        "side",
        "digit",
    ):
        out[k] = asm[k][perm]
    pl = perm.tolist()  # plain ints: list indexing with NumPy integers is slow
    for k in ("names", "kind", "region", "part"):
        src = asm[k]
        out[k] = [src[i] for i in pl]
    p = par[perm]
    out["parent"] = np.where(p >= 0, inv[np.maximum(p, 0)], -1)
    out["mirror"] = inv[asm["mirror"][perm]]
    out["contact_joint"] = (
        inv[asm["contact_joint"]] if len(asm["contact_joint"]) else asm["contact_joint"]
    )
    return out


def below_ground(asm: dict) -> bool:
    """True if a joint or bone end lies below the ground (beyond 0.2 % of the extent)."""
    ends = asm["pos"] + asm["W"][:, :, 1] * asm["blen"][:, None]
    low = min(asm["pos"][:, 1].min(), ends[:, 1].min())
    ext = float(np.ptp(np.concatenate([asm["pos"], ends])[:, 1]))
    return bool(low < asm["ground"] - 0.002 * ext)


def to_creature(
    asm: dict,
    spine: SpineState,
    girdles,
    limbs: LimbsState,
    skull: SkullState,
    report: bal.BalanceReport,
    repairs: int,
    opts: Options,
    attempt_info: dict | None = None,
) -> Creature:
    """Joint arrays (creature px) → a :class:`Creature` in metres, sized from the weight,
    with the ground at ``y = 0`` and the first joint at ``x = 0``."""
    asm = depth_first(asm)
    below = below_ground(asm)
    # size from weight: metres per px
    vol_px = float(asm["vol"].sum())
    scale = ms.size_scale(spine.weight, vol_px, spine.cls)
    shift = np.array([0.0, asm["ground"], 0.0])
    pos = (asm["pos"] - shift) * scale
    W = asm["W"]
    par = asm["parent"]
    x0 = pos[0, 0]
    pos[:, 0] -= x0
    shift_m = np.array([x0, 0.0, 0.0])
    # local rest transforms from world frames
    pw = np.where(par[:, None, None] >= 0, W[np.maximum(par, 0)], np.eye(3)[None])
    pp = np.where(par[:, None] >= 0, pos[np.maximum(par, 0)], 0.0)
    local_r = np.einsum("nji,njk->nik", pw, W)
    offset = np.einsum("nji,nj->ni", pw, pos - pp)
    quat = _matrix_to_quat(local_r)
    # stored limits: anatomical range minus the rest angle, in the joint's local axes
    lim = asm["lim"].copy()
    limb = np.array([k in ("leg", "arm", "wing", "fin") for k in asm["kind"]], bool)
    rel = asm["anat_l"] - asm["anat_a"][:, :, None]  # (n, 3[z,x,y], 2)
    # limb frame -> joint frame flips x and y (rotation by pi about z)
    lz, lx, ly = rel[:, 0], -rel[:, 1, ::-1], -rel[:, 2, ::-1]
    lim[limb] = np.stack([lx, ly, lz], axis=1)[limb]
    end_site = np.full((asm["n"], 3), np.nan)
    has_child = np.zeros(asm["n"], bool)
    has_child[par[par >= 0]] = True
    leaf = np.flatnonzero(~has_child)
    end_site[leaf] = np.array([[0.0, 1.0, 0.0]]) * (asm["blen"][leaf, None] * scale)
    skel = JointSkeleton(asm["names"], par, offset, quat, lim, end_site=end_site)
    dens = asm["density"]
    mass = asm["vol"] * dens * scale**3
    mass_c = (asm["mass_c"] - shift) * scale - shift_m
    contacts = (asm["contacts"] - shift) * scale - shift_m
    rep = report
    # the balance report in metres is the px report scaled (mass ∝ volume, lengths ∝ s)
    com = (np.asarray(rep.com) - shift) * scale - shift_m
    total = float(mass.sum())
    final = replace(
        rep,
        margin=rep.margin * scale,
        sagittal_margin=rep.sagittal_margin * scale,
        tipping_torque=total * bal.G * rep.margin * scale,
        com=tuple(float(v) for v in com),
        mass=total,
        support=tuple((float(a * scale - x0), float(b * scale)) for a, b in rep.support),
    )
    info = attempt_info or {}
    final = replace(final, repairs=repairs, resamples=int(info.get("resamples", 0)))
    if not rep.applicable:
        final = replace(final, reason="no legs with ground contact: swims or rests on its body")
    pts_m = (limbs.points - np.array([0.0, asm["ground"]])) * scale - np.array([x0, 0.0])
    params = dict(
        seed=opts.seed,
        options=_options_dict(opts),
        **{"class": spine.cls},
        legs=spine.legs,
        wings="wing" in asm["kind"],
        weight_kg=spine.weight,
        stance=spine.stance,
        hoof_digits=spine.hoof_digits if spine.stance == "unguligrade" else 0,
        posture=spine.posture,
        skull=skull.shape,
        vertebrae=spine.counts.tolist(),
        nearest_species=spine.neighbours,
        metres_per_px=scale,
        wings_value=spine.wings_value,
        legs_value=spine.legs_value,
        features=spine.features.tolist(),
        girdles=[{"name": g.name, "pairs": [p.kind for p in g.pairs]} for g in girdles],
        descent_residual_px=[float(p.residual) for p in limbs.poses if p.kind == "leg"],
        below_ground=below,
        anatomy_rules=rules_hold(
            asm["names"],
            asm["kind"],
            asm["part"],
            asm["side"],
            W[:, :, 1],
            pos,
            spine.cls,
            spine.posture,
            spine.legs,
            total,
        ),
    )
    return Creature(
        skeleton=skel,
        kind=tuple(asm["kind"]),
        region=tuple(asm["region"]),
        side=asm["side"].astype(np.int64),
        mirror=asm["mirror"].astype(np.int64),
        bone_length=asm["blen"] * scale,
        box_size=asm["box"] * scale,
        mass=mass,
        mass_center=mass_c,
        mass_size=asm["mass_sz"] * scale,
        anatomical_angles=asm["anat_a"],
        anatomical_limits=asm["anat_l"],
        contacts=contacts.reshape(-1, 3),
        contact_joint=asm["contact_joint"],
        spine_points=pts_m,
        params=params,
        balance=final,
        part=tuple(asm["part"]),
        digit=asm["digit"].astype(np.int64),
    )


def _matrix_to_quat(m: NDArray) -> NDArray[np.float64]:
    """:func:`biomorph.core.transforms.matrix_to_quat` (w ≥ 0) for the creature's rest
    rotations: compiled with SciPy's algorithm (the largest of the diagonal and the trace
    picks the formula, then normalised); matrices not orthonormal to 1e-12 (SciPy would
    orthogonalise them first) go to SciPy."""
    m = np.ascontiguousarray(m, dtype=np.float64)
    if not _orthonormal(m):
        return tf.matrix_to_quat(m)
    return _quat_kernel(m)


@numba.njit(cache=True)
def _orthonormal(m: np.ndarray) -> bool:  # pragma: no cover - compiled
    for i in range(m.shape[0]):
        for r in range(3):
            for c in range(3):
                g = m[i, r, 0] * m[i, c, 0] + m[i, r, 1] * m[i, c, 1] + m[i, r, 2] * m[i, c, 2]
                if abs(g - (1.0 if r == c else 0.0)) > 1e-12:
                    return False
    return True


@numba.njit(cache=True)
def _quat_kernel(m: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    n = m.shape[0]
    out = np.empty((n, 4))
    q = np.empty(4)
    for i in range(n):
        a = m[i]
        tr = a[0, 0] + a[1, 1] + a[2, 2]
        c, best = 0, a[0, 0]
        for k, v in ((1, a[1, 1]), (2, a[2, 2]), (3, tr)):
            if v > best:
                c, best = k, v
        if c != 3:
            j = (c + 1) % 3
            k = (j + 1) % 3
            q[c] = 1 - tr + 2 * a[c, c]
            q[j] = a[j, c] + a[c, j]
            q[k] = a[k, c] + a[c, k]
            q[3] = a[k, j] - a[j, k]
        else:
            q[0] = a[2, 1] - a[1, 2]
            q[1] = a[0, 2] - a[2, 0]
            q[2] = a[1, 0] - a[0, 1]
            q[3] = 1 + tr
        nrm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        sgn = -1.0 if q[3] / nrm < 0 else 1.0
        for k in range(4):
            out[i, k] = sgn * (q[k] / nrm) if sgn < 0 else q[k] / nrm
    return out


def _options_dict(opts: Options) -> dict[str, Any]:
    d = {
        k: getattr(opts, k)
        for k in (
            "legs",
            "wings",
            "arms",
            "centaur",
            "weight",
            "neck_length",
            "tail_length",
            "cls",
            "k",
            "temperature",
            "jitter",
            "stand_fraction",
            "require_stable",
        )
    }
    if opts.hoof_digits is not None:
        d["hoof_digits"] = opts.hoof_digits
    if opts.scores is not None:
        d["scores"] = {str(i): float(v) for i, v in sorted(opts.scores.items())}
    d["descent"] = dict(vars(opts.descent))
    return d
