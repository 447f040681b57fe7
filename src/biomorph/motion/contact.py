"""Foot contacts: detection with hysteresis and locking by analytic two-bone IK.

Detection (:func:`detect_contacts`), per foot (a joint named ``*foot*``/``*ankle*``) and its
toe (a child named ``*toe*``): a point is *planted* when it is low and slow — height above
its own resting height below ``height`` × body scale and horizontal speed below ``speed`` ×
body scale per second — and stays planted until it rises above ``height × hysteresis`` or
moves faster than ``speed × hysteresis`` (Schmitt trigger, so noise at the threshold does
not flicker). Ground and body scale are measured on the clip exactly as the foot-skate
metric of :mod:`biomorph.motion.quality` measures them (2nd height percentile of the feet;
median hip height above it), so the constants are fractions of the character, not of a
file's units:

* ``height = 0.04`` above the point's own resting height (its 2nd height percentile): half
  the metric's 8 % band (which is measured from the floor), ≈ 3.5 cm on an adult — an ankle
  rising at heel-off leaves contact, the toe stays;
* ``speed = 1.0`` body scales per second: a walking body moves about one leg length per
  second (Xia walk 0.9 m/s, hip 0.9 m), a planted foot far less, a swinging foot 2–3×;
* ``hysteresis = 1.5``; ``min_s`` = 0.05 s (shorter contacts are ignored);
* ``swing = 0.8``: a contact's fade-out ends at the first frame the point moves faster than
  0.8 × its own 95th-percentile horizontal speed (its swing speed on this clip), the fade
  compressed into the frames before it, so a held slide is released while the foot lifts
  off and not added to the captured swing (dme raw 0.573 → 0.534; 0 turns it off). Fitted
  on the shared captures (0.5 / 0.65 / 0.8 compared); the fade-in is not cut (pulling the
  arriving foot onto its place slows its last low frames, cutting it raised the run's skate);
* ``blend_s = 0.2`` s fade in/out (≥ 1 frame): **chosen on the shared captures** (0.1 / 0.2 /
  0.3 s compared with ``bench/motion.py --skate``; 0.1 s released a held slide within 3
  frames at 30 fps and raised the skate metric of the Xia walk above its input), so it is a
  fitted value to check on other captures. Spreading the release over the whole swing
  instead (the offset interpolated between consecutive contacts, by time or by the foot's
  own travel) was measured worse on every shared walk: it keeps the held offset on the
  low, fast frames right after toe-off and before heel strike.

Locking (:func:`lock_feet`), ``mode="hold"``: during each contact the planted point is held
at one place: horizontally the median position of the contact's slower half of frames (a
foot still gliding in at the first frame is not frozen mid-glide, and a slide is split
between the fade in and the fade out instead of released all at once), vertically the
**lowest height the point reaches during that contact** — a planted heel or toe rests on
the floor; a capture's (or a generated clip's) contact floats above it by noise and drift
(the dme raw clip's left heel wanders between 0.076 and 0.112 hip heights while planted),
and holding it at its median height left it floating (measured: every shared walk skates
less with the lowest height, dme raw 0.654 → 0.614 hip heights/s). A contact cut by the
clip's start (end) takes its place from its last (first) ``blend`` frames only: nothing
before frame 0 needs a fade, so the place where it meets the clip releases no slide into the
first swing (dme raw 0.614 → 0.573; its very last frame instead: 0.601, and the zombie walk's
3-second opening stance pinned out of the leg's reach). With a *reference* clip
(the input of an operator that keeps timing: equalize, edit, layers) the contacts and their
held positions come from the reference, so an edit cannot lift the feet or push them
through the floor; and outside the contacts no foot point is left lower than the reference
had it while the reference's point is within a foot's length (ankle → toe) of its resting
height (fading out over the upper half of that band): a filter or an edit cannot make the
toes scrape (denoising the dme fixed clip lowered its swing toe from 0.088 to 0.071 hip
heights above the floor; the rule took that clip's skate after equalize + lock from 0.608
to 0.544 against its input's 0.571, 0.518 with the cut-contact rule above — with the
detection's exit height, 0.06 L, as the band instead of the foot's 0.13 L: 0.598; unlimited:
0.526, but an unlimited rule would also undo deliberate leg edits in the air).
Between two contacts of a point at most two fades apart (a hop's flight: the jumping jacks'
0.2 s in the air between 0.2 s fades; a walking swing is twice as long), where the held place
is carried across the gap, the held *height* never pulls the point below its own height: it is
held horizontally only (the jacks' lock 0.252 → 0.157 against their input's 0.271; held onto
the floor through the flight, the airborne foot was pulled into the metric's band). Outside
such gaps the fades still pull a landing foot onto its held place (doing this for every
frame outside the contacts raised the Xia self-blend 0.797 → 0.814).
``mode="follow"``: the point follows where the reference had it frame by frame (the input's
own slide is kept; measured worse on the shared walks than holding, so not the default).
``"auto"`` (default) = ``"hold"``.

In both modes the leg (hip → knee → ankle) is solved analytically so the ankle lands on the
target with the knee kept in its plane (the knee's side of the hip–ankle line is kept), the
foot keeps its world orientation (so the toe follows; while both the heel and the toe are
planted the foot turns so the toe lands on its held place), and the weight fades in and out
over ``blend_s``. Targets out of reach are clamped to the leg's length with one
:class:`ContactWarning` (never NaN). Nothing switches on one frame: a held ankle that the
leg cannot reach hands over to the held toe continuously (smoothstep from 1.0 to
``REACH_OUT`` = 1.1 leg lengths: the heel lifts, as at a real toe-off; was a switch when the
ankle's contact ended — a 1.1-unit pop of the Xia walk's left foot at frame 159), two
contacts whose fades overlap move the held place across the gap (was a switch to the nearer
one), and the IK is *soft* near full extension (``soft`` = 0.005 leg lengths; the knee
straightens without the hard clamp's snap). 0.005 and 1.1 were compared with 0.01 / 0.02 /
0.05 and 1.0 / 1.03 / 1.05 / 1.08 / 1.15 on the shared captures (``bench/motion.py
--skate``): a wider soft band raised the dme raw clip's cleaned skate to 0.55-0.63, a handoff
ending at 1.0 to 0.61; at these values every cleaned clip stays within 0.015 of the former
figures or below them.

Cost: forward kinematics runs once per clip and only over the legs' chains (root → toes:
9 of 60 joints on the benchmark skeleton), detection and the IK of every frame and both
legs are compiled loops; ``bench/motion.py --quick`` has the figures.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from numpy.typing import NDArray

from biomorph.core.motion import Motion, frozen, guess_up_axis
from biomorph.core.types import Array
from biomorph.errors import ParameterError
from biomorph.motion._kernels import _qmul, _qrot

_UP = {"x": 0, "y": 1, "z": 2}
#: a held ankle farther from the hip than the leg's length gives way to the held toe
#: (smoothstep from 1.0 to ``REACH_OUT`` leg lengths; the heel lifts because the leg cannot
#: reach it, as in a real toe-off) instead of switching on one frame when the contact ends
REACH_OUT = 1.10


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
    swing: float = 0.8
    soft: float = 0.005
    up: str | None = None
    mode: str = "auto"

    def __post_init__(self) -> None:
        if self.mode not in ("auto", "hold", "follow"):
            raise ParameterError(f"contact mode {self.mode!r}; expected auto, hold or follow")
        for name in ("height", "speed", "hysteresis", "blend_s", "min_s", "swing", "soft"):
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
    grandparent; the toe is its first child named ``toe`` (else its first child). A foot
    joint below another one (HTR's ``R_ankle → R_football → R_toe``) belongs to that leg's
    foot, it does not start a leg of its own."""
    par = motion.skeleton.parent
    names = [s.lower() for s in motion.names]

    def is_foot(s: str) -> bool:
        return ("foot" in s or "ankle" in s) and "toe" not in s and "index" not in s

    legs = []
    for j, s in enumerate(names):
        if is_foot(s):
            knee = int(par[j])
            if knee < 0 or par[knee] < 0 or is_foot(names[knee]):
                continue
            kids = [int(c) for c in np.flatnonzero(par == j)]
            toes = [c for c in kids if "toe" in names[c]] or kids
            legs.append(Leg(int(par[knee]), knee, j, toes[0] if toes else -1))
    return legs or _preset_legs(motion)


def _preset_legs(motion: Motion) -> list[Leg]:
    """Legs of a skeleton without foot/ankle names from its name preset (``biomorph
    creature``'s ``hip1_upper_l → hip1_lower_l → hip1_distal_l``, toe ``hip1_digit3_1_l``):
    thigh → shin → foot, each the parent of the next."""
    from biomorph.errors import InputError
    from biomorph.motion import names as nm

    try:
        idx = nm.resolve(motion.names, nm.detect_preset(motion.names), motion.skeleton.parent)
    except InputError:
        return []
    par = motion.skeleton.parent
    legs = []
    for s in ("l", "r"):
        th, sh, ft = (idx.get(f"{s}_{b}", -1) for b in ("thigh", "shin", "foot"))
        if min(th, sh, ft) >= 0 and par[ft] == sh and par[sh] == th:
            toe = idx.get(f"{s}_toe", -1)
            legs.append(Leg(th, sh, ft, toe if toe >= 0 and par[toe] == ft else -1))
    return legs


# --------------------------------------------------------------------------- leg-chain FK
def _leg_chain(motion: Motion, legs: list[Leg]) -> NDArray[np.int64]:
    """The joints the legs hang from, parents first: the root, every ancestor of each
    hip, the leg joints and toes."""
    par = motion.skeleton.parent
    need: set[int] = {0}
    for lg in legs:
        for j in (lg.toe, lg.ankle, lg.knee, lg.hip):
            while j >= 0 and j not in need:
                need.add(j)
                j = int(par[j])
    return np.array(sorted(need), dtype=np.int64)


@njit(cache=True)
def _fk_chain(rest, rot, offset, root_pos, jt, chain, cpar, pos, quat):  # pragma: no cover
    """World positions ``pos (f, k, 3)`` and orientations ``quat (f, k, 4)`` of the joints
    ``chain`` (parents first; ``cpar`` = index of each one's parent in ``chain`` or -1).
    Local translation: ``jt[t, j]`` when ``jt`` has frames, else ``root_pos[t]`` for joint 0
    and the OFFSET for the others (the :class:`Motion` convention)."""
    f = rot.shape[0]
    has_jt = jt.shape[0] == f
    for t in range(f):
        for c in range(chain.size):
            j = chain[c]
            lx, ly, lz, lw = _qmul(
                rest[j, 0], rest[j, 1], rest[j, 2], rest[j, 3],
                rot[t, j, 0], rot[t, j, 1], rot[t, j, 2], rot[t, j, 3],
            )  # fmt: skip
            if has_jt:
                vx, vy, vz = jt[t, j, 0], jt[t, j, 1], jt[t, j, 2]
            elif j == 0:
                vx, vy, vz = root_pos[t, 0], root_pos[t, 1], root_pos[t, 2]
            else:
                vx, vy, vz = offset[j, 0], offset[j, 1], offset[j, 2]
            p = cpar[c]
            if p < 0:
                quat[t, c, 0], quat[t, c, 1], quat[t, c, 2], quat[t, c, 3] = lx, ly, lz, lw
                pos[t, c, 0], pos[t, c, 1], pos[t, c, 2] = vx, vy, vz
                continue
            px, py, pz, pw = quat[t, p, 0], quat[t, p, 1], quat[t, p, 2], quat[t, p, 3]
            wx, wy, wz, ww = _qmul(px, py, pz, pw, lx, ly, lz, lw)
            quat[t, c, 0], quat[t, c, 1], quat[t, c, 2], quat[t, c, 3] = wx, wy, wz, ww
            rx, ry, rz = _qrot(px, py, pz, pw, vx, vy, vz)
            pos[t, c, 0] = pos[t, p, 0] + rx
            pos[t, c, 1] = pos[t, p, 1] + ry
            pos[t, c, 2] = pos[t, p, 2] + rz


def _chain_fk(motion: Motion, chain: NDArray[np.int64]) -> tuple[Array, Array]:
    """World positions and orientations of the ``chain`` joints only (one compiled pass)."""
    sk = motion.skeleton
    where = {int(j): c for c, j in enumerate(chain)}
    cpar = np.array([where.get(int(sk.parent[j]), -1) for j in chain], dtype=np.int64)
    f = motion.n_frames
    jt = motion.joint_translation
    jt = np.zeros((0, 1, 3)) if jt is None else np.ascontiguousarray(jt, dtype=np.float64)
    pos = np.empty((f, chain.size, 3))
    quat = np.empty((f, chain.size, 4))
    _fk_chain(
        np.ascontiguousarray(sk.rest_rotation, dtype=np.float64),
        np.ascontiguousarray(motion.rotation, dtype=np.float64),
        np.ascontiguousarray(sk.offset, dtype=np.float64),
        np.ascontiguousarray(motion.root_position, dtype=np.float64),
        jt,
        chain,
        cpar,
        pos,
        quat,
    )
    return pos, quat


# --------------------------------------------------------------------------- detection
def _ground_and_scale(w: Array, pts: list[int], ui: int) -> tuple[float, float]:
    """Ground (2nd height percentile of the contact points ``pts``, columns of ``w``) and
    body scale (median height of column 0, the root, above it)."""
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


def _contact_points(legs: list[Leg]) -> list[int]:
    return sorted({p for lg in legs for p in (lg.ankle, lg.toe) if p >= 0})


def _detect(
    w: Array, col: dict[int, int], legs: list[Leg], fps: float, o: ContactOptions, ui: int
) -> dict[int, NDArray[np.bool_]]:
    """Planted frames of every contact point; ``w[:, col[j]]`` is joint ``j``'s path and
    ``w[:, 0]`` the root's."""
    pts = _contact_points(legs)
    ground, scale = _ground_and_scale(w, [col[j] for j in pts], ui)
    horiz = [a for a in range(3) if a != ui]
    min_len = max(1, round(o.min_s * fps))
    out = {}
    for j in pts:
        p = w[:, col[j]]
        # each point against its own resting height (an ankle stands above the floor)
        h = (p[:, ui] - max(ground, float(np.percentile(p[:, ui], 2)))) / scale
        v = np.hypot(*np.gradient(p[:, horiz], axis=0).T) * (fps / scale)
        on = _schmitt(
            (h < o.height) & (v < o.speed),
            (h < o.height * o.hysteresis) & (v < o.speed * o.hysteresis),
        )
        out[j] = _drop_short(on, min_len)
    return out


def _up_of(motion: Motion, o: ContactOptions) -> int:
    return _UP[(o.up or motion.meta.get("up_guess") or guess_up_axis(motion)).lower()]


def detect_contacts(
    motion: Motion, options: ContactOptions | None = None, world: Array | None = None
) -> dict[int, NDArray[np.bool_]]:
    """Planted frames per contact point (joint index → ``bool[f]``), ankles and toes.
    ``world`` (all joints' world positions, ``(f, n, 3)``) saves the forward kinematics
    when the caller has them; otherwise only the legs' chains are evaluated."""
    o = options or ContactOptions()
    legs = find_legs(motion)
    if not legs or motion.n_frames < 2:
        return {}
    ui = _up_of(motion, o)
    if world is not None:
        return _detect(world, {j: j for j in range(motion.n_joints)}, legs, motion.fps, o, ui)
    chain = _leg_chain(motion, legs)
    w, _ = _chain_fk(motion, chain)
    return _detect(w, {int(j): c for c, j in enumerate(chain)}, legs, motion.fps, o, ui)


def _drop_short(on: NDArray[np.bool_], min_len: int) -> NDArray[np.bool_]:
    """``on`` without its runs shorter than ``min_len`` frames."""
    out = np.array(on, dtype=np.bool_)
    _drop_short_kernel(out, int(min_len))
    return out


@njit(cache=True)
def _drop_short_kernel(on, min_len):  # pragma: no cover - compiled
    k, f = 0, on.size
    while k < f:
        if not on[k]:
            k += 1
            continue
        e = k
        while e < f and on[e]:
            e += 1
        if e - k < min_len:
            on[k:e] = False
        k = e


def _runs(on: NDArray[np.bool_]) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], on.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


# --------------------------------------------------------------------------- targets
def _targets(
    on: NDArray[np.bool_],
    pts: Array,
    blend: int,
    ui: int,
    follow: bool = False,
    swing: NDArray[np.bool_] | None = None,
) -> tuple[Array, Array]:
    """Per frame the held position of the nearest contact and its weight (1 inside a
    contact, smoothstep fade over ``blend`` frames outside, 0 elsewhere). The held position
    is the median position of the contact's slower half of frames at the lowest height the
    point reaches in that contact (see the module docstring). ``swing``: frames where the
    point is in full swing; a fade-out ends before the first of them after its contact (the
    smoothstep compressed into the frames left)."""
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    step = np.linalg.norm(np.gradient(pts, axis=0), axis=-1) if on.size > 1 else np.zeros(on.size)
    runs = np.asarray(_runs(on), dtype=np.int64).reshape(-1, 2)
    tgt = np.array(pts)
    wgt = np.zeros(on.size)
    fast = np.zeros(on.size, np.bool_) if swing is None else np.asarray(swing, dtype=np.bool_)
    _targets_kernel(pts, step, runs, int(blend), int(ui), bool(follow), fast, tgt, wgt)
    return tgt, wgt


@njit(cache=True)
def _select(y, k):  # pragma: no cover - compiled
    """The ``k``-th smallest value of ``y`` (reordered in place; Hoare's selection)."""
    lo, hi = 0, y.size - 1
    while lo < hi:
        pivot = y[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while y[i] < pivot:
                i += 1
            while y[j] > pivot:
                j -= 1
            if i <= j:
                y[i], y[j] = y[j], y[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return y[k]


@njit(cache=True)
def _median(x):  # pragma: no cover - compiled
    """``np.median`` of a 1-D array, reordering it (a selection compiles in a fraction of the
    time numba's median or sort takes)."""
    n = x.size
    if n == 0:
        return np.nan
    hi = _select(x, n // 2)
    if n % 2:
        return hi
    return 0.5 * (hi + _select(x[: n // 2], n // 2 - 1))


@njit(cache=True)
def _fade_out_len(fast, e, blend):  # pragma: no cover - compiled
    """Frames of the fade-out after a contact ending at ``e``: it ends where the point
    reaches full swing (``fast``), so the held slide is released while the foot lifts off,
    not added to the captured swing."""
    for k in range(blend):
        if e + k < fast.size and fast[e + k]:
            return k
    return blend


@njit(cache=True)
def _held_place(pts, step, s, e, blend, ui):  # pragma: no cover - compiled
    """Where the contact ``s:e`` is held: the median position of its slower half of frames
    at the lowest height it reaches (see :func:`_targets`)."""
    f = pts.shape[0]
    # a contact cut by the clip's start (end) is held where it meets the rest of the
    # clip: only its last (first) ``blend`` frames choose the place, since nothing
    # before frame 0 (after the last) needs a fade, so no slide is released into the clip
    a0, a1 = s, e
    if s == 0 and e < f:
        a0 = max(s, e - blend)
    elif e == f and s > 0:
        a1 = min(e, s + blend)
    cut = _median(step[a0:a1].copy())
    n = 0
    for k in range(a0, a1):
        n += step[k] <= cut
    p = np.empty(3)
    col = np.empty(n)
    for a in range(3):
        i = 0
        for k in range(a0, a1):
            if step[k] <= cut:
                col[i] = pts[k, a]
                i += 1
        p[a] = _median(col.copy())
    low = pts[s, ui]
    for k in range(s + 1, e):
        low = min(low, pts[k, ui])
    p[ui] = low
    return p


@njit(cache=True)
def _targets_kernel(pts, step, runs, blend, ui, follow, fast, tgt, wgt):  # pragma: no cover
    f = pts.shape[0]
    dist = np.full(f, np.inf)
    held = np.empty((runs.shape[0], 3))
    outs = np.zeros(runs.shape[0], dtype=np.int64)
    for r in range(runs.shape[0]):
        s, e = runs[r, 0], runs[r, 1]
        p = _held_place(pts, step, s, e, blend, ui)
        held[r] = p
        out = _fade_out_len(fast, e, blend)
        outs[r] = out
        for k in range(max(0, s - blend), min(f, e + out)):
            if k < s:
                d = float(s - k)
            elif k >= e:
                d = float(k - e + 1) * (blend + 1) / (out + 1)
            else:
                d = 0.0
            if d >= dist[k]:
                continue
            dist[k] = d
            wk = min(max(1.0 - d / (blend + 1), 0.0), 1.0)
            wk = wk * wk * (3.0 - 2.0 * wk)
            if wk > 0:
                wgt[k] = wk
                for a in range(3):
                    tgt[k, a] = pts[k, a] if follow else p[a]
    if not follow:
        _bridge_gaps(runs, outs, held, blend, tgt)


@njit(cache=True)
def _bridge_gaps(runs, outs, held, blend, tgt):  # pragma: no cover - compiled
    """Two contacts whose fades overlap (the fade-out of one reaches the fade-in of the
    next): the held place moves from one to the other across the gap (smoothstep) instead
    of switching to the nearer one mid-gap at a weight near 1 (a one-frame jump of the whole
    step; cmu_01_01's right toe moved 4.2 units in frame 1163)."""
    for r in range(runs.shape[0] - 1):
        e1, s2 = runs[r, 1], runs[r + 1, 0]
        if e1 + outs[r] <= s2 - blend:
            continue
        for k in range(e1, s2):
            u = (k - e1 + 1) / (s2 - e1 + 1)
            u = u * u * (3.0 - 2.0 * u)
            for a in range(3):
                tgt[k, a] = held[r, a] + u * (held[r + 1, a] - held[r, a])


# --------------------------------------------------------------------------- two-bone IK
@njit(cache=True)
def _unit3(x, y, z):  # pragma: no cover - compiled
    n = math.sqrt(x * x + y * y + z * z)
    if n > 1e-12:
        return x / n, y / n, z / n
    return x, y, z


@njit(cache=True)
def _arc3(ax, ay, az, bx, by, bz):  # pragma: no cover - compiled
    """Shortest-arc quaternion turning unit ``a`` onto unit ``b``."""
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    w = 1.0 + ax * bx + ay * by + az * bz
    if w < 1e-9:  # opposite: 180° about any perpendicular axis
        m = min(abs(ax), abs(ay), abs(az))
        ex, ey, ez = 0.0, 0.0, 1.0
        if m == abs(ax):
            ex, ey, ez = 1.0, 0.0, 0.0
        elif m == abs(ay):
            ex, ey, ez = 0.0, 1.0, 0.0
        px, py, pz = _unit3(ay * ez - az * ey, az * ex - ax * ez, ax * ey - ay * ex)
        return px, py, pz, 0.0
    n = math.sqrt(cx * cx + cy * cy + cz * cz + w * w)
    return cx / n, cy / n, cz / n, w / n


@njit(cache=True)
def _ik_frame(hip, knee, ankle, target, r_hip, r_knee, soft, wk):  # pragma: no cover
    """One frame of :func:`two_bone_ik`; writes ``r_hip``/``r_knee`` (4,), returns True
    when the target was more than 1 % beyond the leg's reach (or inside its inner limit).

    ``soft`` (fraction of the leg's length ``L``, 0 = off): *soft IK* — a target farther than
    ``L − s`` (``s = soft·L``) is reached at ``L − s·exp(−(d − L + s)/s)``, which meets the
    plain distance with equal slope at ``L − s`` and never reaches ``L``, so the knee
    straightens smoothly instead of snapping (the knee angle of a hard clamp has an infinite
    derivative where the target crosses the leg's length, a visible pop). ``wk`` ∈ [0, 1]
    weighs the soft distance against the hard clamp, so a solve fading in from the captured
    pose (weight → 0, target → the captured ankle) starts from the captured pose exactly."""
    k0, k1, k2 = knee[0] - hip[0], knee[1] - hip[1], knee[2] - hip[2]
    s0, s1, s2 = ankle[0] - knee[0], ankle[1] - knee[1], ankle[2] - knee[2]
    a0, a1, a2 = ankle[0] - hip[0], ankle[1] - hip[1], ankle[2] - hip[2]
    t0, t1, t2 = target[0] - hip[0], target[1] - hip[1], target[2] - hip[2]
    l1 = math.sqrt(k0 * k0 + k1 * k1 + k2 * k2)
    l2 = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    d = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    lo = abs(l1 - l2) + 1e-9 * (l1 + l2)
    hi = (l1 + l2) * (1 - 1e-9)
    clamped = d > 1.01 * (l1 + l2) or d < 0.99 * lo
    dc = min(max(d, lo), hi)
    if soft > 0 and wk > 0:
        s = soft * (l1 + l2)
        da = l1 + l2 - s
        if d > da:
            ds = max(l1 + l2 - s * math.exp(-(d - da) / s), lo)
            dc = dc + min(wk, 1.0) * (min(ds, hi) - dc)
    u0, u1, u2 = _unit3(t0, t1, t2) if d > 1e-12 else _unit3(a0, a1, a2)
    kd = k0 * u0 + k1 * u1 + k2 * u2
    b0, b1, b2 = k0 - kd * u0, k1 - kd * u1, k2 - kd * u2
    if math.sqrt(b0 * b0 + b1 * b1 + b2 * b2) > 1e-9 * l1:
        v0, v1, v2 = _unit3(b0, b1, b2)
    else:  # straight leg: bend in the plane of the current leg
        n0 = a1 * k2 - a2 * k1 + 1e-12
        n1 = a2 * k0 - a0 * k2 + 1e-12
        n2 = a0 * k1 - a1 * k0 + 1e-12
        v0, v1, v2 = _unit3(u1 * n2 - u2 * n1, u2 * n0 - u0 * n2, u0 * n1 - u1 * n0)
    cos_a = min(max((l1 * l1 + dc * dc - l2 * l2) / (2 * l1 * dc), -1.0), 1.0)
    sin_a = math.sqrt(1 - cos_a * cos_a)
    nk0 = l1 * (cos_a * u0 + sin_a * v0)
    nk1 = l1 * (cos_a * u1 + sin_a * v1)
    nk2 = l1 * (cos_a * u2 + sin_a * v2)
    e0, e1, e2 = _unit3(k0, k1, k2)
    f0, f1, f2 = _unit3(nk0, nk1, nk2)
    hx, hy, hz, hw = _arc3(e0, e1, e2, f0, f1, f2)
    r_hip[0], r_hip[1], r_hip[2], r_hip[3] = hx, hy, hz, hw
    sx, sy, sz = _qrot(hx, hy, hz, hw, s0, s1, s2)
    g0, g1, g2 = _unit3(sx, sy, sz)
    w0, w1, w2 = _unit3(dc * u0 - nk0, dc * u1 - nk1, dc * u2 - nk2)
    qx, qy, qz, qw = _arc3(g0, g1, g2, w0, w1, w2)
    r_knee[0], r_knee[1], r_knee[2], r_knee[3] = qx, qy, qz, qw
    return clamped


@njit(cache=True)
def _ik_frames(hip, knee, ankle, target, r_hip, r_knee, soft):  # pragma: no cover - compiled
    c = 0
    for t in range(hip.shape[0]):
        if _ik_frame(hip[t], knee[t], ankle[t], target[t], r_hip[t], r_knee[t], soft, 1.0):
            c += 1
    return c


def two_bone_ik(
    hip: Array, knee: Array, ankle: Array, target: Array, soft: float = 0.0
) -> tuple[Array, Array, int]:
    """World rotations ``(r_hip, r_knee)`` (f, 4) that move the ankle of the chain
    ``hip → knee → ankle`` (positions ``(f, 3)``) onto ``target``: ``r_hip`` turns the thigh,
    ``r_knee`` then turns the shin (both applied in world space, about the hip and the new
    knee). The knee stays in the plane of hip, knee and ankle on its side. Returns the count
    of frames whose target was more than 1 % out of reach (every target is clamped to the
    reachable distance). ``soft`` > 0: soft IK over the last ``soft`` × leg length (the
    ankle falls short of targets near full extension so the knee never snaps straight;
    :class:`ContactOptions.soft`)."""
    args = [np.ascontiguousarray(a, dtype=np.float64) for a in (hip, knee, ankle, target)]
    r_hip = np.empty((args[0].shape[0], 4))
    r_knee = np.empty_like(r_hip)
    c = _ik_frames(*args, r_hip, r_knee, float(soft))
    return r_hip, r_knee, int(c)


@njit(cache=True)
def _lock_leg(P, Q, leg, goal, act, tt, wt, ws, soft, rest, joints, rot, ui, floor, tclear):  # noqa: PLR0913 # pragma: no cover
    """Solve one leg on the frames ``act`` and write the new local rotations of its hip,
    knee and ankle into ``rot (f, n, 4)``. ``P``/``Q``: chain world positions/orientations;
    ``leg`` = chain columns of (hip's parent, hip, knee, ankle, toe or -1); ``joints`` =
    skeleton indices of (hip, knee, ankle); ``goal`` the ankle target; ``tt``/``wt`` the toe's
    held place and weight (the foot turns toward it where ``wt > 0``); ``ws`` the solve's
    weight per frame and ``soft`` the soft-IK band (:func:`_ik_frame`); ``ui`` the up axis
    and ``floor`` the height no turned toe goes below; ``tclear`` per frame the reference
    toe's clearance outside the toe's contacts (``-inf`` elsewhere), kept as far as the
    unturned foot reaches it."""
    cp, ch, ck, ca, ct = leg[0], leg[1], leg[2], leg[3], leg[4]
    gv = np.empty(3)
    cv = np.empty(3)
    jh, jk, ja = joints[0], joints[1], joints[2]
    r_hip = np.empty(4)
    r_knee = np.empty(4)
    clamped = 0
    for i in range(act.size):
        t = act[i]
        if _ik_frame(P[t, ch], P[t, ck], P[t, ca], goal[t], r_hip, r_knee, soft, ws[t]):
            clamped += 1
        qh = Q[t, ch]
        hx, hy, hz, hw = _qmul(r_hip[0], r_hip[1], r_hip[2], r_hip[3], qh[0], qh[1], qh[2], qh[3])
        qk = Q[t, ck]
        kx, ky, kz, kw = _qmul(r_hip[0], r_hip[1], r_hip[2], r_hip[3], qk[0], qk[1], qk[2], qk[3])
        kx, ky, kz, kw = _qmul(r_knee[0], r_knee[1], r_knee[2], r_knee[3], kx, ky, kz, kw)
        x, y, z, w = hx, hy, hz, hw
        if cp >= 0:
            qp = Q[t, cp]
            x, y, z, w = _qmul(-qp[0], -qp[1], -qp[2], qp[3], hx, hy, hz, hw)
        rh = rest[jh]
        rot[t, jh, 0], rot[t, jh, 1], rot[t, jh, 2], rot[t, jh, 3] = _qmul(
            -rh[0], -rh[1], -rh[2], rh[3], x, y, z, w
        )
        x, y, z, w = _qmul(-hx, -hy, -hz, hw, kx, ky, kz, kw)
        rk = rest[jk]
        rot[t, jk, 0], rot[t, jk, 1], rot[t, jk, 2], rot[t, jk, 3] = _qmul(
            -rk[0], -rk[1], -rk[2], rk[3], x, y, z, w
        )
        fx, fy, fz, fw = Q[t, ca, 0], Q[t, ca, 1], Q[t, ca, 2], Q[t, ca, 3]
        if ct >= 0 and wt[t] > 0:  # turn the foot so the toe lands on its held place
            pt, pa, g, wk = P[t, ct], P[t, ca], goal[t], wt[t]
            c0, c1, c2 = _unit3(pt[0] - pa[0], pt[1] - pa[1], pt[2] - pa[2])
            g0, g1, g2 = _unit3(tt[t, 0] - g[0], tt[t, 1] - g[1], tt[t, 2] - g[2])
            gv[0], gv[1], gv[2] = _unit3(
                c0 + wk * (g0 - c0), c1 + wk * (g1 - c1), c2 + wk * (g2 - c2)
            )
            # not through the floor: a held ankle nearer to the held toe than the foot's length
            # puts the toe past it along the line (fair1 jumping: 5.5 % of the hip height
            # below the floor); there the foot turns only as far down as the floor
            foot = math.sqrt((pt[0] - pa[0]) ** 2 + (pt[1] - pa[1]) ** 2 + (pt[2] - pa[2]) ** 2)
            cv[0], cv[1], cv[2] = c0, c1, c2
            # the reference's clearance only as far as the unturned foot reaches it (never
            # pitched up past the animation's own foot)
            low = max(floor, min(tclear[t], g[ui] + foot * cv[ui]))
            if foot > 0 and g[ui] + foot * gv[ui] < low:
                gy = min(1.0, max(-1.0, (low - g[ui]) / foot))
                hn = math.sqrt(max(0.0, 1.0 - gv[ui] * gv[ui]))
                if hn > 1e-9:
                    sc = math.sqrt(1.0 - gy * gy) / hn
                    gv[0], gv[1], gv[2] = gv[0] * sc, gv[1] * sc, gv[2] * sc
                    gv[ui] = gy
            g0, g1, g2 = gv[0], gv[1], gv[2]
            ax, ay, az, aw = _arc3(c0, c1, c2, g0, g1, g2)
            fx, fy, fz, fw = _qmul(ax, ay, az, aw, fx, fy, fz, fw)
        x, y, z, w = _qmul(-kx, -ky, -kz, kw, fx, fy, fz, fw)
        ra = rest[ja]
        rot[t, ja, 0], rot[t, ja, 1], rot[t, ja, 2], rot[t, ja, 3] = _qmul(
            -ra[0], -ra[1], -ra[2], ra[3], x, y, z, w
        )
    for j in (jh, jk, ja):  # hemisphere-continuous over time
        for t in range(1, rot.shape[0]):
            if (
                rot[t, j, 0] * rot[t - 1, j, 0]
                + rot[t, j, 1] * rot[t - 1, j, 1]
                + rot[t, j, 2] * rot[t - 1, j, 2]
                + rot[t, j, 3] * rot[t - 1, j, 3]
            ) < 0:
                for a in range(4):
                    rot[t, j, a] = -rot[t, j, a]
    return clamped


# --------------------------------------------------------------------------- locking
def _clearance(
    lg: Leg, col: dict[int, int], pos: Array, w_ref: Array, ui: int, foot: float
) -> tuple[Array, Array]:
    """How far the leg's lowest point must rise (per frame, ≥ 0) so that no foot point is
    lower than the reference had it while the reference's point is within a foot's length
    of its resting height (the rule fades out over the upper half of that band), and the
    toe height that rule asks for (a lower bound for a toe turned toward its held place)."""
    lift = np.zeros(pos.shape[0])
    toe = np.full(pos.shape[0], -np.inf)
    if foot <= 0:
        return lift, toe
    for j in (lg.ankle, lg.toe):
        h_ref, h = w_ref[:, col[j], ui], pos[:, col[j], ui]
        x = np.clip((np.percentile(h_ref, 2) + foot - h_ref) / (0.5 * foot), 0.0, 1.0)
        x = x * x * (3.0 - 2.0 * x)
        lift = np.maximum(lift, np.maximum(h_ref - h, 0.0) * x)
        if j == lg.toe:  # the toe's own lower bound: its height, or the reference's
            toe = h + np.maximum(h_ref - h, 0.0) * x
    return lift, toe


def _leg_goals(  # noqa: PLR0913
    lg: Leg, col: dict[int, int], pos: Array, w_ref: Array, contacts, blend: int, ui: int,
    follow: bool, lift: Array | None = None, swing: float = 0.0, floor: float | None = None,
    toe_clear: Array | None = None, fast: dict[int, NDArray[np.bool_]] | None = None,
) -> tuple[Array, Array, Array, Array, NDArray[np.int64], Array] | None:  # fmt: skip
    """Ankle goal per frame, the toe's held place and weight, the soft-IK weight and the
    frames to solve (``None`` when there is nothing to do). ``lift``: the clearance kept
    from a reference (:func:`_clearance`), applied outside the contacts (not faded by the
    contact weight; inside a contact of the ankle or toe the held place decides).
    ``floor``: no ankle or toe ends below this height — where one would (a held ankle whose
    foot is tipped toe-down, an operator's pose below the input's lowest foot), the ankle
    goal rises by the difference (the foot keeps its orientation, so the toe rises with
    it). ``fast``: frames in full swing per point (``lock_feet``'s ``swing``)."""
    f = pos.shape[0]
    none = np.zeros(f, bool)
    on_a = contacts.get(lg.ankle, none)
    on_t = contacts.get(lg.toe, none) if lg.toe >= 0 else none
    lifted = lift is not None and bool((lift > 0).any())
    ca = col[lg.ankle]
    below = floor is not None and bool(
        (pos[:, ca, ui] < floor).any() or (lg.toe >= 0 and (pos[:, col[lg.toe], ui] < floor).any())
    )
    if not (on_a.any() or on_t.any() or lifted or below):
        return None

    # the ankle target: the held ankle while the ankle is planted; where the toe is planted
    # too, the held ankle gives way to "the held toe minus the toe's current offset from the
    # ankle" (heel off) continuously — as the ankle's fade-out goes and as the held ankle
    # leaves the leg's reach (the heel lifts because the leg cannot reach it), never by a
    # switch on one frame (was: a 1.1-unit jump of the Xia walk's left ankle, frames 158-159)
    def in_swing(j: int) -> NDArray[np.bool_] | None:  # given (the contacts' own clip), or measured
        return fast[j] if fast is not None and j in fast else _in_swing(w_ref[:, col[j]], ui, swing)

    ta, wa = _targets(on_a, w_ref[:, ca], blend, ui, follow, in_swing(lg.ankle))
    hop = _hops(on_a, blend)  # a short flight: held places do not pull the point down
    ta[:, ui] = np.where(hop, np.maximum(ta[:, ui], pos[:, ca, ui]), ta[:, ui])
    goal = pos[:, ca] + wa[:, None] * (ta - pos[:, ca])
    tt, wt = np.zeros((f, 3)), np.zeros(f)
    if lg.toe >= 0:
        ct = col[lg.toe]
        tt, wt = _targets(on_t, w_ref[:, ct], blend, ui, follow, in_swing(lg.toe))
        hop = _hops(on_t, blend)
        tt[:, ui] = np.where(hop, np.maximum(tt[:, ui], pos[:, ct, ui]), tt[:, ui])
        hip = pos[:, col[lg.hip]]
        length = np.linalg.norm(pos[:, col[lg.knee]] - hip, axis=1) + np.linalg.norm(
            pos[:, ca] - pos[:, col[lg.knee]], axis=1
        )
        r = np.linalg.norm(ta - hip, axis=1) / length
        x = np.clip((REACH_OUT - r) / (REACH_OUT - 1.0), 0.0, 1.0)
        q = x * x * (3.0 - 2.0 * x)  # 1 within the leg's length, 0 beyond REACH_OUT
        a = (wa * (1.0 - wt * (1.0 - q)))[:, None]  # the held ankle's share
        g_toe = pos[:, ca] + wt[:, None] * (tt - pos[:, ct])
        goal = a * ta + (1.0 - a) * g_toe  # = the ankle-only goal where wt = 0
    w = np.maximum(wa, wt)
    w_soft = w  # continuous: the soft-IK weight (a raise alone keeps the hard clamp)
    if lifted:
        assert lift is not None
        up = pos[:, ca, ui] + lift  # not faded by w
        # never inside a contact: there the goal is the held place (the raise had put a held
        # ankle back at the operator's own height wherever that was higher, so a filtered
        # clip's ankle bobbed with its hips while the toe held: the jumping jacks' toes slid
        # 0.05-0.17 hip heights/s while planted after equalize)
        raise_ = (up > goal[:, ui]) & ~(on_a | on_t)
        goal[raise_, ui] = up[raise_]
        w = np.where(raise_, 1.0, w)
    if floor is not None:  # nothing through the floor: the ankle, and the toe carried by it
        drop = np.zeros(f)
        if lg.toe >= 0:  # the toe below the ankle (kept where the foot is not turned to it)
            drop = np.minimum(pos[:, col[lg.toe], ui] - pos[:, ca, ui], 0.0) * (1.0 - wt)
        need = floor - (goal[:, ui] + drop)
        if lg.toe >= 0:  # a turned foot puts the toe on its held place, at most this low
            need = np.maximum(need, np.where(wt > 0, floor - tt[:, ui], -np.inf))
        under = need > 0
        if under.any():
            goal[under, ui] += need[under]
            w = np.where(under, 1.0, w)
    act = np.flatnonzero(w > 0).astype(np.int64)
    tclear = np.full(f, -np.inf)
    if toe_clear is not None and lg.toe >= 0:  # a turned toe keeps the reference's clearance
        tclear = np.where(on_t, -np.inf, toe_clear)
    return goal, tt, wt, w_soft, act, tclear


def _hops(on: NDArray[np.bool_], blend: int) -> NDArray[np.bool_]:
    """Frames between two contacts of a point at most ``2 · blend`` frames apart — where the
    fade-out of one contact meets the fade-in of the next and the held place is carried
    across (:func:`_bridge_gaps`): a hop's flight (jumping jacks: 0.2 s in the air, the two
    0.2 s fades), not a walking swing (0.4 s and more)."""
    out = np.zeros(on.size, bool)
    runs = _runs(on)
    for (_, e1), (s2, _) in zip(runs[:-1], runs[1:], strict=False):
        if s2 - e1 <= 2 * blend:
            out[e1:s2] = True
    return out


def _in_swing(p: Array, ui: int, swing: float) -> NDArray[np.bool_] | None:
    """Frames where the point ``p (f, 3)`` moves horizontally faster than ``swing`` × its own
    95th-percentile speed (its swing speed, measured on the clip; ``None`` when off)."""
    if swing <= 0 or p.shape[0] < 2:
        return None
    horiz = [a for a in range(3) if a != ui]
    v = np.hypot(*np.gradient(p[:, horiz], axis=0).T)
    return v > swing * float(np.percentile(v, 95))


def _reference(motion: Motion, reference: Motion | None) -> Motion:
    if (
        reference is not None
        and reference.n_frames == motion.n_frames
        and reference.names == motion.names
    ):
        return reference
    return motion


FLOOR_TOLERANCE = 0.01
"""After an operator that changes the timing or the sides, a foot may end this fraction of
the body scale below the input's lowest foot (the CLI's floor): a mirrored capture whose
legs differ stands that much lower (cmu_01_01 1.8 %, dme fixed 1.4 %), and holding it
exactly at the input's floor raised the planted feet (dme fixed mirror skate 0.495 → 0.586,
input 0.571; with 1 %: 0.539)."""


def foot_floor(motion: Motion, up: str | None = None, tolerance: float = 0.0) -> float | None:
    """The lowest height any foot point (ankle or toe) reaches in ``motion`` (``None`` when
    the skeleton has no legs), less ``tolerance`` × the body scale: the floor
    :func:`lock_feet` keeps."""
    legs = find_legs(motion)
    if not legs:
        return None
    ui = _UP[(up or motion.meta.get("up_guess") or guess_up_axis(motion)).lower()]
    chain = _leg_chain(motion, legs)
    col = {int(j): c for c, j in enumerate(chain)}
    pos = _chain_fk(motion, chain)[0]
    pts = [col[j] for j in _contact_points(legs)]
    low = float(pos[:, pts, ui].min())
    return low - tolerance * _ground_and_scale(pos, pts, ui)[1] if tolerance else low


def inputs_floor(motion: Motion, inputs: Sequence[Motion]) -> float | None:
    """The floor an operator's output keeps: the lowest :func:`foot_floor` (with
    :data:`FLOOR_TOLERANCE`) of the ``inputs`` that share ``motion``'s joints (``None`` when
    none does or none has legs)."""
    floors = [foot_floor(g, tolerance=FLOOR_TOLERANCE) for g in inputs if g.names == motion.names]
    return min((f for f in floors if f is not None), default=None)


def lock_feet(
    motion: Motion,
    reference: Motion | None = None,
    options: ContactOptions | None = None,
    floor: float | None = None,
    contacts: dict[int, NDArray[np.bool_]] | None = None,
    swing: dict[int, NDArray[np.bool_]] | None = None,
) -> Motion:
    """``motion`` with planted feet held in place (see the module docstring).

    Contacts and their held positions come from ``reference`` when given (same frame count
    and joints: the input of an operator that keeps timing, so an edit cannot lift or slide
    the feet), else from ``motion`` itself. No ankle or toe ends below ``floor`` — by default
    the lowest foot point of the reference (or of ``motion``); pass the input's
    (:func:`foot_floor`) after an operator that changes the timing or the sides (speed,
    blend, cycle, mirror). ``contacts`` (joint index → ``bool[f]``) replaces the detection:
    a retarget passes the source's contacts mapped onto the target's feet, and with them
    ``swing``, the frames where each source point is in full swing (:func:`_in_swing` on
    the source; else measured on the reference): a contact's fade-out is compressed into the
    frames before the point's full swing (``ContactOptions.swing``), and that moment is
    the source's — a retarget's own toe path may already be moving fast in the last frames
    of a contact it did not detect (the creature biped's 2.2× longer foot pitching at the
    source's heel-off), and measured there the fade-out shrank to no frame at all: a held
    toe the leg could not reach snapped back 0.09 hip heights in one frame. Returns
    ``motion`` unchanged when the skeleton has no legs or locking is disabled."""
    o = options or ContactOptions()
    legs = find_legs(motion)
    if not o.enabled or not legs or motion.n_frames < 2:
        return motion
    ref = _reference(motion, reference)
    opts = o if o.up is not None else replace(o, up=ref.meta.get("up_guess") or guess_up_axis(ref))
    ui = _UP[opts.up.lower()]
    chain = _leg_chain(motion, legs)
    col = {int(j): c for c, j in enumerate(chain)}
    pos, wq = _chain_fk(motion, chain)
    same = ref is motion or (  # a copy of ``motion`` as its own reference: no second FK
        ref.rotation is motion.rotation
        and ref.root_position is motion.root_position
        and ref.joint_translation is motion.joint_translation
        and ref.skeleton is motion.skeleton
    )
    w_ref = pos if same else _chain_fk(ref, chain)[0]
    if contacts is None:
        contacts = _detect(w_ref, col, legs, motion.fps, opts, ui)
    blend = max(1, round(o.blend_s * motion.fps))
    follow = o.mode == "follow"
    if floor is None:
        floor = float(w_ref[:, [col[j] for j in _contact_points(legs)], ui].min())
    goals = []
    for lg in legs:
        lift = toe_clear = None
        if ref is not motion and lg.toe >= 0:  # an operator's output: keep the input's clearance
            foot = float(np.linalg.norm(motion.skeleton.offset[lg.toe]))
            lift, toe_clear = _clearance(lg, col, pos, w_ref, ui, foot)
        goals.append(
            _leg_goals(
                lg,
                col,
                pos,
                w_ref,
                contacts,
                blend,
                ui,
                follow,
                lift,
                float(o.swing),
                floor,
                toe_clear,
                swing,
            )
        )
    rot = np.array(motion.rotation, dtype=np.float64)
    rest = np.ascontiguousarray(motion.skeleton.rest_rotation, dtype=np.float64)
    par = motion.skeleton.parent
    clamped = 0
    for i, lg in enumerate(legs):
        g = goals[i]
        if g is None or g[3].size == 0:
            continue
        goal, tt, wt, w_soft, act, tfl = g
        cp = col[int(par[lg.hip])] if par[lg.hip] >= 0 else -1  # -1: the hip is a root
        cols = np.array(
            [cp, col[lg.hip], col[lg.knee], col[lg.ankle], col.get(lg.toe, -1)], dtype=np.int64
        )
        joints = np.array([lg.hip, lg.knee, lg.ankle], dtype=np.int64)
        clamped += _lock_leg(
            pos,
            wq,
            cols,
            goal,
            act,
            tt,
            wt,
            w_soft,
            float(o.soft),
            rest,
            joints,
            rot,
            ui,
            floor,
            tfl,
        )
    if clamped:
        warnings.warn(
            f"{clamped} foot-contact target(s) out of the leg's reach; clamped to the leg length",
            ContactWarning,
            stacklevel=2,
        )
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
    "foot_floor",
    "inputs_floor",
    "FLOOR_TOLERANCE",
]
