"""A small synthetic BVH walker for the studio tests (written here, no external data)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# name, parent index, offset (cm)
JOINTS = [
    ("Hips", -1, (0, 90, 0)),
    ("Spine", 0, (0, 10, 0)),
    ("Chest", 1, (0, 20, 0)),
    ("Neck", 2, (0, 20, 0)),
    ("Head", 3, (0, 10, 0)),
    ("LeftShoulder", 2, (15, 15, 0)),
    ("LeftElbow", 5, (0, -28, 0)),
    ("LeftHand", 6, (0, -25, 0)),
    ("RightShoulder", 2, (-15, 15, 0)),
    ("RightElbow", 8, (0, -28, 0)),
    ("RightHand", 9, (0, -25, 0)),
    ("LeftHip", 0, (9, -5, 0)),
    ("LeftKnee", 11, (0, -42, 0)),
    ("LeftAnkle", 12, (0, -40, 0)),
    ("RightHip", 0, (-9, -5, 0)),
    ("RightKnee", 14, (0, -42, 0)),
    ("RightAnkle", 15, (0, -40, 0)),
]


def write_walk_bvh(path: Path, seconds: float = 4.0, fps: float = 60.0, seed: int = 0) -> Path:
    """A walking-like clip: swinging limbs plus a little noise, root moving forward."""
    rng = np.random.default_rng(seed)
    n = int(seconds * fps)
    t = np.arange(n) / fps
    w = 2 * np.pi * 1.0
    lines = ["HIERARCHY"]
    children = {i: [j for j, (_, p, _) in enumerate(JOINTS) if p == i] for i in range(len(JOINTS))}

    def emit(i: int, depth: int) -> None:
        name, parent, off = JOINTS[i]
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if parent < 0 else 'JOINT'} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {off[0]} {off[1]} {off[2]}")
        if parent < 0:
            lines.append(
                f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
            )
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        if children[i]:
            for c in children[i]:
                emit(c, depth + 1)
        else:
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET 0 -5 0")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    emit(0, 0)
    cols = [
        np.zeros(n),
        90 + 2 * np.sin(2 * w * t),
        80 * t,
        np.zeros(n),
        np.zeros(n),
        5 * np.sin(w * t),
    ]
    swing = {"LeftHip": 1, "RightHip": -1, "LeftShoulder": -1, "RightShoulder": 1}
    for name, _, _ in JOINTS[1:]:
        x = np.zeros(n)
        if name in swing:
            x = 30 * swing[name] * np.sin(w * t)
        elif "Knee" in name:
            x = 25 * (1 + np.sin(w * t + (0 if "Left" in name else np.pi)))
        elif "Elbow" in name:
            x = -20 - 10 * np.sin(w * t)
        cols += [np.zeros(n), x + rng.normal(0, 0.8, n), np.zeros(n)]
    data = np.stack(cols, axis=1)
    lines += ["MOTION", f"Frames: {n}", f"Frame Time: {1 / fps:.8f}"]
    body = "\n".join(" ".join(f"{v:.4f}" for v in row) for row in data)
    path.write_text("\n".join(lines) + "\n" + body + "\n")
    return path
