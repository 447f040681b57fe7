"""The GLB byte builder: 4-byte aligned buffer views, accessors, materials, nodes, and the
atomic save (GLB chunks or JSON with an embedded base64 buffer)."""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.types import PathLike
from biomorph.io.atomic import atomic_path

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

_FLOAT, _UINT, _USHORT, _UBYTE, _SHORT, _BYTE = 5126, 5125, 5123, 5121, 5122, 5120
_COMPONENT = {
    np.dtype("float32"): _FLOAT,
    np.dtype("uint32"): _UINT,
    np.dtype("uint16"): _USHORT,
    np.dtype("uint8"): _UBYTE,
    np.dtype("int16"): _SHORT,
    np.dtype("int8"): _BYTE,
}
_TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_TRIANGLES = 4


# the document is a plain dict of lists of dicts (the glTF JSON itself), serialised with
# json.dumps: pygltflib's dataclass-to-JSON conversion cost more than everything else
_BONE_MATERIAL = {
    "name": "bone",
    "doubleSided": False,
    "pbrMetallicRoughness": {
        "baseColorFactor": [0.89, 0.85, 0.78, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 0.7,
    },
}
_SKIN_MATERIAL = {
    "name": "skin",
    "doubleSided": False,
    "pbrMetallicRoughness": {
        "baseColorFactor": [0.80, 0.55, 0.45, 0.55],
        "metallicFactor": 0.0,
        "roughnessFactor": 0.6,
    },
    "alphaMode": "BLEND",
}
_MESH_MATERIAL = {
    "name": "surface",
    "doubleSided": True,
    "pbrMetallicRoughness": {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 0.8,
    },
}


# =========================================================================== buffer builder
class _Builder:
    """Collects binary chunks (4-byte aligned) and the glTF document that points into them."""

    def __init__(self, name: str | None) -> None:
        scene: dict[str, Any] = {"nodes": []}
        if name is not None:
            scene["name"] = name
        self.doc: dict[str, Any] = {
            "asset": {"version": "2.0", "generator": "biomorph"},
            "scene": 0,
            "scenes": [scene],
            "nodes": [],
            "meshes": [],
            "skins": [],
            "animations": [],
            "materials": [],
            "accessors": [],
            "bufferViews": [],
        }
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

    def accessor(
        self,
        arr: NDArray,
        *,
        target: int | None = None,
        bounds: bool = False,
        normalized: bool = False,
        matrix: bool = False,
        view: int | None = None,
        offset: int = 0,
    ) -> int:
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
        acc: dict[str, Any] = {
            "bufferView": view,
            "componentType": comp,
            "count": int(a.shape[0]),
            "type": "MAT4" if matrix else _TYPE[width],
        }
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
        parts = [struct.pack("<4sII", b"glTF", 2, total), struct.pack("<I4s", len(js), b"JSON"), js]
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
