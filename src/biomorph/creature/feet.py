"""Hands and feet as joints: digits of phalanges ending in a hoof, claw or nail.

The limb's distal bone is the metapodial (metacarpal / metatarsal; a bird's
tarsometatarsus, a wing's carpometacarpus). Each digit is a chain of ``phalanx`` joints
hanging off the metapodial's far end, ending in an end joint (``hoof``, ``claw`` or
``nail``; a plain ``phalanx`` where the class has none, e.g. amphibians). Digit plans per
class and foot posture (:func:`digit_plan`):

======================  ================================  ===================================
plan                    digits (anatomy's I..V)            source of the pattern
======================  ================================  ===================================
unguligrade mammal      III, IV: pastern + hoof            artiodactyls (cattle, deer:
                                                           cloven hooves; most species)
unguligrade, 1 digit    III: pastern + hoof                perissodactyls (horse)
digitigrade mammal      II..V: 2 phalanges + claw          dog, cat (I is a dew claw, left out)
plantigrade mammal      I..V: I 1 phalanx, II..V 2 + claw  bear, human (primates: nails)
bird foot               I backwards (hallux), II..IV       anisodactyl bird foot
reptile / amphibian     I..V: 2 phalanges + claw           lizard, crocodile (amphibians: no
                                                           claws, 4 fingers on the hand)
hand (arm)              I..V (reptile bipeds: I..III)      pentadactyl hand / theropod hand
bird / reptile wing     I (alula) 1, II (major) 2          bird wing
mammal wing (bat)       I claw; II..V 3 long phalanges     bat wing
======================  ================================  ===================================

Real phalangeal counts are merged where they are higher (bird digit IV has five; we keep
two + claw): the joints that bend visibly are kept. Lengths are fractions of the metapodial
(horse: MC III 23 cm, P1+P2 14 cm, hoof 7 cm → 0.6, 0.3; dog: MC 6 cm, phalanges 2.5/1.5 cm,
claw 1.2 cm → 0.4, 0.25, 0.2; chicken: TMT 8 cm, digit III ≈ 6 cm → 0.75).

Standing feet: digits lie forward on the ground, splayed in the ground plane; an
unguligrade pastern comes down from the metapodial's end at :data:`PASTERN_DEG` to the
ground (the hoof–pastern axis of a horse is 50–55° to the ground; the leg is grounded
``clearance`` above the ground for it) and the hoof lies on the ground. Every digit joint
and end-bone tip on the ground is a contact point: the support polygon is their hull.
Hands and wing digits continue the distal bone, spread in the palm plane.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np
from numpy.typing import NDArray

#: Inclination of an unguligrade pastern to the ground (degrees).
PASTERN_DEG = 55.0


@dataclass(frozen=True)
class Digit:
    """One digit: number (1 = I, innermost), phalanx length fractions of the metapodial
    (the last is the end joint), the end part, its splay (deg, + = lateral) and whether it
    points backwards (a bird's hallux)."""

    number: int
    fractions: tuple[float, ...]
    end: str
    splay_deg: float
    backward: bool = False


def _spread(numbers, fracs, end, spread_deg, short=()) -> tuple[Digit, ...]:
    n = len(numbers)
    ang = np.linspace(-spread_deg, spread_deg, n) if n > 1 else np.zeros(1)
    return tuple(
        Digit(k, tuple(f * (0.7 if k in short else 1.0) for f in fracs), end, float(a))
        for k, a in zip(numbers, ang, strict=True)
    )


@lru_cache(maxsize=512)
def digit_plan(
    kind: str, role: str, cls: str, stance: str, skull: str = "", hoof_digits: int = 2
) -> tuple[Digit, ...]:
    """The digits of a limb (see the module table); ``()`` for fins. ``hoof_digits`` (1 or
    2) picks the single hoof of a horse or the cloven hoof of cattle and deer."""
    if kind == "fin":
        return ()
    if kind == "wing":
        if cls == "mammal":
            return (Digit(1, (0.15, 0.08), "claw", -35.0),) + tuple(
                Digit(k, (0.9, 0.7, 0.5), "phalanx", a)
                for k, a in zip((2, 3, 4, 5), (-8.0, 5.0, 22.0, 40.0), strict=True)
            )
        return (Digit(1, (0.25,), "phalanx", -20.0), Digit(2, (0.45, 0.25), "phalanx", 0.0))
    if kind == "arm":
        end = "nail" if skull == "primate" else "claw"
        if cls == "reptile":
            return _spread((1, 2, 3), (0.35, 0.25, 0.2), end, 15.0, short=(1,))
        if cls == "amphibian":
            return _spread((2, 3, 4, 5), (0.3, 0.25), "phalanx", 25.0)
        return _spread((1, 2, 3, 4, 5), (0.4, 0.25, 0.18), end, 18.0, short=(1, 5))
    # standing legs
    if cls == "bird":
        claws = (0.12,)
        return (
            Digit(1, (0.2,) + claws, "claw", 0.0, backward=True),
            Digit(2, (0.25, 0.2) + claws, "claw", -25.0),
            Digit(3, (0.3, 0.25) + claws, "claw", 0.0),
            Digit(4, (0.25, 0.2) + claws, "claw", 25.0),
        )
    if cls in ("reptile", "amphibian"):
        end = "phalanx" if cls == "amphibian" else "claw"
        numbers = (2, 3, 4, 5) if (cls == "amphibian" and role == "fore") else (1, 2, 3, 4, 5)
        return _spread(numbers, (0.3, 0.25, 0.15), end, 30.0, short=(1, 5))
    if stance == "unguligrade":
        if hoof_digits == 1:  # horse: digit III alone (long + short pastern, hoof)
            return _spread((3,), (0.6, 0.3), "hoof", 0.0)
        return _spread((3, 4), (0.6, 0.3), "hoof", 4.0)
    if stance == "digitigrade":
        return _spread((2, 3, 4, 5), (0.4, 0.25, 0.2), "claw", 10.0, short=(2, 5))
    end = "nail" if skull == "primate" else "claw"
    thumb = Digit(1, (0.35, 0.15), end, -14.0)
    return (thumb,) + _spread((2, 3, 4, 5), (0.4, 0.2, 0.15), end, 12.0, short=(5,))


def clearance(plan: tuple[Digit, ...], metapodial: float) -> float:
    """Height of the metapodial's far end above the ground so that inclined phalanges
    (unguligrade pasterns) reach the ground (px)."""
    drop = 0.0
    for d in plan:
        if d.end == "hoof":
            drop = max(drop, sum(d.fractions[:-1]) * metapodial * np.sin(np.radians(PASTERN_DEG)))
    return float(drop)


@dataclass(frozen=True)
class Digits:
    """Digit joints of one (right) limb in creature px: ``parent`` is the local index of
    the parent digit joint, -1 for the metapodial; ``contacts`` are ground contact points
    with ``contact_local`` their joint (local index; -1 = the metapodial joint itself)."""

    name: tuple[str, ...]
    parent: NDArray[np.int64]
    W: NDArray[np.float64]  # (m, 3, 3) world rotations, bone along +Y, Z lateral
    pos: NDArray[np.float64]  # (m, 3)
    length: NDArray[np.float64]  # (m,)
    radius: NDArray[np.float64]  # (m,) bone radius for the box
    part: tuple[str, ...]
    digit: NDArray[np.int64]
    contacts: NDArray[np.float64]  # (k, 3)
    contact_local: NDArray[np.int64]


def _cross(a: NDArray, b: NDArray) -> NDArray:
    """Row-wise cross product (the formula of ``np.cross`` without its per-call overhead)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _frames(u: NDArray, lateral: NDArray) -> NDArray:
    """World rotations ``(m, 3, 3)``: +Y along each ``u``, Z towards ``lateral`` (⟂ part)."""
    y = u / np.sqrt((u * u).sum(axis=1))[:, None]
    z = lateral - (lateral * y).sum(axis=1)[:, None] * y
    nz = np.sqrt((z * z).sum(axis=1))[:, None]
    z = np.where(nz > 1e-9, z / np.where(nz > 1e-9, nz, 1.0), [[0.0, 0.0, 1.0]])
    return np.stack([_cross(y, z), y, z], axis=2)


@dataclass(frozen=True, eq=False)
class _Layout:
    """What a digit plan fixes (joint bookkeeping), computed once per plan."""

    n: int
    m: int
    counts: NDArray[np.int64]
    dig: NDArray[np.int64]  # digit of each joint
    first: NDArray[np.int64]
    j_in: NDArray[np.int64]  # index within the digit
    last: NDArray[np.bool_]
    frac: NDArray[np.float64]  # length fractions of the metapodial per joint
    side: NDArray[np.float64]
    splay: NDArray[np.float64]
    cos_splay: NDArray[np.float64]
    sin_splay: NDArray[np.float64]
    back: NDArray[np.bool_]
    parent: NDArray[np.int64]
    rad_end: NDArray[np.float64]  # bone radius factors per joint (end bone, taper)
    rad_taper: NDArray[np.float64]
    names: tuple[str, ...]
    parts: tuple[str, ...]
    numbers: NDArray[np.int64]
    slot: NDArray[np.int64]  # joint k -> flat index in the (n, depth) digit grid


@lru_cache(maxsize=256)
def _layout(plan: tuple[Digit, ...]) -> _Layout:
    n = len(plan)
    counts = np.array([len(d.fractions) for d in plan], np.int64)
    m = int(counts.sum())
    dig = np.repeat(np.arange(n), counts)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if n else counts
    j_in = np.arange(m) - np.repeat(first, counts)
    last = j_in == np.repeat(counts - 1, counts)
    frac = np.concatenate([np.asarray(d.fractions, float) for d in plan]) if n else np.zeros(0)
    depth = int(counts.max()) + 1 if n else 1
    return _Layout(
        n=n,
        m=m,
        counts=counts,
        dig=dig,
        first=first,
        j_in=j_in,
        last=last,
        frac=frac,
        side=(np.arange(n) - (n - 1) / 2) / max(n - 1, 1),
        splay=np.radians([d.splay_deg for d in plan]),
        cos_splay=np.cos(np.radians([d.splay_deg for d in plan])),
        sin_splay=np.sin(np.radians([d.splay_deg for d in plan])),
        back=np.array([d.backward for d in plan], bool),
        parent=np.where(j_in == 0, -1, np.arange(m) - 1).astype(np.int64),
        rad_end=np.where(last, 0.55, 0.7),
        rad_taper=1.0 - 0.1 * j_in,
        names=tuple(f"digit{plan[dig[k]].number}_{j_in[k] + 1}" for k in range(m)),
        parts=tuple(plan[dig[k]].end if last[k] else "phalanx" for k in range(m)),
        numbers=np.array([plan[dig[k]].number for k in range(m)], np.int64),
        slot=dig * depth + j_in,
    )


@numba.njit(cache=True)
def _frames_kernel(u, lateral):  # pragma: no cover - compiled
    """:func:`_frames` compiled (same operations, same order)."""
    m = u.shape[0]
    out = np.empty((m, 3, 3))
    for i in range(m):
        nu = np.sqrt((u[i, 0] * u[i, 0] + u[i, 1] * u[i, 1]) + u[i, 2] * u[i, 2])
        y0, y1, y2 = u[i, 0] / nu, u[i, 1] / nu, u[i, 2] / nu
        d = (lateral[i, 0] * y0 + lateral[i, 1] * y1) + lateral[i, 2] * y2
        z0, z1, z2 = lateral[i, 0] - d * y0, lateral[i, 1] - d * y1, lateral[i, 2] - d * y2
        nz = np.sqrt((z0 * z0 + z1 * z1) + z2 * z2)
        if nz > 1e-9:
            z0, z1, z2 = z0 / nz, z1 / nz, z2 / nz
        else:
            z0, z1, z2 = 0.0, 0.0, 1.0
        out[i, 0, 0] = y1 * z2 - y2 * z1
        out[i, 1, 0] = y2 * z0 - y0 * z2
        out[i, 2, 0] = y0 * z1 - y1 * z0
        out[i, 0, 1], out[i, 1, 1], out[i, 2, 1] = y0, y1, y2
        out[i, 0, 2], out[i, 1, 2], out[i, 2, 2] = z0, z1, z2
    return out


@numba.njit(cache=True)
def _stand_kernel(  # noqa: PLR0913 - a compiled kernel takes its arrays one by one
    start, seg, counts, first, dig, last, cos_s, sin_s, back, ground, eps, sin_max
):  # pragma: no cover - compiled
    """The standing branch of :func:`build` compiled: digit directions on the ground
    (inclined phalanges reaching down, lengthened when too short), segment lengths, joint
    positions (running sums per digit) and the end bones' tips."""
    n = start.shape[0]
    m = seg.shape[0]
    seg = seg.copy()
    fwd = np.empty((n, 3))
    down = np.empty((n, 3))
    grow = np.ones(n)
    for k in range(n):
        sgn = -1.0 if back[k] else 1.0
        fwd[k, 0], fwd[k, 1], fwd[k, 2] = cos_s[k] * sgn, 0.0 * sgn, sin_s[k] * sgn
        h = max(start[k, 1] - ground, 0.0)
        lp = 0.0
        for q in range(first[k], first[k] + counts[k] - 1):
            lp = seg[q] if q == first[k] else lp + seg[q]
        incl = (h > eps) and (counts[k] > 1)
        sin_a = min(h / max(lp, 1e-300), sin_max) if incl else 0.0
        if incl and lp * sin_max < h:
            grow[k] = h / max(lp * sin_a, 1e-300)
        cos_a = np.sqrt(1.0 - sin_a * sin_a)
        down[k, 0] = fwd[k, 0] * cos_a - sin_a * 0.0
        down[k, 1] = fwd[k, 1] * cos_a - sin_a * 1.0
        down[k, 2] = fwd[k, 2] * cos_a - sin_a * 0.0
    dirs = np.empty((m, 3))
    for q in range(m):
        k = dig[q]
        if not last[q]:
            seg[q] = seg[q] * grow[k]
            dirs[q] = down[k]
        else:
            seg[q] = seg[q] * 1.0
            dirs[q] = fwd[k]
    pos = np.empty((m, 3))
    tips = np.empty((n, 3))
    for k in range(n):
        p0, p1, p2 = start[k, 0], start[k, 1], start[k, 2]
        for q in range(first[k], first[k] + counts[k]):
            pos[q, 0], pos[q, 1], pos[q, 2] = p0, p1, p2
            d0, d1, d2 = dirs[q, 0], dirs[q, 1], dirs[q, 2]
            nd = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            p0 = p0 + dirs[q, 0] / nd * seg[q]
            p1 = p1 + dirs[q, 1] / nd * seg[q]
            p2 = p2 + dirs[q, 2] / nd * seg[q]
        tips[k, 0], tips[k, 1], tips[k, 2] = p0, p1, p2
    return dirs, seg, pos, tips


#: Sine of the steepest a phalanx may stand (80°).
_SIN_MAX = float(np.sin(np.radians(80.0)))


def _build_standing(lay: _Layout, start, metapodial, ground, eps):
    return _stand_kernel(
        start,
        lay.frac * metapodial,
        lay.counts,
        lay.first,
        lay.dig,
        lay.last,
        lay.cos_splay,
        lay.sin_splay,
        lay.back,
        float(ground),
        float(eps),
        _SIN_MAX,
    )


def build(
    plan: tuple[Digit, ...],
    W_distal: NDArray,
    tip: NDArray,
    metapodial: float,
    bone_radius: float,
    width: float,
    ground: float | None,
    heel: NDArray | None = None,
    frames: bool = True,
) -> Digits:
    """Digit joints for a limb whose metapodial ends at ``tip`` (px). ``ground`` is the
    ground height for a standing foot (digits laid on the ground) or ``None`` for a free
    hand / wing (digits continue the distal bone ``W_distal[:, 1]``, spread about its
    ``W_distal[:, 0]`` axis). ``heel`` (a plantigrade ankle on the ground) is a contact.
    ``frames=False`` leaves the joints' rotations out (``W`` empty): for the contacts only."""
    tip = np.asarray(tip, float)
    eps = 1e-6 * max(metapodial, 1e-9)
    lay = _layout_of(plan)
    n, m, dig, last = lay.n, lay.m, lay.dig, lay.last
    if ground is not None and m:  # a standing foot: one compiled call
        dirs, seg, pos, W, contacts, clocal = _standing_foot(
            tip,
            float(width),
            lay.frac,
            float(metapodial),
            lay.side,
            lay.counts,
            lay.first,
            dig,
            last,
            lay.j_in,
            lay.cos_splay,
            lay.sin_splay,
            lay.back,
            float(ground),
            float(eps),
            _SIN_MAX,
            heel is not None,
            np.zeros(3) if heel is None else np.asarray(heel, float),
            bool(frames),
        )
        return Digits(
            lay.names,
            lay.parent,
            W,
            pos,
            seg,
            bone_radius * lay.rad_end * lay.rad_taper,
            lay.parts,
            lay.numbers,
            contacts,
            clocal,
        )
    seg = lay.frac * metapodial
    start = tip[None, :] + np.outer(lay.side, [0.0, 0.0, 1.0]) * width  # (n, 3)
    splay = lay.splay
    if ground is None:
        axis, u0 = W_distal[:, 0], W_distal[:, 1]
        c, s_ = np.cos(splay)[:, None], np.sin(splay)[:, None]
        ud = u0 * c + _cross(axis, u0) * s_ + axis * (axis @ u0) * (1 - c)  # Rodrigues
        dirs = ud[dig]
        lateral = np.broadcast_to(W_distal[:, 2], (m, 3))
    if ground is None or not m:
        if ground is not None:
            dirs = np.zeros((0, 3))
        step = dirs / np.sqrt((dirs * dirs).sum(axis=1))[:, None] * seg[:, None] if m else dirs
        # joint positions: each digit's start plus its earlier steps (a running sum per
        # digit, added in the digit's order)
        depth = int(lay.counts.max()) + 1 if n else 1
        grid = np.zeros((n, depth, 3))
        grid[:, 0] = start
        grid.reshape(-1, 3)[lay.slot + 1] = step
        grid = np.cumsum(grid, axis=1)
        flat = grid.reshape(-1, 3)
        pos = flat[lay.slot]
        end_tip = flat[lay.slot + 1][last]
    else:  # standing: digits on the ground (compiled)
        dirs, seg, pos, end_tip = _build_standing(lay, start, metapodial, ground, eps)
        lateral = np.broadcast_to([0.0, 0.0, 1.0], (m, 3))
    if ground is not None:
        contacts, clocal = _contacts_kernel(
            pos,
            end_tip,
            lay.j_in,
            last,
            float(ground),
            float(eps),
            tip,
            heel is not None,
            np.zeros(3) if heel is None else np.asarray(heel, float),
        )
    elif heel is not None:
        contacts, clocal = np.asarray(heel, float).reshape(1, 3), np.array([-1], np.int64)
    else:
        contacts, clocal = np.zeros((0, 3)), np.zeros(0, np.int64)
    return Digits(
        lay.names,
        lay.parent,
        _frames_kernel(dirs, np.ascontiguousarray(lateral, dtype=float))
        if m and frames
        else np.zeros((0, 3, 3)),
        pos,
        seg.astype(float),
        bone_radius * lay.rad_end * lay.rad_taper,
        lay.parts,
        lay.numbers,
        contacts,
        clocal,
    )


_LAYOUTS: dict[int, tuple] = {}


def _layout_of(plan: tuple[Digit, ...]) -> _Layout:
    """:func:`_layout` looked up by the plan object (plans come from the memoised
    :func:`digit_plan`; hashing a plan's digits costs more than the lookup)."""
    hit = _LAYOUTS.get(id(plan))
    if hit is not None and hit[0] is plan:
        return hit[1]
    lay = _layout(tuple(plan))
    if len(_LAYOUTS) > 512:
        _LAYOUTS.clear()
    _LAYOUTS[id(plan)] = (plan, lay)
    return lay


@numba.njit(cache=True)
def _standing_foot(  # noqa: PLR0913 - a compiled kernel takes its arrays one by one
    tip,
    width,
    frac,
    metapodial,
    side,
    counts,
    first,
    dig,
    last,
    j_in,
    cos_s,
    sin_s,
    back,
    ground,
    eps,
    sin_max,
    has_heel,
    heel,
    frames,
):  # pragma: no cover - compiled
    """:func:`build` for a standing foot in one compiled call: the digits' starts spread
    across the metapodial's tip, :func:`_stand_kernel`, the frames (lateral +z) and the
    contacts (:func:`_contacts_kernel`) — the same operations as the separate steps."""
    n = side.shape[0]
    m = frac.shape[0]
    start = np.empty((n, 3))
    for k in range(n):
        start[k, 0] = tip[0] + side[k] * 0.0 * width
        start[k, 1] = tip[1] + side[k] * 0.0 * width
        start[k, 2] = tip[2] + side[k] * 1.0 * width
    seg0 = np.empty(m)
    for q in range(m):
        seg0[q] = frac[q] * metapodial
    dirs, seg, pos, end_tip = _stand_kernel(
        start, seg0, counts, first, dig, last, cos_s, sin_s, back, ground, eps, sin_max
    )
    if frames:
        lateral = np.zeros((m, 3))
        lateral[:, 2] = 1.0
        W = _frames_kernel(dirs, lateral)
    else:
        W = np.zeros((0, 3, 3))
    contacts, clocal = _contacts_kernel(pos, end_tip, j_in, last, ground, eps, tip, has_heel, heel)
    return dirs, seg, pos, W, contacts, clocal


@numba.njit(cache=True)
def _contacts_kernel(
    pos, end_tip, j_in, last, ground, eps, tip, has_heel, heel
):  # pragma: no cover - compiled
    """A standing foot's ground contacts and their joints (local index, -1 = the
    metapodial): the heel (a plantigrade ankle), the metapodial's tip when on the ground,
    then per digit joint its position when on the ground (not the digit's first joint) and,
    after the digit's end joint, the end bone's tip — all at the ground height."""
    m = pos.shape[0]
    out = np.empty((2 * m + 2, 3))
    loc = np.empty(2 * m + 2, np.int64)
    k = 0
    if has_heel:
        out[k, 0], out[k, 1], out[k, 2] = heel[0], heel[1], heel[2]
        loc[k] = -1
        k += 1
    if tip[1] - ground <= eps:
        out[k, 0], out[k, 1], out[k, 2] = tip[0], ground, tip[2]
        loc[k] = -1
        k += 1
    d = 0
    for q in range(m):
        if j_in[q] > 0 and pos[q, 1] - ground <= eps:
            out[k, 0], out[k, 1], out[k, 2] = pos[q, 0], ground, pos[q, 2]
            loc[k] = q
            k += 1
        if last[q]:
            out[k, 0], out[k, 1], out[k, 2] = end_tip[d, 0], ground, end_tip[d, 2]
            loc[k] = q
            k += 1
            d += 1
    return out[:k].copy(), loc[:k].copy()
