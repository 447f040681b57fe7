"""Per-joint anatomical labels: which bone of the animal each joint stands for.

The vocabulary (:data:`PARTS`) is the contract between the skeleton (joints, parents, boxes)
and whatever dresses it (bone models, muscles, rigs): a consumer looks a joint's ``part`` up
in its own library and falls back to the joint's box for labels it does not know.

Axial: ``skull``, ``mandible``, ``cervical``, ``thoracic``, ``lumbar``, ``sacral``,
``caudal`` (fish: the trunk vertebrae are ``thoracic``, they carry the pleural ribs).
Girdles: ``scapula`` (shoulder and centaur girdle), ``pelvis`` (hip girdle).
Fore limb: ``humerus``, ``radius`` (radius + ulna), ``metacarpal``; hind limb: ``femur``,
``tibia`` (tibia + fibula; a bird's tibiotarsus), ``metatarsal`` (a bird's
tarsometatarsus); wing: ``humerus``, ``radius``, ``carpometacarpus``; fin: ``fin_base``
(the fin's proximal radials) then ``fin_ray``. Digits: ``phalanx`` joints, ending in a
``hoof``, ``claw`` or ``nail`` end joint (``digit`` gives the digit number, 1 = the
innermost, as in anatomy's I..V; 0 for every non-digit joint).

Vertebra regions follow the seed's three spine curves (neck, back, tail); the back is split
at the hip: its last ``SACRAL_FRACTION`` of vertebrae are sacral, and in mammals the
``LUMBAR_FRACTION`` before them lumbar (a dog: 13 thoracic, 7 lumbar, 3 sacral of 23 back
vertebrae → 0.30 and 0.13; a horse 18/6/5 → 0.21 and 0.17; we use the rounded means).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

PARTS = (
    "skull",
    "mandible",
    "cervical",
    "thoracic",
    "lumbar",
    "sacral",
    "caudal",
    "scapula",
    "pelvis",
    "humerus",
    "radius",
    "metacarpal",
    "carpometacarpus",
    "femur",
    "tibia",
    "metatarsal",
    "fin_base",
    "fin_ray",
    "phalanx",
    "hoof",
    "claw",
    "nail",
)

#: Fractions of the back (trunk) vertebrae that are lumbar (mammals only) and sacral.
LUMBAR_FRACTION = 0.25
SACRAL_FRACTION = 0.15

#: Limb segment (girdle, upper, lower, distal) → part, by limb kind and girdle.
LIMB_PARTS = {
    ("leg", "fore"): ("scapula", "humerus", "radius", "metacarpal"),
    ("leg", "hind"): ("pelvis", "femur", "tibia", "metatarsal"),
    ("arm", "fore"): ("scapula", "humerus", "radius", "metacarpal"),
    ("wing", "fore"): ("scapula", "humerus", "radius", "carpometacarpus"),
    ("fin", "fore"): ("scapula", "fin_base", "fin_ray", "fin_ray"),
    ("fin", "hind"): ("pelvis", "fin_base", "fin_ray", "fin_ray"),
}


def vertebra_parts(vreg: NDArray, cls: str) -> list[str]:
    """Part per vertebra (head → tail order) from the seed's regions 0 neck / 1 back / 2 tail."""
    vreg = np.asarray(vreg)
    out = ["cervical" if r == 0 else "caudal" if r == 2 else "thoracic" for r in vreg]
    back = np.flatnonzero(vreg == 1)
    n = len(back)
    if n >= 3:
        n_s = max(1, int(round(SACRAL_FRACTION * n)))
        n_l = int(round(LUMBAR_FRACTION * n)) if cls == "mammal" else 0
        for i in back[n - n_s :]:
            out[i] = "sacral"
        for i in back[max(n - n_s - n_l, 1) : n - n_s]:
            out[i] = "lumbar"
    return out


def limb_parts(kind: str, girdle: str) -> tuple[str, str, str, str]:
    """Parts of a limb's (girdle, upper, lower, distal) joints."""
    role = "hind" if girdle == "hip" else "fore"
    return LIMB_PARTS.get((kind, role), LIMB_PARTS[("leg", role)])


def side_label(side: int) -> str:
    """``R`` (+z), ``L`` (−z) or ``C`` (midline)."""
    return "R" if side > 0 else "L" if side < 0 else "C"
