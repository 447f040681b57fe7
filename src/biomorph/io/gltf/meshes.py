"""Plain mesh primitives: per-face ids to per-vertex attributes, merging many meshes into one
primitive, mesh nodes."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.errors import InputError
from biomorph.io.gltf.arrays import _float32, _id_array, _id_attribute_name, _unit_rows, _y_up
from biomorph.io.gltf.builder import (
    _MESH_MATERIAL,
    _TRIANGLES,
    ARRAY_BUFFER,
    ELEMENT_ARRAY_BUFFER,
    _Builder,
)


def _per_vertex_ids(
    mesh: Mesh,
) -> tuple[Mesh, dict[str, NDArray[np.int64]], NDArray[np.int64] | None]:
    """Turn per-face ids into per-vertex ids, splitting vertices shared by faces that differ.

    Returns the (possibly re-indexed) mesh, the per-vertex id arrays and the source vertex
    of each output vertex (``None`` when nothing was split). Unreferenced vertices keep id 0
    when no split is needed and are dropped when one is.
    """
    if not mesh.face_ids:
        return mesh, {}, None
    keys = list(mesh.face_ids)
    ids = np.stack([mesh.face_ids[k] for k in keys], axis=1)  # (m, k)
    corner_v = mesh.faces.reshape(-1)
    corner_ids = np.repeat(ids, 3, axis=0)  # (3m, k)
    n = mesh.n_vertices
    # every vertex takes the ids of one of its corners (scatter, no ufunc.at); the ids are
    # uniform per vertex exactly when every corner then reads back its own ids
    per_vertex = np.zeros((n, len(keys)), dtype=ids.dtype)
    per_vertex[corner_v] = corner_ids
    if np.array_equal(per_vertex[corner_v], corner_ids):
        return mesh, {k: per_vertex[:, i] for i, k in enumerate(keys)}, None
    # split: one output vertex per distinct (vertex, ids) corner
    rows = np.concatenate([corner_v[:, None], corner_ids], axis=1)
    uniq, inverse = np.unique(rows, axis=0, return_inverse=True)
    src = uniq[:, 0]
    faces = inverse.reshape(-1, 3)
    new = Mesh(
        mesh.vertices[src],
        faces,
        normals=None if mesh.normals is None else mesh.normals[src],
        uv=None if mesh.uv is None else mesh.uv[src],
        vertex_colors=None if mesh.vertex_colors is None else mesh.vertex_colors[src],
        face_ids=mesh.face_ids,
    )
    return new, {k: uniq[:, 1 + i] for i, k in enumerate(keys)}, src


def _is_vertex_array(obj: Any) -> bool:
    try:
        arr = np.asarray(obj, dtype=float)
    except (TypeError, ValueError):
        return False
    return arr.ndim == 2 and arr.shape[1] == 3


def _as_meshes(obj: Any) -> list[Mesh]:
    """One mesh or a sequence of meshes -> list of :class:`Mesh`.

    A 2-tuple/list whose first element is an ``(n, 3)`` array is one ``(vertices, faces)``.
    """
    if isinstance(obj, Mesh | Mapping) or (
        isinstance(obj, tuple | list) and len(obj) == 2 and _is_vertex_array(obj[0])
    ):
        return [Mesh.from_any(obj)]
    if isinstance(obj, Sequence) and not isinstance(obj, str | bytes):
        return [Mesh.from_any(m) for m in obj]
    return [Mesh.from_any(obj)]


def _merge(meshes: list[Mesh]) -> Mesh:
    """One mesh from many, with a ``mesh`` face id = position in the list (if > 1)."""
    if len(meshes) == 1:
        return meshes[0]
    # as Mesh.merge (optional vertex arrays kept only when every part has them, face ids
    # missing from a part filled with -1), with one offset pass instead of one per part
    n_vert = np.fromiter((m.n_vertices for m in meshes), dtype=np.int64, count=len(meshes))
    counts = np.fromiter((m.n_faces for m in meshes), dtype=np.int64, count=len(meshes))
    offsets = np.repeat(np.cumsum(n_vert) - n_vert, counts)
    faces = np.concatenate([m.faces for m in meshes]) + offsets[:, None]
    extra: dict[str, NDArray | None] = {}
    for attr in ("normals", "uv", "vertex_colors"):
        vals = [getattr(m, attr) for m in meshes]
        extra[attr] = np.concatenate(vals) if all(v is not None for v in vals) else None
    keys: list[str] = []
    for m in meshes:
        keys.extend(k for k in m.face_ids if k not in keys)
    face_ids = {}
    for k in keys:
        face_ids[k] = np.concatenate(
            [m.face_ids[k] if k in m.face_ids else np.full(m.n_faces, -1, np.int64) for m in meshes]
        )
    if "mesh" not in face_ids:
        face_ids["mesh"] = np.repeat(np.arange(len(meshes)), counts)
    return Mesh(np.concatenate([m.vertices for m in meshes]), faces, face_ids=face_ids, **extra)


def _indices(builder: _Builder, faces: NDArray, n_vertices: int) -> int:
    # 65535 is the primitive-restart value of uint16 indices and must not occur
    dtype = np.uint16 if n_vertices <= 65535 else np.uint32
    return builder.accessor(faces.reshape(-1).astype(dtype), target=ELEMENT_ARRAY_BUFFER)


def _mesh_primitive(
    builder: _Builder, mesh: Mesh, y_up: bool, vertex_attributes: Mapping[str, Any] | None = None
) -> tuple[dict[str, Any], NDArray[np.int64] | None]:
    """A triangle primitive for ``mesh``; also the vertex mapping if ids split vertices.

    ``vertex_attributes`` maps names to float arrays ``(n_vertices,)`` or
    ``(n_vertices, k)`` (k <= 4), written as custom attributes ``_NAME`` (float32)."""
    if mesh.n_faces == 0 or mesh.n_vertices == 0:
        raise InputError(
            f"mesh has {mesh.n_vertices} vertices and {mesh.n_faces} faces; "
            "expected at least one triangle"
        )
    mesh, vertex_ids, src = _per_vertex_ids(mesh)
    pos = _float32("mesh vertices", _y_up(mesh.vertices, y_up, builder.scale))
    attrs: dict[str, int] = {"POSITION": builder.accessor(pos, target=ARRAY_BUFFER, bounds=True)}
    if mesh.normals is not None:
        nrm = _unit_rows(_y_up(mesh.normals, y_up)).astype(np.float32)
        attrs["NORMAL"] = builder.accessor(nrm, target=ARRAY_BUFFER)
    if mesh.uv is not None:
        uv = np.array(mesh.uv, dtype=np.float64)
        uv[:, 1] = 1.0 - uv[:, 1]
        attrs["TEXCOORD_0"] = builder.accessor(_float32("mesh uv", uv), target=ARRAY_BUFFER)
    if mesh.vertex_colors is not None:
        col = np.ascontiguousarray(mesh.vertex_colors, dtype=np.uint8)
        attrs["COLOR_0"] = builder.accessor(col, target=ARRAY_BUFFER, normalized=True)
    for key, ids in vertex_ids.items():
        attrs[_id_attribute_name(key)] = builder.accessor(_id_array(key, ids), target=ARRAY_BUFFER)
    for key, values in (vertex_attributes or {}).items():
        arr = np.asarray(values, dtype=np.float64)
        if src is not None:
            arr = arr[src]
        if arr.shape[0] != mesh.n_vertices or arr.ndim > 2 or (arr.ndim == 2 and arr.shape[1] > 4):
            raise InputError(
                f"vertex attribute {key!r} has shape {arr.shape}; expected "
                f"({mesh.n_vertices},) or ({mesh.n_vertices}, k<=4)"
            )
        name = "_" + ("".join(ch if ch.isalnum() else "_" for ch in key).upper() or "DATA")
        attrs[name] = builder.accessor(
            _float32(f"vertex attribute {key}", arr), target=ARRAY_BUFFER
        )
    prim = {
        "attributes": attrs,
        "indices": _indices(builder, mesh.faces, mesh.n_vertices),
        "material": builder.material(_MESH_MATERIAL),
        "mode": _TRIANGLES,
    }
    return prim, src


def _add_mesh_nodes(
    builder: _Builder,
    meshes: list[Mesh],
    *,
    merge: bool,
    y_up: bool,
    name: str | None,
    vertex_attributes: Mapping[str, Any] | None = None,
) -> list[int]:
    if vertex_attributes and len(meshes) != 1:
        raise InputError(f"vertex_attributes need exactly one mesh; got {len(meshes)}")
    groups = [meshes[0]] if vertex_attributes else ([_merge(meshes)] if merge else meshes)
    nodes = []
    for i, mesh in enumerate(groups):
        label = name or "mesh"
        if len(groups) > 1:
            label = f"{label}_{i}"
        prim, _ = _mesh_primitive(builder, mesh, y_up, vertex_attributes)
        builder.doc["meshes"].append({"name": label, "primitives": [prim]})
        nodes.append(
            builder.node({"name": label, "mesh": len(builder.doc["meshes"]) - 1}, root=True)
        )
    return nodes
