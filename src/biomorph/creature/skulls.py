"""A small library of scalable skulls (the seed: "heads are complicated → offer a selection").

Each skull is a tapered box (cranium at the back, snout at the front) described relative to
its length: height and width ratios, the snout taper and its pitch (degrees below the world
horizontal; skulls marked ``follow_spine`` continue the spine instead, e.g. fish and whales).
The length comes from the species data (inherited from the nearest species for samples).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class SkullShape:
    """Proportions of one skull type (all relative to skull length)."""

    name: str
    height: float  # cranium height / length
    width: float  # cranium width / length
    taper: float  # snout size / cranium size at the front end
    pitch_deg: float  # skull axis below world horizontal (forward), degrees
    follow_spine: bool = False


SKULLS: dict[str, SkullShape] = {
    s.name: s
    for s in (
        SkullShape("mammal_long", 0.42, 0.38, 0.45, 35.0),
        SkullShape("mammal_short", 0.70, 0.60, 0.60, 25.0),
        SkullShape("primate", 0.85, 0.75, 0.55, 10.0),
        SkullShape("bird", 0.45, 0.45, 0.15, 15.0),
        SkullShape("reptile_long", 0.25, 0.35, 0.40, 5.0),
        SkullShape("reptile_short", 0.45, 0.55, 0.55, 10.0),
        SkullShape("dinosaur", 0.55, 0.40, 0.55, 15.0),
        SkullShape("amphibian", 0.30, 0.85, 0.60, 0.0),
        SkullShape("fish", 0.75, 0.40, 0.45, 0.0, follow_spine=True),
        SkullShape("whale", 0.40, 0.45, 0.60, 0.0, follow_spine=True),
        SkullShape("snake", 0.40, 0.55, 0.60, 0.0, follow_spine=True),
    )
}

#: Fallback skull per class.
CLASS_SKULL = {
    "fish": "fish",
    "amphibian": "amphibian",
    "reptile": "reptile_long",
    "bird": "bird",
    "mammal": "mammal_long",
}


def get(name: str) -> SkullShape:
    """Skull shape by name (unknown names fall back to ``mammal_long``)."""
    return SKULLS.get(name, SKULLS["mammal_long"])


def box_size(shape: SkullShape, length: float) -> NDArray[np.float64]:
    """Box ``(x, y, z)`` in the skull's joint frame (+Y along the skull; x dorso-ventral)."""
    return np.array([shape.height * length, length, shape.width * length])


def mesh(shape: SkullShape, length: float) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Tapered-box skull mesh in the joint frame: cranium at y=0, snout tip at y=length."""
    h, w = shape.height * length, shape.width * length
    t = shape.taper
    back = np.array(
        [[-h / 2, 0, -w / 2], [h / 2, 0, -w / 2], [h / 2, 0, w / 2], [-h / 2, 0, w / 2]]
    )
    front = back * np.array([t, 0, t]) + np.array([-(1 - t) * h / 2, length, 0])
    v = np.concatenate([back, front])
    f = np.array(
        [
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
        ]
    )
    return v, f


#: Share of the head's mass carried by the mandible (a dog's mandible is ~15-20 % of the
#: skull's dry mass; we take the low end, the cranium carries brain and eyes).
JAW_MASS_FRACTION = 0.15


@dataclass(frozen=True)
class Jaw:
    """The mandible joint: world rotation (bone along +Y, Z lateral), position, length, box."""

    W: NDArray[np.float64]
    pos: NDArray[np.float64]
    length: float
    box: NDArray[np.float64]


def jaw(shape: SkullShape, length: float, W: NDArray, origin: NDArray) -> Jaw:
    """The mandible of a skull with world rotation ``W`` at ``origin``: hinged below the
    cranium's back (the jaw joint sits ventral and a little rostral of the occiput), running
    along the skull's ventral edge to just behind the snout's lower tip."""
    h, w, t = shape.height * length, shape.width * length, shape.taper
    start = np.array([0.32 * h, 0.12 * length])  # (ventral x, along y)
    end = np.array([(2 * t - 1) * h / 2 + 0.08 * h, 0.95 * length])
    v = end - start
    L = float(np.hypot(*v))
    y = W[:, 0] * v[0] / L + W[:, 1] * v[1] / L
    z = W[:, 2]
    x = np.array(
        [y[1] * z[2] - y[2] * z[1], y[2] * z[0] - y[0] * z[2], y[0] * z[1] - y[1] * z[0]]
    )  # y × z (np.cross's formula)
    Wj = np.stack([x, y, z], axis=1)
    pos = np.asarray(origin, float) + W[:, 0] * start[0] + W[:, 1] * start[1]
    return Jaw(Wj, pos, L, np.array([0.18 * h, L, 0.8 * w]))
