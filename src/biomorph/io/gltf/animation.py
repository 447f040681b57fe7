"""Skeletal animation channels (rest . pose rotations, root and inner translations) and
morph-target mesh frames."""

from __future__ import annotations

from collections.abc import Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core import transforms as tf
from biomorph.core.mesh import Mesh
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import InputError
from biomorph.io.gltf.arrays import _Z_TO_Y, _Z_TO_Y_QUAT, _float32, _unit_rows, _y_up
from biomorph.io.gltf.builder import _FLOAT, ARRAY_BUFFER, _Builder
from biomorph.io.gltf.meshes import _mesh_primitive
from biomorph.io.gltf.skin import _converted_rest


def _is_motion(obj: Any) -> bool:
    return all(hasattr(obj, a) for a in ("skeleton", "rotation", "root_position", "frame_time"))


def _key_times(frames: int, frame_time: float) -> NDArray[np.float32]:
    ft = float(frame_time)
    if not np.isfinite(ft) or ft <= 0:
        raise InputError(f"frame_time is {frame_time!r} s; expected a positive number")
    times = (np.arange(frames, dtype=np.float64) * ft).astype(np.float32)
    if frames > 1 and np.any(np.diff(times) <= 0):
        raise InputError(
            f"{frames} frames at frame_time {ft} s do not give strictly increasing "
            "float32 key times; shorten the motion"
        )
    return times


def _add_motion(
    builder: _Builder,
    motion: Any,
    skeleton: JointSkeleton,
    joints: list[int],
    y_up: bool,
    name: str | None,
) -> None:
    n = len(skeleton)
    rot = np.asarray(motion.rotation, dtype=float)
    root_pos = np.asarray(motion.root_position, dtype=float)
    if rot.ndim != 3 or rot.shape[1:] != (n, 4) or rot.shape[0] < 1:
        raise InputError(f"motion rotation has shape {rot.shape}; expected (frames, {n}, 4)")
    f = rot.shape[0]
    if root_pos.shape != (f, 3):
        raise InputError(f"motion root_position has shape {root_pos.shape}; expected ({f}, 3)")
    if not (np.isfinite(rot).all() and np.isfinite(root_pos).all()):
        raise InputError("motion rotation or root_position holds NaN or inf")
    if np.any(np.linalg.norm(rot, axis=-1) < 1e-9):
        raise InputError("motion rotation holds a zero quaternion; expected unit quaternions")
    times = _key_times(f, motion.frame_time)
    _, rest = _converted_rest(skeleton, True)
    q = tf.quat_multiply(rest, tf.quat_normalize(rot))  # (f, n, 4)
    roots = np.flatnonzero(skeleton.parent < 0)
    if not y_up:
        q[:, roots] = tf.quat_multiply(_Z_TO_Y_QUAT, q[:, roots])
        root_pos = root_pos @ _Z_TO_Y.T
    q = tf.quat_normalize(tf.quat_continuous(q, axis=0)).astype(np.float32)

    t_acc = builder.accessor(times, bounds=True)
    # all rotation outputs in one buffer view, joint-major, one accessor per joint
    block = np.ascontiguousarray(np.swapaxes(q, 0, 1))  # (n, f, 4)
    view = builder.view(block.tobytes())
    accessors = builder.doc["accessors"]
    first = len(accessors)
    accessors.extend(
        {"bufferView": view, "componentType": _FLOAT, "count": f, "type": "VEC4"} for _ in range(n)
    )
    for j in range(1, n):
        accessors[first + j]["byteOffset"] = j * f * 16
    samplers: list[dict[str, Any]] = [
        {"input": t_acc, "output": first + j, "interpolation": "LINEAR"} for j in range(n)
    ]
    channels: list[dict[str, Any]] = [
        {"sampler": j, "target": {"node": joints[j], "path": "rotation"}} for j in range(n)
    ]
    tr_acc = builder.accessor(_float32("motion root_position", root_pos))
    moved: list[tuple[int, int]] = [(int(r), tr_acc) for r in roots]
    jt = getattr(motion, "joint_translation", None)
    if jt is not None:  # translated inner joints (BVH position channels, HTR)
        jt = np.asarray(jt, dtype=float)
        if jt.shape != (f, n, 3):
            raise InputError(
                f"motion joint_translation has shape {jt.shape}; expected ({f}, {n}, 3)"
            )
        inner = skeleton.parent >= 0
        varies = np.any(np.abs(jt - skeleton.offset) > 1e-9, axis=(0, 2)) & inner
        for j in np.flatnonzero(varies):
            moved.append((int(j), builder.accessor(_float32("motion joint_translation", jt[:, j]))))
    for j, acc in moved:
        samplers.append({"input": t_acc, "output": acc, "interpolation": "LINEAR"})
        channels.append(
            {"sampler": len(samplers) - 1, "target": {"node": joints[j], "path": "translation"}}
        )
    builder.doc["animations"].append(
        {"name": name or "motion", "samplers": samplers, "channels": channels}
    )


def _add_frames(
    builder: _Builder, frames: Sequence[Any], frame_time: float, y_up: bool, name: str | None
) -> None:
    """Mesh frames of equal topology as morph targets with a stepping weight animation."""
    meshes = [Mesh.from_any(m) for m in frames]
    if len(meshes) < 2:
        raise InputError(f"frames holds {len(meshes)} mesh(es); expected at least 2")
    base = meshes[0]
    for k, m in enumerate(meshes[1:], start=1):
        if (
            m.n_vertices != base.n_vertices
            or m.faces.shape != base.faces.shape
            or not np.array_equal(m.faces, base.faces)
        ):
            raise InputError(
                f"frame {k} has different topology ({m.n_vertices} vertices, "
                f"{m.n_faces} faces) from frame 0 ({base.n_vertices}, "
                f"{base.n_faces}); morph frames need identical faces"
            )
    times = _key_times(len(meshes), frame_time)
    prim, src = _mesh_primitive(builder, base, y_up)  # ids of frame 0 label all frames
    pick = slice(None) if src is None else src
    base_pos = _y_up(base.vertices[pick], y_up, builder.scale)
    with_normals = all(m.normals is not None for m in meshes)
    if with_normals:
        base_nrm = _unit_rows(_y_up(np.asarray(base.normals, float)[pick], y_up))
    targets = []
    for m in meshes[1:]:
        delta = _float32("frame vertices", _y_up(m.vertices[pick], y_up, builder.scale) - base_pos)
        target = {"POSITION": builder.accessor(delta, target=ARRAY_BUFFER, bounds=True)}
        if with_normals:  # normal displacements, so shading follows the shape
            dn = _unit_rows(_y_up(np.asarray(m.normals, float)[pick], y_up)) - base_nrm
            target["NORMAL"] = builder.accessor(dn.astype(np.float32), target=ARRAY_BUFFER)
        targets.append(target)
    prim["targets"] = targets
    k = len(targets)
    label = name or "frames"
    builder.doc["meshes"].append({"name": label, "primitives": [prim], "weights": [0.0] * k})
    node = builder.node({"name": label, "mesh": len(builder.doc["meshes"]) - 1}, root=True)
    weights = np.zeros((len(meshes), k), np.float32)
    weights[np.arange(1, len(meshes)), np.arange(k)] = 1.0
    sampler = {
        "input": builder.accessor(times, bounds=True),
        "output": builder.accessor(weights.reshape(-1)),
        "interpolation": "LINEAR",
    }
    builder.doc["animations"].append(
        {
            "name": f"{label}_growth",
            "samplers": [sampler],
            "channels": [{"sampler": 0, "target": {"node": node, "path": "weights"}}],
        }
    )


def _scaled(skeleton: JointSkeleton, motion: Any, k: float) -> tuple[JointSkeleton, Any]:
    """Skeleton (and motion view) with every length multiplied by ``k``."""
    sk = skeleton.with_(offset=skeleton.offset * k, end_site=skeleton.end_site * k)
    if motion is None:
        return sk, None
    jt = getattr(motion, "joint_translation", None)
    view = SimpleNamespace(
        skeleton=sk,
        rotation=motion.rotation,
        root_position=np.asarray(motion.root_position, dtype=float) * k,
        frame_time=motion.frame_time,
        joint_translation=None if jt is None else np.asarray(jt, float) * k,
    )
    return sk, view
