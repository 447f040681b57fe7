"""Rigify metarigs: a creature rebuilt as the bone layout Blender's Rigify add-on generates from.

Two levels:

* :func:`rigify_names` / :func:`with_rigify_names` only rename joints (``spine.001``,
  ``thigh.L`` …); the hierarchy stays the generator's (root mid-back).
* :func:`build_metarig` builds a real metarig: one connected chain from the pelvis forward to
  the head (``spine`` … ``neck`` … ``head``), the tail as its own chain from the pelvis,
  girdles (``shoulder.L``, ``pelvis.L``) unconnected on the spine, limbs of 3 connected
  bones, legs with a synthetic ``toe`` (on the ground, forward) and a ``heel`` (across the
  back of the foot, unconnected), as ``limbs.leg`` needs. Every bone's local X is its bend
  axis (spine: the creature's left; limbs: the generator's flexion axis, which is local Z
  of the limb frames, turned to point left), so Rigify's "automatic" rotation axis and
  Blender's X-mirror agree. Rig types are assigned per chain (``spines.basic_spine``,
  ``spines.super_head``, ``spines.basic_tail``, ``basic.super_copy``, ``limbs.leg``,
  ``limbs.arm``, ``basic.copy_chain``), falling back to simpler types when a chain is too
  short for the rig (basic_spine needs 3 bones, basic_tail 2, limbs.arm 3, limbs.leg 4).

Each rig bone rides rigidly on one generator joint (its *owner*), so a walk cycle carries
over exactly (:func:`retarget`): world(rig bone) = world(owner) · carry. The glTF written
with ``--rigify`` stores per bone ``rigify_type``, exact head/tail/roll-axis in Blender's
frame and the connect flag as node extras; :data:`BLENDER_SETUP` (``biomorph creature
rigify-setup``) is the Blender script that applies them after import and can run Rigify's
generate.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.creature.creature import Creature
from biomorph.errors import ParameterError

_LIMB = {
    ("shoulder", "leg"): ("shoulder", "upper_arm", "forearm", "hand"),
    ("shoulder", "arm"): ("shoulder", "upper_arm", "forearm", "hand"),
    ("centaur", "arm"): ("shoulder", "upper_arm", "forearm", "hand"),
    ("hip", "leg"): ("pelvis", "thigh", "shin", "foot"),
    ("shoulder", "wing"): ("wing_root", "wing", "wing.001", "wing.002"),
    ("centaur", "wing"): ("wing_root", "wing", "wing.001", "wing.002"),
}
_SEG = {"girdle": 0, "upper": 1, "lower": 2, "distal": 3}

#: toe length as a share of the foot (distal) bone; heel width as a share of the foot length
#: (Rigify's human metarig: toe ≈ 0.5 foot, heel.02 ≈ 0.5 foot; a paw's digits are shorter)
TOE_SHARE = 0.4
HEEL_SHARE = 0.4


def _numbered(stem: str, k: int) -> str:
    return stem if k == 0 else f"{stem}.{k:03d}"


def rigify_names(c: Creature) -> tuple[str, ...]:
    """Rigify-style names for every joint of ``c`` (same order)."""
    names = list(c.names)
    out = list(names)
    spine_idx = {
        r: [i for i, n in enumerate(names) if n.startswith(f"{r}_")]
        for r in ("neck", "back", "tail")
    }
    # vertebra numbers in the source names run head -> tail
    back = sorted(spine_idx["back"], key=lambda i: -int(names[i].split("_")[1]))
    for k, i in enumerate(back):
        out[i] = _numbered("spine", k)
    neck = sorted(spine_idx["neck"], key=lambda i: -int(names[i].split("_")[1]))
    for k, i in enumerate(neck):
        out[i] = _numbered("neck", k)
    tail = sorted(spine_idx["tail"], key=lambda i: int(names[i].split("_")[1]))
    for k, i in enumerate(tail):
        out[i] = _numbered("tail", k)
    for i, n in enumerate(names):
        if n == "skull":
            out[i] = "head"
        elif c.side[i] != 0 and n.count("_") >= 2:
            out[i] = _limb_name(c, i)
    if len(set(out)) != len(out):  # never produce duplicates: fall back to the source name
        seen: set[str] = set()
        for i, n in enumerate(out):
            if n in seen:
                out[i] = names[i]
            seen.add(out[i])
    return tuple(out)


def _limb_name(c: Creature, i: int) -> str:
    tag, seg, side = c.names[i].rsplit("_", 2)
    girdle, pair = tag.rstrip("0123456789"), tag[len(tag.rstrip("0123456789")) :] or "1"
    kind = _limb_kind(c, i)
    stems = _LIMB.get((girdle, kind), (f"{kind}_root", kind, f"{kind}.001", f"{kind}.002"))
    stem = stems[_SEG.get(seg, 3)]
    infix = "" if girdle != "centaur" else "_centaur"
    if int(pair) > 1:
        infix += f"_{pair}"
    return f"{stem}{infix}.{'L' if side == 'l' else 'R'}"


def _limb_kind(c: Creature, i: int) -> str:
    if c.kind[i] != "girdle":
        return c.kind[i]
    kids = np.flatnonzero(c.skeleton.parent == i)
    return c.kind[int(kids[0])] if kids.size else "limb"


def with_rigify_names(c: Creature) -> Creature:
    """A copy of ``c`` whose skeleton uses :func:`rigify_names`."""
    return replace(c, skeleton=c.skeleton.with_(names=rigify_names(c)))


# =========================================================================== metarig
@dataclass(frozen=True)
class Metarig:
    """A creature's Rigify metarig (creature frame: Y up, facing +x, right on +z).

    ``skeleton`` holds the rig bones (bone along local +Y, local X the bend axis);
    ``owner[b]`` the creature joint bone ``b`` rides on (``carry[b]`` its constant offset,
    ``world_rig = world_owner @ carry``); ``length`` the bone lengths; ``connect`` Rigify's
    connect flags; ``rigify_type`` and ``parameters`` per bone (``""`` / ``{}`` for none).
    """

    skeleton: JointSkeleton
    owner: NDArray[np.int64]
    carry: NDArray[np.float64]
    length: NDArray[np.float64]
    connect: NDArray[np.bool_]
    rigify_type: tuple[str, ...]
    parameters: tuple[dict[str, Any], ...]

    def __len__(self) -> int:
        return len(self.skeleton)


@dataclass
class _Bone:
    name: str
    head: NDArray
    tail: NDArray
    x_hint: NDArray
    parent: int
    owner: int
    connect: bool = False
    rigify_type: str = ""
    parameters: dict[str, Any] | None = None


def _path_up(parent: NDArray, j: int) -> list[int]:
    out = [j]
    while parent[out[-1]] >= 0:
        out.append(int(parent[out[-1]]))
    return out


def _torso_path(c: Creature, hips: int, skull: int) -> list[int]:
    """Joints from ``hips`` to ``skull`` through their lowest common ancestor."""
    par = c.skeleton.parent
    up_h, up_s = _path_up(par, hips), _path_up(par, skull)
    common = next(j for j in up_h if j in set(up_s))
    a = up_h[: up_h.index(common) + 1]
    b = up_s[: up_s.index(common)]
    return a + b[::-1]


def _left(c: Creature) -> NDArray:
    return np.array([0.0, 0.0, -1.0])  # creature frame: right is +z


def _pointing_left(axis: NDArray, left: NDArray) -> NDArray:
    d = float(axis @ left)
    return -axis if d < -0.1 else axis


def _spine_bones(c: Creature, bones: list[_Bone], rig_of: dict[int, int]) -> int:
    """Torso chain pelvis -> head and the tail; returns the pelvis bone index."""
    par, pos, world = c.skeleton.parent, c.joint_positions, c.world
    left = _left(c)
    skull = (
        c.kind.index("skull")
        if "skull" in c.kind
        else int(
            np.argmax(
                [len(_path_up(par, j)) if c.kind[j] == "spine" else -1 for j in range(len(c))]
            )
        )
    )
    hip_girdles = [j for j in range(len(c)) if c.kind[j] == "girdle" and c.region[j] == "hip"]
    hips = int(par[hip_girdles[0]]) if hip_girdles else int(np.flatnonzero(par < 0)[0])
    path = _torso_path(c, hips, skull)
    n_back = 0
    for a, b in zip(path[:-1], path[1:], strict=True):
        owner = a if par[b] == a else b
        if np.linalg.norm(pos[b] - pos[a]) <= 1e-9:  # coincident joints: no segment
            if bones:
                rig_of.setdefault(owner, len(bones) - 1)
            continue
        region = c.region[owner]
        stem = "neck" if region == "neck" else "spine"
        count = sum(1 for x in bones if x.name.split(".")[0] == stem)
        n_back += stem == "spine"
        first_neck = stem == "neck" and count == 0
        bones.append(
            _Bone(
                _numbered(stem, count),
                pos[a],
                pos[b],
                left,
                len(bones) - 1 if bones else -1,
                owner,
                connect=bool(bones) and not first_neck,
            )
        )
        rig_of.setdefault(owner, len(bones) - 1)
    head_end = pos[skull] + world[skull, :3, 1] * c.bone_length[skull]
    bones.append(
        _Bone(
            "head",
            pos[skull],
            head_end,
            left,
            len(bones) - 1,
            skull,
            connect=any(b.name.startswith("neck") for b in bones),
        )
    )
    rig_of[skull] = len(bones) - 1
    # rig types along the chain
    neck = [i for i, b in enumerate(bones) if b.name.startswith("neck")]
    if n_back >= 3:
        bones[0].rigify_type = "spines.basic_spine"
        bones[0].parameters = {"pivot_pos": max(1, min(n_back - 1, n_back // 3))}
    elif n_back >= 2:
        bones[0].rigify_type = "basic.copy_chain"
    elif n_back == 1:
        bones[0].rigify_type = "basic.super_copy"
    if neck:
        bones[neck[0]].rigify_type = "spines.super_head"
    else:
        bones[-1].connect = False
        bones[-1].rigify_type = "basic.super_copy"
    rig_of[hips] = 0
    _tail_bones(c, bones, rig_of, hips, set(path))
    return 0


def _tail_bones(
    c: Creature, bones: list[_Bone], rig_of: dict[int, int], hips: int, on_path: set[int]
) -> None:
    """The tail chain from the hips away from the torso path, following the spine through
    children and parents alike (hips mid-back leave the caudal vertebrae above them in the
    joint tree); coincident joints give no segment."""
    par, pos, world = c.skeleton.parent, c.joint_positions, c.world
    left = _left(c)

    def onward(j: int, seen: set[int]) -> int | None:
        near = [int(k) for k in np.flatnonzero(par == j)] + ([int(par[j])] if par[j] >= 0 else [])
        nxt = [k for k in near if c.kind[k] == "spine" and k not in on_path and k not in seen]
        return nxt[0] if nxt else None

    chain, seen = [hips], {hips}
    while (j := onward(chain[-1], seen)) is not None:
        chain.append(j)
        seen.add(j)
    if len(chain) == 1:
        chain.append(-1)  # no caudal spine: nothing to add
    first = len(bones)
    k = 0
    for a, b in zip(chain[:-1], chain[1:], strict=True):
        if b < 0:
            break
        owner = a if par[b] == a else b
        if np.linalg.norm(pos[b] - pos[a]) <= 1e-9:
            if len(bones) > first:
                rig_of.setdefault(owner, len(bones) - 1)
            continue
        bones.append(
            _Bone(
                _numbered("tail", k),
                pos[a],
                pos[b],
                left,
                0 if k == 0 else len(bones) - 1,
                owner,
                connect=k > 0,
            )
        )
        rig_of.setdefault(owner, len(bones) - 1)
        k += 1
    last = chain[-1]
    if last >= 0 and len(bones) > first and par[last] == chain[-2]:
        end = pos[last] + world[last, :3, 1] * c.bone_length[last]
        if np.linalg.norm(end - pos[last]) > 1e-9:  # the last vertebra's own bone
            bones.append(
                _Bone(
                    _numbered("tail", k), pos[last], end, left, len(bones) - 1, last, connect=True
                )
            )
            rig_of.setdefault(last, len(bones) - 1)
    n = len(bones) - first
    if n >= 2:
        bones[first].rigify_type = "spines.basic_tail"
        bones[first].parameters = {"connect_chain": False}
    elif n == 1:
        bones[first].rigify_type = "basic.super_copy"


def _limb_bones(c: Creature, bones: list[_Bone], rig_of: dict[int, int]) -> None:
    par, pos, world = c.skeleton.parent, c.joint_positions, c.world
    left = _left(c)
    names = rigify_names(c)
    for g in (j for j in range(len(c)) if c.kind[j] == "girdle"):
        chain = [g]
        while True:
            kids = np.flatnonzero(par == chain[-1])
            if kids.size != 1:
                break
            chain.append(int(kids[0]))
        kind = _limb_kind(c, g)
        start = len(bones)
        chain = chain[:4]  # girdle + three limb segments; digits are added as extras
        for k, j in enumerate(chain):
            tail = (
                pos[chain[k + 1]]
                if k + 1 < len(chain)
                else pos[j] + world[j, :3, 1] * max(c.bone_length[j], 1e-6)
            )
            flex = _pointing_left(world[j, :3, 2], left)
            parent = rig_of.get(int(par[j]), 0) if k == 0 else len(bones) - 1
            bones.append(_Bone(names[j], pos[j], tail, flex, parent, j, connect=k > 1))
            rig_of[j] = len(bones) - 1
        limb = len(chain) - 1
        bones[start].rigify_type = "basic.super_copy"
        if limb < 1:
            continue
        first = start + 1
        if kind == "leg" and limb == 3:
            _foot_bones(c, bones, chain[-1])
            bones[first].rigify_type = "limbs.leg"
        elif kind in ("leg", "arm", "wing") and limb == 3:
            bones[first].rigify_type = "limbs.arm"
        else:
            bones[first].rigify_type = "basic.copy_chain" if limb >= 2 else "basic.super_copy"


def _foot_bones(c: Creature, bones: list[_Bone], foot: int) -> None:
    """Synthetic ``toe`` (connected, forward along the ground) and ``heel`` (unconnected
    child of the foot, across its back at ground level) for Rigify's leg."""
    fb = len(bones) - 1
    L = float(np.linalg.norm(bones[fb].tail - bones[fb].head))
    base, side = bones[fb].name.rsplit(".", 1)
    fwd = np.array([1.0, 0.0, 0.0])
    left = _left(c)
    toe_tail = bones[fb].tail + fwd * TOE_SHARE * L
    bones.append(
        _Bone(f"{base}_toe.{side}", bones[fb].tail, toe_tail, left, fb, foot, connect=True)
    )
    w = HEEL_SHARE * L
    ground = bones[fb].tail.copy()
    ground[1] = min(ground[1], bones[fb].head[1])
    sgn = -1.0 if side == "L" else 1.0  # heel points outward: +z for the right foot
    h0, h1 = ground - left * sgn * 0.5 * w, ground + left * sgn * 0.5 * w
    h0 = h0 - fwd * 0.1 * L
    h1 = h1 - fwd * 0.1 * L
    bones.append(_Bone(f"{base}_heel.{side}", h0, h1, fwd, fb, foot))


def _other_bones(c: Creature, bones: list[_Bone], rig_of: dict[int, int]) -> None:
    """Every joint not yet in the rig (digits, extra vertebrae) as an unconnected bone of
    its own under its parent's rig bone; chains of them get ``basic.copy_chain``."""
    par, pos, world = c.skeleton.parent, c.joint_positions, c.world
    left = _left(c)
    names = rigify_names(c)
    taken = {b.name for b in bones}
    for j in range(len(c)):
        if j in rig_of:
            continue
        p = int(par[j])
        L = c.bone_length[j]
        if L <= 1e-9 or p < 0:
            rig_of[j] = rig_of.get(p, 0)
            continue
        name = names[j] if names[j] not in taken else c.names[j]
        taken.add(name)
        parent = rig_of.get(p, 0)
        chained = bones[parent].owner == p and p not in (b.owner for b in bones[:parent])
        bones.append(
            _Bone(
                name,
                pos[j],
                pos[j] + world[j, :3, 1] * L,
                _pointing_left(world[j, :3, 2], left),
                parent,
                j,
            )
        )
        rig_of[j] = len(bones) - 1
        if not bones[parent].rigify_type and not chained:
            bones[-1].rigify_type = "basic.super_copy"


def _no_zero_bones(c: Creature, bones: list[_Bone]) -> None:
    """Bones shorter than 0.1 % of the creature's size (coincident joints) get that length
    along their owner's bone axis, and their children are unconnected (Blender deletes
    zero-length bones)."""
    floor = 1e-3 * max(c.height, c.length, 1e-3)
    for i, b in enumerate(bones):
        if np.linalg.norm(b.tail - b.head) < floor:
            b.tail = b.head + c.world[b.owner, :3, 1] * floor
            for k in bones:
                if k.parent == i:
                    k.connect = False


#: connected chain lengths each rig type accepts (Rigify 0.6: limbs.leg exactly 4, limbs.arm
#: exactly 3, basic_spine >= 3, basic_tail / copy_chain >= 2, super_head >= 1)
_CHAIN = {
    "limbs.leg": (4, 4),
    "limbs.arm": (3, 3),
    "spines.basic_spine": (3, 10**6),
    "spines.basic_tail": (2, 10**6),
    "basic.copy_chain": (2, 10**6),
    "spines.super_head": (1, 10**6),
}


def _chain_length(bones: list[_Bone], i: int) -> int:
    """Length of the connected chain from bone ``i`` as Rigify follows it (stops where a
    bone has no or several connected children)."""
    kids: dict[int, list[int]] = {}
    for k, b in enumerate(bones):
        if b.connect and b.parent >= 0:
            kids.setdefault(b.parent, []).append(k)
    n = 1
    while len(kids.get(i, [])) == 1:
        i = kids[i][0]
        n += 1
    return n


def _fit_rig_types(bones: list[_Bone]) -> None:
    """Downgrade a rig type whose connected chain is too short or long for it."""
    for i, b in enumerate(bones):
        if b.rigify_type not in _CHAIN:
            continue
        lo, hi = _CHAIN[b.rigify_type]
        n = _chain_length(bones, i)
        if lo <= n <= hi:
            continue
        b.rigify_type = "basic.copy_chain" if n >= 2 else "basic.super_copy"
        b.parameters = {}


def _frames(bones: list[_Bone]) -> NDArray:
    """World rest matrices (k, 4, 4): Y along the bone, X the bend hint made orthogonal."""
    out = np.tile(np.eye(4), (len(bones), 1, 1))
    for i, b in enumerate(bones):
        y = b.tail - b.head
        y = y / max(np.linalg.norm(y), 1e-12)
        x = b.x_hint - (b.x_hint @ y) * y
        if np.linalg.norm(x) < 1e-6:
            helper = np.array([1.0, 0, 0]) if abs(y[0]) < 0.9 else np.array([0, 0, 1.0])
            x = helper - (helper @ y) * y
        x = x / np.linalg.norm(x)
        out[i, :3, :3] = np.stack([x, y, np.cross(x, y)], axis=1)
        out[i, :3, 3] = b.head
    return out


def build_metarig(c: Creature) -> Metarig:
    """The Rigify metarig of ``c`` (see the module docstring)."""
    if not any(k == "spine" for k in c.kind):
        raise ParameterError("a Rigify metarig needs a spine; the creature has none")
    bones: list[_Bone] = []
    rig_of: dict[int, int] = {}
    _spine_bones(c, bones, rig_of)
    _limb_bones(c, bones, rig_of)
    _other_bones(c, bones, rig_of)
    _no_zero_bones(c, bones)
    _fit_rig_types(bones)
    world = _frames(bones)
    parent = np.array([b.parent for b in bones], np.int64)
    local = world.copy()
    inner = parent >= 0
    local[inner] = tf.invert_rigid(world[parent[inner]]) @ world[inner]
    sk = JointSkeleton(
        [b.name for b in bones],
        parent,
        local[:, :3, 3],
        rest_rotation=tf.quat_normalize(tf.matrix_to_quat(local[:, :3, :3])),
    )
    owner = np.array([b.owner for b in bones], np.int64)
    carry = tf.invert_rigid(c.world[owner]) @ world
    length = np.array([np.linalg.norm(b.tail - b.head) for b in bones])
    return Metarig(
        sk,
        owner,
        carry,
        length,
        np.array([b.connect for b in bones]),
        tuple(b.rigify_type for b in bones),
        tuple(dict(b.parameters or {}) for b in bones),
    )


def retarget(motion: Any, rig: Metarig) -> Any:
    """The creature ``motion`` carried onto the metarig's bones (exact: each rig bone
    follows its owner joint rigidly); inner joints get translation keys where their owner
    moves relative to the parent's owner."""
    from biomorph.core.motion import Motion

    w = motion.world_matrices()[:, rig.owner] @ rig.carry[None]
    par = rig.skeleton.parent
    local = w.copy()
    inner = par >= 0
    local[:, inner] = tf.invert_rigid(w[:, par[inner]]) @ w[:, inner]
    rest = tf.quat_to_matrix(rig.skeleton.rest_rotation)
    pose_m = np.swapaxes(rest, -1, -2)[None] @ local[..., :3, :3]
    pose = tf.quat_continuous(tf.quat_normalize(tf.matrix_to_quat(pose_m)), axis=0)
    trans = local[..., :3, 3]
    root = np.flatnonzero(par < 0)[0]
    moved = np.abs(trans[:, inner] - rig.skeleton.offset[inner]).max() if inner.any() else 0
    jt = trans if moved > 1e-9 else None
    return Motion(rig.skeleton, pose, trans[:, root], motion.frame_time, joint_translation=jt)


def joint_extras(rig: Metarig, to_target: NDArray) -> list[dict[str, Any]]:
    """Per-bone glTF extras: ``rigify_type``, ``biomorph_head``/``biomorph_tail``/
    ``biomorph_z`` (Blender armature space: glTF ``(x, y, z)`` -> Blender ``(x, -z, y)``),
    ``biomorph_connect`` and ``biomorph_parameters``; ``to_target`` maps the creature frame
    into glTF's."""
    world = rig.skeleton.world_matrices()
    to_blender = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]) @ to_target
    heads = world[:, :3, 3] @ to_blender.T
    tails = (world[:, :3, 3] + world[:, :3, 1] * rig.length[:, None]) @ to_blender.T
    zs = world[:, :3, 2] @ to_blender.T
    out = []
    for i in range(len(rig)):
        ex: dict[str, Any] = {
            "biomorph_head": np.round(heads[i], 9).tolist(),
            "biomorph_tail": np.round(tails[i], 9).tolist(),
            "biomorph_z": np.round(zs[i], 9).tolist(),
            "biomorph_connect": int(rig.connect[i]),
        }
        if rig.rigify_type[i]:
            ex["rigify_type"] = rig.rigify_type[i]
        if rig.parameters[i]:
            ex["biomorph_parameters"] = rig.parameters[i]
        out.append(ex)
    return out
