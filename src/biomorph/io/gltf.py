"""glTF 2.0 binary (.glb) writer: skinned skeletons, skeletal animation, plain meshes.

What gets written
-----------------
* **JointSkeleton** → one node per joint (TRS = the joint's local rest transform: translation
  ``offset``, rotation ``rest_rotation``), all under one armature node; a skin over all joints
  with inverse bind matrices (inverse rest world matrices, column-major float32); one box
  (or octahedron) per bone, from the joint towards each child (leaf joints: towards the BVH
  ``End Site``, or a small cube), rigidly skinned to the joint through ``JOINTS_0`` /
  ``WEIGHTS_0``. The skinned mesh node sits at the scene root with no transform, as the
  spec asks, so Blender imports an armature with one bone per joint.
* **Motion-like objects** (duck-typed: ``.skeleton``, ``.rotation`` ``float[f, n, 4]`` pose
  quaternions xyzw applied after each joint's rest rotation, ``.root_position``
  ``float[f, 3]``, ``.frame_time`` seconds) → the skeleton above plus one animation: a
  rotation channel per joint (rest · pose, hemisphere-continuous) and a translation channel
  per root joint (and per translated inner joint when the motion has ``joint_translation``),
  LINEAR samplers, float32 key times ``k · frame_time``.
* **Meshes** (:class:`biomorph.core.mesh.Mesh` or anything ``Mesh.from_any`` accepts, or a
  list of them) → plain mesh nodes with ``POSITION`` (with min/max), ``NORMAL``,
  ``TEXCOORD_0`` (v flipped: glTF's origin is top-left), ``COLOR_0`` (RGBA unsigned byte,
  normalised) and each ``face_ids`` entry as a per-vertex custom attribute ``_<NAME>_ID``
  (unsigned short when the ids fit in 0..65535, else float). Vertices shared by faces with
  different ids are split so every face keeps its ids. A list of meshes is merged into a
  single primitive (with a ``_MESH_ID`` attribute giving each vertex's list index) unless
  ``merge=False``: 100,000 small leaves become one draw call, not 100,000 nodes.
* **Mesh frames** (``frames=[mesh0, mesh1, …]``, equal topology) → one mesh with a morph
  target per frame after the first and a weight animation that steps through them (linear
  blends between consecutive frames), for growing leaves; face ids and normals are kept.

Frames and units: metres, seconds, glTF is Y-up. ``y_up=True`` (default) means the input is
already Y-up (creatures, motion); pass ``y_up=False`` for Z-up data (trees, leaves) and it is
rotated by −90° about x, ``(x, y, z) → (x, z, −y)``, on the way out. ``scale`` multiplies
every length (``0.01`` turns a centimetre BVH into metres).

Buffers are built with numpy (``tobytes``), every buffer view 4-byte aligned with its
``target`` set for vertex/index data; indices are ``uint16`` when they fit, ``uint32``
otherwise. Files are written atomically. Example::

    from biomorph.io.gltf import write_gltf, read_gltf_summary
    write_gltf("walk.glb", motion)                   # skinned, animated armature
    write_gltf("canopy.glb", leaves, y_up=False)     # list of Z-up leaf meshes, merged
    read_gltf_summary("walk.glb")["animations"]      # -> 1
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pygltflib as g
from numpy.typing import ArrayLike, NDArray

from biomorph.core import transforms as tf
from biomorph.core.mesh import Mesh
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import FormatError, InputError, ParameterError
from biomorph.io.atomic import atomic_path

PathLike = str | os.PathLike[str]

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

_FLOAT, _UINT, _USHORT, _UBYTE, _SHORT, _BYTE = 5126, 5125, 5123, 5121, 5122, 5120
_COMPONENT = {np.dtype("float32"): _FLOAT, np.dtype("uint32"): _UINT,
              np.dtype("uint16"): _USHORT, np.dtype("uint8"): _UBYTE,
              np.dtype("int16"): _SHORT, np.dtype("int8"): _BYTE}
_TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_TRIANGLES = 4

#: rotation taking Z-up data into glTF's Y-up frame: (x, y, z) -> (x, z, -y)
_Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_Z_TO_Y_QUAT = np.array([-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])

# the document is a plain dict of lists of dicts (the glTF JSON itself), serialised with
# json.dumps: pygltflib's dataclass-to-JSON conversion cost more than everything else
_BONE_MATERIAL = {"name": "bone", "doubleSided": False,
                  "pbrMetallicRoughness": {"baseColorFactor": [0.89, 0.85, 0.78, 1.0],
                                           "metallicFactor": 0.0, "roughnessFactor": 0.7}}
_MESH_MATERIAL = {"name": "surface", "doubleSided": True,
                  "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                           "metallicFactor": 0.0, "roughnessFactor": 0.8}}


# =========================================================================== buffer builder
class _Builder:
    """Collects binary chunks (4-byte aligned) and the glTF document that points into them."""

    def __init__(self, name: str | None) -> None:
        scene: dict[str, Any] = {"nodes": []}
        if name is not None:
            scene["name"] = name
        self.doc: dict[str, Any] = {
            "asset": {"version": "2.0", "generator": "biomorph"}, "scene": 0,
            "scenes": [scene], "nodes": [], "meshes": [], "skins": [], "animations": [],
            "materials": [], "accessors": [], "bufferViews": []}
        self.chunks: list[bytes] = []
        self.size = 0
        self._materials: dict[str, int] = {}
        self.scale = 1.0  # multiplies mesh lengths (skeletons are scaled before)

    def view(self, data: bytes, target: int | None = None, stride: int | None = None) -> int:
        """Append ``data`` as a new buffer view (aligned to 4 bytes); return its index."""
        pad = -self.size % 4
        if pad:
            self.chunks.append(b"\0" * pad)
            self.size += pad
        bv: dict[str, Any] = {"buffer": 0, "byteOffset": self.size, "byteLength": len(data)}
        if stride is not None:
            bv["byteStride"] = stride
        if target is not None:
            bv["target"] = target
        views = self.doc["bufferViews"]
        views.append(bv)
        self.chunks.append(data)
        self.size += len(data)
        return len(views) - 1

    def accessor(self, arr: NDArray, *, target: int | None = None, bounds: bool = False,
                 normalized: bool = False, matrix: bool = False, view: int | None = None,
                 offset: int = 0) -> int:
        """Add an accessor for ``arr`` (``(count,)`` or ``(count, k)``, or ``(count, 4, 4)``
        with ``matrix=True``: written column-major). ``bounds`` writes exact min/max."""
        a = np.asarray(arr)
        if matrix:
            a = np.ascontiguousarray(np.swapaxes(a, -1, -2)).reshape(len(a), 16)
        comp = _COMPONENT[a.dtype]
        width = 1 if a.ndim == 1 else a.shape[1]
        if view is None:
            data = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
            elem = data.dtype.itemsize * width
            if target == ARRAY_BUFFER and elem % 4:
                # vertex attribute elements must start on 4-byte boundaries: pad each one
                stride = elem + (-elem % 4)
                padded = np.zeros((len(data), stride), np.uint8)
                padded[:, :elem] = data.reshape(len(data), -1).view(np.uint8)
                view = self.view(padded.tobytes(), target, stride=stride)
            else:
                view = self.view(data.tobytes(), target)
        acc: dict[str, Any] = {"bufferView": view, "componentType": comp,
                               "count": int(a.shape[0]), "type": "MAT4" if matrix
                               else _TYPE[width]}
        if offset:
            acc["byteOffset"] = offset
        if normalized:
            acc["normalized"] = True
        if bounds:
            flat = a.reshape(len(a), -1)
            acc["min"] = flat.min(axis=0).tolist()
            acc["max"] = flat.max(axis=0).tolist()
        accessors = self.doc["accessors"]
        accessors.append(acc)
        return len(accessors) - 1

    def material(self, mat: dict[str, Any]) -> int:
        if mat["name"] not in self._materials:
            self.doc["materials"].append(mat)
            self._materials[mat["name"]] = len(self.doc["materials"]) - 1
        return self._materials[mat["name"]]

    def node(self, node: dict[str, Any], root: bool = False) -> int:
        nodes = self.doc["nodes"]
        nodes.append(node)
        idx = len(nodes) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(idx)
        return idx

    def json_text(self, buffer: dict[str, Any] | None) -> str:
        """The document as compact JSON; empty top-level lists (and an empty scene node
        list) are left out, as the schema asks (``minItems: 1``)."""
        doc = {k: v for k, v in self.doc.items() if not (isinstance(v, list) and not v)}
        scene = doc["scenes"][0]
        if not scene["nodes"]:
            doc["scenes"] = [{k: v for k, v in scene.items() if k != "nodes"}]
        if buffer is not None:
            doc["buffers"] = [buffer]
        return json.dumps(doc, separators=(",", ":"), allow_nan=False)

    def glb_parts(self) -> list[bytes]:
        """GLB pieces: 12-byte header, JSON chunk (space padded), BIN chunk (zero padded)."""
        pad = -self.size % 4
        size = self.size + pad
        js = self.json_text({"byteLength": size} if size else None).encode("utf-8")
        js += b" " * (-len(js) % 4)
        total = 12 + 8 + len(js) + (8 + size if size else 0)
        parts = [struct.pack("<4sII", b"glTF", 2, total), struct.pack("<I4s", len(js), b"JSON"),
                 js]
        if size:
            parts += [struct.pack("<I4s", size, b"BIN\0"), *self.chunks, b"\0" * pad]
        return parts

    def glb(self) -> bytes:
        """The whole file as bytes."""
        return b"".join(self.glb_parts())

    def gltf_text(self) -> str:
        """Self-contained JSON glTF: the buffer embedded as a base64 data URI."""
        import base64

        blob = b"".join(self.chunks)
        blob += b"\0" * (-len(blob) % 4)
        buffer = None
        if blob:
            uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
            buffer = {"byteLength": len(blob), "uri": uri}
        return self.json_text(buffer)

    def save(self, path: PathLike) -> Path:
        """Write atomically (temporary file + rename): binary GLB, streamed chunk by chunk,
        or, for a ``.gltf`` path, JSON with the buffer embedded."""
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            if Path(path).suffix.lower() == ".gltf":
                fh.write(self.gltf_text().encode("utf-8"))
            else:
                for part in self.glb_parts():
                    fh.write(part)
        return Path(path)


# =========================================================================== helpers
def _unit_rows(v: NDArray, fallback: NDArray | None = None) -> NDArray:
    """Rows of ``v`` scaled to unit length; zero rows take ``fallback`` (default +y)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = np.divide(v, n, out=np.zeros_like(v), where=n > 1e-12)
    bad = n[..., 0] <= 1e-12
    if bad.any():
        out[bad] = np.array([0.0, 1.0, 0.0]) if fallback is None else fallback[bad]
    return out


def _float32(name: str, arr: ArrayLike) -> NDArray[np.float32]:
    a = np.asarray(arr, dtype=np.float64)
    if a.size:  # min and max propagate NaN and show inf: two passes, no temporaries
        lo, hi = float(a.min()), float(a.max())
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise InputError(f"{name} holds NaN or inf; expected finite values")
        if max(-lo, hi) > 3.0e38:
            raise InputError(f"{name} exceeds the float32 range; expected |value| < 3e38")
    return a.astype(np.float32)


def _y_up(v: ArrayLike, y_up: bool, scale: float = 1.0) -> NDArray[np.float64]:
    """``(n, 3)`` rows times ``scale``, turned from Z-up to Y-up unless ``y_up``:
    ``(x, y, z) -> (x, z, -y)`` by moving columns (exact, no matrix product)."""
    a = np.asarray(v, dtype=np.float64)
    if scale != 1.0:
        a = a * scale
    if y_up:
        return a
    out = np.empty_like(a)
    out[:, 0] = a[:, 0]
    out[:, 1] = a[:, 2]
    np.negative(a[:, 1], out=out[:, 2])
    return out


def _id_attribute_name(key: str) -> str:
    base = "".join(ch if ch.isalnum() else "_" for ch in str(key)).upper().strip("_") or "FACE"
    if not base.endswith("_ID") and base != "ID":
        base += "_ID"
    return "_" + base


def _id_array(name: str, ids: NDArray[np.int64]) -> NDArray:
    """Per-vertex ids as unsigned short (0..65535) or float32 (exact up to 2**24)."""
    if ids.size == 0 or (ids.min() >= 0 and ids.max() <= 65535):
        return ids.astype(np.uint16)
    if np.abs(ids).max() > 2**24:
        raise InputError(f"face id {name!r} holds {int(np.abs(ids).max())}; glTF custom "
                         "attributes store ids exactly only up to 16777216")
    return ids.astype(np.float32)


def _joint_nodes(names: Sequence[str], translation: NDArray, rotation: NDArray
                 ) -> list[dict[str, Any]]:
    """One node per joint with its local TRS; zero translations and identity rotations
    (``|xyz| <= 1e-8``, ``w > 0``) are left out."""
    has_t = np.any(translation != 0, axis=1).tolist()
    has_r = (~(np.all(np.abs(rotation[:, :3]) <= 1e-8, axis=1) & (rotation[:, 3] > 0))).tolist()
    t_list, r_list = translation.tolist(), rotation.tolist()
    nodes = []
    for i, nm in enumerate(names):
        node: dict[str, Any] = {"name": nm}
        if has_t[i]:
            node["translation"] = t_list[i]
        if has_r[i]:
            node["rotation"] = r_list[i]
        nodes.append(node)
    return nodes


# =========================================================================== meshes
def _per_vertex_ids(mesh: Mesh) -> tuple[Mesh, dict[str, NDArray[np.int64]],
                                          NDArray[np.int64] | None]:
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
    new = Mesh(mesh.vertices[src], faces,
               normals=None if mesh.normals is None else mesh.normals[src],
               uv=None if mesh.uv is None else mesh.uv[src],
               vertex_colors=None if mesh.vertex_colors is None else mesh.vertex_colors[src],
               face_ids=mesh.face_ids)
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
    if isinstance(obj, Mesh | Mapping) or (isinstance(obj, tuple | list) and len(obj) == 2
                                           and _is_vertex_array(obj[0])):
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
        face_ids[k] = np.concatenate([
            m.face_ids[k] if k in m.face_ids else np.full(m.n_faces, -1, np.int64)
            for m in meshes])
    if "mesh" not in face_ids:
        face_ids["mesh"] = np.repeat(np.arange(len(meshes)), counts)
    return Mesh(np.concatenate([m.vertices for m in meshes]), faces, face_ids=face_ids,
                **extra)


def _indices(builder: _Builder, faces: NDArray, n_vertices: int) -> int:
    # 65535 is the primitive-restart value of uint16 indices and must not occur
    dtype = np.uint16 if n_vertices <= 65535 else np.uint32
    return builder.accessor(faces.reshape(-1).astype(dtype), target=ELEMENT_ARRAY_BUFFER)


def _mesh_primitive(builder: _Builder, mesh: Mesh, y_up: bool
                    ) -> tuple[dict[str, Any], NDArray[np.int64] | None]:
    """A triangle primitive for ``mesh``; also the vertex mapping if ids split vertices."""
    if mesh.n_faces == 0 or mesh.n_vertices == 0:
        raise InputError(f"mesh has {mesh.n_vertices} vertices and {mesh.n_faces} faces; "
                         "expected at least one triangle")
    mesh, vertex_ids, src = _per_vertex_ids(mesh)
    pos = _float32("mesh vertices", _y_up(mesh.vertices, y_up, builder.scale))
    attrs: dict[str, int] = {"POSITION": builder.accessor(pos, target=ARRAY_BUFFER,
                                                          bounds=True)}
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
        attrs[_id_attribute_name(key)] = builder.accessor(_id_array(key, ids),
                                                          target=ARRAY_BUFFER)
    prim = {"attributes": attrs, "indices": _indices(builder, mesh.faces, mesh.n_vertices),
            "material": builder.material(_MESH_MATERIAL), "mode": _TRIANGLES}
    return prim, src


def _add_mesh_nodes(builder: _Builder, meshes: list[Mesh], *, merge: bool, y_up: bool,
                    name: str | None) -> list[int]:
    groups = [_merge(meshes)] if merge else meshes
    nodes = []
    for i, mesh in enumerate(groups):
        label = name or "mesh"
        if len(groups) > 1:
            label = f"{label}_{i}"
        prim, _ = _mesh_primitive(builder, mesh, y_up)
        builder.doc["meshes"].append({"name": label, "primitives": [prim]})
        nodes.append(builder.node({"name": label, "mesh": len(builder.doc["meshes"]) - 1},
                                  root=True))
    return nodes


# =========================================================================== bones
# unit solids in a bone frame: x, y across (half-width 0.5), z along the bone from 0 to 1;
# listed as triangles with their own corners so flat normals come out per triangle
_BOX = np.array([[-.5, -.5, 0], [.5, -.5, 0], [.5, .5, 0], [-.5, .5, 0],
                 [-.5, -.5, 1], [.5, -.5, 1], [.5, .5, 1], [-.5, .5, 1]])
_BOX_TRIS = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                      [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
_OCTA = np.array([[0, 0, 0], [-.5, -.5, .15], [.5, -.5, .15], [.5, .5, .15], [-.5, .5, .15],
                  [0, 0, 1]])
_OCTA_TRIS = np.array([[0, 2, 1], [0, 3, 2], [0, 4, 3], [0, 1, 4],
                       [5, 1, 2], [5, 2, 3], [5, 3, 4], [5, 4, 1]])
_SHAPES = {"box": (_BOX, _BOX_TRIS), "octahedron": (_OCTA, _OCTA_TRIS)}


def _bone_frames(direction: NDArray) -> tuple[NDArray, NDArray]:
    """Two unit vectors perpendicular to each (unit) direction row."""
    helper = np.where(np.abs(direction[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    u = _unit_rows(np.cross(helper, direction))
    v = np.cross(direction, u)
    return u, v


def _bone_solids(skeleton: JointSkeleton, world: NDArray, shape: str,
                 width: float | ArrayLike | None) -> tuple[NDArray, NDArray, NDArray, NDArray]:
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
            raise ParameterError(f"bone_width must be a positive number or {n} positive "
                                 f"numbers (one per joint, metres); got {np.asarray(width)!r}")
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

    def solids(templ: NDArray, tri: NDArray, axes: NDArray, origin: NDArray,
               joints: NDArray) -> tuple[NDArray, NDArray]:
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


def _joint_meshes(skeleton: JointSkeleton, world: NDArray, meshes: Mapping[Any, Any],
                  scale: float = 1.0) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Per-joint meshes given in the joint's local frame, moved to bind space."""
    owner, parts = [], []
    for key, obj in meshes.items():
        j = skeleton.index(key) if isinstance(key, str) else int(key)
        if not 0 <= j < len(skeleton):
            raise ParameterError(f"meshes key {key!r} is not a joint index in 0..{len(skeleton)-1}")
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


# =========================================================================== skeleton
def _converted_rest(skeleton: JointSkeleton, y_up: bool) -> tuple[NDArray, NDArray]:
    """Local rest translation and (unit) rotation per joint, roots turned to Y-up."""
    trans = np.array(skeleton.offset, dtype=float)
    rot = tf.quat_normalize(np.asarray(skeleton.rest_rotation, dtype=float))
    if not y_up:
        roots = skeleton.parent < 0
        trans[roots] = trans[roots] @ _Z_TO_Y.T
        rot[roots] = tf.quat_multiply(_Z_TO_Y_QUAT, rot[roots])
    return trans, rot


def _add_skeleton(builder: _Builder, skeleton: JointSkeleton, *, bone_shape: str | None,
                  bone_width: Any, joint_meshes: Mapping[Any, Any] | None, y_up: bool,
                  name: str | None) -> list[int]:
    """Joint nodes, armature node, skin and skinned bone mesh; returns joint node indices."""
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
            nodes[i]["children"] = (order[starts[i]:ends[i]] + first).tolist()
    for node in nodes:
        builder.node(node)
    roots = np.flatnonzero(skeleton.parent < 0)
    armature = builder.node({"name": name or "armature",
                             "children": (roots + first).tolist()}, root=True)
    joints = list(range(first, first + n))

    ibm = tf.invert_rigid(world).astype(np.float32)
    ibm[:, 3, :] = np.array([0, 0, 0, 1], np.float32)  # exact last row
    skin = {"name": f"{name or 'armature'}_skin", "joints": joints, "skeleton": armature,
            "inverseBindMatrices": builder.accessor(ibm, matrix=True)}
    builder.doc["skins"].append(skin)

    parts = []
    if bone_shape is not None:
        if bone_shape not in _SHAPES:
            raise ParameterError(f"bone_shape must be one of {', '.join(_SHAPES)} or None; "
                                 f"got {bone_shape!r}")
        parts.append(_bone_solids(skeleton, world, bone_shape, bone_width))
    if joint_meshes:
        parts.append(_joint_meshes(skeleton, world, joint_meshes, builder.scale))
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
            "POSITION": builder.accessor(_float32("bone vertices", pos), target=ARRAY_BUFFER,
                                         bounds=True),
            "NORMAL": builder.accessor(nrm.astype(np.float32), target=ARRAY_BUFFER),
            "JOINTS_0": builder.accessor(joints0, target=ARRAY_BUFFER),
            "WEIGHTS_0": builder.accessor(weights0, target=ARRAY_BUFFER)}
        prim = {"attributes": attrs, "indices": _indices(builder, faces, len(pos)),
                "material": builder.material(_BONE_MATERIAL), "mode": _TRIANGLES}
        label = f"{name or 'armature'}_bones"
        builder.doc["meshes"].append({"name": label, "primitives": [prim]})
        builder.node({"name": label, "mesh": len(builder.doc["meshes"]) - 1,
                      "skin": len(builder.doc["skins"]) - 1}, root=True)
    return joints


# =========================================================================== animation
def _is_motion(obj: Any) -> bool:
    return all(hasattr(obj, a) for a in ("skeleton", "rotation", "root_position",
                                         "frame_time"))


def _key_times(frames: int, frame_time: float) -> NDArray[np.float32]:
    ft = float(frame_time)
    if not np.isfinite(ft) or ft <= 0:
        raise InputError(f"frame_time is {frame_time!r} s; expected a positive number")
    times = (np.arange(frames, dtype=np.float64) * ft).astype(np.float32)
    if frames > 1 and np.any(np.diff(times) <= 0):
        raise InputError(f"{frames} frames at frame_time {ft} s do not give strictly increasing "
                         "float32 key times; shorten the motion")
    return times


def _add_motion(builder: _Builder, motion: Any, skeleton: JointSkeleton, joints: list[int],
                y_up: bool, name: str | None) -> None:
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
    accessors.extend({"bufferView": view, "componentType": _FLOAT, "count": f, "type": "VEC4"}
                     for _ in range(n))
    for j in range(1, n):
        accessors[first + j]["byteOffset"] = j * f * 16
    samplers: list[dict[str, Any]] = [
        {"input": t_acc, "output": first + j, "interpolation": "LINEAR"} for j in range(n)]
    channels: list[dict[str, Any]] = [
        {"sampler": j, "target": {"node": joints[j], "path": "rotation"}} for j in range(n)]
    tr_acc = builder.accessor(_float32("motion root_position", root_pos))
    moved: list[tuple[int, int]] = [(int(r), tr_acc) for r in roots]
    jt = getattr(motion, "joint_translation", None)
    if jt is not None:  # translated inner joints (BVH position channels, HTR)
        jt = np.asarray(jt, dtype=float)
        if jt.shape != (f, n, 3):
            raise InputError(f"motion joint_translation has shape {jt.shape}; expected "
                             f"({f}, {n}, 3)")
        inner = skeleton.parent >= 0
        varies = np.any(np.abs(jt - skeleton.offset) > 1e-9, axis=(0, 2)) & inner
        for j in np.flatnonzero(varies):
            moved.append((int(j), builder.accessor(
                _float32("motion joint_translation", jt[:, j]))))
    for j, acc in moved:
        samplers.append({"input": t_acc, "output": acc, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1,
                         "target": {"node": joints[j], "path": "translation"}})
    builder.doc["animations"].append({"name": name or "motion", "samplers": samplers,
                                      "channels": channels})


def _add_frames(builder: _Builder, frames: Sequence[Any], frame_time: float, y_up: bool,
                name: str | None) -> None:
    """Mesh frames of equal topology as morph targets with a stepping weight animation."""
    meshes = [Mesh.from_any(m) for m in frames]
    if len(meshes) < 2:
        raise InputError(f"frames holds {len(meshes)} mesh(es); expected at least 2")
    base = meshes[0]
    for k, m in enumerate(meshes[1:], start=1):
        if m.n_vertices != base.n_vertices or m.faces.shape != base.faces.shape or \
                not np.array_equal(m.faces, base.faces):
            raise InputError(f"frame {k} has different topology ({m.n_vertices} vertices, "
                             f"{m.n_faces} faces) from frame 0 ({base.n_vertices}, "
                             f"{base.n_faces}); morph frames need identical faces")
    times = _key_times(len(meshes), frame_time)
    prim, src = _mesh_primitive(builder, base, y_up)  # ids of frame 0 label all frames
    pick = slice(None) if src is None else src
    base_pos = _y_up(base.vertices[pick], y_up, builder.scale)
    with_normals = all(m.normals is not None for m in meshes)
    if with_normals:
        base_nrm = _unit_rows(_y_up(np.asarray(base.normals, float)[pick], y_up))
    targets = []
    for m in meshes[1:]:
        delta = _float32("frame vertices",
                         _y_up(m.vertices[pick], y_up, builder.scale) - base_pos)
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
    sampler = {"input": builder.accessor(times, bounds=True),
               "output": builder.accessor(weights.reshape(-1)), "interpolation": "LINEAR"}
    builder.doc["animations"].append({
        "name": f"{label}_growth", "samplers": [sampler],
        "channels": [{"sampler": 0, "target": {"node": node, "path": "weights"}}]})


def _scaled(skeleton: JointSkeleton, motion: Any, k: float) -> tuple[JointSkeleton, Any]:
    """Skeleton (and motion view) with every length multiplied by ``k``."""
    sk = skeleton.with_(offset=skeleton.offset * k, end_site=skeleton.end_site * k)
    if motion is None:
        return sk, None
    jt = getattr(motion, "joint_translation", None)
    view = SimpleNamespace(skeleton=sk, rotation=motion.rotation,
                           root_position=np.asarray(motion.root_position, dtype=float) * k,
                           frame_time=motion.frame_time,
                           joint_translation=None if jt is None else np.asarray(jt, float) * k)
    return sk, view


# =========================================================================== public API
def write_gltf(path: PathLike, obj: Any = None, *, motion: Any = None,
               bone_shape: str | None = "box", bone_width: float | ArrayLike | None = None,
               meshes: Any = None, y_up: bool = True, name: str | None = None, merge: bool = True,
               frames: Sequence[Any] | None = None, frame_time: float = 1 / 30,
               scale: float = 1.0) -> Path:
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
            raise ParameterError(f"motion is a {type(motion).__name__}; expected an object with "
                                 ".skeleton, .rotation, .root_position and .frame_time")
        if skeleton is None:
            skeleton = motion.skeleton
        if len(motion.skeleton) != len(skeleton):
            raise InputError(f"motion animates {len(motion.skeleton)} joints; the skeleton "
                             f"has {len(skeleton)}")
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
        joint_meshes = meshes if isinstance(meshes, Mapping) and not (
            "vertices" in meshes and "faces" in meshes) else None
        joints = _add_skeleton(builder, skeleton, bone_shape=bone_shape, bone_width=bone_width,
                               joint_meshes=joint_meshes, y_up=y_up, name=name)
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
            _add_mesh_nodes(builder, parts, merge=merge, y_up=y_up, name=name)
        elif frames is None:
            raise InputError("nothing to write: expected a JointSkeleton, a motion, meshes or "
                             "frames")
    if frames is not None:
        _add_frames(builder, frames, frame_time, y_up, name)
    return builder.save(path)


def write_mesh(path: PathLike, mesh: Any, *, y_up: bool = True, name: str | None = None,
               merge: bool = True, scale: float = 1.0) -> Path:
    """Write one mesh or a list of meshes as ``.glb`` (see :func:`write_gltf`)."""
    return write_gltf(path, None, meshes=_as_meshes(mesh), y_up=y_up, name=name, merge=merge,
                      scale=scale)


def write_mesh_animation(path: PathLike, frames: Sequence[Any], frame_time: float, *,
                         y_up: bool = True, name: str | None = None) -> Path:
    """Write equal-topology mesh frames (e.g. a growing leaf) as a morph-target animation."""
    return write_gltf(path, None, frames=frames, frame_time=frame_time, y_up=y_up, name=name)


# =========================================================================== reading back
def read_gltf_summary(path: PathLike) -> dict[str, Any]:
    """What a .glb/.gltf file holds, for ``biomorph info``.

    Keys: ``nodes``, ``skins``, ``joints`` (over all skins), ``animations``, ``duration``
    (s, longest animation), ``meshes``, ``primitives``, ``vertices``, ``triangles``,
    ``attributes`` (sorted vertex attribute names), ``bounds`` (``[min, max]`` of all
    POSITION accessors, unskinned, or ``None``), ``generator``.
    """
    p = Path(path)
    if not p.is_file():
        raise FormatError(path, "file does not exist")
    try:
        doc = g.GLTF2().load(os.fspath(p))
    except Exception as exc:  # pygltflib raises many kinds on malformed input
        raise FormatError(path, f"not a readable glTF/GLB file ({type(exc).__name__}: "
                                f"{exc}); expected glTF 2.0") from None
    if doc is None or doc.asset is None:
        raise FormatError(path, "not a glTF 2.0 file: no asset header")
    accessors = doc.accessors or []

    def count(idx: int | None) -> int:
        if idx is None or not 0 <= idx < len(accessors):
            raise FormatError(path, f"accessor index {idx!r} out of range 0..{len(accessors)-1}")
        return int(accessors[idx].count)

    vertices = triangles = primitives = 0
    attributes: set[str] = set()
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for mesh in doc.meshes or []:
        for prim in mesh.primitives:
            primitives += 1
            attrs = {k: v for k, v in vars(prim.attributes).items() if v is not None}
            attributes.update(attrs)
            if "POSITION" not in attrs:
                continue
            nv = count(attrs["POSITION"])
            vertices += nv
            acc = accessors[attrs["POSITION"]]
            if acc.min is not None and acc.max is not None and len(acc.min) == 3:
                lo, hi = np.minimum(lo, acc.min), np.maximum(hi, acc.max)
            mode = 4 if prim.mode is None else prim.mode
            ni = nv if prim.indices is None else count(prim.indices)
            if mode == 4:
                triangles += ni // 3
            elif mode in (5, 6):
                triangles += max(ni - 2, 0)
    duration = 0.0
    for anim in doc.animations or []:
        for s in anim.samplers:
            acc = accessors[s.input] if s.input is not None and 0 <= s.input < len(accessors) \
                else None
            if acc is not None and acc.max:
                duration = max(duration, float(acc.max[0]))
    return {
        "nodes": len(doc.nodes or []),
        "skins": len(doc.skins or []),
        "joints": int(sum(len(s.joints) for s in doc.skins or [])),
        "animations": len(doc.animations or []),
        "duration": round(duration, 6),
        "meshes": len(doc.meshes or []),
        "primitives": primitives,
        "vertices": vertices,
        "triangles": triangles,
        "attributes": sorted(attributes),
        "bounds": None if not np.isfinite(lo).all() else [lo.tolist(), hi.tolist()],
        "generator": doc.asset.generator,
    }


__all__ = ["write_gltf", "write_mesh", "write_mesh_animation", "read_gltf_summary"]
