"""Retargeting between skeletons with other names and proportions, and left/right mirroring.

Retarget (:func:`retarget`)
---------------------------
1. Names: both skeletons are mapped to canonical humanoid joints (:mod:`biomorph.motion.names`:
   CMU, Mixamo, Rokoko/HumanIK, Rigify presets, detected from the names, or a user CSV of
   ``source,target`` names). The legs and hips (:data:`~biomorph.motion.names.REQUIRED`) must
   be mapped on both sides.
2. Rest-pose alignment: for every mapped joint the target's rest bone (joint → its mapped
   child, or its first child) is turned onto the source's rest bone direction, so a T-pose
   source drives an A-pose target without lifting its arms by the difference.
3. Rotations: the source joint's world rotation *relative to its rest* is applied to the
   aligned target joint in world space, then converted to the target's local pose rotations
   parents first; unmapped target joints keep their rest pose relative to their parent.
4. Root: the hips trajectory is scaled by the ratio of leg lengths (thigh + shin, measured on
   the rest poses), so a shorter character takes proportionally shorter steps and its hips
   stay at its own height; the source's floor (its lowest foot) is put at the target's 0,
   and then the target's own lowest foot (a rig whose hip sockets sit higher relative to its
   hips stood 10–15 % of its hip height above the floor: the Mixamo-named Rokoko rig under
   cmu and Xia walks).
5. Legs of feet proportioned otherwise (foot / leg length more than :data:`FOOT_RATIO` apart,
   a creature's): they follow the source's foot paths, not only its angles
   (:func:`_adapt_legs`); an unmapped joint between the hips and a thigh (a pelvic girdle)
   takes the source's hips → thigh direction (:func:`_girdle_rests`).
6. Feet: :func:`biomorph.motion.contact.lock_feet` then holds the planted feet (the CLI and
   ``feet=True`` do this by default), on the source's contacts where the feet differ.

Mirror (:func:`mirror`)
-----------------------
Left and right swap by name (Left/Right, ``.L``/``.R``, ``_l``/``_r``, ``L_``/``R_``): the
world rotation of each joint (rest included) is reflected across the body's sagittal plane
(normal: the lateral axis, found from the rest positions of the left/right pairs) —
``R' = M R M`` with ``M`` the reflection, i.e. the quaternion component along the lateral
axis kept and the other two negated — and assigned to its mirror joint; the root trajectory
is reflected too.
"""

from __future__ import annotations

import math
import os

import numpy as np
from numba import njit

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, frozen, ro, ro_int
from biomorph.core.skeleton import JointSkeleton
from biomorph.core.types import Array
from biomorph.errors import InputError
from biomorph.motion import names as nm
from biomorph.motion._kernels import _qmul, _qrot, fk_positions, mirror_rotations


def _rest_world(sk: JointSkeleton) -> tuple[Array, Array]:
    """World positions (n, 3) and orientations (n, 4) of the rest pose."""
    n = sk.n_joints
    pos, quat = np.empty((1, n, 3)), np.empty((1, n, 4))
    fk_positions(
        ro(sk.rest_rotation),
        ro(tf.quat_identity((1, n))),
        ro(sk.offset[None]),
        ro_int(sk.parent),
        pos,
        quat,
    )
    return pos[0], quat[0]


@njit(cache=True)
def _retarget_kernel(
    rest_s, rot_s, parent_s, src_of, pre, post, rest_t, rest_w, parent, rot_out
):  # pragma: no cover
    """Per frame: the source's world rotations (FK, as ``fk_positions``) into a per-frame
    buffer, then per target joint (parents first): mapped joints get the world rotation
    ``ws[src] · pre[j] · post[j]`` (source delta from rest, then the aligned target rest:
    ``pre = qs⁻¹``, ``post = align · qt``), unmapped ones their parent's world times
    ``rest_w`` (their rest, or the rest turned onto the source's hips → thigh direction:
    :func:`_girdle_rests`); the local pose is ``rest⁻¹ · parent⁻¹ · world``."""
    f, n = rot_s.shape[0], parent.size
    world = np.empty((n, 4))
    ws = np.empty((rot_s.shape[1], 4))
    for t in range(f):
        for j in range(rot_s.shape[1]):
            lx, ly, lz, lw = _qmul(
                rest_s[j, 0],
                rest_s[j, 1],
                rest_s[j, 2],
                rest_s[j, 3],
                rot_s[t, j, 0],
                rot_s[t, j, 1],
                rot_s[t, j, 2],
                rot_s[t, j, 3],
            )
            p = parent_s[j]
            if p >= 0:
                lx, ly, lz, lw = _qmul(ws[p, 0], ws[p, 1], ws[p, 2], ws[p, 3], lx, ly, lz, lw)
            ws[j, 0], ws[j, 1], ws[j, 2], ws[j, 3] = lx, ly, lz, lw
        for j in range(n):
            p = parent[j]
            if p >= 0:
                px, py, pz, pw = world[p, 0], world[p, 1], world[p, 2], world[p, 3]
            else:
                px, py, pz, pw = 0.0, 0.0, 0.0, 1.0
            s = src_of[j]
            if s >= 0:
                x, y, z, w = _qmul(
                    ws[s, 0],
                    ws[s, 1],
                    ws[s, 2],
                    ws[s, 3],
                    pre[j, 0],
                    pre[j, 1],
                    pre[j, 2],
                    pre[j, 3],
                )
                x, y, z, w = _qmul(x, y, z, w, post[j, 0], post[j, 1], post[j, 2], post[j, 3])
            else:
                x, y, z, w = _qmul(
                    px, py, pz, pw, rest_w[j, 0], rest_w[j, 1], rest_w[j, 2], rest_w[j, 3]
                )
            world[j, 0], world[j, 1], world[j, 2], world[j, 3] = x, y, z, w
            # local = rest^-1 * parent^-1 * world
            lx, ly, lz, lw = _qmul(-px, -py, -pz, pw, x, y, z, w)
            lx, ly, lz, lw = _qmul(
                -rest_t[j, 0], -rest_t[j, 1], -rest_t[j, 2], rest_t[j, 3], lx, ly, lz, lw
            )
            if (
                t > 0
                and (
                    lx * rot_out[t - 1, j, 0]
                    + ly * rot_out[t - 1, j, 1]
                    + lz * rot_out[t - 1, j, 2]
                    + lw * rot_out[t - 1, j, 3]
                )
                < 0
            ):
                lx, ly, lz, lw = -lx, -ly, -lz, -lw
            rot_out[t, j, 0], rot_out[t, j, 1], rot_out[t, j, 2], rot_out[t, j, 3] = lx, ly, lz, lw


def _maps(
    source: JointSkeleton,
    target: JointSkeleton,
    source_preset: str | None,
    target_preset: str | None,
    csv_map: str | os.PathLike[str] | None,
) -> list[tuple[int, int, str]]:
    """(source joint, target joint, canonical name) pairs."""
    if csv_map is not None:
        pairs = nm.read_map_csv(csv_map)
        si = {nm.bare(n): i for i, n in enumerate(source.names)}
        ti = {nm.bare(n): i for i, n in enumerate(target.names)}
        miss = [a for a in pairs if nm.bare(a) not in si] + [
            b for b in pairs.values() if nm.bare(b) not in ti
        ]
        if miss:
            raise InputError(
                f"{os.fspath(csv_map)}: joint {miss[0]!r} is not in the "
                f"{'source' if nm.bare(miss[0]) not in si else 'target'} skeleton"
            )
        out = [(si[nm.bare(a)], ti[nm.bare(b)], "") for a, b in pairs.items()]
        s_can = {v: k for k, v in nm.resolve(source.names, nm.detect_preset(source.names)).items()}
        out = [(s, t, s_can.get(s, "")) for s, t, _ in out]
    else:
        sp = source_preset or nm.detect_preset(source.names)
        tp = target_preset or nm.detect_preset(target.names)
        s_map = nm.resolve(source.names, sp, source.parent)
        t_map = nm.resolve(target.names, tp, target.parent)
        for side, m, p, sk in (("source", s_map, sp, source), ("target", t_map, tp, target)):
            miss = [c for c in nm.REQUIRED if c not in m]
            if miss:
                raise InputError(
                    f"retarget map misses required joint {miss[0]!r} in the {side} "
                    f"skeleton (preset {p!r}: expected "
                    f"{nm.PRESETS[p].get(miss[0], miss[0])!r} among "
                    f"{', '.join(sk.names[:4])}, …)"
                )
        out = [(s_map[c], t_map[c], c) for c in nm.CANONICAL if c in s_map and c in t_map]
    # joints outside the canonical set (fingers, extra spine or clavicle joints) follow by
    # identical name when both skeletons have them
    used_s, used_t = {s for s, _, _ in out}, {t for _, t, _ in out}
    si = {nm.bare(n): i for i, n in enumerate(source.names)}
    for t, name in enumerate(target.names):
        s = si.get(nm.bare(name))
        if s is not None and t not in used_t and s not in used_s:
            out.append((s, t, ""))
    got = {c for *_, c in out}
    miss = [c for c in nm.REQUIRED if c not in got]
    if miss:
        raise InputError(
            f"retarget map misses required joint {miss[0]!r}; expected the hips "
            "and both legs (thigh, shin, foot) mapped"
        )
    return out


def _girdle_rests(
    target: JointSkeleton,
    pt: Array,
    qt: Array,
    ps: Array,
    s_of: dict[int, int],
    s_can: dict[str, int],
    t_can: dict[str, int],
    align: dict[int, Array],
) -> Array:
    """The rest rotations the retarget composes unmapped target joints with: their own, but
    an unmapped joint that carries a thigh (a creature's pelvic girdle, ``hip1_girdle_l →
    hip1_upper_l``) is turned so that its thigh bone (girdle → hip socket) points where the
    source's hips → thigh points at rest. Kept at its rest, the generated biped's girdle
    (every rest bone along +y) put both hip sockets on one point 0.2 leg lengths *above* the
    pelvis: legs hanging from the middle of the body, too high for the floor."""
    rest_w = np.array(target.rest_rotation, dtype=float)
    hips_t = t_can.get("hips")
    if hips_t is None or "hips" not in s_can:
        return rest_w
    par = target.parent
    for side in ("l", "r"):
        th_t, th_s = t_can.get(f"{side}_thigh"), s_can.get(f"{side}_thigh")
        if th_t is None or th_s is None:
            continue
        g = int(par[th_t])
        if g < 0 or g in s_of or g == hips_t:
            continue
        chain = []  # unmapped joints from the girdle up to the nearest mapped ancestor
        j = g
        while j >= 0 and j not in s_of:
            chain.append(j)
            j = int(par[j])
        if j != hips_t:
            continue
        # the girdle's world orientation at the source's rest (mapped hips: align · qt)
        w = tf.quat_multiply(align[hips_t], qt[hips_t])
        for k in reversed(chain[1:]):
            w = tf.quat_multiply(w, rest_w[k])
        w = tf.quat_multiply(w, rest_w[g])
        d = np.asarray(target.offset[th_t], dtype=float)
        u = ps[th_s] - ps[s_can["hips"]]
        if np.linalg.norm(d) < 1e-12 or np.linalg.norm(u) < 1e-12:
            continue
        a = d / np.linalg.norm(d)
        b = tf.quat_rotate(tf.quat_conjugate(w), u / np.linalg.norm(u))
        c = np.cross(a, b)
        q = np.array([*c, 1.0 + float(a @ b)])
        if q[3] > 1e-9:
            rest_w[g] = tf.quat_multiply(rest_w[g], tf.quat_normalize(q))
    return rest_w


def _leg_length(sk: JointSkeleton, pos: Array, m: dict[str, int]) -> float:
    out = []
    for s in ("l", "r"):
        a, b, c = m[f"{s}_thigh"], m[f"{s}_shin"], m[f"{s}_foot"]
        out.append(np.linalg.norm(pos[b] - pos[a]) + np.linalg.norm(pos[c] - pos[b]))
    return float(np.mean(out))


def retarget(
    source: Motion,
    target: JointSkeleton,
    source_preset: str | None = None,
    target_preset: str | None = None,
    csv_map: str | os.PathLike[str] | None = None,
    feet: bool = True,
) -> Motion:
    """``source`` played on the ``target`` skeleton (see the module docstring)."""
    pairs = _maps(source.skeleton, target, source_preset, target_preset, csv_map)
    s_of = {t: s for s, t, _ in pairs}
    ps, qs = _rest_world(source.skeleton)
    pt, qt = _rest_world(target)
    s_can = {c: s for s, _, c in pairs if c}
    t_can = {c: t for _, t, c in pairs if c}
    scale = _leg_length(target, pt, t_can) / max(_leg_length(source.skeleton, ps, s_can), 1e-12)
    # rest alignment per mapped target joint: turn its rest bone onto the source's
    align = {}
    t_kids = {j: [int(k) for k in np.flatnonzero(target.parent == j)] for j in s_of}
    for t, s in s_of.items():
        kids = [k for k in t_kids[t] if k in s_of] or t_kids[t]
        if not kids:
            align[t] = tf.quat_identity()
            continue
        k = kids[0]
        dt = pt[k] - pt[t]
        ds = (
            (ps[s_of[k]] - ps[s])
            if k in s_of
            else tf.quat_rotate(tf.quat_multiply(qs[s], tf.quat_conjugate(qt[t])), dt)
        )
        if np.linalg.norm(dt) < 1e-12 or np.linalg.norm(ds) < 1e-12:
            align[t] = tf.quat_identity()
            continue
        a, b = dt / np.linalg.norm(dt), ds / np.linalg.norm(ds)
        c = np.cross(a, b)
        q = np.array([*c, 1.0 + float(a @ b)])
        align[t] = (
            tf.quat_normalize(q)
            if q[3] > 1e-9
            else tf.quat_from_axis_angle(np.cross(a, np.eye(3)[np.argmin(np.abs(a))]), np.pi)
        )
    f, n = source.n_frames, target.n_joints
    src_of = np.full(n, -1, dtype=np.int64)
    pre = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    post = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    for t, s in s_of.items():
        src_of[t] = s
        pre[t] = tf.quat_conjugate(qs[s])
        post[t] = tf.quat_multiply(align[t], qt[t])
    rot = np.empty((f, n, 4))
    _retarget_kernel(
        ro(source.skeleton.rest_rotation),
        ro(source.rotation),
        ro_int(source.skeleton.parent),
        ro_int(src_of),
        ro(pre),
        ro(post),
        ro(target.rest_rotation),
        ro(_girdle_rests(target, pt, qt, ps, s_of, s_can, t_can, align)),
        ro_int(target.parent),
        rot,
    )
    hips_s, hips_t = s_can["hips"], t_can["hips"]
    # the root's world position is its translation; other hips need the FK positions
    src_hips = source.root_position if hips_s == 0 else source.world_positions()[:, hips_s]
    root = src_hips * scale
    # the source's floor (its lowest foot) lands on the target's y = 0 (an ASF capture's floor
    # sat 0.4 hip heights above a creature biped's ground)
    from biomorph.motion.contact import _UP, foot_floor

    up = str(source.meta.get("up_guess") or "y").lower()
    foot_s = _foot_ratio(source.skeleton, ps, s_can)
    foot_t = _foot_ratio(target, pt, t_can)
    other = foot_s > 0 and foot_t > 0 and max(foot_s, foot_t) > FOOT_RATIO * min(foot_s, foot_t)
    legs_s = _SourceLegs(source, s_can) if other else None  # one FK for floor, paths, contacts
    floor = foot_floor(source, up) if legs_s is None else legs_s.floor(up)
    if floor is not None and up in _UP:
        root[:, _UP[up]] -= floor * scale
    if t_can["hips"] != 0:  # joints above the target's hips: keep them at rest, move the root
        root = root - (pt[hips_t] - pt[0])
    adapt = legs_s is not None and floor is not None and up in _UP
    meta = {
        "source": source.meta.get("source"),
        "format": "retarget",
        "up_guess": source.meta.get("up_guess", "y"),
        "retarget": {
            "joints": len(pairs),
            "leg_scale": scale,
            "legs": "source's foot paths" if adapt else "source's angles",
        },
    }
    if adapt:  # the legs follow the source's foot paths (writes ``rot`` in place)
        assert legs_s is not None and floor is not None
        tmp = Motion(target, frozen(rot.view()), frozen(root), source.frame_time, None, {})
        drop = _adapt_legs(legs_s, tmp, rot, s_can, t_can, scale, floor, _UP[up])
        root = np.array(root)
        root[:, _UP[up]] -= drop
    out = Motion(target, frozen(rot), frozen(root), source.frame_time, None, meta)
    if feet:
        if legs_s is not None:
            out = _lock_like_source(legs_s, out, s_can, t_can)
        else:
            from biomorph.motion.contact import lock_feet

            out = lock_feet(out)
    low = foot_floor(out, up) if up in _UP else None
    if low is not None and low != 0.0:  # its own lowest foot on y = 0, as the source's was
        root = np.array(out.root_position)
        root[:, _UP[up]] -= low
        out = out.with_(root_position=frozen(root))
    return out


class _SourceLegs:
    """The source's leg chains (legs found by name, and by canonical name) evaluated once:
    world positions and orientations, shared by the floor, the foot paths and the contacts."""

    def __init__(self, source: Motion, s_can: dict[str, int]) -> None:
        from biomorph.motion.contact import Leg, _chain_fk, _leg_chain, find_legs

        self.motion = source
        self.named = find_legs(source)
        sides = [s for s in ("l", "r") if all(f"{s}_{b}" in s_can for b in _LEG)]
        self.canon = {s: Leg(*(s_can[f"{s}_{b}"] for b in _LEG)) for s in sides}
        chain = _leg_chain(source, [*self.named, *self.canon.values()])
        self.col = {int(j): c for c, j in enumerate(chain)}
        self.pos, self.quat = _chain_fk(source, chain)

    def floor(self, up: str) -> float | None:
        """:func:`~biomorph.motion.contact.foot_floor` of the source."""
        from biomorph.motion.contact import _UP, _contact_points

        if not self.named or up not in _UP:
            return None
        pts = [self.col[j] for j in _contact_points(self.named)]
        return float(self.pos[:, pts, _UP[up]].min())

    def contacts(self) -> dict[int, np.ndarray]:
        """:func:`~biomorph.motion.contact.detect_contacts` of the source."""
        from biomorph.motion.contact import ContactOptions, _detect, _up_of

        m, o = self.motion, ContactOptions()
        if not self.named or m.n_frames < 2:
            return {}
        return _detect(self.pos, self.col, self.named, m.fps, o, _up_of(m, o))


FOOT_RATIO = 1.5
"""Feet proportioned this much otherwise (foot length / leg length, source vs target) are
locked on the source's contacts (:func:`_lock_like_source`); similar feet on their own."""


def _foot_ratio(sk: JointSkeleton, pos: Array, m: dict[str, int]) -> float:
    """Foot (ankle → toe) over leg (thigh + shin) length on the rest pose; 0 without toes."""
    if "l_toe" not in m or "l_foot" not in m:
        return 0.0
    foot = float(np.linalg.norm(pos[m["l_toe"]] - pos[m["l_foot"]]))
    return foot / max(_leg_length(sk, pos, m), 1e-12)


def _foot_frame(q0: Array, d0: Array, ui: int) -> tuple[Array, Array]:
    """The foot's lateral axis in its own frame (horizontal and across the rest foot ``d0``,
    the foot's rest world orientation ``q0``) and the rest foot's horizontal direction."""
    up = np.zeros(3)
    up[ui] = 1.0
    lat = np.cross(up, d0)
    if np.linalg.norm(lat) < 1e-9 * max(float(np.linalg.norm(d0)), 1e-300):
        lat = np.zeros(3)
        lat[(ui + 2) % 3] = 1.0
    lat /= np.linalg.norm(lat)
    return tf.quat_rotate(tf.quat_conjugate(q0), lat), np.cross(lat, up)


@njit(cache=True)
def _pitch_kernel(sq, local, ahead, ui, ta, tt, goal, want, tq):  # pragma: no cover - compiled
    """Per frame: turn the target foot (world orientation ``tq[t]``, ankle ``ta[t]``, toe
    ``tt[t]``) in the vertical plane of its heading so that, with the ankle at ``goal[t]``, its
    toe is at height ``want[t]`` (clamped at straight up / down). The heading is the source
    foot's lateral axis ``local`` (in the foot's frame; orientation ``sq[t]``) turned a
    quarter about the up axis: the foot vector's own horizontal part has no heading where the
    foot points straight down (after a toe-off) and flips between ahead of and behind the
    ankle there; the lateral axis stays horizontal unless the foot rolls onto its side."""
    f = tq.shape[0]
    for t in range(f):
        ax, ay, az = _qrot(sq[t, 0], sq[t, 1], sq[t, 2], sq[t, 3], local[0], local[1], local[2])
        if ui == 1:  # h = a × up (horizontal)
            hx, hy, hz = -az, 0.0, ax
        elif ui == 2:
            hx, hy, hz = ay, -ax, 0.0
        else:
            hx, hy, hz = 0.0, az, -ay
        hn = math.sqrt(hx * hx + hy * hy + hz * hz)
        if hn < 1e-9:
            hx, hy, hz = ahead[0], ahead[1], ahead[2]
            hn = math.sqrt(hx * hx + hy * hy + hz * hz)
        hx, hy, hz = hx / hn, hy / hn, hz / hn
        cx, cy, cz = tt[t, 0] - ta[t, 0], tt[t, 1] - ta[t, 1], tt[t, 2] - ta[t, 2]
        foot = math.sqrt(cx * cx + cy * cy + cz * cz)
        if foot <= 1e-12:
            continue
        sy = min(max((want[t] - goal[t, ui]) / foot, -1.0), 1.0)
        ch = math.sqrt(1.0 - sy * sy)
        g = [hx * ch, hy * ch, hz * ch]
        g[ui] = sy
        cx, cy, cz = cx / foot, cy / foot, cz / foot
        w = 1.0 + cx * g[0] + cy * g[1] + cz * g[2]
        if w < 1e-9:  # opposite: no unique turn, leave the foot
            continue
        x, y, z = cy * g[2] - cz * g[1], cz * g[0] - cx * g[2], cx * g[1] - cy * g[0]
        n = math.sqrt(x * x + y * y + z * z + w * w)
        x, y, z, w = x / n, y / n, z / n, w / n
        tq[t, 0], tq[t, 1], tq[t, 2], tq[t, 3] = _qmul(
            x, y, z, w, tq[t, 0], tq[t, 1], tq[t, 2], tq[t, 3]
        )


_LEG = ("thigh", "shin", "foot", "toe")


def _adapt_legs(
    legs_s: _SourceLegs,
    out: Motion,
    rot: Array,
    s_can: dict[str, int],
    t_can: dict[str, int],
    scale: float,
    floor: float,
    ui: int,
) -> Array:
    """The legs of a target whose feet are proportioned otherwise (:data:`FOOT_RATIO`) follow
    the source's foot *paths*, not only its angles. Per leg and frame:

    1. the ankle goal is the source's ankle scaled by the leg ratio (the source's floor on
       y = 0) plus the rig's constant offset: the median over the frames of the target's hip
       socket minus the source's scaled socket (a creature's pelvis and sockets sit otherwise
       than a human's; the constant keeps its legs where its own body puts them, the
       frame-to-frame path is the source's);
    2. the foot is pitched so its toe is as high as the source's toe (scaled, same offset):
       its heading (:func:`_heading`) and its roll are kept, only its angle in the vertical
       plane changes, clamped at straight up / down;
    3. where a goal is out of the leg's reach (less the IK's soft band) — the rig's sockets
       pass farther from the source's foot path on some frames than the median says (the
       zombie walk's straight stance legs: a quarter of the frames up to 5 % beyond reach,
       the planted ankles left hanging 4 % of hip height up) — the pelvis is lowered by what
       the leg lacks straight down (per frame, the most either leg lacks; returned, the
       caller moves the root);
    4. hip and knee are solved for the ankle goal by the contact module's two-bone IK (soft
       over the last 0.5 % of the leg's reach, :class:`~biomorph.motion.contact.ContactOptions`
       ``soft``), the foot keeping the pitched orientation.

    At the source's angles, a foot 2.2× longer relative to the leg (the generated biped's
    foot is 0.35 of its leg, a human's 0.16) held its heel 0.14 hip heights up when the
    source's was planted and swept its toe 2.2× lower through the swing; with the source's
    heights, heel and toe are on the floor when the source's are and the source's contacts
    (:func:`_lock_like_source`) hold them."""
    from biomorph.motion.contact import ContactOptions, Leg, _chain_fk, _leg_chain, _lock_leg

    sides = [s for s in legs_s.canon if all(f"{s}_{b}" in t_can for b in _LEG)]
    if not sides:
        return np.zeros(out.n_frames)
    s_legs = [legs_s.canon[s] for s in sides]
    t_legs = [Leg(*(t_can[f"{s}_{b}"] for b in _LEG)) for s in sides]
    s_col = legs_s.col
    s_pos = legs_s.pos * scale
    s_pos[..., ui] -= floor * scale  # the source in the target's units, its floor at 0
    s_quat = legs_s.quat
    ps, qs = _rest_world(legs_s.motion.skeleton)
    t_chain = _leg_chain(out, t_legs)
    t_col = {int(j): c for c, j in enumerate(t_chain)}
    t_pos, t_quat = _chain_fk(out, t_chain)
    rest = np.ascontiguousarray(out.skeleton.rest_rotation, dtype=float)
    par = out.skeleton.parent
    f = out.n_frames
    soft = ContactOptions().soft
    goals, wants = [], []
    drop = np.zeros(f)
    for sl, lg in zip(s_legs, t_legs, strict=True):
        off = np.median(t_pos[:, t_col[lg.hip]] - s_pos[:, s_col[sl.hip]], axis=0)
        goals.append(np.ascontiguousarray(s_pos[:, s_col[sl.ankle]] + off))
        wants.append(s_pos[:, s_col[sl.toe], ui] + off[ui])  # the toe's height
        # what the leg lacks to reach the goal, straight down: the pelvis drops by it
        hip, knee = t_pos[:, t_col[lg.hip]], t_pos[:, t_col[lg.knee]]
        reach = (1.0 - soft) * (
            np.linalg.norm(knee - hip, axis=1)
            + np.linalg.norm(t_pos[:, t_col[lg.ankle]] - knee, axis=1)
        )
        v = goals[-1] - hip
        vh2 = np.sum(v * v, axis=1) - v[:, ui] ** 2
        need = -np.sqrt(np.maximum(reach * reach - vh2, 0.0)) - v[:, ui]
        drop = np.maximum(drop, need)
    t_pos[..., ui] -= drop[:, None]  # the root lowered: every chain joint with it
    for sl, lg, goal, want in zip(s_legs, t_legs, goals, wants, strict=True):
        ca = t_col[lg.ankle]
        local, ahead = _foot_frame(qs[sl.ankle], ps[sl.toe] - ps[sl.ankle], ui)
        tq = np.ascontiguousarray(t_quat[:, ca])
        _pitch_kernel(
            np.ascontiguousarray(s_quat[:, s_col[sl.ankle]]), local, ahead, ui,
            np.ascontiguousarray(t_pos[:, ca]), np.ascontiguousarray(t_pos[:, t_col[lg.toe]]),
            goal, np.ascontiguousarray(want), tq,
        )  # fmt: skip
        t_quat[:, ca] = tq
        cp = t_col[int(par[lg.hip])] if par[lg.hip] >= 0 else -1
        cols = np.array([cp, t_col[lg.hip], t_col[lg.knee], ca, -1], dtype=np.int64)
        joints = np.array([lg.hip, lg.knee, lg.ankle], dtype=np.int64)
        _lock_leg(
            t_pos, t_quat, cols, goal, np.arange(f, dtype=np.int64), np.zeros((f, 3)),
            np.zeros(f), np.ones(f), soft, rest, joints, rot, ui, -np.inf, np.full(f, -np.inf),
        )  # fmt: skip
    return drop


def _lock_like_source(
    legs_s: _SourceLegs, out: Motion, s_can: dict[str, int], t_can: dict[str, int]
) -> Motion:
    """Lock the target's feet on the *source's* contacts (ankle and toe mapped by their
    canonical names): a foot proportioned otherwise (a creature's foot is 0.37 hip heights
    long, a human's 0.14) swings its toe through the floor band at the source's foot angles,
    so contacts detected on the target missed the planted toes. Outside its contacts no toe
    ends lower than the retarget put it (``lock_feet``'s reference clearance, the retarget
    itself as the reference): the toe turned toward a held place during a fade does not
    scrape. A contact's fade-out ends where the *source's* point reaches full swing (``lock_feet``'s
    ``swing``), as it would locking the source."""
    from biomorph.motion.contact import ContactOptions, _in_swing, _up_of, find_legs, lock_feet

    legs = find_legs(out)
    src = legs_s.contacts()
    o = ContactOptions()
    ui = _up_of(legs_s.motion, o)
    mapped: dict[int, np.ndarray] = {}
    fast: dict[int, np.ndarray] = {}
    for c in ("l_foot", "l_toe", "r_foot", "r_toe"):
        if c in s_can and c in t_can and s_can[c] in src:
            mapped[t_can[c]] = src[s_can[c]]
            sw = _in_swing(legs_s.pos[:, legs_s.col[s_can[c]]], ui, o.swing)
            if sw is not None:  # full swing as the source's point reaches it
                fast[t_can[c]] = sw
    points = {p for lg in legs for p in (lg.ankle, lg.toe) if p >= 0}
    if not mapped or not points <= set(mapped):
        return lock_feet(out)
    ref = out.with_(meta=dict(out.meta))  # the same frames as a reference: its clearance kept
    keep = {j: v for j, v in mapped.items() if j in points}
    return lock_feet(out, ref, o, contacts=keep, swing={j: fast[j] for j in keep if j in fast})


def _lateral_axis(sk: JointSkeleton, pairs: list[tuple[int, int]], pos: Array | None = None) -> int:
    """The axis along which the left/right pairs differ most: of the rest pose, or of the
    world positions ``pos (f, n, 3)`` (summed over frames) when given."""
    if pos is None:
        pos = _rest_world(sk)[0][None]
    d = np.zeros(3)
    for a, b in pairs:
        d += np.abs(pos[:, a] - pos[:, b]).sum(axis=0)
    return int(np.argmax(d))


def _rotation_between(u: Array, v: Array) -> Array:
    """The smallest rotation matrix taking direction ``u`` onto ``v`` (180° about any
    perpendicular axis when they are opposite)."""
    u = u / np.linalg.norm(u)
    v = v / np.linalg.norm(v)
    c = float(u @ v)
    if c < -1.0 + 1e-12:
        w = np.cross(u, np.eye(3)[int(np.argmin(np.abs(u)))])
        w /= np.linalg.norm(w)
        return 2.0 * np.outer(w, w) - np.eye(3)
    k = np.cross(u, v)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + kx + kx @ kx / (1.0 + c)


SYMMETRIC_DEG = 30.0
"""A rig whose every bone lies within this angle of its mirror bone's image (captured CMU,
Xia, dme rigs: at most 8°) mirrors its local angles as they are; beyond it (Rokoko: 180°, each
bone along +x on both sides) the frames are corrected (:func:`_mirror_corrections`)."""


def _mirror_corrections(
    sk: JointSkeleton, other: Array, a: int, world0: Array
) -> tuple[Array, bool]:
    """Per joint j a constant rotation ``C[j]`` (quaternions ``(n, 4)``) with the mirrored
    world rotation ``M·W[other j]·M·C[j]`` putting every child bone of j where the mirror of
    the other side's bone is: ``C[j]·d = M·d'`` for each child offset ``d`` and its mirror
    child's ``d'`` (and the End Sites). Identity on a rig whose left and right local frames are
    mirror images (CMU, Mixamo, Xia…); on rigs with the joint orientations baked in (Rokoko:
    every bone along its local +x on both sides) a Kabsch fit over the children, or with one
    child the rotation closest to ``M·S`` (``S`` the reflection across the lateral direction
    in the other joint's frame at ``world0``, its world orientations at frame 0) that puts the
    bone in place. Returns the corrections and whether they are used: identity, False when every
    bone is within :data:`SYMMETRIC_DEG` of its mirror image."""
    n = sk.n_joints
    m = np.ones(3)
    m[a] = -1.0
    off = np.asarray(sk.offset, dtype=float)
    end = np.asarray(sk.end_site, dtype=float)
    children: list[list[int]] = [[] for _ in range(n)]
    for c in range(1, n):
        children[int(sk.parent[c])].append(c)
    scale = float(np.abs(off).max()) or 1.0
    corr = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    mat = np.diag(m)
    e = np.eye(3)[a]
    worst = 0.0
    for j in range(n):
        o = int(other[j])
        src, dst = [], []
        for c in children[j]:
            src.append(off[c])
            dst.append(m * off[int(other[c])])
        if np.isfinite(end[j]).all() and np.isfinite(end[o]).all():
            src.append(end[j])
            dst.append(m * end[o])
        src_a, dst_a = np.array(src).reshape(-1, 3), np.array(dst).reshape(-1, 3)
        keep = np.linalg.norm(src_a, axis=1) > 1e-9 * scale
        src_a, dst_a = src_a[keep], dst_a[keep]
        if not len(src_a) or np.abs(src_a - dst_a).max() <= 1e-9 * scale:
            continue
        cos = (
            np.sum(src_a * dst_a, 1) / np.linalg.norm(src_a, axis=1) / np.linalg.norm(dst_a, axis=1)
        )
        worst = max(worst, float(np.degrees(np.arccos(np.clip(cos.min(), -1.0, 1.0)))))
        h = src_a.T @ dst_a
        u_, s_, vt = np.linalg.svd(h)
        if s_[1] > 1e-6 * s_[0]:  # two or more independent bones: the fit fixes the twist
            dd = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u_.T)) or 1.0])
            r = vt.T @ dd @ u_.T
        else:  # one bone direction: closest to the frame's own mirror, then onto the bone
            nl = tf.quat_rotate(tf.quat_conjugate(world0[o]), e)
            k0 = mat @ (np.eye(3) - 2.0 * np.outer(nl, nl))
            w = src_a[0] / np.linalg.norm(src_a[0])
            if float(w @ dst_a[0]) > 0.0:
                k0 = np.eye(3)
            r = _rotation_between(k0 @ w, dst_a[0] / np.linalg.norm(dst_a[0])) @ k0
        corr[j] = tf.matrix_to_quat(r)
    if worst <= SYMMETRIC_DEG:  # a captured rig's own asymmetry: mirror the angles as they are
        return np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), False
    return corr, True


def mirror(motion: Motion, axis: int | None = None) -> Motion:
    """Swap left and right (see the module docstring); ``axis`` the lateral axis (0, 1, 2),
    found from the rest pose when None (from the animated pose when the rest pose is not
    left/right symmetric, e.g. Rokoko's all-along-x rest; never the up axis)."""
    sk = motion.skeleton
    pairs = nm.left_right_pairs(sk.names)
    if not pairs:
        raise InputError(
            f"mirror needs left/right joint names (Left…/Right…, ….L/….R, …_l/…_r);"
            f" the skeleton has none ({', '.join(sk.names[:4])}, …)"
        )
    other = np.arange(sk.n_joints)
    for i, j in pairs:
        other[i], other[j] = j, i
    world0 = np.empty((1, sk.n_joints, 4))  # world orientations of frame 0
    fk_positions(
        ro(sk.rest_rotation),
        ro(np.ascontiguousarray(motion.rotation[:1])),
        ro(sk.offset[None]),
        ro_int(sk.parent),
        np.empty((1, sk.n_joints, 3)),
        world0,
    )
    world0 = world0[0]
    if axis is None:
        a = _lateral_axis(sk, pairs)
        corr, use_corr = _mirror_corrections(sk, other, a, world0)
        up = {"x": 0, "y": 1, "z": 2}.get(str(motion.meta.get("up_guess") or "y").lower(), 1)
        if use_corr or a == up:  # rest pose not symmetric: the lateral axis of the motion
            step = max(1, motion.n_frames // 64)
            pos = np.array(motion.world_positions()[::step])
            pos[..., up] = 0.0
            a = _lateral_axis(sk, pairs, pos)
            corr, use_corr = _mirror_corrections(sk, other, a, world0)
    else:
        a = int(axis)
        corr, use_corr = _mirror_corrections(sk, other, a, world0)
    sign = -np.ones(4)
    sign[a] = 1.0
    sign[3] = 1.0
    rot = np.empty(motion.rotation.shape)
    # per frame: world rotations (FK), the mirror joint's reflected, back to local poses
    mirror_rotations(
        ro(sk.rest_rotation),
        ro(motion.rotation),
        ro_int(sk.parent),
        ro_int(other),
        ro(sign),
        ro(corr),
        use_corr,
        rot,
    )
    pos = np.array(motion.root_position)
    pos[:, a] = -pos[:, a]
    jt = None
    if motion.joint_translation is not None:
        jt = np.array(motion.joint_translation[:, other])
        jt[..., a] = -jt[..., a]
        if use_corr:  # local translations in the corrected parent frames: C[parent]⁻¹·M·t
            par = np.maximum(np.asarray(sk.parent), 0)
            jt = tf.quat_rotate(tf.quat_conjugate(corr[par])[None], jt)
        jt[:, 0] = pos
    meta = dict(motion.meta)
    meta["history"] = [*meta.get("history", []), f"mirror axis={'xyz'[a]}"]
    return motion.with_(
        rotation=frozen(rot), root_position=frozen(pos), joint_translation=jt, meta=meta
    )


__all__ = ["retarget", "mirror"]
