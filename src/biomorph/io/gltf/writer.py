"""Public writers: :func:`write_gltf`, :func:`write_mesh`, :func:`write_mesh_animation`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import InputError, ParameterError
from biomorph.io.gltf.animation import _add_frames, _add_motion, _is_motion, _scaled
from biomorph.io.gltf.builder import PathLike, _Builder
from biomorph.io.gltf.meshes import _add_mesh_nodes, _as_meshes
from biomorph.io.gltf.skin import _add_skeleton


def write_gltf(
    path: PathLike,
    obj: Any = None,
    *,
    motion: Any = None,
    bone_shape: str | None = "box",
    bone_width: float | ArrayLike | None = None,
    meshes: Any = None,
    y_up: bool = True,
    name: str | None = None,
    merge: bool = True,
    frames: Sequence[Any] | None = None,
    frame_time: float = 1 / 30,
    scale: float = 1.0,
    joint_extras: Sequence[Mapping[str, Any] | None] | None = None,
    extras: Mapping[str, Any] | None = None,
    vertex_attributes: Mapping[str, Any] | None = None,
    joint_geometry: Any = None,
    skinned_mesh: Any = None,
) -> Path:
    """Write a skeleton, an animated skeleton, meshes or mesh frames as binary glTF (.glb).

    Parameters
    ----------
    path : output ``.glb`` file (or ``.gltf``: JSON with the buffer embedded as base64),
        written atomically.
    obj : a :class:`~biomorph.core.skeleton.JointSkeleton`; a Motion-like object (``.skeleton``,
        ``.rotation`` ``(f, n, 4)``, ``.root_position`` ``(f, 3)`` metres, ``.frame_time`` s);
        a mesh or a list of meshes; or ``None`` when only ``meshes``/``frames`` are given.
        Objects with a ``.skeleton`` but no motion (e.g. a generated creature) are unwrapped.
    motion : animate ``obj`` (a JointSkeleton) with this Motion-like object instead.
    bone_shape : ``"box"`` (default), ``"octahedron"`` or ``None`` (skin without geometry).
    bone_width : bone thickness in the skeleton's units (scalar or one per joint); default
        12 % of each bone's length, at least 4 % of the median bone length.
    meshes : extra geometry. With a skeleton, a mapping ``{joint name or index: mesh}`` gives
        meshes in that joint's local frame, rigidly skinned to it (bone models); a mesh or a
        list of meshes is added unskinned in world space.
    y_up : the input is Y-up (default). ``False`` for Z-up data: rotated into glTF's Y-up.
    name : scene / armature / mesh name.
    merge : merge a list of meshes into one primitive with a ``_MESH_ID`` attribute (default)
        instead of one node per mesh.
    frames : equal-topology meshes written as morph targets with a weight animation.
    frame_time : seconds between ``frames``.
    scale : multiplies every length on the way out (e.g. ``0.01`` for a BVH in centimetres);
        ``bone_width`` is given in the input's units and scaled too.
    joint_extras : one JSON-ready mapping (or ``None``) per joint, written as that joint
        node's ``extras`` (Blender's importer makes them bone custom properties).
    extras : JSON-ready mapping written as the armature node's ``extras`` (with a skeleton),
        else as the scene's ``extras`` (e.g. a canopy's ground tile).
    joint_geometry : ``(vertices (k, 3), normals (k, 3), joint (k,), faces (m, 3))``: bone
        models already concatenated, each vertex in its joint's local frame, rigidly skinned
        to that joint (the fast path for many small per-joint meshes).
    skinned_mesh : ``(vertices, normals, joints (k, 4), weights (k, 4), faces)`` in the
        skeleton's rest world frame: a second, smoothly weighted skinned mesh (a body
        envelope); weights are normalised to sum to 1.
    vertex_attributes : float arrays per vertex of the (single) mesh, ``{name: (n,) or
        (n, k<=4)}``, written as custom attributes ``_NAME`` (e.g. absorbed light).

    Returns the written path.
    """
    builder = _Builder(name)
    skeleton = None
    if obj is not None and not isinstance(obj, JointSkeleton) and _is_motion(obj):
        if motion is not None:
            raise ParameterError("obj is already a motion; pass motion= only with a skeleton")
        motion, skeleton = obj, obj.skeleton
    elif isinstance(obj, JointSkeleton):
        skeleton = obj
    elif obj is not None and isinstance(getattr(obj, "skeleton", None), JointSkeleton):
        skeleton = obj.skeleton
    if motion is not None:
        if not _is_motion(motion):
            raise ParameterError(
                f"motion is a {type(motion).__name__}; expected an object with "
                ".skeleton, .rotation, .root_position and .frame_time"
            )
        if skeleton is None:
            skeleton = motion.skeleton
        if len(motion.skeleton) != len(skeleton):
            raise InputError(
                f"motion animates {len(motion.skeleton)} joints; the skeleton has {len(skeleton)}"
            )
    if not isinstance(y_up, bool | np.bool_):
        raise ParameterError(f"y_up must be True or False; got {y_up!r}")
    if not (isinstance(scale, int | float | np.number) and np.isfinite(scale) and scale > 0):
        raise ParameterError(f"scale must be a positive finite number; got {scale!r}")
    builder.scale = float(scale)
    if scale != 1 and skeleton is not None:
        skeleton, motion = _scaled(skeleton, motion, float(scale))
        if bone_width is not None:
            bone_width = np.asarray(bone_width, dtype=float) * scale
    if skeleton is not None:
        joint_meshes = (
            meshes
            if isinstance(meshes, Mapping) and not ("vertices" in meshes and "faces" in meshes)
            else None
        )
        joints = _add_skeleton(
            builder,
            skeleton,
            bone_shape=bone_shape,
            bone_width=bone_width,
            joint_meshes=joint_meshes,
            y_up=y_up,
            name=name,
            joint_extras=joint_extras,
            extras=extras,
            joint_geometry=joint_geometry,
            skinned=skinned_mesh,
        )
        if motion is not None:
            _add_motion(builder, motion, skeleton, joints, y_up, name)
        if meshes is not None and joint_meshes is None:
            _add_mesh_nodes(builder, _as_meshes(meshes), merge=merge, y_up=y_up, name=None)
    else:
        parts = []
        if obj is not None:
            parts.extend(_as_meshes(obj))
        if meshes is not None:
            parts.extend(_as_meshes(meshes))
        if parts:
            _add_mesh_nodes(
                builder,
                parts,
                merge=merge,
                y_up=y_up,
                name=name,
                vertex_attributes=vertex_attributes,
            )
            if extras:
                builder.doc["scenes"][0]["extras"] = dict(extras)
        elif frames is None:
            raise InputError(
                "nothing to write: expected a JointSkeleton, a motion, meshes or frames"
            )
    if frames is not None:
        _add_frames(builder, frames, frame_time, y_up, name)
    return builder.save(path)


def write_mesh(
    path: PathLike,
    mesh: Any,
    *,
    y_up: bool = True,
    name: str | None = None,
    merge: bool = True,
    scale: float = 1.0,
) -> Path:
    """Write one mesh or a list of meshes as ``.glb`` (see :func:`write_gltf`)."""
    return write_gltf(
        path, None, meshes=_as_meshes(mesh), y_up=y_up, name=name, merge=merge, scale=scale
    )


def write_mesh_animation(
    path: PathLike,
    frames: Sequence[Any],
    frame_time: float,
    *,
    y_up: bool = True,
    name: str | None = None,
) -> Path:
    """Write equal-topology mesh frames (e.g. a growing leaf) as a morph-target animation."""
    return write_gltf(path, None, frames=frames, frame_time=frame_time, y_up=y_up, name=name)
