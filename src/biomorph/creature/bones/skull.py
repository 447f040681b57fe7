"""Skull and mandible models per class: mammal muzzle, bird beak, reptile snout, amphibian
and fish heads, with cranium, orbits and a separate lower jaw.

Unit models use the skull joint's box as a unit cube (x dorsal in [−0.5, 0.5], y from the
back of the cranium at 0 to the snout tip at 1, z lateral); the mandible has its own unit
cube, the jaw joint's box (x its depth, y from the jaw joint at the condyles to the
symphysis, z its width), because the jaw is its own joint. Each family is one
:class:`SkullPlan` of shares of the box, read off typical skulls (rounded, relative, never
metres):

* **mammal** (dog/wolf, mesaticephalic): facial part (muzzle) about half the skull length,
  cranium (braincase) the rear half, orbits at the fronto-facial junction facing forward-
  out, zygomatic arches the widest part (the skull's width), mandible about 0.85 of the
  skull length with a tall coronoid process and an angular process — Evans & de Lahunta,
  *Miller's Anatomy of the Dog* (4th ed., 2013, ch. 4: skull regions, cephalic index);
  ``mammal_short`` (cat) muzzle about 0.3, ``primate`` 0.15 under a globular braincase,
  ``whale`` rostrum about 0.65;
* **bird**: large rounded braincase, orbits the largest openings of the skull (about half
  its height, a thin interorbital septum between them), a pointed bill about half the skull
  length over a long thin lower bill, a thin jugal bar instead of a zygomatic arch —
  Baumel et al., *Handbook of Avian Anatomy: Nomina Anatomica Avium* (2nd ed., 1993,
  osteologia: cranium, rostrum maxillare/mandibulare);
* **reptile** (crocodylian / lizard): flat and wide, orbits on the top of the head facing
  up-out, the snout 0.55–0.65 of the skull length in crocodylians (``reptile_long``), 0.4
  in lizards (``reptile_short``), 0.5 in theropods (``dinosaur``); a long mandible reaching
  the tip with a retroarticular process behind the jaw joint — Busbey (1995), in Thomason
  (ed.) *Functional Morphology in Vertebrate Paleontology*, pp. 173–192 (skull
  flattening in crocodilians); Romer, *Osteology of the Reptiles* (1956);
* **amphibian** (frog/salamander): very wide and flat, a short rounded snout, large dorsal
  orbits — Duellman & Trueb, *Biology of Amphibians* (1986, ch. 13);
* **fish**: a deep head, a short snout, lateral orbits and the gill covers (opercula) at
  the back.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import NDArray

from biomorph.creature.bones.prim import SIDES, Parts, ellipsoid, torus, tube, unit


@dataclass(frozen=True)
class SkullPlan:
    """Shares of the skull box (x dorsal, y back to front, z lateral; half-sizes 0.5)."""

    family: str
    snout: float  # facial part (muzzle/beak/snout) share of the length
    cranium: tuple[float, float, float]  # braincase half-sizes (x, y share of cranial part, z)
    snout_root: tuple[float, float]  # snout half-sizes (x, z) where it leaves the cranium
    snout_tip: tuple[float, float]  # ... at the tip
    snout_drop: float  # the snout's axis falls this far (x) from root to tip
    orbit: tuple[float, float, float, float]  # (x, y, radius, lateral z) of the orbit rims
    orbit_axis: int  # 2: facing out (z), 0: facing up (dorsal orbits)
    zygomatic: float  # arch half-thickness (0: a thin jugal bar, birds)
    jaw_depth: float  # mandible depth (share of the jaw box height)
    coronoid: float  # coronoid process height above the jaw box (share of its height)
    retroarticular: float  # process behind the jaw joint (share of the jaw's length)


PLANS: dict[str, SkullPlan] = {
    "mammal": SkullPlan(
        "mammal",
        0.5,
        (0.46, 0.5, 0.4),
        (0.34, 0.34),
        (0.16, 0.13),
        0.14,
        (0.14, 0.5, 0.12, 0.33),
        2,
        0.04,
        0.9,
        3.0,
        0.0,
    ),
    "mammal_short": SkullPlan(
        "mammal",
        0.3,
        (0.46, 0.5, 0.4),
        (0.34, 0.32),
        (0.22, 0.2),
        0.1,
        (0.14, 0.58, 0.15, 0.3),
        2,
        0.05,
        1.0,
        3.0,
        0.0,
    ),
    "primate": SkullPlan(
        "mammal",
        0.15,
        (0.5, 0.55, 0.45),
        (0.3, 0.3),
        (0.24, 0.22),
        0.2,
        (0.02, 0.82, 0.13, 0.22),
        1,
        0.04,
        1.0,
        2.5,
        0.0,
    ),
    "whale": SkullPlan(
        "mammal",
        0.65,
        (0.45, 0.5, 0.45),
        (0.25, 0.38),
        (0.08, 0.1),
        0.05,
        (0.0, 0.33, 0.08, 0.42),
        2,
        0.03,
        0.8,
        1.0,
        0.0,
    ),
    "bird": SkullPlan(
        "bird",
        0.5,
        (0.48, 0.5, 0.47),
        (0.2, 0.2),
        (0.01, 0.01),
        0.12,
        (0.1, 0.34, 0.19, 0.3),
        2,
        0.0,
        0.7,
        0.6,
        0.05,
    ),
    "reptile_long": SkullPlan(
        "reptile",
        0.6,
        (0.45, 0.5, 0.46),
        (0.28, 0.36),
        (0.14, 0.17),
        0.05,
        (0.4, 0.3, 0.1, 0.16),
        0,
        0.05,
        1.0,
        1.2,
        0.1,
    ),
    "reptile_short": SkullPlan(
        "reptile",
        0.4,
        (0.45, 0.5, 0.45),
        (0.32, 0.34),
        (0.16, 0.14),
        0.08,
        (0.28, 0.48, 0.13, 0.28),
        2,
        0.04,
        1.0,
        1.5,
        0.08,
    ),
    "dinosaur": SkullPlan(
        "reptile",
        0.5,
        (0.45, 0.5, 0.44),
        (0.36, 0.3),
        (0.2, 0.14),
        0.06,
        (0.26, 0.4, 0.12, 0.3),
        2,
        0.05,
        1.0,
        1.5,
        0.1,
    ),
    "snake": SkullPlan(
        "reptile",
        0.35,
        (0.45, 0.5, 0.45),
        (0.3, 0.34),
        (0.18, 0.16),
        0.04,
        (0.2, 0.55, 0.12, 0.34),
        2,
        0.0,
        0.8,
        1.0,
        0.1,
    ),
    "amphibian": SkullPlan(
        "amphibian",
        0.3,
        (0.4, 0.5, 0.48),
        (0.3, 0.45),
        (0.16, 0.3),
        0.05,
        (0.3, 0.5, 0.17, 0.27),
        0,
        0.03,
        0.9,
        0.8,
        0.0,
    ),
    "fish": SkullPlan(
        "fish",
        0.3,
        (0.48, 0.5, 0.42),
        (0.34, 0.3),
        (0.18, 0.14),
        0.12,
        (0.12, 0.55, 0.13, 0.36),
        2,
        0.0,
        1.0,
        0.8,
        0.0,
    ),
}
#: skull type (:mod:`biomorph.creature.skulls`) -> plan; unknown types use their class's
TYPE_PLAN = {"mammal_long": "mammal"}
CLASS_PLAN = {
    "mammal": "mammal",
    "bird": "bird",
    "reptile": "reptile_long",
    "amphibian": "amphibian",
    "fish": "fish",
}


#: share of the skull box's height the lower jaw takes (the jaw joint's box, as the
#: generator sizes it, is about 0.18 of the skull's height)
JAW_SHARE = 0.18


def plan_for(skull_type: str, cls: str) -> str:
    """The plan name for a skull type (falling back to the class's plan)."""
    name = TYPE_PLAN.get(skull_type, skull_type)
    return name if name in PLANS else CLASS_PLAN.get(cls, "mammal")


def _cranium_end(p: SkullPlan) -> float:
    return 1.0 - p.snout


@cache
def skull(
    plan: str, lod: int, with_mandible: bool, palate: float = -0.5 + 1.45 * 0.18
) -> tuple[NDArray, NDArray, NDArray]:
    """Unit skull of ``plan`` (see the module docstring); ``with_mandible`` adds the lower
    jaw as its own closed piece where the creature has no jaw joint; ``palate``: the
    snout's floor (x, the top of the lower jaw where the jaw joint puts it)."""
    p = PLANS[plan]
    s = SIDES[lod] + 2
    s2 = max(4, s // 2)
    parts = Parts()
    ce = _cranium_end(p)
    cx, cy, cz = p.cranium
    half_y = 0.5 * ce * cy / 0.5 + 0.02
    parts.add(ellipsoid([0.5 - cx, half_y, 0.0], [cx, half_y, cz], s))  # braincase
    # snout (muzzle / beak / snout): a swept section from the cranium's front to the tip
    # over the palate (its floor stays at the jaw's top, the skull's bottom 18 %), its top
    # (the nasal line or culmen) falling to the tip's height
    k = 5 + lod
    u = np.linspace(0.0, 1.0, k)
    y = (ce - 0.08) + (1.0 - (ce - 0.08)) * u
    (xr, zr), (xt, zt) = p.snout_root, p.snout_tip
    shape = u if p.family != "bird" else u**0.7  # a beak closes to a point
    rx = xr + (xt - xr) * shape
    rz = zr + (zt - zr) * shape
    centre = np.minimum(palate + rx, 0.5 - rx)  # the floor level, the top falling with rx
    if p.family == "bird":  # the bill's tip meets the lower bill's
        centre = centre * (1 - u) + (palate - 0.02) * u
    path = np.stack([centre, y, np.zeros(k)], axis=1)
    parts.add(tube(path, rx, s, radius2=rz, ref=[1.0, 0, 0]))
    ox, oy, orad, oz = p.orbit
    for side in (1, -1):  # orbit rims, facing out (or up for dorsal orbits)
        axis = p.orbit_axis
        parts.add(torus([ox, oy * ce + 0.02, oz * side], axis, orad, 0.03, s))
    if p.zygomatic > 0:  # zygomatic arches: from the temporal region behind the orbit,
        # bowing out (the skull's widest part) to the maxilla below the orbit
        for side in (1, -1):
            za = np.array(
                [
                    [-0.18, 0.14, (cz - 0.04) * side],
                    [-0.14, 0.5 * ce, 0.48 * side],
                    [-0.1, ce + 0.04, (rz[0] - 0.02) * side],
                ]
            )
            parts.add(tube(za, p.zygomatic, s2, ref=[1.0, 0, 0]))
    elif p.family == "bird":  # the thin jugal bar from the quadrate to the bill
        for side in (1, -1):
            jb = np.array([[-0.3, 0.12, 0.33 * side], [-0.18, ce + 0.05, 0.17 * side]])
            parts.add(tube(jb, 0.02, s2, ref=[1.0, 0, 0]))
    if p.family == "fish":  # gill covers on the sides of the head's rear
        for side in (1, -1):
            parts.add(ellipsoid([-0.05, 0.16, 0.4 * side], [0.36, 0.16, 0.06], s))
    if with_mandible:
        v, _, f = mandible(plan, lod)
        # the jaw joint's box inside the skull's: the bottom JAW_SHARE, 0.84 of the length
        parts.add((v * [JAW_SHARE, 0.84, 0.8] + [-0.5 + 0.5 * JAW_SHARE, 0.12, 0.0], f))
    return unit(parts.mesh())


@cache
def mandible(plan: str, lod: int) -> tuple[NDArray, NDArray, NDArray]:
    """Unit lower jaw in the jaw joint's box: two rami from the condyles (y = 0, at the
    sides) converging to the symphysis at the tip, a coronoid process rising from each ramus
    above the box (into the temporal fossa), an angular or retroarticular process behind."""
    p = PLANS[plan]
    s = max(4, SIDES[lod] // 2 + 1)
    parts = Parts()
    k = 5 + lod
    u = np.linspace(0.0, 1.0, k)
    depth = 0.5 * p.jaw_depth * (1.0 - 0.35 * u)
    if p.family == "bird":  # the lower bill closes to a point
        depth = 0.5 * p.jaw_depth * (1.0 - 0.9 * u**1.5)
    for side in (1, -1):
        z = side * (0.45 * (1 - u) + 0.04 * u)
        path = np.stack([np.zeros(k), u * 0.98 + 0.01, z], axis=1)
        parts.add(tube(path, depth, s, radius2=0.07, ref=[1.0, 0, 0]))
        if p.coronoid > 0:  # a plate rising dorsally in front of the condyle
            cor = np.array([[0.2, 0.14, 0.42 * side], [0.5 + p.coronoid, 0.1, 0.4 * side]])
            parts.add(tube(cor, [0.1, 0.05], s, radius2=0.03, ref=[0, 1.0, 0]))
        if p.retroarticular > 0:  # behind the jaw joint (reptiles, birds)
            ra = np.array([[0.0, 0.02, 0.45 * side], [0.1, -p.retroarticular, 0.45 * side]])
            parts.add(tube(ra, [0.4, 0.2], s, radius2=0.05, ref=[1.0, 0, 0]))
        elif p.family == "mammal":  # angular process below and behind the condyle
            ang = np.array([[-0.2, 0.08, 0.44 * side], [-0.6, -0.02, 0.44 * side]])
            parts.add(tube(ang, [0.06, 0.03], s, radius2=0.03, ref=[0, 1.0, 0]))
    return unit(parts.mesh())
