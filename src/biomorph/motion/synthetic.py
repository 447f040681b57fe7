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


#: The points a foot stands on: ankle (heel) and toe of each leg.
_CONTACT_POINTS = ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")
#: Soft-minimum width as a fraction of the hip height above the floor: 2 % (~2 cm on the
#: 0.95 m humanoid) is below a lifted foot's clearance, so a swinging foot carries no weight,
#: and wide enough that the hand-over between heel, toe and the other foot is smooth.
_SOFT = 0.02
#: Width of the stance hand-over in cos(phase): 0.15 rad either side of the turn of the
#: thighs (about 5 % of the cycle each), where both feet are nearly still.
_DOUBLE_SUPPORT = 0.1
#: Height of the swing foot's lift above the line between its footprints, in leg lengths
#: (hip to ankle): 0.2 (17 cm on the 0.84 m leg), a real heel's rise after toe-off.
_LIFT = 0.3
#: The swinging foot is over its next footprint at this fraction of the swing and then
#: comes straight down (terminal swing: a real foot slows before it lands).
_ARRIVE = 0.85
#: The widest thigh swing (degrees) the speed fit may ask for.
_MAX_SWING = 60.0


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
    """A procedural walk that plants its feet: legs and arms swing at ``stride_hz``
    (strides per second); the root's travel and height come from the legs (each frame the
    root moves by minus the step of the stance foot relative to the hips, and sits where
    that foot touches the floor, y = 0), heading +Z turning at ``turn_deg_s``; the swinging
    foot is carried from its footprint to the next one by two-bone IK.

    ``speed`` (m/s) is the speed asked for: the thigh swing amplitude is fitted so that
    stride length × ``stride_hz`` gives it (clamped at a 60° swing); the speed reached is
    in ``meta["speed"]`` and the swing in ``meta["swing_deg"]``. Optional Gaussian noise
    (``noise_deg``, seeded by ``seed``) is added to every rotation channel after the feet
    are planted — capture jitter for the equalizer to remove."""
    sk = humanoid(n_joints)
    # one stride cycle of padding either side: every swing in the clip has both footprints
    pad = int(np.ceil(fps / stride_hz)) if stride_hz > 0 else 0
    t = np.arange(-pad, n_frames + pad) / fps
    ph = 2 * np.pi * stride_hz * t
    swing = _swing_for(sk, speed, stride_hz)
    per_rad = turn_deg_s / (2 * np.pi * stride_hz) if stride_hz > 0 else 0.0
    # the legs and the root come from the 21-joint body (fingers do not touch the floor)
    body = humanoid()
    eb = _angles(body, ph, turn_deg_s * t, swing, per_rad)
    if stride_hz > 0:
        eb = _swing_legs(body, eb, ph, t, stride_hz)
    pos = _plant(body, _quat(eb), ph)[pad : pad + n_frames]
    e = _angles(sk, ph, turn_deg_s * t, swing, per_rad)
    e[:, [sk.names.index(s) for s in body.names]] = eb
    pos[:, [0, 2]] -= pos[:1, [0, 2]]
    e = e[pad : pad + n_frames]
    if noise_deg > 0:
        e += np.random.default_rng(seed).normal(0, noise_deg, e.shape)
    reached = _cycle_speed(sk, stride_hz, swing) if swing > 0 else 0.0
    meta = {
        "source": "built-in walk",
        "up_guess": "y",
        "euler_wraps_in_file": 0,
        "speed": reached,
        "swing_deg": swing,
    }
    return Motion(sk, _quat(e), pos, 1.0 / fps, meta=meta)


def _quat(e: np.ndarray) -> np.ndarray:
    return tf.quat_continuous(tf.euler_to_quat(e, "ZXY", degrees=True), axis=0)


def _swing_legs(
    sk: JointSkeleton, e: np.ndarray, ph: np.ndarray, t: np.ndarray, stride_hz: float
) -> np.ndarray:
    """The swinging legs by two-bone IK: the ankle goes from the footprint it left to the
    footprint it lands on (where the joint curves put it at the turn of the thighs) along a
    quintic ease that arrives at ``_ARRIVE`` of the swing, lifted by ``_LIFT`` leg lengths
    (a bump ``sin(pi u) ** (1 + u)``: quick off the floor, soft onto it); the foot levels
    out towards mid-swing. The thigh and knee angles of the stance legs are the curves'."""
    e = np.array(e)
    pose = Motion(sk, _quat(e), _plant(sk, _quat(e), ph), 1.0)
    w, r = pose.world_positions(), pose.world_rotations()
    for side, off in (("Left", 0.0), ("Right", np.pi)):
        hip, knee, ankle = (sk.names.index(side + s) for s in ("UpLeg", "Leg", "Foot"))
        l1, l2 = (float(np.linalg.norm(sk.offset[j])) for j in (knee, ankle))
        rel = ph + off - np.pi / 2
        u = np.mod(rel, 2 * np.pi) / np.pi  # 0..1 in swing (the thigh swings forward)
        ts = (np.floor(rel / (2 * np.pi)) * 2 * np.pi + np.pi / 2 - off) / (2 * np.pi * stride_hz)
        te = ts + 0.5 / stride_hz
        sw = (u < 1) & (ts >= t[0]) & (te <= t[-1])
        p0 = np.stack([np.interp(ts[sw], t, w[:, ankle, k]) for k in range(3)], axis=1)
        p1 = np.stack([np.interp(te[sw], t, w[:, ankle, k]) for k in range(3)], axis=1)
        us = u[sw]
        ue = np.clip(us / _ARRIVE, 0.0, 1.0)
        ease = ue**3 * (10 - 15 * ue + 6 * ue**2)
        target = p0 + (p1 - p0) * ease[:, None]
        target[:, 1] += _LIFT * (l1 + l2) * np.sin(np.pi * us) ** (1.0 + us)
        par = sk.parent[hip]
        loc = tf.quat_rotate(tf.quat_conjugate(r[sw, par]), target - w[sw, hip])
        d = np.hypot(loc[:, 1], loc[:, 2])
        # a soft reach limit (a smooth minimum of the distance and 99.9 % of the leg, over
        # 0.5 % of it): the knee straightens smoothly, never snaps at full reach
        reach, soft = 0.999 * (l1 + l2), 0.005 * (l1 + l2)
        d = reach - soft * np.logaddexp(0.0, (reach - d) / soft)
        d = np.clip(d, abs(l1 - l2) + 1e-9, (l1 + l2) * (1 - 1e-9))
        k = np.arccos(np.clip((d**2 - l1**2 - l2**2) / (2 * l1 * l2), -1.0, 1.0))
        a = np.arctan2(-loc[:, 2], -loc[:, 1]) - np.arctan2(l2 * np.sin(k), l1 + l2 * np.cos(k))
        a_deg, k_deg = np.degrees(a), np.degrees(k)
        pitch = e[sw, hip, 1] + e[sw, knee, 1] + e[sw, ankle, 1]  # the foot's, of the curves
        # the ankle dorsiflexes in swing: the foot levels out towards mid-swing
        e[sw, ankle, 1] = pitch * (1 - np.sin(np.pi * us)) - a_deg - k_deg
        e[sw, hip, 1] = a_deg
        e[sw, knee, 1] = k_deg
    return e


def _hips_yaw(ph: np.ndarray, turn_per_rad: float) -> np.ndarray:
    """The hips' yaw (degrees) at phase ``ph``: the walk's 4° sway plus the turn."""
    return -4 * np.sin(ph) + turn_per_rad * ph


def _angles(
    sk: JointSkeleton, ph: np.ndarray, yaw_deg: np.ndarray, swing: float, turn_per_rad: float = 0.0
) -> np.ndarray:
    """Euler ZXY angles in degrees, (frames, joints, (z, x, y)): the walk's joint curves with
    the thigh swinging ``swing`` degrees either side."""
    e = np.zeros((len(ph), sk.n_joints, 3))
    idx = {s: i for i, s in enumerate(sk.names)}

    def setx(name: str, v: np.ndarray) -> None:
        e[:, idx[name], 1] = v

    setx("LeftUpLeg", swing * np.sin(ph))
    setx("RightUpLeg", -swing * np.sin(ph))
    setx("LeftLeg", 30 * np.maximum(0, np.sin(ph - 1.2)) + 5)
    setx("RightLeg", 30 * np.maximum(0, -np.sin(ph - 1.2)) + 5)
    setx("LeftFoot", -10 * np.sin(ph - 0.5))
    setx("RightFoot", 10 * np.sin(ph - 0.5))
    setx("LeftArm", -20 * np.sin(ph))
    setx("RightArm", 20 * np.sin(ph))
    setx("LeftForeArm", -15 - 10 * np.sin(ph))
    setx("RightForeArm", -15 + 10 * np.sin(ph))
    for side, off in (("Left", 0.0), ("Right", np.pi)):
        # stance (the thigh swings back): the foot rolls flat onto the floor and off again
        u = np.mod(ph + off - np.pi / 2, 2 * np.pi) / np.pi - 1.0
        st = u >= 0
        j = [idx[side + s] for s in ("UpLeg", "Leg", "Foot")]
        pitch = e[st][:, j, 1].sum(axis=1)
        e[st, j[2], 1] = pitch * (1 - np.sin(np.pi * u[st])) ** 2 - e[st, j[0], 1] - e[st, j[1], 1]
        # the planted foot keeps the heading it landed with (the hip turns, not the foot);
        # in swing the thigh's twist eases back to none by the next landing
        land = ph - np.pi * np.where(st, u, u + 2.0)  # the phase of the last landing
        twist = _hips_yaw(land, turn_per_rad) - _hips_yaw(ph, turn_per_rad)
        lift = _hips_yaw(land, turn_per_rad) - _hips_yaw(land + np.pi, turn_per_rad)
        us = np.clip(u + 1.0, 0.0, 1.0)
        ue = np.clip(us / _ARRIVE, 0.0, 1.0)
        ease = ue**3 * (10 - 15 * ue + 6 * ue**2)
        e[:, j[0], 2] = np.where(st, twist, lift * (1 - ease))
    e[:, idx["LeftArm"], 0] = -75  # arms down from the T-pose
    e[:, idx["RightArm"], 0] = 75
    e[:, idx["Spine"], 2] = 6 * np.sin(ph)  # torso twist
    e[:, idx["Hips"], 2] = _hips_yaw(ph, 0.0) + yaw_deg
    e[:, idx["Neck"], 1] = 3 * np.sin(2 * ph)
    for j, name in enumerate(sk.names):
        if "Finger" in name:
            e[:, j, 0] = 10 + 8 * np.sin(ph + 0.3 * j)
    return e


def _plant(sk: JointSkeleton, q: np.ndarray, ph: np.ndarray) -> np.ndarray:
    """Root positions that keep the stance foot on the floor. Forward kinematics of the
    in-place pose gives heel (ankle) and toe of each foot relative to the hips; each frame
    the root moves by minus the horizontal step of the stance foot and sits at the height
    that puts it on the floor (y = 0). The stance leg is the one whose thigh swings back
    (left while cos(phase) > 0), handed over smoothly across double support where both
    thighs turn and the feet are still; within a foot the lower of heel and toe carries the
    weight (a soft minimum: the foot rolls heel to toe)."""
    pts = [sk.names.index(s) for s in _CONTACT_POINTS]
    rel = Motion(sk, q, np.zeros((len(q), 3)), 1.0).world_positions()[:, pts]
    h = rel[:, :, 1]
    tau = max(_SOFT * float(-h.min()) if h.size else 1.0, 1e-9)
    left = 0.5 * (1.0 + np.tanh(np.cos(ph) / _DOUBLE_SUPPORT))
    w = np.empty_like(h)
    for k, side in ((0, left), (2, 1.0 - left)):
        foot = h[:, k : k + 2]
        x = np.exp(-(foot - foot.min(axis=1, keepdims=True)) / tau)
        w[:, k : k + 2] = side[:, None] * x / x.sum(axis=1, keepdims=True)
    pos = np.zeros((len(q), 3))
    if len(q) > 1:
        wm = 0.5 * (w[1:] + w[:-1])  # the weights at the half step
        pos[1:] = -np.cumsum(np.einsum("fp,fpk->fk", wm, np.diff(rel, axis=0)), axis=0)
    pos[:, 1] = -np.einsum("fp,fp->f", w, h)
    return pos


def _cycle_speed(sk: JointSkeleton, stride_hz: float, swing: float) -> float:
    """Mean horizontal speed (m/s) of the planted walk with thigh swing ``swing``: one
    stride cycle sampled at 240 points, straight ahead."""
    ph = np.linspace(0.0, 2 * np.pi, 241)
    q = tf.euler_to_quat(_angles(sk, ph, np.zeros_like(ph), swing), "ZXY", degrees=True)
    pos = _plant(sk, tf.quat_continuous(q, axis=0), ph)
    return float(np.linalg.norm(pos[-1, [0, 2]] - pos[0, [0, 2]])) * stride_hz


def _swing_for(sk: JointSkeleton, speed: float, stride_hz: float) -> float:
    """The thigh swing (degrees) whose planted walk travels at ``speed``: secant steps on
    the (nearly linear) speed-per-swing curve, clamped to ±60° (a longer stride is out of
    a leg's reach; the walk then goes as fast as 60° takes it)."""
    if speed <= 0 or stride_hz <= 0:
        return 0.0
    a0, s0 = 0.0, 0.0
    a1 = 28.0
    s1 = _cycle_speed(sk, stride_hz, a1)
    for _ in range(6):
        if abs(s1 - speed) < 1e-4 * speed or s1 == s0:
            break
        a0, s0, a1 = a1, s1, min(_MAX_SWING, max(0.0, a1 + (speed - s1) * (a1 - a0) / (s1 - s0)))
        s1 = _cycle_speed(sk, stride_hz, a1)
    return a1


def spin(n_frames: int = 240, fps: float = 60.0, turns: float = 1.0) -> Motion:
    """The humanoid standing still while the root turns ``turns`` full circles about Y
    (Euler Y passes ±180° — the wrap case)."""
    base = walk(n_frames, fps, speed=0.0, stride_hz=0.0)
    ang = np.linspace(0, 2 * np.pi * turns, n_frames)
    rot = np.array(base.rotation)
    rot[:, 0] = tf.quat_continuous(tf.quat_from_axis_angle("y", ang), axis=0)
    return base.with_(rotation=rot)


__all__ = ["humanoid", "walk", "spin"]
