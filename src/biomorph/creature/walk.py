"""A walk cycle that stays on the ground: planted feet by two-bone IK (issue 14).

Every standing leg follows a foot trajectory in the world: during its stance phase the foot
is planted (fixed on the ground), during its swing it moves one stride forward with a lift
of ``lift`` × hip height (a sine bump). The body (the skeleton's root) moves forward at the
constant speed ``stride / period``. Each frame, the thigh/upper arm and shank/forearm are
solved by analytic two-bone IK so the ankle/wrist reaches its target, bending in the leg's
rest plane (the knee keeps its side); the metapodial keeps its standing world orientation,
so the digits (:mod:`biomorph.creature.feet`) stay flat on the ground while planted.

Gaits (phase offsets as fractions of the cycle, leg starts its stance at 0):

* 2 legs — walk: left and right half a cycle apart, duty factor 0.6 (double support).
* 4 legs — lateral-sequence ``walk`` (hind L 0, fore L 0.25, hind R 0.5, fore R 0.75, duty
  0.65: the footfall order of horses, dogs and most mammals at a walk) or ``trot``
  (diagonal pairs, duty 0.5).
* 6 legs — alternating tripod (front L, middle R, hind L | the others), duty 0.55.

The stride is ``stride_factor`` × the mean hip/shoulder height (relative stride length
λ/h ≈ 0.8–1.0 at a walk, Alexander 1984, Am. Zool. 24:85). Arms, wings, fins and the tail
swing sinusoidally as before. Keys are one per frame at ``fps`` (``Motion.fps``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from biomorph.core import transforms as tf
from biomorph.creature.creature import Creature
from biomorph.errors import ParameterError

GAITS = ("walk", "trot")


@dataclass(frozen=True)
class WalkPlan:
    """Timing of a walk: legs, their phase offsets, duty factor, period (s), stride (m),
    hip height (m), lift (m) and the keys' fps."""

    legs: tuple[dict, ...]
    offsets: tuple[float, ...]
    duty: float
    period: float
    stride: float
    height: float
    lift: float
    fps: float
    frames: int
    drop: float = 0.0


#: The body walks this fraction of the hip height lower than it stands (bent knees give the
#: legs the reach a planted stride needs).
WALK_DROP = 0.04


def _drop(creature: Creature, legs: list[dict], h: float) -> float:
    """How much lower the body walks: :data:`WALK_DROP` × hip height, less where a low belly,
    tail or jaw would touch the ground or a leg could not fold that far."""
    P0, E0 = creature.joint_positions, creature.bone_ends
    body = [j for j in range(len(creature)) if creature.kind[j] not in ("leg",)]
    clear = float(min(P0[body, 1].min(), E0[body, 1].min())) if body else h
    slack = []
    for g in legs:
        hip, knee, ank = P0[g["upper"]], P0[g["lower"]], P0[g["distal"]]
        l1, l2 = np.linalg.norm(knee - hip), np.linalg.norm(ank - knee)
        slack.append((hip[1] - ank[1]) - 1.05 * abs(l1 - l2))  # the foot passes under
    return float(max(0.0, min(WALK_DROP * h, 0.8 * clear, 0.8 * min(slack))))


def _reach_stride(creature: Creature, legs: list[dict], duty: float, drop: float) -> float:
    """Longest stride every leg can plant: over the stance the ankle travels ±stride·duty/2
    about its rest position relative to the hip, within 99.5 % of the leg's reach."""
    P0 = creature.joint_positions
    best = np.inf
    for g in legs:
        hip, knee, ank = P0[g["upper"]], P0[g["lower"]], P0[g["distal"]]
        reach = 0.995 * (np.linalg.norm(knee - hip) + np.linalg.norm(ank - knee))
        dy = hip[1] - drop - ank[1]
        dz2 = (hip[2] - ank[2]) ** 2
        e = np.sqrt(max(reach**2 - dy**2 - dz2, 0.0))
        dx = abs(ank[0] - hip[0])
        best = min(best, 2.0 * max(e - dx, 0.0) / duty)
        lo = 1.06 * abs(np.linalg.norm(knee - hip) - np.linalg.norm(ank - knee))
        if dy**2 + dz2 < lo**2:  # the foot cannot pass under the hip: stop short of it
            best = min(best, 2.0 * max(dx - np.sqrt(lo**2 - dy**2 - dz2), 0.0) / duty)
    return float(best)


def _leg_lengths(P0: NDArray, g: dict) -> tuple[float, float]:
    return (
        float(np.linalg.norm(P0[g["lower"]] - P0[g["upper"]])),
        float(np.linalg.norm(P0[g["distal"]] - P0[g["lower"]])),
    )


def _leg_lift(P0: NDArray, g: dict, drop: float, lift: float) -> float:
    """Swing lift of one leg: a short femur under a long shank cannot fold its foot close to
    the hip, so its lift stays inside that (else IK would push the foot into the ground)."""
    l1, l2 = _leg_lengths(P0, g)
    dy = float(P0[g["upper"], 1] - drop - P0[g["distal"], 1])  # the foot may pass under
    return float(np.clip(0.9 * (dy - 1.05 * abs(l1 - l2)), 0.0, lift))


def knee_clearance(creature: Creature, g: dict) -> float:
    """Lowest height a leg's knee/elbow may take: its shank bone's half-thickness (so the
    bone model, not only the joint, stays above the ground)."""
    return 0.5 * float(max(creature.box_size[g["lower"], 0], creature.box_size[g["lower"], 2]))


def _knee_circle(
    hip: NDArray, target: NDArray, l1: float, l2: float
) -> tuple[NDArray, NDArray, NDArray]:
    """The circle of knee positions of a two-bone chain from ``hip (f, 3)`` reaching for
    ``target (f, 3)`` (clamped into reach): centre ``(f, 3)``, radius ``(f,)``, axis ``(f, 3)``."""
    d = target - hip
    dist = np.linalg.norm(d, axis=1)
    lo, hi = abs(l1 - l2) * 1.0001 + 1e-12, (l1 + l2) * 0.9999
    dist_c = np.clip(dist, lo, hi)
    u = d / np.maximum(dist, 1e-12)[:, None]
    cos_a = np.clip((l1**2 + dist_c**2 - l2**2) / (2 * l1 * dist_c), -1.0, 1.0)
    return hip + (l1 * cos_a)[:, None] * u, l1 * np.sqrt(1.0 - cos_a**2), u


def _highest_knee(hip: NDArray, target: NDArray, l1: float, l2: float) -> NDArray:
    """Highest knee position's height ``(f,)`` over the chain's knee circle."""
    centre, rho, u = _knee_circle(hip, target, l1, l2)
    return centre[:, 1] + rho * np.sqrt(np.clip(1.0 - u[:, 1] ** 2, 0.0, 1.0))


def _knee_safe_stride(
    creature: Creature,
    legs: list[dict],
    offsets: list[float],
    duty: float,
    drop: float,
    stride: float,
    lift: float,
) -> float:
    """The longest stride up to ``stride`` with which every leg's knee can stay at or above
    its :func:`knee_clearance` through a whole cycle (bisection over the stride on the
    leg's actual foot path, 48 phases): a sprawling leg with a long femur over a short shank
    must not bring its foot so close under the hip that the knee has to go down."""
    P0 = creature.joint_positions
    t = np.linspace(0.0, 1.0, 48, endpoint=False)

    def ok(s: float) -> bool:
        for g, off in zip(legs, offsets, strict=True):
            l1, l2 = _leg_lengths(P0, g)
            if l1 < 1e-12 or l2 < 1e-12:
                continue
            lift_i = _leg_lift(P0, g, drop, lift)
            tgt, _ = foot_targets(P0[g["distal"]], t, 1.0, s, off, duty, lift_i)
            hip = np.tile(P0[g["upper"]] - [0.0, drop, 0.0], (len(t), 1))
            hip[:, 0] += s * t  # the body moves on at one stride per cycle
            if _highest_knee(hip, tgt, l1, l2).min() < knee_clearance(creature, g):
                return False
        return True

    if ok(stride):
        return stride
    lo, hi = 0.0, stride
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def _raise_knee(
    hip: NDArray, target: NDArray, l1: float, l2: float, pole: NDArray, clear: float
) -> NDArray:
    """Knee positions ``(f, 3)`` on the chain's knee circle: the one nearest the ``pole``
    side whose height is at least ``clear`` (the highest one where none is)."""
    centre, rho, u = _knee_circle(hip, target, l1, l2)
    e1 = pole[None, :] - (u @ pole)[:, None] * u
    bad = np.linalg.norm(e1, axis=1) < 1e-9
    e1[bad] = np.cross(u[bad], [0.0, 0.0, 1.0])
    e1 /= np.maximum(np.linalg.norm(e1, axis=1), 1e-12)[:, None]
    e2 = np.cross(u, e1)
    amp = np.hypot(e1[:, 1], e2[:, 1])
    phi_star = np.arctan2(e2[:, 1], e1[:, 1])  # direction of the highest point
    kappa = (clear - centre[:, 1]) / np.maximum(rho * amp, 1e-12)
    half = np.arccos(np.clip(kappa, -1.0, 1.0))  # allowed: |phi - phi_star| <= half
    dev = (0.0 - phi_star + np.pi) % (2 * np.pi) - np.pi  # wrap phi = 0 about phi_star
    phi = phi_star + np.clip(dev, -half, half)
    phi = np.where(kappa <= -1.0, 0.0, phi)
    return centre + rho[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)


def plan_walk(
    creature: Creature,
    frames: int = 32,
    cycles: int = 2,
    fps: float = 30.0,
    gait: str = "walk",
    stride_factor: float = 0.9,
    lift: float = 0.12,
) -> WalkPlan:
    """Check the walk options and derive the gait timing (see the module docstring)."""
    if frames < 4 or cycles < 1 or not np.isfinite(fps) or fps <= 0:
        raise ParameterError(
            f"walk needs frames >= 4, cycles >= 1, fps > 0; got {frames}, {cycles}, {fps}"
        )
    if gait not in GAITS:
        raise ParameterError(f"gait {gait!r}; expected one of {', '.join(GAITS)}")
    if not (0 < stride_factor <= 2 and 0 <= lift <= 0.5):
        raise ParameterError(
            f"stride_factor {stride_factor} / lift {lift}: expected "
            "0 < stride_factor <= 2 and 0 <= lift <= 0.5"
        )
    legs = _legs(creature)
    P0 = creature.joint_positions
    h = float(np.mean([P0[g["upper"], 1] for g in legs])) if legs else 0.1 * creature.length
    offs, duty = phase_offsets(legs, gait) if legs else ([], 0.6)
    drop = _drop(creature, legs, h) if legs else 0.0
    stride = (
        min(stride_factor * h, 0.95 * _reach_stride(creature, legs, duty, drop)) if legs else 0.0
    )
    if legs:  # no knee or elbow below the ground anywhere in the cycle
        stride = _knee_safe_stride(creature, legs, offs, duty, drop, stride, lift * h)
    return WalkPlan(
        tuple(legs),
        tuple(offs),
        duty,
        frames / fps,
        stride,
        h,
        lift * h,
        float(fps),
        frames * cycles,
        drop,
    )


DUTY = {2: 0.6, 4: 0.65, 6: 0.55, "trot": 0.5}


def _legs(c: Creature) -> list[dict]:
    """Standing legs: upper, lower and distal joint indices, girdle tag, side."""
    idx = {n: i for i, n in enumerate(c.names)}
    out = []
    for j, n in enumerate(c.names):
        parts = n.split("_")
        if c.kind[j] == "leg" and len(parts) == 3 and parts[1] == "upper":
            tag, sd = parts[0], parts[2]
            out.append(
                {
                    "tag": tag,
                    "side": sd,
                    "upper": j,
                    "lower": idx[f"{tag}_lower_{sd}"],
                    "distal": idx[f"{tag}_distal_{sd}"],
                }
            )
    return out


def phase_offsets(legs: list[dict], gait: str = "walk") -> tuple[list[float], float]:
    """Phase offset per leg and the duty factor for the leg count and gait."""
    n = len(legs)
    tags = sorted({g["tag"] for g in legs}, key=lambda t: (not t.startswith("shoulder"), t))
    if n == 4 and gait == "trot":
        off = {
            ("hip1", "l"): 0.0,
            ("shoulder1", "r"): 0.0,
            ("hip1", "r"): 0.5,
            ("shoulder1", "l"): 0.5,
        }
        return [off.get((g["tag"], g["side"]), 0.0) for g in legs], DUTY["trot"]
    if n == 4:
        off = {
            ("hip1", "l"): 0.0,
            ("shoulder1", "l"): 0.25,
            ("hip1", "r"): 0.5,
            ("shoulder1", "r"): 0.75,
        }
        return [off.get((g["tag"], g["side"]), 0.0) for g in legs], DUTY[4]
    if n == 6:  # tripod: alternate sides along the body
        rank = {t: k for k, t in enumerate(tags)}
        return [0.5 * ((rank[g["tag"]] + (g["side"] == "r")) % 2) for g in legs], DUTY[6]
    return [0.0 if g["side"] == "l" else 0.5 for g in legs], DUTY.get(n, 0.6)


def _rot_between(a: NDArray, b: NDArray) -> NDArray:
    """Smallest rotations taking unit vectors ``a (3,)`` to unit vectors ``b (f, 3)``:
    ``(f, 3, 3)`` (Rodrigues)."""
    b = np.atleast_2d(b)
    v = np.cross(a, b)
    s = np.linalg.norm(v, axis=1)
    c = np.clip(b @ a, -1.0, 1.0)
    k = v / np.maximum(s, 1e-300)[:, None]
    K = np.zeros((len(b), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    R = np.eye(3) + s[:, None, None] * K + (1 - c)[:, None, None] * (K @ K)
    R[s < 1e-12] = np.eye(3)
    return R


def two_bone_ik(
    hip: NDArray, target: NDArray, l1: float, l2: float, pole: NDArray
) -> tuple[NDArray, NDArray]:
    """Knee positions ``(f, 3)`` and the (clamped) ankle positions of a two-bone chain from
    ``hip (f, 3)`` reaching for ``target (f, 3)``, bending towards ``pole`` (unit vector,
    made ⟂ to each hip→target line). Targets out of reach are approached along the line."""
    d = target - hip
    dist = np.linalg.norm(d, axis=1)
    lo, hi = abs(l1 - l2) * 1.0001 + 1e-12, (l1 + l2) * 0.9999
    dist_c = np.clip(dist, lo, hi)
    u = d / np.maximum(dist, 1e-12)[:, None]
    p = pole[None, :] - (u @ pole)[:, None] * u
    p = p / np.maximum(np.linalg.norm(p, axis=1), 1e-12)[:, None]
    cos_a = (l1**2 + dist_c**2 - l2**2) / (2 * l1 * dist_c)
    a = np.arccos(np.clip(cos_a, -1.0, 1.0))
    knee = hip + l1 * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * p)
    return knee, hip + dist_c[:, None] * u


def foot_targets(
    rest: NDArray, t: NDArray, period: float, stride: float, offset: float, duty: float, lift: float
) -> tuple[NDArray, NDArray]:
    """World ankle targets ``(frames, 3)`` for a foot resting at ``rest`` (body at x = 0 at
    t = 0) and a stance mask. Planted feet do not move; the mid-stance foot sits at its rest
    position relative to the body."""
    ph = t / period + offset
    n = np.floor(ph)
    u = ph - n
    c = stride * (duty / 2 - offset)
    swing = u >= duty
    s = np.where(swing, (u - duty) / max(1 - duty, 1e-9), 0.0)
    s_smooth = s * s * (3 - 2 * s)
    x = rest[0] + n * stride + c + stride * s_smooth
    y = rest[1] + lift * np.sin(np.pi * s) * swing
    out = np.tile(rest, (len(t), 1))
    out[:, 0], out[:, 1] = x, y
    return out, ~swing


def walk_cycle(
    creature: Creature,
    frames: int = 32,
    cycles: int = 2,
    fps: float = 30.0,
    amplitude_deg: float = 18.0,
    gait: str = "walk",
    stride_factor: float = 0.9,
    lift: float = 0.12,
):
    """A :class:`~biomorph.core.motion.Motion` of ``cycles`` walk cycles of ``frames``
    frames at ``fps`` (keys at the clip's fps) with IK-planted feet."""
    from biomorph.core.motion import Motion

    plan = plan_walk(creature, frames, cycles, fps, gait, stride_factor, lift)
    sk = creature.skeleton
    n = len(sk)
    total = plan.frames
    period, stride, duty = plan.period, plan.stride, plan.duty
    t = np.arange(total) / fps
    ph = 2 * np.pi * t / period
    W0 = creature.world[:, :3, :3]
    P0 = creature.joint_positions
    Wt = np.broadcast_to(W0, (total, n, 3, 3)).copy()  # world rotations per frame
    shift = np.zeros((total, 3))
    shift[:, 0] = stride / period * t
    shift[:, 1] = -plan.drop
    for g, off in zip(plan.legs, plan.offsets, strict=True):
        iu, il, idd = g["upper"], g["lower"], g["distal"]
        l1 = float(np.linalg.norm(P0[il] - P0[iu]))
        l2 = float(np.linalg.norm(P0[idd] - P0[il]))
        if l1 < 1e-12 or l2 < 1e-12:
            continue
        lift_i = _leg_lift(P0, g, plan.drop, plan.lift)
        tgt, _ = foot_targets(P0[idd], t, period, stride, off, duty, lift_i)
        u0 = (P0[idd] - P0[iu]) / max(np.linalg.norm(P0[idd] - P0[iu]), 1e-12)
        pole = (P0[il] - P0[iu]) - ((P0[il] - P0[iu]) @ u0) * u0
        pn = np.linalg.norm(pole)
        pole = pole / pn if pn > 1e-9 * l1 else W0[iu][:, 0]
        d1 = (P0[il] - P0[iu]) / l1
        d2 = (P0[idd] - P0[il]) / l2
        hip = P0[iu] + shift
        knee, _ = two_bone_ik(hip, tgt, l1, l2, pole)
        clear = knee_clearance(creature, g)
        low = knee[:, 1] < clear
        if low.any():  # a splayed knee that would dip turns up round the hip-foot line
            knee[low] = _raise_knee(hip[low], tgt[low], l1, l2, pole, clear)
        ankle_dir = tgt - knee
        ankle_dir = ankle_dir / np.maximum(np.linalg.norm(ankle_dir, axis=1), 1e-12)[:, None]
        Wt[:, iu] = _rot_between(d1, (knee - hip) / l1) @ W0[iu]
        Wt[:, il] = _rot_between(d2, ankle_dir) @ W0[il]
        # the metapodial (and the digits under it) keep their standing orientation
    # pose quaternions: P_j = W_j,rest^T W_parent,rest W_parent^T W_j
    par = sk.parent
    has_p = par >= 0
    Wp0 = np.where(has_p[:, None, None], W0[np.maximum(par, 0)], np.eye(3))
    Wp = np.where(has_p[None, :, None, None], Wt[:, np.maximum(par, 0)], np.eye(3))
    pose = np.einsum("nji,njk->nik", W0, Wp0)[None] @ np.swapaxes(Wp, -1, -2) @ Wt
    q_ik = tf.matrix_to_quat(pose)
    root = np.tile(sk.offset[0], (total, 1)) + shift
    free = np.array(
        [
            k in ("arm", "wing", "fin") or (k == "spine" and r == "tail")
            for k, r in zip(creature.kind, creature.region, strict=True)
        ]
    )
    amp = np.radians(amplitude_deg)
    for _ in range(5):  # free limbs and tail swing less until they clear the ground
        mo = Motion(sk, tf.quat_multiply(q_ik, _free_limbs(creature, ph, amp)), root, 1.0 / fps)
        if not free.any() or amp == 0.0:
            return mo
        M = mo.world_matrices()[:, free]
        ends = M[..., :3, 3] + M[..., :3, 1] * creature.bone_length[free][None, :, None]
        if min(M[..., 1, 3].min(), ends[..., 1].min()) >= -1e-3 * creature.height:
            return mo
        amp = 0.0 if amp < np.radians(2.0) else 0.5 * amp
    return mo


def _free_limbs(creature: Creature, t: NDArray, amp: float) -> NDArray:
    """Pose quaternions of the limbs without ground contact and the tail (local sines)."""
    n = len(creature)
    angle = np.zeros((len(t), n, 3))  # about local x, y, z
    par = creature.skeleton.parent
    carries = set()  # vertebrae carrying a leg girdle do not sway (planted feet)
    for j in range(n):
        if creature.kind[j] == "leg":
            k = int(par[j])
            while k >= 0:
                carries.add(k)
                k = int(par[k])
    for j, name in enumerate(creature.names):
        k = creature.kind[j]
        parts = name.split("_")
        seg = parts[1] if len(parts) == 3 else ""
        if k in ("arm", "fin", "wing"):
            side = 0.0 if creature.side[j] > 0 else np.pi
            ph = t + side + 0.5 * np.pi
            if k == "wing":
                angle[:, j, 0] = (
                    (1.2 * amp if seg == "upper" else 0.3 * amp)
                    * np.sin(t)
                    * (seg in ("upper", "lower"))
                )
            elif k == "fin":
                angle[:, j, 2] = 0.5 * amp * np.sin(ph) if seg == "upper" else 0.0
            elif seg == "upper":
                angle[:, j, 2] = 0.4 * amp * np.sin(ph)
        elif k == "spine" and creature.region[j] == "tail" and j not in carries:
            angle[:, j, 0] = 0.15 * amp * np.sin(t)
    return tf.euler_to_quat(angle[..., [2, 0, 1]], "ZXY")  # R = Rz Rx Ry


def walk_quality(creature: Creature, motion, plan: WalkPlan) -> dict[str, float]:
    """Foot slide (largest horizontal travel of a contact joint during one stance, as a
    fraction of the stride) and ground penetration (lowest joint or bone end below the
    ground, as a fraction of the body height) of a walk clip made with ``plan``."""
    if not plan.legs:
        return {"slide_fraction": 0.0, "penetration_fraction": 0.0, "stride_m": 0.0}
    M = motion.world_matrices()  # (frames, n, 4, 4)
    P = M[..., :3, 3]
    ends = P + M[..., :3, 1] * creature.bone_length[None, :, None]
    low = float(min(P[..., 1].min(), ends[..., 1].min()))
    distal = {g["distal"]: off for g, off in zip(plan.legs, plan.offsets, strict=True)}
    parent = creature.skeleton.parent
    t = np.arange(motion.n_frames) / plan.fps
    worst = 0.0
    for j in {int(x) for x in creature.contact_joint}:
        k = j
        while k >= 0 and k not in distal:
            k = int(parent[k])
        if k < 0:
            continue
        ph = t / plan.period + distal[k]
        cyc, u = np.floor(ph), ph - np.floor(ph)
        for cnum in np.unique(cyc):
            sel = (cyc == cnum) & (u < plan.duty)
            if sel.sum() >= 2:
                worst = max(worst, float(np.ptp(P[sel, j][:, [0, 2]], axis=0).max()))
    return {
        "slide_fraction": worst / max(plan.stride, 1e-12),
        "penetration_fraction": max(0.0, -low) / max(creature.height, 1e-12),
        "stride_m": plan.stride,
    }
