"""The generated creature: a JointSkeleton plus per-bone boxes, masses and a balance report.

Frames: Y up, metres, the creature faces +x, its right side is +z, the ground is ``y = 0``.
Every joint frame has its bone along local +Y (Blender's convention); spine and skull frames
keep local Z lateral, limb frames follow the limb (Z is the flexion axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.jsonable import dumps, to_jsonable
from biomorph.core.skeleton import JointSkeleton
from biomorph.creature.balance import BalanceReport


@dataclass(frozen=True, eq=False)
class Creature:
    """A generated vertebrate skeleton.

    Attributes
    ----------
    skeleton : the joint hierarchy (rest pose = the generated standing pose; ``limits`` are
        ranges of the pose rotation about the joint's local x, y, z, ZXY order, radians,
        relative to that rest pose — 0 lies inside every range).
    kind : per joint ``spine | skull | girdle | leg | arm | wing | fin``.
    region : per joint ``neck | back | tail | head | <girdle name>``.
    side : per joint +1 right (+z), -1 left, 0 midline.
    mirror : per joint index of its mirror partner (itself on the midline).
    bone_length : per joint length of its bone (m); the bone runs along local +Y.
    box_size : per joint box (x, y, z) in the joint frame (m), centred at (0, L/2, 0).
    mass : per joint mass (kg) of the body part carried by the bone.
    mass_center : per joint centre of that mass, world (m).
    mass_size : per joint box (m) of the soft-tissue volume (for inertia).
    anatomical_angles / anatomical_limits : limb joints' Euler angles (z, x, y) and their
        anatomical limits (rad) in the limb convention of :mod:`biomorph.creature.limbs`.
    contacts : world positions of the ground contacts (k, 3); contact_joint their joints.
    params : everything needed to regenerate (seed, options, sampled values).
    balance : the :class:`BalanceReport`.
    part : per joint the bone it stands for, from the vocabulary
        :data:`biomorph.creature.anatomy.PARTS` — ``skull mandible cervical thoracic lumbar
        sacral caudal scapula pelvis humerus radius metacarpal carpometacarpus femur tibia
        metatarsal fin_base fin_ray phalanx hoof claw nail`` (see that module for what each
        covers). Consumers (bone models, muscles, rigs) fall back to the box for a label they
        do not know, so new labels may be added.
    digit : per joint the digit number (1 = innermost, anatomy's I..V) of a ``phalanx`` /
        ``hoof`` / ``claw`` / ``nail`` joint, 0 elsewhere. The side letter (``L``/``R``/``C``)
        is :meth:`side_label`; the left/right partner is ``mirror``.
    """

    skeleton: JointSkeleton
    kind: tuple[str, ...]
    region: tuple[str, ...]
    side: NDArray[np.int64]
    mirror: NDArray[np.int64]
    bone_length: NDArray[np.float64]
    box_size: NDArray[np.float64]
    mass: NDArray[np.float64]
    mass_center: NDArray[np.float64]
    mass_size: NDArray[np.float64]
    anatomical_angles: NDArray[np.float64]
    anatomical_limits: NDArray[np.float64]
    contacts: NDArray[np.float64]
    contact_joint: NDArray[np.int64]
    spine_points: NDArray[np.float64]  # (10, 2) control points in the sagittal plane (m)
    params: dict[str, Any] = field(default_factory=dict)
    balance: BalanceReport | None = None
    part: tuple[str, ...] = ()
    digit: NDArray[np.int64] | None = None

    # ------------------------------------------------------------------ derived
    @property
    def names(self) -> tuple[str, ...]:
        return self.skeleton.names

    def __len__(self) -> int:
        return len(self.skeleton)

    @cached_property
    def world(self) -> NDArray[np.float64]:
        """Rest world transforms ``(n, 4, 4)``."""
        return self.skeleton.world_matrices()

    @cached_property
    def joint_positions(self) -> NDArray[np.float64]:
        return self.world[:, :3, 3]

    @cached_property
    def bone_ends(self) -> NDArray[np.float64]:
        """World position of each bone's far end (m)."""
        y = self.world[:, :3, 1]
        return self.joint_positions + y * self.bone_length[:, None]

    def side_label(self, j: int) -> str:
        """``R`` (+z), ``L`` (−z) or ``C`` (midline) for joint ``j``."""
        return "R" if self.side[j] > 0 else "L" if self.side[j] < 0 else "C"

    @property
    def total_mass(self) -> float:
        return float(self.mass.sum())

    @cached_property
    def center_of_mass(self) -> NDArray[np.float64]:
        return (self.mass[:, None] * self.mass_center).sum(axis=0) / max(self.total_mass, 1e-30)

    @cached_property
    def height(self) -> float:
        """Body height above the ground (m): highest joint or bone end."""
        return float(max(self.joint_positions[:, 1].max(), self.bone_ends[:, 1].max()))

    @cached_property
    def length(self) -> float:
        """Extent along x (m)."""
        p = np.concatenate([self.joint_positions, self.bone_ends])
        return float(np.ptp(p[:, 0]))

    def inertia(self) -> NDArray[np.float64]:
        """Principal moments (n, 3) of each bone's mass box about its centre (kg m²)."""
        from biomorph.creature.mass import box_inertia

        return box_inertia(self.mass, self.mass_size)

    def features(self) -> NDArray[np.float64]:
        """A fixed-length descriptor for diversity measures (PCA features + counts + size)."""
        f = np.asarray(self.params.get("features", np.zeros(29)), float)
        kinds = [self.kind.count(k) for k in ("leg", "arm", "wing", "fin")]
        return np.concatenate(
            [
                f,
                np.array(kinds, float) / 12.0,
                [np.log(self.total_mass + 1.0) / 12.0, len(self) / 200.0],
            ]
        )

    # ------------------------------------------------------------------ export
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description: parameters, seed, bones, masses, balance report."""
        sk = self.skeleton
        bones = []
        for i, name in enumerate(sk.names):
            bones.append(
                {
                    "name": name,
                    "parent": sk.names[sk.parent[i]] if sk.parent[i] >= 0 else None,
                    "kind": self.kind[i],
                    "region": self.region[i],
                    "side": int(self.side[i]),
                    "part": self.part[i] if self.part else None,
                    "digit": int(self.digit[i]) if self.digit is not None else 0,
                    "offset": sk.offset[i].tolist(),
                    "rest_rotation": sk.rest_rotation[i].tolist(),
                    "limits_rad": sk.limits[i].tolist(),
                    "length": float(self.bone_length[i]),
                    "box": self.box_size[i].tolist(),
                    "mass": float(self.mass[i]),
                    "mass_center": self.mass_center[i].tolist(),
                    "world_position": self.joint_positions[i].tolist(),
                }
            )
        return {
            "format": "biomorph-creature",
            "version": 1,
            "params": to_jsonable(self.params),
            "n_joints": len(sk),
            "height_m": self.height,
            "length_m": self.length,
            "mass_kg": self.total_mass,
            "center_of_mass": self.center_of_mass.tolist(),
            "contacts": self.contacts.tolist(),
            "balance": None if self.balance is None else self.balance.to_dict(),
            "bones": bones,
        }

    def summary(self) -> dict[str, Any]:
        """Short machine-readable summary (for ``--json``)."""
        b = self.balance
        return {
            "seed": self.params.get("seed"),
            "class": self.params.get("class"),
            "legs": self.params.get("legs"),
            "wings": self.params.get("wings"),
            "limbs": {k: self.kind.count(k) for k in ("leg", "arm", "wing", "fin")},
            "joints": len(self),
            "mass_kg": round(self.total_mass, 4),
            "height_m": round(self.height, 4),
            "length_m": round(self.length, 4),
            "stable": None if b is None else b.stable,
            "stability_margin_m": None if b is None else round(b.margin, 5),
        }


def write_json(path, creature: Creature):
    """Write ``creature.to_dict()`` as JSON (atomically)."""
    from biomorph.io.atomic import write_text

    return write_text(path, dumps(creature.to_dict(), indent=1))
