"""File formats, one module per format, dispatched by file extension.

=================  ==============================  =====================================
function           extensions                      returns / takes
=================  ==============================  =====================================
read_points        .las .laz .ply .xyz .txt .csv   PointCloud
                   .asc .pts .npy
write_points       same                            PointCloud
read_graph         .ply .mtg                       BranchGraph
write_graph        .ply .mtg                       BranchGraph
read_bvh           .bvh                            Motion
write_bvh          .bvh                            Motion
read_motion        .bvh .htr .asf (+ .amc)         Motion
write_mesh         .obj .ply .glb .gltf            (vertices, faces) / trimesh.Trimesh
write_gltf         .glb .gltf                      JointSkeleton / Motion / mesh
=================  ==============================  =====================================

Every reader raises :class:`biomorph.errors.FormatError` (file, line, expectation) on
malformed input; every writer writes atomically (see :mod:`biomorph.io.atomic`).
Format modules are imported lazily so heavy libraries load only when used.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Any

from biomorph.core.types import PathLike
from biomorph.errors import FormatError, UnsupportedFormatError, check_regular_file

POINT_FORMATS = {
    ".las": "las",
    ".laz": "las",
    ".ply": "ply",
    ".xyz": "xyz",
    ".txt": "xyz",
    ".csv": "xyz",
    ".asc": "xyz",
    ".pts": "xyz",
    ".npy": "npy",
}
GRAPH_FORMATS = {".ply": "ply", ".mtg": "mtg"}
MESH_FORMATS = {".obj": "obj", ".ply": "ply", ".glb": "gltf", ".gltf": "gltf"}
MOTION_FORMATS = {".bvh": "bvh", ".htr": "htr", ".asf": "asf", ".amc": "asf"}


def _module(table: dict[str, str], path: PathLike, what: str) -> Any:
    ext = Path(path).suffix.lower()
    name = table.get(ext)
    if name is None:
        known = " ".join(sorted(table))
        raise UnsupportedFormatError(
            f"{os.fspath(path)}: cannot handle {what} files with "
            f"extension {ext or '(none)'!r}; expected one of {known}"
        )
    return importlib.import_module(f"biomorph.io.{name}")


def _check_readable(path: PathLike) -> None:
    """Refuse missing files, folders, named pipes and device files before any reader opens
    them (a FIFO would block the reader forever)."""
    check_regular_file(path)


#: largest coordinate magnitude accepted (m): georeferenced coordinates stay below 1e7 m
#: (UTM northings); beyond 1e9 squared distances lose every digit below a metre and
#: overflow to inf near 1e154
MAX_COORDINATE = 1e9


def _check_extent(path: PathLike, xyz: Any, what: str) -> None:
    import numpy as np

    arr = np.asarray(xyz)
    if arr.size == 0 or arr.dtype.kind != "f":
        return
    peak = np.abs(arr).max(axis=1) if arr.ndim == 2 else np.abs(arr)
    if not np.all(peak <= MAX_COORDINATE):
        row = int(np.flatnonzero(~(peak <= MAX_COORDINATE))[0])
        raise FormatError(
            path,
            f"{what} {row} has a coordinate of magnitude {peak[row]:.3g}; "
            f"expected at most {MAX_COORDINATE:g} m",
        )


def read_points(path: PathLike, **kwargs: Any):
    """Read a point cloud (float64, attributes kept) from any supported format."""
    mod = _module(POINT_FORMATS, path, "point cloud")
    _check_readable(path)
    cloud = mod.read_points(path, **kwargs)
    _check_extent(path, cloud.world_xyz, "point")
    return cloud


def write_points(path: PathLike, cloud, **kwargs: Any) -> Path:
    """Write a PointCloud; the format follows the extension."""
    return _module(POINT_FORMATS, path, "point cloud").write_points(path, cloud, **kwargs)


def read_graph(path: PathLike, **kwargs: Any):
    """Read a BranchGraph (skeleton PLY with vertex+edge elements, or MTG)."""
    mod = _module(GRAPH_FORMATS, path, "skeleton graph")
    _check_readable(path)
    graph = mod.read_graph(path, **kwargs)
    _check_extent(path, graph.position, "node")
    return graph


def write_graph(path: PathLike, graph, **kwargs: Any) -> Path:
    """Write a BranchGraph (PLY or MTG)."""
    return _module(GRAPH_FORMATS, path, "skeleton graph").write_graph(path, graph, **kwargs)


def read_bvh(path: PathLike, **kwargs: Any):
    """Read a BVH file into a :class:`biomorph.motion.Motion`."""
    _check_readable(path)
    return importlib.import_module("biomorph.io.bvh").read_bvh(path, **kwargs)


def write_bvh(path: PathLike, motion, **kwargs: Any) -> Path:
    """Write a Motion (or a JointSkeleton in rest pose) as BVH."""
    return importlib.import_module("biomorph.io.bvh").write_bvh(path, motion, **kwargs)


def read_motion(path: PathLike, **kwargs: Any):
    """Read BVH, HTR or ASF/AMC motion into a Motion (format by extension)."""
    mod = _module(MOTION_FORMATS, path, "motion")
    _check_readable(path)
    return mod.read_motion(path, **kwargs)


def read_mesh(path: PathLike, **kwargs: Any):
    """Read a mesh as :class:`biomorph.core.mesh.Mesh`: PLY with plyfile, OBJ with the own
    reader (face-id groups restored), other formats (.glb .gltf .stl .off) through trimesh."""
    ext = Path(path).suffix.lower()
    if ext not in (".ply", ".obj", ".glb", ".gltf", ".stl", ".off"):
        raise UnsupportedFormatError(
            f"{os.fspath(path)}: cannot read meshes with extension "
            f"{ext or '(none)'!r}; expected one of .glb .gltf .obj "
            ".off .ply .stl"
        )
    _check_readable(path)
    name = "ply" if ext == ".ply" else "obj"
    return importlib.import_module(f"biomorph.io.{name}").read_mesh(path, **kwargs)


def write_mesh(path: PathLike, mesh, **kwargs: Any) -> Path:
    """Write a mesh given as ``(vertices, faces)``, a dict or a ``trimesh.Trimesh``."""
    return _module(MESH_FORMATS, path, "mesh").write_mesh(path, mesh, **kwargs)


def write_gltf(path: PathLike, obj, **kwargs: Any) -> Path:
    """Write a skinned JointSkeleton (optionally animated by a Motion) or meshes as .glb."""
    return importlib.import_module("biomorph.io.gltf").write_gltf(path, obj, **kwargs)


__all__ = [
    "read_points",
    "write_points",
    "read_graph",
    "write_graph",
    "read_bvh",
    "write_bvh",
    "read_motion",
    "read_mesh",
    "write_mesh",
    "write_gltf",
]
