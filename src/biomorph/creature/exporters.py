"""Write a creature in any supported format, chosen by the file extension.

========  =====================================================================
.json     parameters, seed, bones (offsets, rotations, limits, boxes), masses, balance
.glb      skinned glTF: joint hierarchy + one bone mesh per joint, rigidly weighted
.bvh      hierarchy and rest pose (frame 0), optionally a procedural walk cycle
.obj      bone meshes in world space, one OBJ group per bone
.osim     OpenSim model: bodies with mass/inertia, joints with ranges in radians
.xml      MuJoCo MJCF (also ``.mjcf``)
========  =====================================================================
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from biomorph.creature.creature import Creature, write_json
from biomorph.errors import UnsupportedFormatError

FORMATS = (".json", ".glb", ".bvh", ".obj", ".osim", ".xml", ".mjcf")


def check_extension(path: str | os.PathLike[str]) -> str:
    """The lower-case extension of ``path`` if it is a creature format, else raise."""
    ext = Path(path).suffix.lower()
    if ext not in FORMATS:
        raise UnsupportedFormatError(
            f"{os.fspath(path)}: cannot write a creature as "
            f"{ext or '(no extension)'!r}; expected one of "
            f"{' '.join(FORMATS)}"
        )
    return ext


#: creature frame (faces +x, right on +z, Y up) -> glTF's convention (+Z forward, the
#: creature's left on +X, Y up): Blender then shows it facing -Y with left/right on X
TO_GLTF = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])

#: Blender's glTF importer ignores children closer than 4 mm when it picks a bone's
#: direction and length (io_scene_gltf2 ``MIN_BONE_LENGTH = 0.004``): shorter bones came in
#: 90 deg off and as long as their parent. Child offsets below this floor are lengthened.
BONE_FLOOR_M = 0.0045


def export(
    creature: Creature,
    path: str | os.PathLike[str],
    bone_shape: str = "bone",
    walk: bool = False,
    rigify: bool = False,
    lod: int = 1,
    skin: bool = False,
) -> Path:
    """Write ``creature`` to ``path`` (format by extension); atomic; returns the path.

    ``walk`` adds a procedural walk cycle (glb, bvh). ``rigify``: for ``.glb`` a real
    Rigify metarig (:func:`biomorph.creature.rigify.build_metarig`, rig types and exact
    bone heads/tails as node extras); for the other formats Rigify-style names only.
    ``.glb`` files use glTF's axes (+Z forward, left on +X); ``skin`` adds the body
    envelope skinned with smooth weights (glb) or as its own OBJ group (obj). ``bone_shape``
    ``bone`` (procedural bone models, :mod:`biomorph.creature.bones`) or ``box`` (the
    seed's boxes); ``lod`` 0, 1 or 2."""
    ext = check_extension(path)
    if rigify and not any(k == "spine" for k in creature.kind):
        from biomorph.errors import ParameterError

        raise ParameterError("--rigify needs a creature with a spine")
    if ext == ".glb":
        return write_glb(
            creature, path, bone_shape=bone_shape, walk=walk, rigify=rigify, lod=lod, skin=skin
        )
    original = creature
    if rigify:
        from biomorph.creature.rigify import with_rigify_names

        creature = with_rigify_names(creature)

    def walk_motion():
        from biomorph.creature.walk import walk_cycle

        return walk_cycle(original).with_(skeleton=creature.skeleton)

    if ext == ".json":
        return write_json(path, creature)
    if ext == ".bvh":
        from biomorph.io.bvh import write_bvh

        if walk:
            return write_bvh(path, walk_motion())
        return write_bvh(path, creature.skeleton)
    if ext == ".obj":
        from biomorph.creature.mesh import world_mesh
        from biomorph.io.obj import write_mesh

        mesh = world_mesh(creature, bone_shape, lod=lod)
        if skin:  # the envelope as one more group (bone id -1)
            from biomorph.core.mesh import Mesh
            from biomorph.creature.skin import body

            env = body(creature, lod=lod).envelope
            mesh = Mesh(
                np.concatenate([mesh.vertices, env.vertices]),
                np.concatenate([mesh.faces, env.faces + mesh.n_vertices]),
                normals=np.concatenate([mesh.normals, env.normals]),
                face_ids={
                    "bone": np.concatenate([mesh.face_ids["bone"], np.full(env.n_faces, -1)])
                },
            )
        return write_mesh(path, mesh, object_name="creature")
    if ext == ".osim":
        from biomorph.io.osim import write_osim

        return write_osim(path, creature)
    from biomorph.io.mjcf import write_mjcf

    return write_mjcf(path, creature)


def _to_gltf_axes(skeleton, motion):
    """Skeleton (and motion) with every root turned by :data:`TO_GLTF`."""
    from biomorph.core import transforms as tf

    q = tf.matrix_to_quat(TO_GLTF)
    roots = skeleton.parent < 0
    off, rest = np.array(skeleton.offset), np.array(skeleton.rest_rotation)
    off[roots] = off[roots] @ TO_GLTF.T
    rest[roots] = tf.quat_multiply(q, rest[roots])
    sk = skeleton.with_(offset=off, rest_rotation=rest)
    if motion is None:
        return sk, None
    return sk, motion.with_(skeleton=sk, root_position=np.asarray(motion.root_position) @ TO_GLTF.T)


#: name of the ground-level root bone of the GLB (game engines' and Rigify's ``root``)
ROOT_NAME = "root"
#: Rigify metarigs: the root bone lies on the ground, pointing forward, this share of the
#: creature's length long (Rigify's own root is drawn at about the rig's size)
ROOT_LENGTH_SHARE = 0.3


def ground_point(creature: Creature) -> np.ndarray:
    """The ground under the creature's centre of mass (creature frame, y = 0)."""
    com = np.asarray(creature.center_of_mass, float)
    return np.array([com[0], 0.0, com[2]])


def with_ground_root(skeleton, motion, ground: np.ndarray):
    """``skeleton`` (and ``motion``) under a new root joint :data:`ROOT_NAME` at ``ground``
    (creature frame), bone +Y pointing at the old root (so importers that aim a bone at its
    child keep it). The old root becomes its child; a motion's root travel moves to the new
    root along the ground (x, z) and its height change stays on the old root (a translation
    channel), so root motion rides on the ground bone. Returns ``(skeleton, motion)``."""
    from biomorph.core import transforms as tf
    from biomorph.core.skeleton import JointSkeleton
    from biomorph.creature.walk import _rot_between

    if ROOT_NAME in skeleton.names:
        raise ValueError(f"skeleton already has a joint named {ROOT_NAME!r}")
    off0 = np.asarray(skeleton.offset[0], float)
    aim = off0 - ground
    aim = aim / np.linalg.norm(aim) if np.linalg.norm(aim) > 1e-12 else np.array([0, 1.0, 0])
    R0 = _rot_between(np.array([0.0, 1.0, 0.0]), aim[None])[0]
    q0 = tf.matrix_to_quat(R0)
    q0_inv = q0 * np.array([-1.0, -1.0, -1.0, 1.0])
    par = np.asarray(skeleton.parent)
    offset = np.concatenate([ground[None], skeleton.offset])
    offset[1] = (off0 - ground) @ R0  # R0^T (off0 - ground)
    rest = np.concatenate([q0[None], skeleton.rest_rotation])
    rest[1] = tf.quat_multiply(q0_inv, skeleton.rest_rotation[0])
    sk = JointSkeleton(
        (ROOT_NAME, *skeleton.names),
        np.r_[-1, np.where(par >= 0, par + 1, 0)],
        offset,
        rest_rotation=rest,
        limits=np.concatenate([np.tile([-np.pi, np.pi], (1, 3, 1)), skeleton.limits]),
        end_site=np.concatenate([np.full((1, 3), np.nan), skeleton.end_site]),
    )
    if motion is None:
        return sk, None
    from biomorph.core.motion import Motion

    f = motion.n_frames
    rp = np.asarray(motion.root_position, float)
    travel = rp - off0
    ground_path = ground + travel * np.array([1.0, 0.0, 1.0])
    jt0 = getattr(motion, "joint_translation", None)
    jt = np.empty((f, len(sk), 3))
    jt[:, 1:] = np.broadcast_to(skeleton.offset, (f, len(skeleton), 3)) if jt0 is None else jt0
    jt[:, 0] = ground_path
    jt[:, 1] = (rp - ground_path) @ R0
    ident = np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), (f, 1, 4))
    rot = np.concatenate([ident, np.asarray(motion.rotation, float)], axis=1)
    return sk, Motion(sk, rot, ground_path, motion.frame_time, joint_translation=jt)


def _root_extras(creature: Creature, ground: np.ndarray) -> dict:
    """Rigify metarig extras of the root bone: on the ground, pointing forward, Z up."""
    to_blender = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]) @ TO_GLTF
    tail = ground + np.array([ROOT_LENGTH_SHARE * max(creature.length, 1e-3), 0.0, 0.0])
    return {
        "biomorph_head": np.round(ground @ to_blender.T, 9).tolist(),
        "biomorph_tail": np.round(tail @ to_blender.T, 9).tolist(),
        "biomorph_z": np.round(np.array([0.0, 1.0, 0.0]) @ to_blender.T, 9).tolist(),
        "biomorph_connect": 0,
    }


def floor_bone_lengths(skeleton, floor: float = BONE_FLOOR_M):
    """``skeleton`` with non-zero child offsets shorter than ``floor`` stretched to it (the
    subtree moves along the offset); returns ``(skeleton, number changed)``."""
    off = np.array(skeleton.offset)
    d = np.linalg.norm(off, axis=1)
    short = (skeleton.parent >= 0) & (d > 1e-12) & (d < floor)
    off[short] *= (floor / d[short])[:, None]
    return skeleton.with_(offset=off), int(short.sum())


def write_glb(
    creature: Creature,
    path: str | os.PathLike[str],
    *,
    bone_shape: str = "bone",
    walk: bool = False,
    rigify: bool = False,
    lod: int = 1,
    skin: bool = False,
) -> Path:
    """Skinned GLB of ``creature`` in glTF's axes: bone models rigidly skinned to their
    joints, optionally the body envelope with smooth weights (``skin``), a walk cycle and/or
    a Rigify metarig (see :func:`export`)."""
    from biomorph.creature.bones import geometry
    from biomorph.io.gltf import write_gltf

    geo = geometry(creature, bone_shape, lod)
    motion = None
    if walk:
        from biomorph.creature.walk import walk_cycle

        motion = walk_cycle(creature)
    extras: list | None = None
    owner_of = None
    if rigify:
        from biomorph.creature.rigify import build_metarig, joint_extras, retarget

        rig = build_metarig(creature)
        geo, owner_of = _geometry_on_rig(creature, rig, geo)
        skeleton = rig.skeleton
        motion = None if motion is None else retarget(motion, rig)
        extras = joint_extras(rig, TO_GLTF)
    else:
        skeleton = creature.skeleton
        if motion is None:
            skeleton, _ = floor_bone_lengths(skeleton)
    skinned = _skin_arrays(creature, skeleton, lod, owner_of) if skin else None
    # the ground-level root bone: every joint index moves up by one
    ground = ground_point(creature)
    skeleton, motion = with_ground_root(skeleton, motion, ground)
    geo = (geo[0], geo[1], geo[2] + 1, geo[3])
    if skinned is not None:
        skinned = (*skinned[:2], skinned[2] + 1, *skinned[3:])
    if extras is not None:
        extras = [_root_extras(creature, ground), *extras]
    skeleton, motion = _to_gltf_axes(skeleton, motion)
    if skinned is not None:
        skinned = (skinned[0] @ TO_GLTF.T, skinned[1] @ TO_GLTF.T, *skinned[2:])
    arm_extras = {"biomorph_metarig": 1} if rigify else None
    return write_gltf(
        path,
        skeleton,
        motion=motion,
        bone_shape=None,
        joint_geometry=geo,
        name="creature",
        joint_extras=extras,
        extras=arm_extras,
        skinned_mesh=skinned,
    )


def _skin_arrays(creature: Creature, skeleton, lod: int, owner_of):
    """Envelope vertices/normals in the exported skeleton's rest world frame, joints and
    weights re-indexed onto its bones (rig bones ride on creature joints)."""
    from biomorph.creature.skin import body

    b = body(creature, lod=lod)
    env = b.envelope
    jnt, w = b.joints, b.weights
    if owner_of is not None:
        jnt = owner_of[jnt]
        # rig world differs from the creature's only by the carry offsets: positions of the
        # rest pose are the same points
    return env.vertices, env.normals, jnt, w, env.faces


def _geometry_on_rig(creature: Creature, rig, geo):
    """Bone-model vertices moved from their creature joint's frame into a rig bone riding
    on that joint (or on its nearest ancestor that has one); also the rig bone per joint."""
    first: dict[int, int] = {}
    for b, o in enumerate(rig.owner.tolist()):
        first.setdefault(o, b)
    par = creature.skeleton.parent
    n = len(creature)
    to_rig = np.zeros(n, np.int64)
    mats = np.tile(np.eye(4), (n, 1, 1))
    for j in range(n):
        o = j
        while o not in first and par[o] >= 0:
            o = int(par[o])
        b = first.get(o, 0)
        to_rig[j] = b
        # rig frame = owner frame @ carry; j's frame relative to o's
        rel = np.linalg.inv(creature.world[o]) @ creature.world[j]
        mats[j] = np.linalg.inv(rig.carry[b]) @ rel
    v, nrm, jnt, f = geo
    m = mats[jnt]
    v2 = np.einsum("kij,kj->ki", m[:, :3, :3], v) + m[:, :3, 3]
    n2 = np.einsum("kij,kj->ki", m[:, :3, :3], nrm)
    return (v2, n2, to_rig[jnt], f), to_rig
