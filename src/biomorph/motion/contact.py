"""Foot contacts: detection with hysteresis and locking by analytic two-bone IK.

Detection (:func:`detect_contacts`), per foot (a joint named ``*foot*``/``*ankle*``) and its
toe (a child named ``*toe*``): a point is *planted* when it is low and slow — height above
the ground below ``height`` × body scale and horizontal speed below ``speed`` × body scale
per second — and stays planted until it rises above ``height × hysteresis`` or moves faster
than ``speed × hysteresis`` (Schmitt trigger, so noise at the threshold does not flicker).
Ground and body scale are measured on the clip exactly as the foot-skate metric of
:mod:`biomorph.motion.quality` measures them (2nd height percentile of the feet; median hip
height above it), so the constants are fractions of the character, not of a file's units:

* ``height = 0.04`` above the point's own resting height (its 2nd height percentile): half
  the metric's 8 % band (which is measured from the floor), ≈ 3.5 cm on an adult — an ankle
  rising at heel-off leaves contact, the toe stays;
* ``speed = 1.0`` body scales per second: a walking body moves about one leg length per
  second (Xia walk 0.9 m/s, hip 0.9 m), a planted foot far less, a swinging foot 2–3×;
* ``hysteresis = 1.5``; ``min_s`` = 0.05 s (shorter contacts are ignored);
* ``blend_s = 0.2`` s fade in/out (≥ 1 frame): **chosen on the shared captures** (0.1 / 0.2 /
  0.3 s compared with ``bench/motion.py --skate``; 0.1 s released a held slide within 3
  frames at 30 fps and raised the skate metric of the Xia walk above its input), so it is a
  fitted value to check on other captures.

Locking (:func:`lock_feet`), ``mode="hold"``: during each contact the planted point is held
at the median position of its slower half of frames — cleaning a clip that skates;
with a *reference* clip (the input of an operator that keeps timing: equalize, edit,
layers) the contacts and their held positions come from the reference, so an edit cannot
lift the feet or push them through the floor. ``mode="follow"``: the point follows where
the reference had it frame by frame (the input's own slide is kept; measured worse on the
shared walks than holding, so not the default). ``"auto"`` (default) = ``"hold"``.
In both modes the leg (hip → knee → ankle) is solved analytically so the
ankle lands on the target with the knee kept in its plane (the knee's side of the hip–ankle
line is kept), the foot keeps its world orientation (so the toe follows), and the weight
fades in and out over ``blend_s``. Targets out of reach are clamped to the leg's length
with one :class:`ContactWarning` (never NaN).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from numpy.typing import NDArray

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, frozen, guess_up_axis
from biomorph.core.types import Array
from biomorph.errors import ParameterError

_UP = {"x": 0, "y": 1, "z": 2}


class ContactWarning(UserWarning):
    """A contact target was out of the leg's reach and was clamped."""


@dataclass(frozen=True)
class ContactOptions:
    """Foot-contact detection and locking (see the module docstring for each constant)."""

    enabled: bool = True
    height: float = 0.04
    speed: float = 1.0
    hysteresis: float = 1.5
    blend_s: float = 0.2
    min_s: float = 0.05
    up: str | None = None
    mode: str = "auto"

    def __post_init__(self) -> None:
        if self.mode not in ("auto", "hold", "follow"):
            raise ParameterError(f"contact mode {self.mode!r}; expected auto, hold or follow")
        for name in ("height", "speed", "hysteresis", "blend_s", "min_s"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v < 0 or (name == "hysteresis" and v < 1):
                raise ParameterError(
                    f"contact {name} {v!r}; expected a finite number >= "
                    f"{1 if name == 'hysteresis' else 0}"
                )


@dataclass(frozen=True)
class Leg:
    """Joint indices of one leg: ``hip → knee → ankle`` and the ankle's toe (or -1)."""

    hip: int
    knee: int
    ankle: int
    toe: int


def find_legs(motion: Motion) -> list[Leg]:
    """Every foot joint (``foot``/``ankle`` in the name, not ``toe``) with a parent and a
    grandparent; the toe is its first child named ``toe`` (else its first child)."""
    par = motion.skeleton.parent
    names = [s.lower() for s in motion.names]
    legs = []
    for j, s in enumerate(names):
        if ("foot" in s or "ankle" in s) and "toe" not in s and "index" not in s:
            knee = int(par[j])
            if knee < 0 or par[knee] < 0:
                continue
            kids = [int(c) for c in np.flatnonzero(par == j)]
            toes = [c for c in kids if "toe" in names[c]] or kids
            legs.append(Leg(int(par[knee]), knee, j, toes[0] if toes else -1))
    return legs


def _ground_and_scale(w: Array, legs: list[Leg], ui: int) -> tuple[float, float]:
    pts = [lg.ankle for lg in legs] + [lg.toe for lg in legs if lg.toe >= 0]
    h = w[:, pts, ui]
    ground = float(np.percentile(h, 2))
    scale = float(np.median(w[:, 0, ui] - ground))
    return ground, scale if scale > 0 else float(np.ptp(w[..., ui]) or 1.0)


@njit(cache=True)
def _schmitt(low_on, low_off):  # pragma: no cover - compiled
    """On where ``low_on``; stays on while ``low_off`` (the looser test)."""
    out = np.zeros(low_on.shape, dtype=np.bool_)
    state = False
    for k in range(low_on.size):
        state = low_off[k] if state else low_on[k]
        out[k] = state
    return out


def detect_contacts(
    motion: Motion, options: ContactOptions | None = None, world: Array | None = None
) -> dict[int, NDArray[np.bool_]]:
    """Planted frames per contact point (joint index → ``bool[f]``), ankles and toes."""
    o = options or ContactOptions()
    legs = find_legs(motion)
    if not legs or motion.n_frames < 2:
        return {}
    ui = _UP[(o.up or motion.meta.get("up_guess") or guess_up_axis(motion)).lower()]
    w = motion.world_positions() if world is None else world
    ground, scale = _ground_and_scale(w, legs, ui)
    horiz = [a for a in range(3) if a != ui]
    out = {}
    for j in {p for lg in legs for p in (lg.ankle, lg.toe) if p >= 0}:
        # each point against its own resting height (an ankle stands above the floor)
        h = (w[:, j, ui] - max(ground, float(np.percentile(w[:, j, ui], 2)))) / scale
        v = np.linalg.norm(np.gradient(w[:, j][:, horiz], axis=0), axis=-1) * motion.fps / scale
        on = _schmitt(
            (h < o.height) & (v < o.speed),
            (h < o.height * o.hysteresis) & (v < o.speed * o.hysteresis),
        )
        out[j] = _drop_short(on, max(1, round(o.min_s * motion.fps)))
    return out


def _drop_short(on: NDArray[np.bool_], min_len: int) -> NDArray[np.bool_]:
    on = on.copy()
    for s, e in _runs(on):
        if e - s < min_len:
            on[s:e] = False
    return on


def _runs(on: NDArray[np.bool_]) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], on.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def _targets(
    on: NDArray[np.bool_], pts: Array, blend: int, follow: bool = False
) -> tuple[Array, Array]:
    """Per frame the held position of the nearest contact and its weight (1 inside a
    contact, smoothstep fade over ``blend`` frames outside, 0 elsewhere). The held position
    is the median position of the contact's slower half of frames: a foot still gliding in
    at the first frame is not frozen mid-glide, and a slide is split between the fade in
    and the fade out instead of released all at once."""
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    step = np.linalg.norm(np.gradient(pts, axis=0), axis=-1) if on.size > 1 else np.zeros(on.size)
    runs = np.asarray(_runs(on), dtype=np.int64).reshape(-1, 2)
    tgt = np.array(pts)
    wgt = np.zeros(on.size)
    _targets_kernel(pts, step, runs, int(blend), bool(follow), tgt, wgt)
    return tgt, wgt


@njit(cache=True)
def _targets_kernel(pts, step, runs, blend, follow, tgt, wgt):  # pragma: no cover - compiled
    f = pts.shape[0]
    dist = np.full(f, np.inf)
    for r in range(runs.shape[0]):
        s, e = runs[r, 0], runs[r, 1]
        st = step[s:e]
        cut = np.median(st)
        sel = pts[s:e][st <= cut]
        p = np.empty(3)
        for a in range(3):
            p[a] = np.median(sel[:, a])
        for k in range(max(0, s - blend), min(f, e + blend)):
            d = float(s - k) if k < s else (float(k - e + 1) if k >= e else 0.0)
            if d >= dist[k]:
                continue
            dist[k] = d
            wk = min(max(1.0 - d / (blend + 1), 0.0), 1.0)
            wk = wk * wk * (3.0 - 2.0 * wk)
            if wk > 0:
                wgt[k] = wk
                for a in range(3):
                    tgt[k, a] = pts[k, a] if follow else p[a]


def _unit(v: Array) -> Array:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def _arc(a: Array, b: Array) -> Array:
    """Shortest-arc quaternions rotating unit vectors ``a`` onto ``b`` (per row)."""
    c = np.cross(a, b)
    d = np.einsum("ij,ij->i", a, b)
    q = np.concatenate([c, (1.0 + d)[:, None]], axis=1)
    anti = q[:, 3] < 1e-9  # opposite vectors: any perpendicular axis, 180°
    if anti.any():
        perp = np.cross(a[anti], np.eye(3)[np.argmin(np.abs(a[anti]), axis=1)])
        q[anti] = np.concatenate([_unit(perp), np.zeros((anti.sum(), 1))], axis=1)
    return tf.quat_normalize(q)


def two_bone_ik(hip: Array, knee: Array, ankle: Array, target: Array) -> tuple[Array, Array, int]:
    """World rotations ``(r_hip, r_knee)`` (f, 4) that move the ankle of the chain
    ``hip → knee → ankle`` (positions ``(f, 3)``) onto ``target``: ``r_hip`` turns the thigh,
    ``r_knee`` then turns the shin (both applied in world space, about the hip and the new
    knee). The knee stays in the plane of hip, knee and ankle on its side. Returns the count
    of frames whose target was more than 1 % out of reach (every target is clamped to the
    reachable distance)."""
    l1 = np.linalg.norm(knee - hip, axis=-1)
    l2 = np.linalg.norm(ankle - knee, axis=-1)
    to_t = target - hip
    d = np.linalg.norm(to_t, axis=-1)
    lo = np.abs(l1 - l2) + 1e-9 * (l1 + l2)
    hi = (l1 + l2) * (1 - 1e-9)
    # a stance leg is often straight: count only targets more than 1 % beyond its reach
    clamped = int(np.count_nonzero((d > 1.01 * (l1 + l2)) | (d < 0.99 * lo)))
    dc = np.clip(d, lo, hi)
    u = _unit(np.where(d[:, None] > 1e-12, to_t, ankle - hip))
    bend = (knee - hip) - np.einsum("ij,ij->i", knee - hip, u)[:, None] * u
    fallback = _unit(np.cross(u, np.cross(ankle - hip, knee - hip) + 1e-12))
    v = np.where(
        np.linalg.norm(bend, axis=-1, keepdims=True) > 1e-9 * l1[:, None], _unit(bend), fallback
    )
    cos_a = np.clip((l1**2 + dc**2 - l2**2) / (2 * l1 * dc), -1.0, 1.0)
    new_knee = hip + l1[:, None] * (cos_a[:, None] * u + np.sqrt(1 - cos_a**2)[:, None] * v)
    new_ankle = hip + dc[:, None] * u
    r_hip = _arc(_unit(knee - hip), _unit(new_knee - hip))
    shin = tf.quat_rotate(r_hip, ankle - knee)
    r_knee = _arc(_unit(shin), _unit(new_ankle - new_knee))
    return r_hip, r_knee, clamped


def lock_feet(
    motion: Motion, reference: Motion | None = None, options: ContactOptions | None = None
) -> Motion:
    """``motion`` with planted feet held in place (see the module docstring).

    Contacts and their held positions come from ``reference`` when given (same frame count
    and joints: the input of an operator that keeps timing, so an edit cannot lift or slide
    the feet), else from ``motion`` itself. Returns ``motion`` unchanged when the skeleton has
    no legs or locking is disabled."""
    o = options or ContactOptions()
    legs = find_legs(motion)
    if not o.enabled or not legs or motion.n_frames < 2:
        return motion
    ref = motion
    if (
        reference is not None
        and reference.n_frames == motion.n_frames
        and reference.names == motion.names
    ):
        ref = reference
    opts = o if o.up is not None else replace(o, up=ref.meta.get("up_guess") or guess_up_axis(ref))
    follow = o.mode == "follow"
    pos, wq = motion._fk(None)
    w_ref = pos if ref is motion else ref.world_positions()
    contacts = detect_contacts(ref, opts, w_ref)
    blend = max(1, round(o.blend_s * motion.fps))
    changed: list[int] = []
    rot = np.array(motion.rotation)
    rest = motion.skeleton.rest_rotation
    par = motion.skeleton.parent
    clamped = 0
    for lg in legs:
        on_a = contacts.get(lg.ankle, np.zeros(motion.n_frames, bool))
        on_t = (
            contacts.get(lg.toe, np.zeros(motion.n_frames, bool))
            if lg.toe >= 0
            else np.zeros(motion.n_frames, bool)
        )
        if not (on_a.any() or on_t.any()):
            continue
        # the ankle target: held ankle while the ankle is planted; while only the toe is
        # planted (heel off), the held toe minus the toe's current offset from the ankle
        ta, wa = _targets(on_a, w_ref[:, lg.ankle], blend, follow)
        goal = pos[:, lg.ankle] + wa[:, None] * (ta - pos[:, lg.ankle])
        if lg.toe >= 0:
            tt, wt = _targets(on_t, w_ref[:, lg.toe], blend, follow)
            only_toe = (wt > wa) & ~on_a
            toe_goal = tt - (pos[:, lg.toe] - pos[:, lg.ankle])
            g2 = pos[:, lg.ankle] + wt[:, None] * (toe_goal - pos[:, lg.ankle])
            goal = np.where(only_toe[:, None], g2, goal)
        act = np.flatnonzero(np.maximum(wa, wt if lg.toe >= 0 else 0) > 0)
        if act.size == 0:
            continue
        r_hip, r_knee, c = two_bone_ik(
            pos[act, lg.hip], pos[act, lg.knee], pos[act, lg.ankle], goal[act]
        )
        clamped += c
        hip_w = tf.quat_multiply(r_hip, wq[act, lg.hip])
        knee_w = tf.quat_multiply(r_knee, tf.quat_multiply(r_hip, wq[act, lg.knee]))
        parent_w = wq[act, par[lg.hip]] if par[lg.hip] >= 0 else tf.quat_identity((act.size,))
        inv = tf.quat_conjugate
        rot[act, lg.hip] = tf.quat_multiply(
            inv(rest[lg.hip]), tf.quat_multiply(inv(parent_w), hip_w)
        )
        rot[act, lg.knee] = tf.quat_multiply(
            inv(rest[lg.knee]), tf.quat_multiply(inv(hip_w), knee_w)
        )
        foot_w = wq[act, lg.ankle]
        if lg.toe >= 0:  # both planted: turn the foot so the toe lands on its held place
            both = np.flatnonzero(wt[act] > 0)
            if both.size:
                a_new = goal[act][both]
                cur = _unit(pos[act[both], lg.toe] - pos[act[both], lg.ankle])
                want = tt[act[both]] - a_new
                want = cur + wt[act[both], None] * (_unit(want) - cur)
                foot_w = np.array(foot_w)
                foot_w[both] = tf.quat_multiply(_arc(cur, _unit(want)), foot_w[both])
        rot[act, lg.ankle] = tf.quat_multiply(
            inv(rest[lg.ankle]), tf.quat_multiply(inv(knee_w), foot_w)
        )
        changed += [lg.hip, lg.knee, lg.ankle]
    if clamped:
        warnings.warn(
            f"{clamped} foot-contact target(s) out of the leg's reach; clamped to the leg length",
            ContactWarning,
            stacklevel=2,
        )
    if changed:
        rot[:, changed] = tf.quat_continuous(rot[:, changed], axis=0)
    meta = dict(motion.meta)
    meta["feet_locked"] = {
        "contacts": {motion.names[j]: int(v.sum()) for j, v in contacts.items()},
        "clamped": clamped,
    }
    return motion.with_(rotation=frozen(rot), meta=meta)


__all__ = [
    "ContactOptions",
    "ContactWarning",
    "Leg",
    "find_legs",
    "detect_contacts",
    "two_bone_ik",
    "lock_feet",
]
