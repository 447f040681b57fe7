"""Joint nodes, armature node, skin with inverse bind matrices and the skinned bone mesh."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import InputError, ParameterError
from biomorph.io.gltf.arrays import _Z_TO_Y, _Z_TO_Y_QUAT, _float32, _joint_nodes, _unit_rows
from biomorph.io.gltf.builder import (
    _BONE_MATERIAL,
    _SKIN_MATERIAL,
    _TRIANGLES,
    ARRAY_BUFFER,
    _Builder,
)
from biomorph.io.gltf.meshes import _indices
from biomorph.io.gltf.sticks import _SHAPES, _bone_solids, _joint_meshes


def _converted_rest(skeleton: JointSkeleton, y_up: bool) -> tuple[NDArray, NDArray]:
    """Local rest translation and (unit) rotation per joint, roots turned to Y-up."""
    trans = np.array(skeleton.offset, dtype=float)
    rot = tf.quat_normalize(np.asarray(skeleton.rest_rotation, dtype=float))
    if not y_up:
        roots = skeleton.parent < 0
        trans[roots] = trans[roots] @ _Z_TO_Y.T
        rot[roots] = tf.quat_multiply(_Z_TO_Y_QUAT, rot[roots])
    return trans, rot


def _add_skeleton(
    builder: _Builder,
    skeleton: JointSkeleton,
    *,
    bone_shape: str | None,
    bone_width: Any,
    joint_meshes: Mapping[Any, Any] | None,
    y_up: bool,
    name: str | None,
    joint_extras: Sequence[Mapping[str, Any] | None] | None = None,
    extras: Mapping[str, Any] | None = None,
    joint_geometry: Any = None,
    skinned: Any = None,
) -> list[int]:
    """Joint nodes, armature node, skin and skinned bone mesh; returns joint node indices.

    ``joint_extras`` (one JSON-ready mapping or ``None`` per joint) and ``extras`` (armature
    node) become glTF ``extras``, which Blender's importer turns into custom properties of
    the bones / object."""
    n = len(skeleton)
    if n > 65535:
        raise InputError(f"skeleton has {n} joints; glTF JOINTS_0 holds at most 65535")
    check = np.concatenate([skeleton.offset.ravel(), skeleton.rest_rotation.ravel()])
    if not np.isfinite(check).all():
        raise InputError("skeleton offsets or rest rotations hold NaN or inf")
    trans, rot = _converted_rest(skeleton, y_up)
    world = skeleton.world_matrices(tf.make_transform(tf.quat_to_matrix(rot), trans))

    first = len(builder.doc["nodes"])
    nodes = _joint_nodes(skeleton.names, trans, rot)
    order = np.argsort(skeleton.parent, kind="stable")
    sorted_parent = skeleton.parent[order]
    starts = np.searchsorted(sorted_parent, np.arange(n))
    ends = np.searchsorted(sorted_parent, np.arange(n), side="right")
    for i in range(n):
        if ends[i] > starts[i]:
            nodes[i]["children"] = (order[starts[i] : ends[i]] + first).tolist()
    if joint_extras is not None:
        if len(joint_extras) != n:
            raise ParameterError(
                f"joint_extras holds {len(joint_extras)} entries; expected {n} (one per joint)"
            )
        for node, ex in zip(nodes, joint_extras, strict=True):
            if ex:
                node["extras"] = dict(ex)
    for node in nodes:
        builder.node(node)
    roots = np.flatnonzero(skeleton.parent < 0)
    arm_node: dict[str, Any] = {"name": name or "armature", "children": (roots + first).tolist()}
    if extras:
        arm_node["extras"] = dict(extras)
    armature = builder.node(arm_node, root=True)
    joints = list(range(first, first + n))

    ibm = tf.invert_rigid(world).astype(np.float32)
    ibm[:, 3, :] = np.array([0, 0, 0, 1], np.float32)  # exact last row
    skin = {
        "name": f"{name or 'armature'}_skin",
        "joints": joints,
        "skeleton": armature,
        "inverseBindMatrices": builder.accessor(ibm, matrix=True),
    }
    builder.doc["skins"].append(skin)

    parts = []
    if bone_shape is not None:
        if bone_shape not in _SHAPES:
            raise ParameterError(
                f"bone_shape must be one of {', '.join(_SHAPES)} or None; got {bone_shape!r}"
            )
        parts.append(_bone_solids(skeleton, world, bone_shape, bone_width))
    if joint_meshes:
        parts.append(_joint_meshes(skeleton, world, joint_meshes, builder.scale))
    if joint_geometry is not None:
        parts.append(_joint_geometry(skeleton, world, joint_geometry, builder.scale))
    parts = [p for p in parts if len(p[0])]
    if parts:
        base = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
        pos = np.concatenate([p[0] for p in parts])
        nrm = np.concatenate([p[1] for p in parts])
        jnt = np.concatenate([p[2] for p in parts])
        faces = np.concatenate([p[3] + b for p, b in zip(parts, base, strict=True)])
        jdtype = np.uint8 if n <= 256 else np.uint16
        joints0 = np.zeros((len(pos), 4), jdtype)
        joints0[:, 0] = jnt
        weights0 = np.zeros((len(pos), 4), np.float32)
        weights0[:, 0] = 1.0
        attrs = {
            "POSITION": builder.accessor(
                _float32("bone vertices", pos), target=ARRAY_BUFFER, bounds=True
            ),
            "NORMAL": builder.accessor(nrm.astype(np.float32), target=ARRAY_BUFFER),
            "JOINTS_0": builder.accessor(joints0, target=ARRAY_BUFFER),
            "WEIGHTS_0": builder.accessor(weights0, target=ARRAY_BUFFER),
        }
        prim = {
            "attributes": attrs,
            "indices": _indices(builder, faces, len(pos)),
            "material": builder.material(_BONE_MATERIAL),
            "mode": _TRIANGLES,
        }
        label = f"{name or 'armature'}_bones"
        builder.doc["meshes"].append({"name": label, "primitives": [prim]})
        builder.node(
            {
                "name": label,
                "mesh": len(builder.doc["meshes"]) - 1,
                "skin": len(builder.doc["skins"]) - 1,
            },
            root=True,
        )
    if skinned is not None:
        _add_smooth_skin(builder, skinned, n, world, f"{name or 'armature'}_skin_mesh")
    return joints


def _joint_geometry(
    skeleton: JointSkeleton, world: NDArray, geometry: Sequence[Any], scale: float
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """``(vertices, normals, joint, faces)`` with each vertex in its joint's frame, moved
    to bind space in one batched transform."""
    try:
        verts, nrm, jnt, faces = (np.asarray(a) for a in geometry)
    except (TypeError, ValueError):
        raise ParameterError("joint_geometry must be (vertices, normals, joint, faces)") from None
    k = len(verts)
    if (
        verts.shape != (k, 3)
        or nrm.shape != (k, 3)
        or jnt.shape != (k,)
        or faces.ndim != 2
        or faces.shape[1] != 3
    ):
        raise ParameterError(
            f"joint_geometry shapes {verts.shape}, {nrm.shape}, "
            f"{jnt.shape}, {faces.shape}; expected (k, 3), (k, 3), (k,), "
            "(m, 3)"
        )
    n = len(skeleton)
    if k and (jnt.min() < 0 or jnt.max() >= n):
        raise ParameterError(f"joint_geometry joint index outside 0..{n - 1}")
    if faces.size and (faces.min() < 0 or faces.max() >= k):
        raise ParameterError(f"joint_geometry face index outside 0..{k - 1}")
    jnt = jnt.astype(np.int64)
    rot, trans = world[jnt, :3, :3], world[jnt, :3, 3]
    pos = np.einsum("kij,kj->ki", rot, verts * scale) + trans
    return pos, _unit_rows(np.einsum("kij,kj->ki", rot, nrm)), jnt, faces.astype(np.int64)


def _add_smooth_skin(
    builder: _Builder, skinned: Sequence[Any], n: int, world: NDArray, label: str
) -> None:
    """A second skinned mesh (e.g. a body envelope) with up to four weighted joints per
    vertex: ``(vertices, normals, joints (k, 4), weights (k, 4), faces)`` in bind space
    (the skeleton's rest world frame, before any ``scale``)."""
    try:
        verts, nrm, jnt, wts, faces = (np.asarray(a) for a in skinned)
    except (TypeError, ValueError):
        raise ParameterError(
            "skinned_mesh must be (vertices, normals, joints, weights, faces)"
        ) from None
    k = len(verts)
    if (
        verts.shape != (k, 3)
        or nrm.shape != (k, 3)
        or jnt.shape != (k, 4)
        or wts.shape != (k, 4)
        or faces.ndim != 2
        or faces.shape[1] != 3
        or not k
    ):
        raise ParameterError(
            f"skinned_mesh shapes {verts.shape}, {nrm.shape}, {jnt.shape}, "
            f"{wts.shape}, {faces.shape}; expected (k, 3), (k, 3), (k, 4), "
            "(k, 4), (m, 3) with k > 0"
        )
    if jnt.min() < 0 or jnt.max() >= n:
        raise ParameterError(f"skinned_mesh joint index outside 0..{n - 1}")
    w = np.clip(np.asarray(wts, float), 0.0, None)
    total = w.sum(axis=1, keepdims=True)
    if np.any(total <= 0):
        raise ParameterError("skinned_mesh has vertices whose weights sum to 0")
    w = (w / total).astype(np.float32)
    w[:, 0] += 1.0 - w.sum(axis=1)  # exact unit sums in float32
    jdtype = np.uint8 if n <= 256 else np.uint16
    attrs = {
        "POSITION": builder.accessor(
            _float32("skin vertices", verts * builder.scale), target=ARRAY_BUFFER, bounds=True
        ),
        "NORMAL": builder.accessor(
            _unit_rows(np.asarray(nrm, float)).astype(np.float32), target=ARRAY_BUFFER
        ),
        "JOINTS_0": builder.accessor(np.where(w > 0, jnt, 0).astype(jdtype), target=ARRAY_BUFFER),
        "WEIGHTS_0": builder.accessor(w, target=ARRAY_BUFFER),
    }
    prim = {
        "attributes": attrs,
        "indices": _indices(builder, np.asarray(faces), k),
        "material": builder.material(_SKIN_MATERIAL),
        "mode": _TRIANGLES,
    }
    builder.doc["meshes"].append({"name": label, "primitives": [prim]})
    builder.node(
        {
            "name": label,
            "mesh": len(builder.doc["meshes"]) - 1,
            "skin": len(builder.doc["skins"]) - 1,
        },
        root=True,
    )
