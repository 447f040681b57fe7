"""Standing posture and proportions from real animals (issue 14).

Published ranges the generator keeps its creatures inside and the bench counts
(:func:`biomorph.creature.quality.anatomy_check`); sources in ``docs/creature.md``.

* Trunk pitch (back chord hip → shoulder above the horizontal): quadrupeds near level
  (horse ≈ 0–5°, a giraffe's sloping back ≈ 25°), bipeds from theropod-horizontal (0–15°)
  to bird-inclined (20–50°; a kangaroo ≈ 45°), never head-down.
* Head pitch (skull axis): from a grazing horse's face (≈ −60°) to 30° snout-up at most.
* Femur from the vertical while standing: mammals and reptiles 0–60° (horse ≈ 35–45°, dog
  ≈ 45°; a level femur is a crouch, not a stance); birds hold it forward, 20–90°.
* Standing height: withers (quadrupeds) or hip (bipeds) ``h = a · M^b`` with ``b = 1/3``
  (geometric similarity; Alexander, Jayes, Maloiy & Wathuta 1979, J. Zool. 189:305, measure
  limb-bone exponents 0.35–0.36 for mammals from shrew to elephant); ``a`` from a 600-kg
  horse's 1.2-m withers (0.142, checked against a 4-kg cat: 0.23 m, real ≈ 0.25 m) and for
  birds from an ostrich's (120 kg, ≈ 1.0 m) and a chicken's hip (2 kg, ≈ 0.25 m): 0.2.
  Sprawling postures (crocodiles, salamanders) are left as sampled.
"""

from __future__ import annotations

#: (low, high) in degrees unless noted; ``withers_ratio`` is height / allometric height.
RANGES = {
    "trunk_pitch_quadruped": (-15.0, 30.0),
    "trunk_pitch_biped": (-5.0, 60.0),
    "head_pitch": (-70.0, 30.0),
    "femur_from_vertical": (0.0, 65.0),
    "femur_from_vertical_bird": (20.0, 90.0),
    "withers_ratio": (0.75, 1.35),
}

#: What the generator aims for inside those ranges (the checks keep a margin for the
#: balance repair's lean and the descent's search).
TARGET = {
    "trunk_pitch_quadruped": (-8.0, 20.0),
    "trunk_pitch_biped": (0.0, 50.0),
    "head_pitch": (-60.0, 25.0),
    "femur_max": 58.0,
    "femur_min_bird": 22.0,
}

#: ``(a, b)`` of the standing-height allometry ``h = a · M^b`` (m, kg) per class.
ALLOMETRY = {"mammal": (0.142, 1 / 3), "reptile": (0.142, 1 / 3), "bird": (0.2, 1 / 3)}


def allometric_height(cls: str, posture: str, mass: float) -> float | None:
    """Predicted withers (quadrupeds) / hip (bipeds) height in metres, or ``None`` where
    no allometry applies (sprawling postures, amphibians, fish)."""
    ab = ALLOMETRY.get(cls)
    if ab is None or posture == "sprawling":
        return None
    return float(ab[0] * mass ** ab[1])
