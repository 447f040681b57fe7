"""Leaf-pillar file helpers shared by the CLI, the demo and the API.

* :func:`write_leaf_mesh` — a Z-up leaf/canopy mesh by extension (``.obj .ply .glb .can``);
  glTF gets the explicit Z-up → Y-up conversion, CARIBU scenes keep Z-up (CARIBU's own
  convention);
* :func:`read_points_csv` — two named numeric columns of a CSV file with a header line.

Errors name the file and line (:class:`~biomorph.errors.FormatError`).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.errors import FormatError

MESH_EXT = (".obj", ".ply", ".glb", ".can")
#: scene ``extras`` key of the ground tile a ``leaf canopy`` GLB carries (Z-up metres)
GROUND_TILE_KEY = "biomorph_ground_tile"


def write_leaf_mesh(path: str | Path, mesh: Any, **gltf: Any) -> Path:
    """Write a Z-up leaf/canopy mesh by extension (.obj .ply .glb .can); returns the path.

    Extra keyword arguments go to the glTF writer (``.glb`` only)."""
    from biomorph import io

    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".can":
        from biomorph.io.caribu import write_can

        return write_can(path, mesh)
    if ext == ".glb":
        if gltf:
            from biomorph.io.gltf import write_gltf

            return write_gltf(path, mesh, y_up=False, **gltf)
        return io.write_mesh(path, mesh, y_up=False)
    return io.write_mesh(path, mesh)


def read_points_csv(path: str | Path, columns: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    """Named columns of a CSV file (header line required) as float arrays."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "file does not exist")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        names = reader.fieldnames or []
        if any(c not in names for c in columns):
            raise FormatError(
                path,
                f"expected columns {' and '.join(columns)}; found {', '.join(names) or 'none'}",
                line=1,
            )
        vals = []
        for i, row in enumerate(reader, start=2):
            try:
                vals.append([float(row[c]) for c in columns])
            except (TypeError, ValueError):
                raise FormatError(path, f"non-numeric value in {dict(row)}", line=i) from None
    arr = np.array(vals, float).reshape(-1, len(columns))
    return tuple(arr[:, k] for k in range(len(columns)))


_COMPONENT = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def _accessor(gltf: Any, blob: bytes, index: int) -> np.ndarray:
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    dtype = np.dtype(_COMPONENT[acc.componentType])
    width = _WIDTH[acc.type]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or dtype.itemsize * width
    raw = np.frombuffer(
        blob, dtype=np.uint8, count=stride * (acc.count - 1) + dtype.itemsize * width, offset=start
    )
    rows = np.lib.stride_tricks.as_strided(raw, (acc.count, dtype.itemsize * width), (stride, 1))
    return (
        np.ascontiguousarray(rows).view(dtype).reshape(acc.count, width).squeeze(-1)
        if width == 1
        else np.ascontiguousarray(rows).view(dtype).reshape(acc.count, width)
    )


def read_canopy(path: str | Path) -> Any:
    """A Z-up canopy mesh with its ``plant``/``leaf`` face ids, from ``.glb`` (as written by
    :func:`write_leaf_mesh`: glTF Y-up turned back to Z-up, ids from the ``_PLANT_ID`` /
    ``_LEAF_ID`` vertex attributes), ``.obj`` (face-id groups), ``.ply`` or a CARIBU
    ``.can`` scene (plant and leaf ids from the labels; metres)."""
    return read_canopy_scene(path)[0]


def read_canopy_scene(path: str | Path) -> tuple[Any, tuple[float, float, float, float] | None]:
    """:func:`read_canopy`'s mesh and the ground tile ``(xmin, ymin, xmax, ymax)`` (Z-up
    metres) that ``leaf canopy`` / a ``leaf plant`` stand stores in a GLB's scene extras
    (:data:`GROUND_TILE_KEY`), or ``None`` (other formats, or no tile stored); the file is
    read once."""
    from biomorph.core.mesh import Mesh

    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "file does not exist")
    ext = path.suffix.lower()
    if ext in (".obj", ".ply"):
        from biomorph import io

        return io.read_mesh(path), None
    if ext == ".can":
        from biomorph.io.caribu import read_can

        return read_can(path), None
    if ext != ".glb":
        raise FormatError(path, f"extension {ext or '(none)'!r}: expected .glb, .obj, .ply or .can")
    import pygltflib

    try:
        gltf = pygltflib.GLTF2().load_binary(str(path))
        blob = gltf.binary_blob() or b""
    except Exception as exc:  # noqa: BLE001 - any parse failure is a format error
        raise FormatError(path, f"not a readable binary glTF ({exc})") from None
    verts, faces, ids = [], [], {"plant": [], "leaf": []}
    offset = 0
    try:
        for mesh in gltf.meshes:
            for prim in mesh.primitives:
                if prim.mode not in (None, 4) or prim.indices is None:
                    continue
                pos = _accessor(gltf, blob, prim.attributes.POSITION).astype(np.float64)
                idx = _accessor(gltf, blob, prim.indices).astype(np.int64).reshape(-1, 3)
                extra = {k: getattr(prim.attributes, k, None) for k in ("_PLANT_ID", "_LEAF_ID")}
                for key, name in (("plant", "_PLANT_ID"), ("leaf", "_LEAF_ID")):
                    acc = extra.get(name)
                    vals = (
                        _accessor(gltf, blob, acc).astype(np.int64)
                        if acc is not None
                        else np.full(len(pos), 1 if key == "leaf" else 0, np.int64)
                    )
                    ids[key].append(vals[idx[:, 0]])
                verts.append(np.stack([pos[:, 0], -pos[:, 2], pos[:, 1]], axis=1))
                faces.append(idx + offset)
                offset += len(pos)
    except (ValueError, IndexError, KeyError, TypeError) as exc:
        raise FormatError(path, f"broken glTF accessor ({exc})") from None
    if not faces:
        raise FormatError(path, "holds no triangles; expected a canopy mesh")
    mesh = Mesh(
        np.concatenate(verts),
        np.concatenate(faces),
        face_ids={k: np.concatenate(v) for k, v in ids.items()},
    )
    return mesh, _ground_tile(gltf)


def _ground_tile(gltf: Any) -> tuple[float, float, float, float] | None:
    """The valid ground tile in a loaded glTF's scene extras, or ``None``."""
    try:
        extras = gltf.scenes[gltf.scene or 0].extras or {}
        tile = extras.get(GROUND_TILE_KEY) if isinstance(extras, dict) else None
        vals = tuple(float(v) for v in tile) if tile is not None else ()
    except (ValueError, TypeError, IndexError, AttributeError):
        return None
    if len(vals) != 4 or not (vals[2] > vals[0] and vals[3] > vals[1]):
        return None
    return vals[0], vals[1], vals[2], vals[3]


__all__ = [
    "GROUND_TILE_KEY",
    "MESH_EXT",
    "read_canopy",
    "read_canopy_scene",
    "read_points_csv",
    "write_leaf_mesh",
]
