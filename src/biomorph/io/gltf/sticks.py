"""Display solids for a bare JointSkeleton (no bone models given): one box or octahedron per
parent->child bone, a cube at tips, in bind space; and per-joint meshes given in joint frames
moved to bind space. Creature bone models come from :mod:`biomorph.creature.bones` and arrive
here as per-joint meshes."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core.mesh import Mesh
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import ParameterError
from biomorph.io.gltf.arrays import _unit_rows

# unit solids in a bone frame: x, y across (half-width 0.5), z along the bone from 0 to 1;
# listed as triangles with their own corners so flat normals come out per triangle
_BOX = np.array(
    [
        [-0.5, -0.5, 0],
        [0.5, -0.5, 0],
        [0.5, 0.5, 0],
        [-0.5, 0.5, 0],
        [-0.5, -0.5, 1],
        [0.5, -0.5, 1],
        [0.5, 0.5, 1],
        [-0.5, 0.5, 1],
    ]
)
_BOX_TRIS = np.array(
    [
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ]
)
_OCTA = np.array(
    [
        [0, 0, 0],
        [-0.5, -0.5, 0.15],
        [0.5, -0.5, 0.15],
        [0.5, 0.5, 0.15],
        [-0.5, 0.5, 0.15],
        [0, 0, 1],
    ]
)
_OCTA_TRIS = np.array(
    [[0, 2, 1], [0, 3, 2], [0, 4, 3], [0, 1, 4], [5, 1, 2], [5, 2, 3], [5, 3, 4], [5, 4, 1]]
)
_SHAPES = {"box": (_BOX, _BOX_TRIS), "octahedron": (_OCTA, _OCTA_TRIS)}


def _bone_frames(direction: NDArray) -> tuple[NDArray, NDArray]:
    """Two unit vectors perpendicular to each (unit) direction row."""
    helper = np.where(np.abs(direction[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    u = _unit_rows(np.cross(helper, direction))
    v = np.cross(direction, u)
    return u, v


def _bone_solids(
    skeleton: JointSkeleton, world: NDArray, shape: str, width: float | ArrayLike | None
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Bone geometry in bind (rest world) space.

    Returns ``(positions (k, 3), normals (k, 3), joint (k,), faces (t, 3))``: one solid per
    parent→child bone (and per End Site), owned by the parent joint; a cube at leaf joints
    without an End Site (and at a lone root).
    """
    n = len(skeleton)
    parent = skeleton.parent
    child = np.flatnonzero(parent >= 0)
    owner = [parent[child]]
    local_end = [skeleton.offset[child]]
    has_end = np.isfinite(skeleton.end_site).all(axis=1)
    owner.append(np.flatnonzero(has_end))
    local_end.append(skeleton.end_site[has_end])
    owner_a = np.concatenate(owner)
    end_a = np.concatenate(local_end)
    length = np.linalg.norm(end_a, axis=1)
    keep = length > 1e-9
    owner_a, end_a, length = owner_a[keep], end_a[keep], length[keep]
    n_child = np.bincount(owner_a, minlength=n)
    tips = np.flatnonzero(n_child == 0)

    med = float(np.median(length)) if length.size else 0.0
    if med == 0.0:  # no bones: size cubes by the skeleton's extent
        ext = np.ptp(world[:, :3, 3], axis=0).max() if n > 1 else 0.0
        med = ext * 0.1 if ext > 0 else 0.1
    if width is None:
        w_bone = np.maximum(0.12 * length, 0.04 * med)
        w_tip = np.full(tips.size, 0.08 * med)
    else:
        w = np.asarray(width, dtype=float)
        if w.ndim == 0:
            w = np.full(n, float(w))
        if w.shape != (n,) or not np.isfinite(w).all() or np.any(w <= 0):
            raise ParameterError(
                f"bone_width must be a positive number or {n} positive "
                f"numbers (one per joint, metres); got {np.asarray(width)!r}"
            )
        w_bone, w_tip = w[owner_a], w[tips]
    template, tris = _SHAPES[shape]

    # frames in the owner joint's local space, then into bind space
    d = end_a / length[:, None] if length.size else np.zeros((0, 3))
    u, v = _bone_frames(d)
    axes_b = np.stack([u * w_bone[:, None], v * w_bone[:, None], end_a], axis=1)  # (b,3,3)
    origin_b = np.zeros((len(owner_a), 3))
    # tip cubes centred on the joint, axis-aligned in its local frame
    cube_t, cube_tris = _BOX, _BOX_TRIS
    axes_t = np.eye(3)[None] * w_tip[:, None, None]
    origin_t = np.tile([0.0, 0.0, -0.5], (tips.size, 1)) * w_tip[:, None]

    def solids(
        templ: NDArray, tri: NDArray, axes: NDArray, origin: NDArray, joints: NDArray
    ) -> tuple[NDArray, NDArray]:
        corners = templ[tri].reshape(-1, 3)  # (3t, 3) unshared corners
        local = origin[:, None, :] + np.einsum("kc,bcj->bkj", corners, axes)
        rot, trans = world[joints, :3, :3], world[joints, :3, 3]
        bind = np.einsum("bij,bkj->bki", rot, local) + trans[:, None, :]
        return bind.reshape(-1, 3), np.repeat(joints, len(corners))

    p1, j1 = solids(template, tris, axes_b, origin_b, owner_a)
    p2, j2 = solids(cube_t, cube_tris, axes_t, origin_t, tips)
    pos = np.concatenate([p1, p2])
    joint = np.concatenate([j1, j2])
    tri_pts = pos.reshape(-1, 3, 3)
    fn = _unit_rows(np.cross(tri_pts[:, 1] - tri_pts[:, 0], tri_pts[:, 2] - tri_pts[:, 0]))
    normals = np.repeat(fn, 3, axis=0)
    faces = np.arange(len(pos)).reshape(-1, 3)
    return pos, normals, joint, faces


def _joint_meshes(
    skeleton: JointSkeleton, world: NDArray, meshes: Mapping[Any, Any], scale: float = 1.0
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Per-joint meshes given in the joint's local frame, moved to bind space."""
    owner, parts = [], []
    for key, obj in meshes.items():
        j = skeleton.index(key) if isinstance(key, str) else int(key)
        if not 0 <= j < len(skeleton):
            raise ParameterError(
                f"meshes key {key!r} is not a joint index in 0..{len(skeleton) - 1}"
            )
        m = Mesh.from_any(obj)
        if m.normals is None:
            m = m.compute_normals()
        owner.append(j)
        parts.append(m)
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3), int)
    # one batched transform for all meshes: vertex k moves with joint jnt[k]
    n_vert = np.fromiter((m.n_vertices for m in parts), np.int64, len(parts))
    n_face = np.fromiter((m.n_faces for m in parts), np.int64, len(parts))
    jnt = np.repeat(np.asarray(owner, dtype=np.int64), n_vert)
    base = np.repeat(np.cumsum(n_vert) - n_vert, n_face)
    faces = np.concatenate([m.faces for m in parts]) + base[:, None]
    verts = np.concatenate([m.vertices for m in parts]) * scale
    nrm = np.concatenate([np.asarray(m.normals, dtype=float) for m in parts])
    rot, trans = world[jnt, :3, :3], world[jnt, :3, 3]
    pos = np.einsum("kij,kj->ki", rot, verts) + trans
    return pos, _unit_rows(np.einsum("kij,kj->ki", rot, nrm)), jnt, faces
