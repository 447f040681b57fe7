"""A simple procedural walk cycle so a creature can go straight into the motion pillar.

Limb joints swing about their flexion axis (local z) sinusoidally; legs follow a lateral-
sequence walk (left/right half a cycle apart, fore pairs a quarter cycle after hind pairs),
the middle joint bends while the limb swings forward, wings flap, the tail sways. The root
moves forward at a speed that matches the stride. Rotations are pose quaternions applied
after each joint's rest rotation (:class:`biomorph.motion.motion.Motion` convention).
"""

from __future__ import annotations

import numpy as np

from biomorph.core import transforms as tf
from biomorph.creature.creature import Creature
from biomorph.errors import ParameterError


def walk_cycle(creature: Creature, frames: int = 32, cycles: int = 2, fps: float = 30.0,
               amplitude_deg: float = 18.0):
    """A :class:`~biomorph.motion.motion.Motion` of ``cycles`` walk cycles."""
    from biomorph.core.motion import Motion

    if frames < 4 or cycles < 1 or fps <= 0:
        raise ParameterError(f"walk needs frames >= 4, cycles >= 1, fps > 0; got {frames}, "
                             f"{cycles}, {fps}")
    sk = creature.skeleton
    n = len(sk)
    total = frames * cycles
    t = np.arange(total) / frames * 2 * np.pi               # phase (rad)
    angle = np.zeros((total, n, 3))                         # about local x, y, z
    amp = np.radians(amplitude_deg)
    names = sk.names
    for j in range(n):
        k = creature.kind[j]
        if k in ("leg", "arm", "fin", "wing"):
            seg = names[j].split("_")[1]
            side = 0.0 if creature.side[j] > 0 else np.pi
            fore = 0.5 * np.pi if creature.region[j] in ("shoulder", "centaur") else 0.0
            ph = t + side + fore
            if k == "wing":
                angle[:, j, 0] = (1.2 * amp if seg == "upper" else 0.3 * amp) * np.sin(t)
            elif k == "fin":
                angle[:, j, 2] = 0.5 * amp * np.sin(ph) if seg == "upper" else 0.0
            elif seg == "upper":
                angle[:, j, 2] = amp * np.sin(ph) * (1 if k == "leg" else 0.4)
            elif seg == "lower" and k == "leg":
                bend = -1.0 if creature.region[j] == "hip" else 1.0
                angle[:, j, 2] = bend * 1.2 * amp * np.clip(np.cos(ph), 0, None)
        elif k == "spine" and creature.region[j] == "tail":
            angle[:, j, 0] = 0.15 * amp * np.sin(t)
    q = tf.euler_to_quat(angle[..., [2, 0, 1]], "ZXY")      # R = Rz Rx Ry
    legs = [j for j in range(n) if creature.kind[j] == "leg" and names[j].split("_")[1] == "upper"]
    L = float(np.mean([creature.bone_length[j] for j in legs])) if legs else 0.1 * creature.length
    stride = 2 * L * np.sin(amp) * 2
    speed = stride / (frames / fps)
    root = np.tile(sk.offset[0], (total, 1))
    root[:, 0] += speed * np.arange(total) / fps
    return Motion(sk, q, root, 1.0 / fps)
