"""Hands and feet as joints: digits of phalanges ending in a hoof, claw or nail.

The limb's distal bone is the metapodial (metacarpal / metatarsal; a bird's
tarsometatarsus, a wing's carpometacarpus). Each digit is a chain of ``phalanx`` joints
hanging off the metapodial's far end, ending in an end joint (``hoof``, ``claw`` or
``nail``; a plain ``phalanx`` where the class has none, e.g. amphibians). Digit plans per
class and foot posture (:func:`digit_plan`):

======================  ================================  ===================================
plan                    digits (anatomy's I..V)            source of the pattern
======================  ================================  ===================================
unguligrade mammal      III, IV: pastern + hoof            cloven-hoofed ungulates (most
                                                           unguligrade species in the data)
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
    return tuple(Digit(k, tuple(f * (0.7 if k in short else 1.0) for f in fracs), end,
                       float(a)) for k, a in zip(numbers, ang, strict=True))


def digit_plan(kind: str, role: str, cls: str, stance: str, skull: str = ""
               ) -> tuple[Digit, ...]:
    """The digits of a limb (see the module table); ``()`` for fins."""
    if kind == "fin":
        return ()
    if kind == "wing":
        if cls == "mammal":
            return (Digit(1, (0.15, 0.08), "claw", -35.0),) + tuple(
                Digit(k, (0.9, 0.7, 0.5), "phalanx", a)
                for k, a in zip((2, 3, 4, 5), (-8.0, 5.0, 22.0, 40.0), strict=True))
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
        return (Digit(1, (0.2,) + claws, "claw", 0.0, backward=True),
                Digit(2, (0.25, 0.2) + claws, "claw", -25.0),
                Digit(3, (0.3, 0.25) + claws, "claw", 0.0),
                Digit(4, (0.25, 0.2) + claws, "claw", 25.0))
    if cls in ("reptile", "amphibian"):
        end = "phalanx" if cls == "amphibian" else "claw"
        numbers = (2, 3, 4, 5) if (cls == "amphibian" and role == "fore") else (1, 2, 3, 4, 5)
        return _spread(numbers, (0.3, 0.25, 0.15), end, 30.0, short=(1, 5))
    if stance == "unguligrade":
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
    W: NDArray[np.float64]          # (m, 3, 3) world rotations, bone along +Y, Z lateral
    pos: NDArray[np.float64]        # (m, 3)
    length: NDArray[np.float64]     # (m,)
    radius: NDArray[np.float64]     # (m,) bone radius for the box
    part: tuple[str, ...]
    digit: NDArray[np.int64]
    contacts: NDArray[np.float64]   # (k, 3)
    contact_local: NDArray[np.int64]


def _frame(u: NDArray, lateral: NDArray) -> NDArray:
    y = u / np.linalg.norm(u)
    z = lateral - (lateral @ y) * y
    nz = np.linalg.norm(z)
    z = z / nz if nz > 1e-9 else np.array([0.0, 0.0, 1.0])
    return np.stack([np.cross(y, z), y, z], axis=1)


def _yaw(a: float, back: bool) -> NDArray:
    a = np.radians(a)
    d = np.array([np.cos(a), 0.0, np.sin(a)])
    return -d if back else d


def build(plan: tuple[Digit, ...], W_distal: NDArray, tip: NDArray, metapodial: float,
          bone_radius: float, width: float, ground: float | None,
          heel: NDArray | None = None) -> Digits:
    """Digit joints for a limb whose metapodial ends at ``tip`` (px). ``ground`` is the
    ground height for a standing foot (digits laid on the ground) or ``None`` for a free
    hand / wing (digits continue the distal bone ``W_distal[:, 1]``, spread about its
    ``W_distal[:, 0]`` axis). ``heel`` (a plantigrade ankle on the ground) is a contact."""
    names, parent, Ws, pos, lens, rad, parts, nums = [], [], [], [], [], [], [], []
    contacts, clocal = [], []
    eps = 1e-6 * max(metapodial, 1e-9)
    if heel is not None:
        contacts.append(np.asarray(heel, float))
        clocal.append(-1)
    if ground is not None and tip[1] - ground <= eps:
        contacts.append(np.array([tip[0], ground, tip[2]]))
        clocal.append(-1)
    n = len(plan)
    for k, d in enumerate(plan):
        side = (k - (n - 1) / 2) / max(n - 1, 1)
        p = np.asarray(tip, float) + np.array([0.0, 0.0, side * width])
        seg = np.array(d.fractions) * metapodial
        if ground is None:
            axis = W_distal[:, 0]
            u0 = W_distal[:, 1]
            a = np.radians(d.splay_deg)
            # rotate the distal direction about the palm normal (Rodrigues)
            u = (u0 * np.cos(a) + np.cross(axis, u0) * np.sin(a)
                 + axis * (axis @ u0) * (1 - np.cos(a)))
            dirs = [u] * len(seg)
            lateral = W_distal[:, 2]
        else:
            h = max(float(p[1] - ground), 0.0)
            fwd = _yaw(d.splay_deg, d.backward)
            n_ph = len(seg) - 1
            lp = float(seg[:-1].sum())
            if h > eps and n_ph > 0:
                sin_a = min(h / lp, np.sin(np.radians(80.0))) if lp > 0 else 0.0
                if lp * np.sin(np.radians(80.0)) < h:   # too short to reach: lengthen
                    seg[:-1] *= h / (lp * sin_a)
                cos_a = np.sqrt(1 - sin_a ** 2)
                down = fwd * cos_a + np.array([0.0, -sin_a, 0.0])
                dirs = [down] * n_ph + [fwd]
            else:
                dirs = [fwd] * len(seg)
            lateral = np.array([0.0, 0.0, 1.0])
        prev = -1
        for j, (L, u) in enumerate(zip(seg, dirs, strict=True)):
            last = j == len(seg) - 1
            names.append(f"digit{d.number}_{j + 1}")
            parent.append(prev)
            prev = len(names) - 1
            Ws.append(_frame(np.asarray(u, float), lateral))
            pos.append(p.copy())
            lens.append(float(L))
            rad.append(bone_radius * (0.55 if last else 0.7) * (1.0 - 0.1 * j))
            parts.append(d.end if last else "phalanx")
            nums.append(d.number)
            if ground is not None and j > 0 and p[1] - ground <= eps:
                contacts.append(np.array([p[0], ground, p[2]]))
                clocal.append(prev)
            p = p + np.asarray(u, float) / np.linalg.norm(u) * L
            if ground is not None and last:
                p[1] = max(p[1], ground)
                contacts.append(np.array([p[0], ground, p[2]]))
                clocal.append(prev)
    m = len(names)
    return Digits(tuple(names), np.array(parent, np.int64),
                  np.array(Ws).reshape(m, 3, 3), np.array(pos).reshape(m, 3),
                  np.array(lens, float), np.array(rad, float), tuple(parts),
                  np.array(nums, np.int64), np.array(contacts, float).reshape(-1, 3),
                  np.array(clocal, np.int64))
