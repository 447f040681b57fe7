"""Built-in motions (no data files needed): a procedural humanoid walk for the demo, tests
and benchmarks. Y-up, metres, forward +Z, BVH channel order ZXY."""

from __future__ import annotations

import numpy as np

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, dfs_preorder, reorder_joints
from biomorph.core.skeleton import JointSkeleton

# name, parent, offset (m)
_BODY = [
    ("Hips", None, (0, 0.95, 0)),
    ("Spine", "Hips", (0, 0.10, 0)),
    ("Spine1", "Spine", (0, 0.15, 0)),
    ("Neck", "Spine1", (0, 0.25, 0)),
    ("Head", "Neck", (0, 0.10, 0)),
    ("LeftShoulder", "Spine1", (0.05, 0.20, 0)),
    ("LeftArm", "LeftShoulder", (0.15, 0, 0)),
    ("LeftForeArm", "LeftArm", (0.28, 0, 0)),
    ("LeftHand", "LeftForeArm", (0.25, 0, 0)),
    ("RightShoulder", "Spine1", (-0.05, 0.20, 0)),
    ("RightArm", "RightShoulder", (-0.15, 0, 0)),
    ("RightForeArm", "RightArm", (-0.28, 0, 0)),
    ("RightHand", "RightForeArm", (-0.25, 0, 0)),
    ("LeftUpLeg", "Hips", (0.10, -0.05, 0)),
    ("LeftLeg", "LeftUpLeg", (0, -0.42, 0)),
    ("LeftFoot", "LeftLeg", (0, -0.42, 0)),
    ("LeftToeBase", "LeftFoot", (0, -0.06, 0.12)),
    ("RightUpLeg", "Hips", (-0.10, -0.05, 0)),
    ("RightLeg", "RightUpLeg", (0, -0.42, 0)),
    ("RightFoot", "RightLeg", (0, -0.42, 0)),
    ("RightToeBase", "RightFoot", (0, -0.06, 0.12)),
]


def humanoid(n_joints: int | None = None) -> JointSkeleton:
    """A 21-joint humanoid; with ``n_joints`` > 21, finger chains are added to the hands
    (3 joints each, alternating hands) until the count is reached."""
    rows = list(_BODY)
    k = 0
    while n_joints is not None and len(rows) < n_joints:
        side = "Left" if k % 2 == 0 else "Right"
        sx = 1 if side == "Left" else -1
        finger = k // 2
        parent = f"{side}Hand"
        for seg in range(3):
            if len(rows) >= n_joints:
                break
            name = f"{side}Finger{finger}_{seg}"
            off = (sx * (0.08 if seg == 0 else 0.03), 0, 0.02 * (finger - 2) if seg == 0 else 0)
            rows.append((name, parent, off))
            parent = name
        k += 1
    names = [r[0] for r in rows]
    parent = [-1 if r[1] is None else names.index(r[1]) for r in rows]
    offset = np.array([r[2] for r in rows], float)
    channels = [
        ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
        if p < 0
        else ("Zrotation", "Xrotation", "Yrotation")
        for p in parent
    ]
    end = np.full((len(names), 3), np.nan)
    for i, name in enumerate(names):
        if (
            name in ("Head", "LeftHand", "RightHand", "LeftToeBase", "RightToeBase")
            and i not in parent
        ):
            end[i] = {"Head": (0, 0.15, 0)}.get(name, (0, 0, 0.05))
    sk = JointSkeleton(names, parent, offset, channels=channels, end_site=end)
    return reorder_joints(sk, dfs_preorder(sk.parent))[0]  # BVH (depth-first) joint order


def walk(
    n_frames: int = 240,
    fps: float = 60.0,
    n_joints: int | None = None,
    speed: float = 1.2,
    stride_hz: float = 0.9,
    noise_deg: float = 0.0,
    turn_deg_s: float = 0.0,
    seed: int = 0,
) -> Motion:
    """A procedural walk: legs and arms swing at ``stride_hz`` (strides per second), the
    hips bob and sway, the root moves at ``speed`` m/s along +Z (turning at ``turn_deg_s``),
    plus optional Gaussian noise (``noise_deg``) on every rotation channel — capture jitter
    for the equalizer to remove."""
    sk = humanoid(n_joints)
    n = sk.n_joints
    t = np.arange(n_frames) / fps
    ph = 2 * np.pi * stride_hz * t
    e = np.zeros((n_frames, n, 3))  # Euler ZXY angles in degrees per joint: (z, x, y)
    idx = {s: i for i, s in enumerate(sk.names)}

    def setx(name: str, v: np.ndarray) -> None:
        e[:, idx[name], 1] = v

    setx("LeftUpLeg", 28 * np.sin(ph))
    setx("RightUpLeg", -28 * np.sin(ph))
    setx("LeftLeg", 30 * np.maximum(0, np.sin(ph - 1.2)) + 5)
    setx("RightLeg", 30 * np.maximum(0, -np.sin(ph - 1.2)) + 5)
    setx("LeftFoot", -10 * np.sin(ph - 0.5))
    setx("RightFoot", 10 * np.sin(ph - 0.5))
    setx("LeftArm", -20 * np.sin(ph))
    setx("RightArm", 20 * np.sin(ph))
    setx("LeftForeArm", -15 - 10 * np.sin(ph))
    setx("RightForeArm", -15 + 10 * np.sin(ph))
    e[:, idx["LeftArm"], 0] = -75  # arms down from the T-pose
    e[:, idx["RightArm"], 0] = 75
    e[:, idx["Spine"], 2] = 6 * np.sin(ph)  # torso twist
    e[:, idx["Hips"], 2] = -4 * np.sin(ph) + turn_deg_s * t
    e[:, idx["Neck"], 1] = 3 * np.sin(2 * ph)
    for j, name in enumerate(sk.names):
        if "Finger" in name:
            e[:, j, 0] = 10 + 8 * np.sin(ph + 0.3 * j)
    if noise_deg > 0:
        e += np.random.default_rng(seed).normal(0, noise_deg, e.shape)
    q = tf.euler_to_quat(e, "ZXY", degrees=True)
    q = tf.quat_continuous(q, axis=0)
    yaw = np.radians(turn_deg_s) * t
    vel = np.stack([np.sin(yaw), np.zeros_like(yaw), np.cos(yaw)], axis=1) * speed
    pos = np.concatenate([[np.zeros(3)], np.cumsum(vel[1:] / fps, axis=0)])
    pos[:, 1] = 0.95 + 0.025 * np.cos(2 * ph)
    pos[:, 0] += 0.02 * np.sin(ph)
    return Motion(
        sk,
        q,
        pos,
        1.0 / fps,
        meta={"source": "built-in walk", "up_guess": "y", "euler_wraps_in_file": 0},
    )


def spin(n_frames: int = 240, fps: float = 60.0, turns: float = 1.0) -> Motion:
    """The humanoid standing still while the root turns ``turns`` full circles about Y
    (Euler Y passes ±180° — the wrap case)."""
    base = walk(n_frames, fps, speed=0.0, stride_hz=0.0)
    ang = np.linspace(0, 2 * np.pi * turns, n_frames)
    rot = np.array(base.rotation)
    rot[:, 0] = tf.quat_continuous(tf.quat_from_axis_angle("y", ang), axis=0)
    return base.with_(rotation=rot)


__all__ = ["humanoid", "walk", "spin"]
