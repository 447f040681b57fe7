"""Limbs by type: fins, arms, wings and legs with ground contact (seed §5.1, §6.7).

A limb is a chain of three bones (upper, lower, distal: upper arm/forearm/hand or thigh/shank/
foot) hanging from a girdle attachment point. Every joint has three rotational DOF with
limits, as Euler angles ``(z, x, y)`` composed ``R = Rz · Rx · Ry`` relative to the parent
bone's frame; at zero angles a bone points straight down (world −y), z is the lateral axis
(flexion/extension in the sagittal plane), x the forward axis (abduction), y the bone's own
axis (twist). Angles here are for the **right** limb (+z side); left limbs are mirrored.

Limbs without ground contact follow the seed's rules: fins straight back, wings with a random
angle per joint from a per-joint interval; arms rest as their class does (mammals: humerus
along the trunk, elbow flexed; others folded against the body, :data:`FREE_ARM_REST_DEG`)
instead of the seed's upper arm down and forearm 90° forward. Legs with ground contact use
the seed's iterative descent (:func:`descend`): start with every flexion DOF at its most
bent limit; each iteration, for each joint and each DOF chosen with its probability, rotate
by the current step towards the orientation where the bone points straight down (the
seed's comparison of the child's negative local y with world y), clamp at vertical ("gerade
noch erlaubt"), reject a rotation that puts any bone end below the ground, then multiply
the step by 4/5 — and halve it when the contact point moved less than ``stall`` (0.1 frame
px) — down to a minimum step. All constants are :class:`DescentParams` fields with the
seed's values.

Beyond the seed, standing legs get anatomical preferences (``DescentParams.plausible``): the
descent searches a standing box per segment type (:data:`STAND_LIMITS_DEG`; knee, hock and
elbow flex in their anatomical direction only) starting at its most bent corner, rejects
rotations that make the chain less plausible (:func:`implausibility`: a bone pointing up or
too flat, or leaning against its anatomical side, :data:`LEAN_SIDE`), runs ``restarts``
times and keeps the plausible grounded solution with the least flexion from the neutral
standing pose (:data:`NEUTRAL_DEG`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np
from numpy.typing import NDArray

LIMB_TYPES = ("leg", "arm", "wing", "fin")
DEG = np.pi / 180.0


@dataclass(frozen=True)
class DescentParams:
    """Constants of the ground-contact descent (seed §6.7 defaults).

    Lengths are in the seed's annotation units (px of the 1000-px frame); the generator
    converts them with the creature's scale.
    """

    step_deg: float = 30.0  # first step
    shrink: float = 0.8  # ×4/5 per iteration
    stall: float = 0.1  # px: less progress than this halves the step
    min_step_deg: float = 0.05  # steps never get smaller ("bis zu einer Minimalgröße")
    tolerance: float = 0.5  # px: contact counts as reached
    max_iter: int = 120
    p_flex: float = 0.9  # probability a flexion DOF is changed in an iteration
    p_abduct: float = 0.05  # abduction kept rare so legs are not splayed (seed)
    p_twist: float = 0.0  # twist does not move the contact point
    # anatomical preferences of standing legs (new beyond the seed)
    plausible: bool = True  # reject moves that raise a distal joint / turn a bone
    direction_slack_deg: float = 15.0  # how far a bone may lean against its anatomical side
    max_tilt_deg: tuple[float, float, float] = (85.0, 70.0, 70.0)  # bones' tilt from vertical
    restarts: int = 2  # descents from the same start, different random streams;
    #                                 the plausible one closest to the neutral pose is kept
    relax: tuple[float, ...] = ()  # optionally blend towards neutral by these fractions,
    #                                 re-grounding by bisection, while flexion decreases


#: Anatomical limits (degrees) per limb role and joint: rows joint 0..2, columns z, x, y.
#: Hind legs fold zig-zag (thigh forward, shank back, foot forward); fore legs the other way.
LIMITS_DEG = {
    "hind": np.array(
        [
            [[-40, 100], [-60, 25], [-20, 20]],
            [[-150, 0], [-10, 10], [-15, 15]],
            [[0, 150], [-15, 15], [-15, 15]],
        ],
        dtype=float,
    ),
    "fore": np.array(
        [
            [[-100, 40], [-60, 25], [-20, 20]],
            [[0, 150], [-10, 10], [-15, 15]],
            [[-150, 100], [-15, 15], [-15, 15]],
        ],
        dtype=float,
    ),
    "wing": np.array(
        [
            [[-45, 45], [-120, -50], [-30, 30]],
            [[-60, 60], [-20, 20], [-30, 30]],
            [[-60, 60], [-20, 20], [-30, 30]],
        ],
        dtype=float,
    ),
    "fin": np.array(
        [
            [[-120, -60], [-45, 45], [-30, 30]],
            [[-30, 30], [-20, 20], [-20, 20]],
            [[-30, 30], [-20, 20], [-20, 20]],
        ],
        dtype=float,
    ),
    "arm": np.array(
        [
            [[-60, 120], [-60, 25], [-60, 60]],
            [[0, 150], [-10, 10], [-60, 60]],
            [[-60, 60], [-30, 30], [-20, 20]],
        ],
        dtype=float,
    ),
}

#: Per-joint random intervals (degrees) of wing angles (z, x, y): a spread, slightly swept wing.
WING_INTERVALS_DEG = np.array(
    [
        [[-25, 15], [-105, -75], [-10, 10]],
        [[-35, 10], [-10, 10], [-10, 10]],
        [[-10, 35], [-10, 10], [-10, 10]],
    ],
    dtype=float,
)

SPRAWL_DEG = {"erect": 0.0, "crouched": -8.0, "sprawling": -25.0}

#: Search box of the descent for standing legs (degrees; a sub-range of :data:`LIMITS_DEG`,
#: which stay the stored anatomical limits): the hip/shoulder folds at most to a level bone,
#: the knee/elbow and the ankle flex in their anatomical direction only, and the fore wrist
#: of a standing leg is extended (the hand folded back under the forearm is a resting pose).
#: The descent starts at the most bent of these limits.
STAND_LIMITS_DEG = {
    "hind": np.array(
        [
            [[-30, 85], [-60, 25], [-20, 20]],
            [[-150, 0], [-10, 10], [-15, 15]],
            [[0, 150], [-15, 15], [-15, 15]],
        ],
        dtype=float,
    ),
    "fore": np.array(
        [
            [[-85, 30], [-60, 25], [-20, 20]],
            [[0, 150], [-10, 10], [-15, 15]],
            [[-30, 100], [-15, 15], [-15, 15]],
        ],
        dtype=float,
    ),
}

#: Side (world +x forward = +1, backward = -1) each bone of a standing leg leans to, from
#: proximal to distal end: hind legs zig-zag femur forward, shank back, metatarsus forward
#: (mammal knee and hock, and the bird/dinosaur digitigrade pattern); fore legs humerus
#: back, forearm and hand forward (elbow flexes the other way). A bone may lean against its
#: side by ``DescentParams.direction_slack_deg`` and must point down, tilted from vertical by
#: at most ``DescentParams.max_tilt_deg``.
LEAN_SIDE = {"hind": np.array([1.0, -1.0, 1.0]), "fore": np.array([-1.0, 1.0, 1.0])}

#: Neutral standing pose (degrees, flexion z per joint; bones' sagittal directions from
#: vertical: hind femur 30° forward, shank 30° back, metatarsus 15° forward; fore humerus 30°
#: back, forearm vertical, hand 15° forward): the descent's solutions are ranked by their
#: total flexion away from it, measured on the bones' directions (cumulative angles) so that
#: a crouch spreads over all joints instead of folding one.
NEUTRAL_DEG = {"hind": np.array([30.0, -60.0, 45.0]), "fore": np.array([-30.0, 30.0, 15.0])}


def flexion_from_neutral(angles: NDArray, role: str, n_active: int = 3) -> float:
    """Total |difference| (rad) of the bones' sagittal directions (cumulative flexion angles
    of the first ``n_active`` joints) from the neutral standing pose of ``role``."""
    a = np.cumsum(np.asarray(angles, float)[:n_active, 0])
    n = np.cumsum(NEUTRAL_DEG[role][:n_active] * DEG)
    return float(np.abs(a - n).sum())


# --------------------------------------------------------------------------- kinematics
@numba.njit(cache=True)
def _euler_into(a: float, b: float, c: float, out: np.ndarray) -> None:  # pragma: no cover
    """``Rz(a) @ Rx(b) @ Ry(c)`` written into ``out (3, 3)`` without allocating."""
    ca, sa = np.cos(a), np.sin(a)
    cb, sb = np.cos(b), np.sin(b)
    cc, sc = np.cos(c), np.sin(c)
    out[0, 0] = ca * cc - sa * sb * sc
    out[0, 1] = -sa * cb
    out[0, 2] = ca * sc + sa * sb * cc
    out[1, 0] = sa * cc + ca * sb * sc
    out[1, 1] = ca * cb
    out[1, 2] = sa * sc - ca * sb * cc
    out[2, 0] = -cb * sc
    out[2, 1] = sb
    out[2, 2] = cb * cc


@numba.njit(cache=True)
def _matmul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@numba.njit(cache=True)
def _fk(
    base: np.ndarray, lengths: np.ndarray, ang: np.ndarray, rot_out: np.ndarray, pts_out: np.ndarray
) -> None:  # pragma: no cover - compiled
    """Cumulative rotations (3,3,3) and joint points (4,3) of a 3-bone chain."""
    e = np.empty((3, 3))
    for k in range(3):
        pts_out[0, k] = base[k]
    for j in range(3):
        _euler_into(ang[j, 0], ang[j, 1], ang[j, 2], e)
        if j == 0:
            for p in range(3):
                for q in range(3):
                    rot_out[0, p, q] = e[p, q]
        else:
            _matmul_into(rot_out[j - 1], e, rot_out[j])
        for k in range(3):
            pts_out[j + 1, k] = pts_out[j, k] - lengths[j] * rot_out[j, k, 1]


@numba.njit(cache=True)
def _implausible(pts, lengths, contact, side, slack, drop):  # pragma: no cover - compiled
    """How far the chain up to ``contact`` is from a plausible standing leg: the summed
    shortfall of each bone's drop below ``drop[q]`` (cosine of its largest tilt) × its length
    — a distal joint never higher than its proximal one — plus each bone's lean against its
    anatomical ``side`` beyond ``slack`` (sine) × its length. 0 = plausible."""
    v = 0.0
    for q in range(contact):
        dy = pts[q + 1, 1] - pts[q, 1] + drop[q] * lengths[q]
        if dy > 0.0:
            v += dy
        lean = -side[q] * (pts[q + 1, 0] - pts[q, 0]) - slack * lengths[q]
        if lean > 0.0:
            v += lean
    return v


@numba.njit(cache=True)
def _descend_kernel(
    base,
    lengths,
    ang0,
    lo,
    hi,
    prob,
    n_active,
    contact,
    ground,
    step0,
    shrink,
    stall,
    min_step,
    tol,
    max_iter,
    rand,
    plausible,
    side,
    slack,
    drop,
):  # pragma: no cover
    ang = ang0.copy()
    rot = np.zeros((3, 3, 3))
    pts = np.zeros((4, 3))
    _fk(base, lengths, ang, rot, pts)
    eps = 1e-9 * (lengths[0] + lengths[1] + lengths[2])
    viol = _implausible(pts, lengths, contact, side, slack, drop) if plausible else 0.0
    dist = pts[contact, 1] - ground
    step = step0
    it = 0
    down = np.array([0.0, -1.0, 0.0])
    eye = np.eye(3)
    etmp = np.empty((3, 3))
    mtmp = np.empty((3, 3))
    while it < max_iter and dist > tol:
        prev = dist
        for j in range(n_active):
            for k in range(3):
                if rand[it, j, k] >= prob[j, k]:
                    continue
                # world axis of DOF k of joint j (Euler z, x, y composed in that order)
                if j == 0:
                    rp = eye
                else:
                    rp = rot[j - 1]
                if k == 0:
                    w = rp[:, 2].copy()
                else:
                    _euler_into(ang[j, 0], ang[j, 1] if k == 2 else 0.0, 0.0, etmp)
                    _matmul_into(rp, etmp, mtmp)
                    w = mtmp[:, 0].copy() if k == 1 else mtmp[:, 1].copy()
                d = -rot[j][:, 1]
                dp = d - (d @ w) * w
                tp = down - (down @ w) * w
                ndp = np.sqrt(dp @ dp)
                ntp = np.sqrt(tp @ tp)
                if ndp < 1e-9 or ntp < 1e-9:
                    continue
                cr = np.cross(dp, tp)
                theta = np.arctan2(w @ cr, dp @ tp)  # rotation bringing d closest to down
                if abs(theta) < 1e-12:
                    continue
                delta = min(step, abs(theta))  # clamp at vertical
                if theta < 0:
                    delta = -delta
                old = ang[j, k]
                new = min(max(old + delta, lo[j, k]), hi[j, k])
                if new == old:
                    continue
                ang[j, k] = new
                _fk(base, lengths, ang, rot, pts)
                below = False
                for q in range(1, contact + 1):
                    if pts[q, 1] < ground - 1e-9:
                        below = True
                if not below and plausible:
                    v = _implausible(pts, lengths, contact, side, slack, drop)
                    if v > viol + eps:
                        below = True  # never less plausible than before
                    else:
                        viol = v
                if below:
                    ang[j, k] = old
                    _fk(base, lengths, ang, rot, pts)
        dist = pts[contact, 1] - ground
        step = step * shrink
        if prev - dist < stall:
            step = step * 0.5
        if step < min_step:
            step = min_step
        it += 1
    return ang, dist, it


def implausibility(
    points: NDArray,
    lengths: NDArray,
    contact: int,
    role: str,
    params: DescentParams = DescentParams(),
    upper_max_deg: float | None = None,
) -> float:
    """Rise of distal joints plus lean against the anatomical side (see :data:`LEAN_SIDE`)
    of a posed chain ``points (4, 3)``, in length units; 0 for a plausible standing leg.
    ``upper_max_deg`` tightens the upper bone's largest tilt from the vertical (a standing
    femur's class range, :mod:`biomorph.creature.stance`)."""
    return float(
        _implausible(
            np.asarray(points, float),
            np.asarray(lengths, float),
            int(contact),
            LEAN_SIDE[role],
            np.sin(params.direction_slack_deg * DEG),
            _drop(params, upper_max_deg),
        )
    )


def _drop(params: DescentParams, upper_max_deg: float | None = None) -> NDArray[np.float64]:
    """Cosines of the bones' largest tilts from the vertical (the least drop per length)."""
    return _drop_cached(tuple(params.max_tilt_deg), upper_max_deg)


@lru_cache(maxsize=64)
def _drop_cached(max_tilt_deg: tuple, upper_max_deg: float | None) -> NDArray[np.float64]:
    tilt = np.asarray(max_tilt_deg, float).copy()
    if upper_max_deg is not None:
        tilt[0] = min(tilt[0], upper_max_deg)
    out = np.cos(tilt * DEG)
    out.setflags(write=False)
    return out


def descend(
    base: NDArray,
    lengths: NDArray,
    start: NDArray,
    limits: NDArray,
    prob: NDArray,
    ground: float,
    contact: int,
    rng: np.random.Generator,
    params: DescentParams = DescentParams(),
    n_active: int = 3,
    role: str = "hind",
    upper_max_deg: float | None = None,
) -> tuple[NDArray[np.float64], float, int]:
    """Run the seed's ground-contact descent for one 3-bone chain.

    ``base (3,)`` attachment point, ``lengths (3,)``, ``start (3,3)`` angles (rad), ``limits
    (3,3,2)`` rad, ``prob (3,3)`` per-DOF probabilities, ``ground`` height, ``contact`` the
    chain point that should touch (2 = end of the second bone, 3 = tip), ``n_active`` joints
    that may move. Units of lengths/ground/params must agree (frame px by default). With
    ``params.plausible`` a rotation is also rejected when it makes the chain less plausible
    (:func:`implausibility` for ``role`` grows): no joint rises above its proximal one, no
    bone turns against its anatomical side, once reached.
    Returns ``(angles (3,3), remaining distance, iterations)``.
    """
    rand = rng.random((params.max_iter, 3, 3))
    ang, dist, it = _descend_kernel(
        np.asarray(base, float),
        np.asarray(lengths, float),
        np.asarray(start, float),
        np.ascontiguousarray(limits[..., 0]),
        np.ascontiguousarray(limits[..., 1]),
        np.asarray(prob, float),
        int(n_active),
        int(contact),
        float(ground),
        params.step_deg * DEG,
        params.shrink,
        params.stall,
        params.min_step_deg * DEG,
        params.tolerance,
        int(params.max_iter),
        rand,
        bool(params.plausible),
        LEAN_SIDE[role],
        float(np.sin(params.direction_slack_deg * DEG)),
        _drop(params, upper_max_deg),
    )
    return ang, float(dist), int(it)


def forward(
    base: NDArray, lengths: NDArray, angles: NDArray
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Cumulative bone rotations ``(3,3,3)`` (world, bone along −y) and points ``(4,3)``."""
    rot = np.zeros((3, 3, 3))
    pts = np.zeros((4, 3))
    _fk(np.asarray(base, float), np.asarray(lengths, float), np.asarray(angles, float), rot, pts)
    return rot, pts


@numba.njit(cache=True)
def _contact_height(base, lengths, ang, j, a, contact, ground, rot, pts):  # pragma: no cover
    """Height of the chain's ``contact`` point above ``ground`` with flexion ``j`` set to ``a``
    (``ang`` is left as it was)."""
    old = ang[j, 0]
    ang[j, 0] = a
    _fk(base, lengths, ang, rot, pts)
    ang[j, 0] = old
    return pts[contact, 1] - ground


@numba.njit(cache=True)
def _bisect_flexion(base, lengths, ang, j, a0, target, f0, contact, ground):  # pragma: no cover
    """48 bisection steps of flexion ``j`` between ``a0`` (height ``f0``) and ``target``;
    returns the end on or above the ground (the compiled inner loop of :func:`_snap`)."""
    rot = np.zeros((3, 3, 3))
    pts = np.zeros((4, 3))
    a, b = a0, target
    fa = f0
    for _ in range(48):
        m = 0.5 * (a + b)
        fm = _contact_height(base, lengths, ang, j, m, contact, ground, rot, pts)
        if (fm > 0) == (fa > 0):
            a, fa = m, fm
        else:
            b = m
    return a if fa >= 0 else b


def _snap(base, lengths, ang, limits, ground, contact, n_active, accept=None, scan=0):
    """Close the remaining gap exactly: bisect one flexion angle (knee first, then hip, then
    ankle) so the contact point lies on the ground with no bone end below it (and, given
    ``accept(points)``, the result accepted). Works from above or below the ground. Returns
    new angles or ``None``. ``scan`` > 0 (the continuous re-grounding of :func:`reground`)
    brackets the root nearest the current angle (``scan`` steps towards each limit) instead
    of the whole range to a limit, which misses a root when the height rises again."""
    base = np.asarray(base, float)
    lengths = np.asarray(lengths, float)
    ang = np.ascontiguousarray(ang, dtype=float)
    rot = np.zeros((3, 3, 3))
    pts = np.zeros((4, 3))
    ground = float(ground)
    for j in [1, 0, 2] if n_active == 3 else [1, 0]:
        lo, hi = limits[j, 0]
        a0 = float(ang[j, 0])
        f0 = _contact_height(base, lengths, ang, j, a0, contact, ground, rot, pts)
        if f0 == 0.0:
            return ang
        if scan:
            t = _snap_scan(
                base,
                lengths,
                ang,
                j,
                a0,
                f0,
                float(lo),
                float(hi),
                contact,
                ground,
                scan,
                accept,
            )
            if t is not None:
                return t
            continue
        for target in (float(lo), float(hi)):
            ft = _contact_height(base, lengths, ang, j, target, contact, ground, rot, pts)
            if (ft <= 0 <= f0) or (f0 <= 0 <= ft):
                t = _bisected_pose(base, lengths, ang, j, a0, target, f0, contact, ground, accept)
                if t is not None:
                    return t
    return None


def _bisected_pose(base, lengths, ang, j, a, b, fa, contact, ground, accept):
    """The pose with joint ``j``'s flexion bisected in the bracket ``[a, b]`` (height ``fa``
    at ``a``), or ``None`` when a bone end dips below the ground or ``accept`` refuses it."""
    t = ang.copy()
    t[j, 0] = _bisect_flexion(base, lengths, ang, j, a, b, fa, contact, ground)
    _, p = forward(base, lengths, t)
    scale = max(float(np.sum(lengths)), 1e-9)
    if np.all(p[1 : contact + 1, 1] >= ground - 1e-6 * scale) and (accept is None or accept(p)):
        return t
    return None


def _snap_scan(base, lengths, ang, j, a0, f0, lo, hi, contact, ground, scan, accept):
    """:func:`_snap` for one joint, the root nearest ``a0``: steps of 1/``scan`` of the way
    to either limit, alternating, bisecting the first bracket whose result is accepted."""
    rot = np.zeros((3, 3, 3))
    pts = np.zeros((4, 3))
    prev = {lo: (a0, f0), hi: (a0, f0)}
    for k in range(1, scan + 1):
        for target in (lo, hi):
            a_prev, f_prev = prev[target]
            a_k = a0 + (target - a0) * k / scan
            f_k = _contact_height(base, lengths, ang, j, a_k, contact, ground, rot, pts)
            prev[target] = (a_k, f_k)
            if not ((f_k <= 0 <= f_prev) or (f_prev <= 0 <= f_k)):
                continue
            t = _bisected_pose(base, lengths, ang, j, a_prev, a_k, f_prev, contact, ground, accept)
            if t is not None:
                return t
    return None


def reground(
    pose: LimbPose,
    base: NDArray,
    lengths: NDArray,
    ground: float,
    params: DescentParams = DescentParams(),
    continuous: bool = False,
) -> LimbPose | None:
    """Move a posed leg to a new attachment ``base`` keeping its joint angles, then close the
    (small) vertical gap by bisection — a continuous re-grounding used by balance repair.
    ``continuous`` (the bipeds' repair): a contact at most ``params.tolerance`` above the
    ground keeps the angles (the descent's own acceptance: a leg it left a fraction of a px
    above the ground is not re-snapped), and the bisection takes the root nearest the
    current angle (:func:`_snap`'s ``scan``). Returns ``None`` if the leg cannot reach."""
    plant = pose.foot_flat
    contact, n_active = (2, 2) if plant else (3, 3)
    box = pose.box if pose.box is not None else STAND_LIMITS_DEG[pose.role] * DEG
    if not params.plausible:
        box = pose.limits
    ang = None
    if continuous:
        _, p = forward(base, lengths, pose.angles)
        gap = float(p[contact, 1] - ground)
        eps = 1e-9 * float(np.sum(lengths))
        if -eps <= gap <= params.tolerance and np.all(p[1 : contact + 1, 1] >= ground - eps):
            ang = pose.angles.copy()
    if ang is None:
        ang = _snap(
            np.asarray(base, float),
            np.asarray(lengths, float),
            pose.angles.copy(),
            box,
            ground,
            contact,
            n_active,
            _plausible_test(lengths, contact, pose.role, params, pose.upper_max_deg),
            8 if continuous else 0,
        )
    if ang is None:
        return None
    if plant:
        cum_z = ang[0, 0] + ang[1, 0]
        ang[2] = [np.clip(np.pi / 2 - cum_z, *pose.limits[2, 0]), 0.0, 0.0]
    rot, pts = forward(base, lengths, ang)
    if np.any(pts[1:, 1] < ground - 1e-6 * float(np.sum(lengths))):
        return None
    c = pts[2 if plant else 3].copy()
    return LimbPose(
        "leg",
        pose.role,
        ang,
        pose.limits,
        rot,
        pts,
        c,
        plant,
        float(c[1] - ground),
        0,
        np.asarray(lengths, float),
        pose.box,
        pose.upper_max_deg,
    )


def _relax(base, lengths, ang, box, ground, contact, n_active, role, accept, fractions):
    """Spread the flexion: blend the flexion angles towards the neutral standing pose by each
    fraction in turn and close the gap again by bisection (:func:`_snap`); keep a blend when
    it is grounded, plausible and flexes less in total (the preferred solution)."""
    neutral = NEUTRAL_DEG[role][:n_active] * DEG

    def flex(a):
        return flexion_from_neutral(a, role, n_active)

    cur, cost = ang, flex(ang)
    for lam in fractions:
        t = cur.copy()
        t[:n_active, 0] = np.clip(
            cur[:n_active, 0] + lam * (neutral - cur[:n_active, 0]),
            box[:n_active, 0, 0],
            box[:n_active, 0, 1],
        )
        t = _snap(base, lengths, t, box, ground, contact, n_active, accept)
        if t is not None and flex(t) < cost:
            cur, cost = t, flex(t)
    return cur


def _plausible_test(lengths, contact, role, params, upper_max_deg=None):
    """``accept(points)`` for :func:`_snap`: the chain is a plausible standing leg."""
    if not params.plausible:
        return None
    tol = 0.002 * float(np.sum(lengths))
    return lambda p: implausibility(p, lengths, contact, role, params, upper_max_deg) <= tol


@dataclass(frozen=True)
class LimbPose:
    """Result of posing one (right) limb: angles, limits and the chain geometry."""

    kind: str  # leg | arm | wing | fin
    role: str  # fore | hind (which limit table)
    angles: NDArray[np.float64]  # (3, 3) z, x, y per joint, rad
    limits: NDArray[np.float64]  # (3, 3, 2) rad
    rotations: NDArray[np.float64]  # (3, 3, 3) cumulative world rotations (bone along -y)
    points: NDArray[np.float64]  # (4, 3) attach, two joints, tip
    contact: NDArray[np.float64] | None  # contact point (3,) for legs
    foot_flat: bool  # plantigrade: distal bone lies on the ground
    residual: float  # remaining contact distance (same units as input)
    iterations: int
    lengths: NDArray[np.float64] | None = None  # final segment lengths (if stretched)
    box: NDArray[np.float64] | None = None  # (3, 3, 2) rad: the standing box searched
    upper_max_deg: float | None = None  # the upper bone's largest tilt from the vertical


def pose_leg(
    base: NDArray,
    lengths: NDArray,
    ground: float,
    role: str,
    stance: str,
    posture: str,
    rng: np.random.Generator,
    params: DescentParams = DescentParams(),
    foot_clearance: float = 0.0,
    hip_max_deg: float | None = None,
    lean_max_deg: float | None = None,
    hip_min_deg: float | None = None,
) -> LimbPose:
    """Pose a leg with ground contact by the seed's descent.

    ``hip_max_deg`` (hind legs): the femur's largest tilt from the vertical, in 3-D (its
    flexion and abduction together; a class range of :mod:`biomorph.creature.stance`).
    ``lean_max_deg``: the upper bone's largest sagittal flexion to its anatomical side (hind
    femur forward, fore humerus back) — the generator uses it to keep the hind knees behind
    the front elbows. ``hip_min_deg`` (hind legs): the femur's least forward flexion (birds
    hold the femur forward).

    Digitigrade/unguligrade: the tip of the distal bone comes down to ``ground +
    foot_clearance`` (the height its digits need to reach the ground, e.g. an ungulate's
    pastern). Plantigrade: the wrist/ankle comes down to ``ground + foot_clearance`` and the
    distal bone is laid flat, pointing forward (the ankle angle is then set, not searched).
    """
    limits = LIMITS_DEG[role] * DEG
    box = STAND_LIMITS_DEG[role] * DEG if params.plausible else limits
    # most bent flexion: hind thigh forward (max), shank back (min), foot forward (max)
    start = start_pose(role, posture, params.plausible)
    upper_max = hip_max_deg if role == "hind" and params.plausible else None
    if params.plausible and (upper_max is not None or lean_max_deg is not None):
        # a standing femur stays this far from the vertical (class ranges, stance.py), the
        # upper bone leans at most lean_max_deg to its side
        caps = [c for c in (upper_max, lean_max_deg) if c is not None]
        box = box.copy()
        if role == "hind":
            box[0, 0, 1] = max(min(box[0, 0, 1], min(caps) * DEG), box[0, 0, 0])
            start[0, 0] = box[0, 0, 1]
        elif lean_max_deg is not None:
            box[0, 0, 0] = min(max(box[0, 0, 0], -lean_max_deg * DEG), box[0, 0, 1])
            start[0, 0] = box[0, 0, 0]
    if params.plausible and hip_min_deg is not None and role == "hind":
        box = box.copy()
        box[0, 0, 0] = min(max(box[0, 0, 0], hip_min_deg * DEG), box[0, 0, 1])
    prob = np.array([[params.p_flex, params.p_abduct, params.p_twist]] * 3)
    plant = stance == "plantigrade"
    contact = 2 if plant else 3
    n_active = 2 if plant else 3
    g = ground + foot_clearance
    lengths = np.asarray(lengths, float)
    for _ in range(30):  # a leg whose folded start pierces the ground is shortened (as the
        _, p0 = forward(base, lengths, start)  # generator does): it cannot stand plausibly
        if p0[1:, 1].min() >= g:
            break
        lengths = lengths * 0.9
    accept = _plausible_test(lengths, contact, role, params, upper_max)
    vtol = 0.002 * float(np.sum(lengths))
    best, best_key = None, None
    for _ in range(max(1, params.restarts)):
        ang, dist, it = descend(
            base, lengths, start, box, prob, g, contact, rng, params, n_active, role, upper_max
        )
        if dist > params.tolerance:
            snapped = _snap(
                np.asarray(base, float),
                np.asarray(lengths, float),
                ang,
                box,
                g,
                contact,
                n_active,
                accept,
            )
            if snapped is not None:
                ang = snapped
        _, p = forward(base, lengths, ang)
        gap = max(float(p[contact, 1] - g), 0.0)
        bad = (
            implausibility(p, lengths, contact, role, params, upper_max) > vtol
            if params.plausible
            else False
        )
        # plausible first, then on the ground, then least flexion away from neutral
        key = (bad, gap > params.tolerance, flexion_from_neutral(ang, role, n_active))
        if best_key is None or key < best_key:
            best, best_key = (ang, it), key
    ang, it = best
    if params.plausible and not best_key[0] and not best_key[1]:
        ang = _relax(
            np.asarray(base, float),
            np.asarray(lengths, float),
            ang,
            box,
            g,
            contact,
            n_active,
            role,
            accept,
            params.relax,
        )
    rot, pts = forward(base, lengths, ang)
    resid0 = pts[contact, 1] - g
    if resid0 > params.tolerance and base[1] - pts[contact, 1] > 1e-9:
        # last resort: scale the chain about the attachment so the contact touches exactly
        f = (base[1] - g) / (base[1] - pts[contact, 1])
        if np.all(base[1] + f * (pts[1 : contact + 1, 1] - base[1]) >= g - 1e-9):
            lengths = np.asarray(lengths, float) * f
            rot, pts = forward(base, lengths, ang)
    if plant:
        # lay the distal bone flat, pointing forward: cumulative z-angle of +90°
        cum_z = ang[0, 0] + ang[1, 0]
        ang[2] = [np.clip(np.pi / 2 - cum_z, *limits[2, 0]), 0.0, 0.0]
        rot, pts = forward(base, lengths, ang)
        if pts[3, 1] < g - 1e-6 * float(np.sum(lengths)) or pts[3, 1] > g + 0.003 * float(
            np.sum(lengths)
        ):
            # the foot cannot lie flat within the ankle's limits: stand on the toes instead
            return pose_leg(
                base,
                lengths,
                ground,
                role,
                "digitigrade",
                posture,
                rng,
                params,
                hip_max_deg=hip_max_deg,
                lean_max_deg=lean_max_deg,
                hip_min_deg=hip_min_deg,
            )
        contact_pt = pts[2].copy()
    else:
        contact_pt = pts[3].copy()
    resid = float(contact_pt[1] - g)
    return LimbPose(
        "leg",
        role,
        ang,
        limits,
        rot,
        pts,
        contact_pt,
        plant,
        resid,
        it,
        np.asarray(lengths, float),
        box if params.plausible else None,
        upper_max,
    )


#: Resting pose of a free arm (degrees of flexion z at shoulder, elbow, wrist; + swings
#: forward): ``humerus`` is added to the trunk's own lean (the humerus lies along the trunk,
#: from the shoulder towards the hip) and clipped to ``humerus_range`` (from vertical).
#: Mammals (primates, kangaroos standing): humerus near vertical along the trunk, elbow
#: flexed 40° (the middle of the 30–90° users see in standing primates and kangaroos;
#: a relaxed human elbow rests at ~15–30°), hand continuing the forearm. Other classes
#: (theropods, birds without wings, amphibians): the arm folded against the body as in
#: theropod resting poses (Senter & Robins 2005; Senter 2006): humerus retracted 30° behind
#: the trunk line, elbow flexed 100°, wrist folded 60° back towards the forearm.
#: Where the rest pose would put the fingertips ahead of ``front`` (the head), the arm takes
#: the pose nearest to it (5° grid) inside the class's ranges (``elbow_range``,
#: ``wrist_range``) whose fingertips stay behind: a long arm folds rather than reaching out.
FREE_ARM_REST_DEG = {
    "mammal": {
        "humerus": 0.0,
        "humerus_range": (-30.0, 10.0),
        "elbow": 40.0,
        "elbow_range": (30.0, 90.0),
        "wrist": 0.0,
        "wrist_range": (-45.0, 0.0),
    },
    "folded": {
        "humerus": -30.0,
        "humerus_range": (-60.0, 0.0),
        "elbow": 100.0,
        "elbow_range": (60.0, 150.0),
        "wrist": -60.0,
        "wrist_range": (-60.0, 0.0),
    },
}


def free_arm_rest(
    cls: str,
    trunk_lean: float,
    base: NDArray | None = None,
    lengths: NDArray | None = None,
    front: float | None = None,
    floor: float | None = None,
) -> NDArray[np.float64]:
    """Resting flexion angles ``(3,)`` rad of a free arm for class ``cls`` whose trunk leans
    forward by ``trunk_lean`` rad (the shoulder ahead of the hip; 0 for an upright trunk,
    π/2 for a horizontal one). With ``base``, ``lengths`` (upper, lower, hand + fingers),
    ``front`` and ``floor``, the arm keeps every joint and its fingertips at y ≥ ``floor``
    and the fingertips at x ≤ ``front``: the pose nearest the rest pose on a 5° grid of the
    class's ranges that does (above the floor first, then the least far forward)."""
    r = FREE_ARM_REST_DEG["mammal" if cls == "mammal" else "folded"]
    lo, hi = r["humerus_range"]
    rest = np.array([np.clip(r["humerus"] - trunk_lean / DEG, lo, hi), r["elbow"], r["wrist"]])
    if base is None or lengths is None or (front is None and floor is None):
        return rest * DEG
    L = np.asarray(lengths, float)
    front = np.inf if front is None else float(front)
    floor = -np.inf if floor is None else float(floor)

    def chain(a):  # sagittal chain: bone k points at the summed flexion from straight down
        c = np.cumsum(a * DEG, axis=-1)
        x = float(base[0]) + np.cumsum(L * np.sin(c), axis=-1)
        y = float(base[1]) - np.cumsum(L * np.cos(c), axis=-1)
        return x[..., -1], y.min(axis=-1)

    x, low = chain(rest)
    if x <= front and low >= floor:
        return rest * DEG
    cand, sin_c, cos_c = _arm_grid("mammal" if cls == "mammal" else "folded")
    best = _arm_pick(cand, sin_c, cos_c, L, float(base[0]), float(base[1]), front, floor, rest)
    if best < 0:
        return rest * DEG  # nothing in the ranges clears the ground: lift_clear folds it
    return cand[best] * DEG


@numba.njit(cache=True)
def _arm_pick(cand, sin_c, cos_c, L, bx, by, front, floor, rest):  # pragma: no cover
    """:func:`free_arm_rest`'s grid search compiled (``chain`` on every grid pose with the
    grid's sines and cosines, the same sums in the same order): among the poses whose joints
    and fingertips stay at or above ``floor``, the first of least summed |difference| from
    ``rest`` with the fingertips at or behind ``front``, else the first with the fingertips
    furthest back; -1 when no pose clears the floor."""
    best, best_cost = -1, np.inf
    back, back_x = -1, np.inf
    for i in range(cand.shape[0]):
        sx = 0.0
        sy = 0.0
        low = np.inf
        for k in range(3):
            tx = L[k] * sin_c[i, k]
            ty = L[k] * cos_c[i, k]
            sx = tx if k == 0 else sx + tx
            sy = ty if k == 0 else sy + ty
            low = min(low, by - sy)
        if not low >= floor:
            continue
        x = bx + sx
        if x < back_x:
            back, back_x = i, x
        if x <= front:
            c = 0.0
            for k in range(3):
                c += abs(cand[i, k] - rest[k])
            if c < best_cost:
                best, best_cost = i, c
    if best >= 0 and np.isfinite(best_cost):
        return best
    return back


@lru_cache(maxsize=4)
def _arm_grid(rest: str) -> tuple[NDArray, NDArray, NDArray]:
    """The 5° grid of a free arm's flexion ranges (:func:`free_arm_rest`), ``(k, 3)`` degrees,
    with the sines and cosines of its cumulative angles (what ``chain`` computes)."""
    r = FREE_ARM_REST_DEG[rest]
    ranges = (r["humerus_range"], r["elbow_range"], r["wrist_range"])
    grid = [np.arange(a, b + 1e-9, 5.0) for a, b in ranges]
    cand = np.stack(np.meshgrid(*grid, indexing="ij"), axis=-1).reshape(-1, 3)
    c = np.cumsum(cand * DEG, axis=-1)
    out = (cand, np.sin(c), np.cos(c))
    for a in out:
        a.setflags(write=False)
    return out


def pose_free(
    kind: str,
    base: NDArray,
    lengths: NDArray,
    rng: np.random.Generator,
    splay_deg: float = 12.0,
    cls: str = "mammal",
    trunk_lean: float = 0.0,
    front: float | None = None,
    finger_share: float = 0.0,
    floor: float | None = None,
) -> LimbPose:
    """Pose a limb without ground contact: ``fin``, ``arm`` or ``wing`` (seed §5.1); an arm
    takes its class's resting pose (:func:`free_arm_rest`) instead of the seed's
    forearm-90°-forward, which held long arms straight out ahead of the head; ``front`` is
    the x its fingertips (``finger_share`` × the hand beyond the hand) stay behind and
    ``floor`` the height they and the joints stay above."""
    role = {"fin": "fin", "arm": "arm", "wing": "wing"}[kind]
    limits = LIMITS_DEG[role] * DEG
    ang = np.zeros((3, 3))
    if kind == "fin":
        ang[0, 0] = -np.pi / 2  # straight back (world -x)
        ang[0, 1] = -splay_deg * DEG  # a little outwards
    elif kind == "arm":
        reach = np.asarray(lengths, float) * [1.0, 1.0, 1.0 + finger_share]
        ang[:, 0] = free_arm_rest(cls, trunk_lean, base, reach, front, floor)
    else:
        iv = WING_INTERVALS_DEG * DEG
        ang = rng.uniform(iv[..., 0], iv[..., 1])
    ang = np.clip(ang, limits[..., 0], limits[..., 1])
    rot, pts = forward(base, lengths, ang)
    return LimbPose(kind, role, ang, limits, rot, pts, None, False, 0.0, 0)


def moved(pose: LimbPose, base: NDArray, lengths: NDArray) -> LimbPose:
    """A free limb's pose with the same joint angles at a new attachment ``base``."""
    rot, pts = forward(base, lengths, pose.angles)
    return LimbPose(pose.kind, pose.role, pose.angles, pose.limits, rot, pts, None, False, 0.0, 0)


def lift_clear(
    pose: LimbPose, base: NDArray, lengths: NDArray, ground: float, clearance: float
) -> LimbPose:
    """Swing a free limb backwards/up in 15° steps until no bone end is below the ground."""
    ang = pose.angles.copy()
    lim = pose.limits
    for _ in range(12):
        rot, pts = forward(base, lengths, ang)
        if np.all(pts[1:, 1] >= ground + clearance):
            return LimbPose(pose.kind, pose.role, ang, lim, rot, pts, None, False, 0.0, 0)
        # fold: proximal joint backwards, then distal joints towards the proximal bone
        if ang[0, 0] - 15 * DEG >= lim[0, 0, 0]:
            ang[0, 0] -= 15 * DEG
        elif ang[1, 0] + 15 * DEG <= lim[1, 0, 1]:
            ang[1, 0] += 15 * DEG
        else:
            ang[0, 1] = max(ang[0, 1] - 15 * DEG, lim[0, 1, 0])
    rot, pts = forward(base, lengths, ang)
    return LimbPose(pose.kind, pose.role, ang, lim, rot, pts, None, False, 0.0, 0)


def start_pose(role: str, posture: str, standing: bool = True) -> NDArray[np.float64]:
    """The descent's start: every flexion DOF at its most bent limit (of the standing box
    :data:`STAND_LIMITS_DEG` unless ``standing=False``), posture abduction (a fresh array)."""
    return _start_pose(role, posture, bool(standing)).copy()


@lru_cache(maxsize=64)
def _start_pose(role: str, posture: str, standing: bool) -> NDArray[np.float64]:
    limits = (STAND_LIMITS_DEG if standing else LIMITS_DEG)[role] * DEG
    start = np.zeros((3, 3))
    start[:, 0] = (
        [limits[0, 0, 1], limits[1, 0, 0], limits[2, 0, 1]]
        if role == "hind"
        else [limits[0, 0, 0], limits[1, 0, 1], limits[2, 0, 0]]
    )
    start[0, 1] = np.clip(SPRAWL_DEG.get(posture, 0.0) * DEG, limits[0, 1, 0], limits[0, 1, 1])
    return start


def max_reach(lengths: NDArray, stance: str, posture: str) -> float:
    """Vertical reach of the straightened leg (down to the contact point), with the posture's
    fixed abduction."""
    abd = abs(SPRAWL_DEG.get(posture, 0.0)) * DEG
    L = np.asarray(lengths, float)
    reach = L[0] * np.cos(abd) + L[1]
    if stance != "plantigrade":
        reach += L[2]
    return float(reach)
