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
   stay at its own height; the source's floor (its lowest foot) is put at the target's 0.
5. Feet: :func:`biomorph.motion.contact.lock_feet` then holds the planted feet (the CLI and
   ``feet=True`` do this by default).

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

import os

import numpy as np
from numba import njit

from biomorph.core import transforms as tf
from biomorph.core.motion import Motion, frozen, ro, ro_int
from biomorph.core.skeleton import JointSkeleton
from biomorph.core.types import Array
from biomorph.errors import InputError
from biomorph.motion import names as nm
from biomorph.motion._kernels import _qmul, fk_positions, mirror_rotations


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
    rest_s, rot_s, parent_s, src_of, pre, post, rest_t, parent, rot_out
):  # pragma: no cover
    """Per frame: the source's world rotations (FK, as ``fk_positions``) into a per-frame
    buffer, then per target joint (parents first): mapped joints get the world rotation
    ``ws[src] · pre[j] · post[j]`` (source delta from rest, then the aligned target rest:
    ``pre = qs⁻¹``, ``post = align · qt``), unmapped ones their parent's world times their
    rest; the local pose is ``rest⁻¹ · parent⁻¹ · world``."""
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
                    px, py, pz, pw, rest_t[j, 0], rest_t[j, 1], rest_t[j, 2], rest_t[j, 3]
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
    floor = foot_floor(source, up)
    if floor is not None and up in _UP:
        root[:, _UP[up]] -= floor * scale
    if t_can["hips"] != 0:  # joints above the target's hips: keep them at rest, move the root
        root = root - (pt[hips_t] - pt[0])
    meta = {
        "source": source.meta.get("source"),
        "format": "retarget",
        "up_guess": source.meta.get("up_guess", "y"),
        "retarget": {"joints": len(pairs), "leg_scale": scale},
    }
    out = Motion(target, frozen(rot), frozen(root), source.frame_time, None, meta)
    if feet:
        foot_s = _foot_ratio(source.skeleton, ps, s_can)
        foot_t = _foot_ratio(target, pt, t_can)
        if foot_s > 0 and foot_t > 0 and max(foot_s, foot_t) > FOOT_RATIO * min(foot_s, foot_t):
            out = _lock_like_source(source, out, s_can, t_can)
        else:
            from biomorph.motion.contact import lock_feet

            out = lock_feet(out)
    return out


FOOT_RATIO = 1.5
"""Feet proportioned this much otherwise (foot length / leg length, source vs target) are
locked on the source's contacts (:func:`_lock_like_source`); similar feet on their own."""


def _foot_ratio(sk: JointSkeleton, pos: Array, m: dict[str, int]) -> float:
    """Foot (ankle → toe) over leg (thigh + shin) length on the rest pose; 0 without toes."""
    if "l_toe" not in m or "l_foot" not in m:
        return 0.0
    foot = float(np.linalg.norm(pos[m["l_toe"]] - pos[m["l_foot"]]))
    return foot / max(_leg_length(sk, pos, m), 1e-12)


def _lock_like_source(
    source: Motion, out: Motion, s_can: dict[str, int], t_can: dict[str, int]
) -> Motion:
    """Lock the target's feet on the *source's* contacts (ankle and toe mapped by their
    canonical names): a foot proportioned otherwise (a creature's foot is 0.37 hip heights
    long, a human's 0.14) swings its toe through the floor band at the source's foot angles,
    so contacts detected on the target missed the planted toes."""
    from biomorph.motion.contact import detect_contacts, find_legs, lock_feet

    legs = find_legs(out)
    src = detect_contacts(source)
    mapped: dict[int, np.ndarray] = {}
    for c in ("l_foot", "l_toe", "r_foot", "r_toe"):
        if c in s_can and c in t_can and s_can[c] in src:
            mapped[t_can[c]] = src[s_can[c]]
    points = {p for lg in legs for p in (lg.ankle, lg.toe) if p >= 0}
    if not mapped or not points <= set(mapped):
        return lock_feet(out)
    return lock_feet(out, contacts={j: v for j, v in mapped.items() if j in points})


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
