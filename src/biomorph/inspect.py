"""``biomorph info``: say what a file holds, as a JSON-friendly dict.

=========  ============================================  ===================================
kind       extensions                                    reported
=========  ============================================  ===================================
points     .las .laz .ply .xyz .txt .csv .asc .pts .npy  points, bbox, extent, attributes,
                                                         spacing (median nearest-neighbour)
graph      .ply (with an ``edge`` element) .mtg          nodes, edges, trees, tips,
                                                         branchings, total length, radii
motion     .bvh .htr .asf/.amc                           joints, channels, frames, fps,
                                                         duration, end sites
mesh       .obj .ply (with faces) .glb .gltf .stl .off   vertices, faces, area, bbox, groups
=========  ============================================  ===================================

Lengths are in the file's units (metres for point clouds and skeletons by convention).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.core.types import PathLike
from biomorph.errors import ParameterError, UnsupportedFormatError, check_regular_file

MESH_EXTENSIONS = {".obj", ".glb", ".gltf", ".stl", ".off"}
MOTION_EXTENSIONS = {".bvh", ".htr", ".asf", ".amc"}


def file_kind(path: PathLike) -> str:
    """``"points"``, ``"graph"``, ``"motion"`` or ``"mesh"`` from the extension (and, for
    PLY, the header). Raises :class:`UnsupportedFormatError` for unknown extensions."""
    from biomorph.io import POINT_FORMATS

    p = Path(path)
    ext = p.suffix.lower()
    check_regular_file(p)
    if ext == ".ply":
        from biomorph.io.ply import ply_kind

        return ply_kind(p)
    if ext == ".mtg":
        return "graph"
    if ext in MOTION_EXTENSIONS:
        return "motion"
    if ext in MESH_EXTENSIONS:
        return "mesh"
    if ext in POINT_FORMATS:
        return "points"
    known = sorted(set(POINT_FORMATS) | MESH_EXTENSIONS | MOTION_EXTENSIONS | {".mtg"})
    raise UnsupportedFormatError(
        f"{os.fspath(path)}: cannot describe files with extension "
        f"{ext or '(none)'!r}; expected one of {' '.join(known)}"
    )


def _round(a: Any, digits: int = 6) -> Any:
    arr = np.asarray(a, dtype=float)
    return np.round(arr, digits).tolist()


def median_spacing(xyz: np.ndarray, sample: int = 20_000, seed: int = 0) -> float:
    """Median distance (metres) from a point to its nearest other point, estimated on up to
    ``sample`` query points against a subsample of at most 2·10^6 points."""
    from scipy.spatial import cKDTree

    n = xyz.shape[0]
    if n < 2:
        return float("nan")
    rng = np.random.default_rng(seed)
    base = xyz if n <= 2_000_000 else xyz[rng.choice(n, 2_000_000, replace=False)]
    tree = cKDTree(base)
    q = base if base.shape[0] <= sample else base[rng.choice(base.shape[0], sample, replace=False)]
    d, _ = tree.query(q, k=2)
    return float(np.median(d[:, 1]))


def describe_cloud(cloud: Any) -> dict[str, Any]:
    """Summary of a :class:`PointCloud`."""
    lo, hi = cloud.bounds()
    info: dict[str, Any] = {
        "points": cloud.n_points,
        "bbox_min": _round(lo + cloud.offset),
        "bbox_max": _round(hi + cloud.offset),
        "extent": _round(hi - lo),
        "attributes": {k: str(np.asarray(v).dtype) for k, v in cloud.attributes.items()},
        "spacing_median": round(median_spacing(cloud.xyz), 6),
    }
    meta = cloud.meta or {}
    for key in ("las_version", "point_format", "extra_dimensions", "delimiter", "header"):
        if meta.get(key) not in (None, [], ""):
            info[key] = meta[key]
    for key in ("scales", "offsets"):
        if meta.get(key) is not None:
            info[key] = np.asarray(meta[key]).tolist()
    return info


def describe_graph(graph: Any) -> dict[str, Any]:
    """Summary of a :class:`BranchGraph`."""
    lo, hi = graph.position.min(axis=0), graph.position.max(axis=0)
    info: dict[str, Any] = {
        "nodes": graph.n_nodes,
        "edges": int(graph.edges.shape[0]),
        "trees": int(len(np.unique(graph.trees))),
        "roots": int(graph.roots.size),
        "tips": int(graph.leaves.size),
        "branching_nodes": int(np.sum(graph.n_children >= 2)),
        "total_length": round(graph.total_length, 6),
        "bbox_min": _round(lo),
        "bbox_max": _round(hi),
        "max_node_depth": int(graph.node_depth.max(initial=0)),
    }
    if graph.radius is not None:
        info["radius_min"] = round(float(graph.radius.min()), 6)
        info["radius_max"] = round(float(graph.radius.max()), 6)
    if graph.depth is not None:
        info["max_branch_order"] = int(graph.depth.max(initial=0))
    return info


def describe_motion(motion: Any) -> dict[str, Any]:
    """Summary of a Motion (``.skeleton``, ``.rotation``, ``.root_position``, ``.frame_time``)."""
    sk = motion.skeleton
    n_frames = int(np.asarray(motion.rotation).shape[0])
    ft = float(motion.frame_time)
    channels = sk.channels
    n_channels = sum(len(c) for c in channels) if channels is not None else 3 * sk.n_joints + 3
    end_sites = int(np.sum(np.isfinite(sk.end_site).all(axis=1)))
    info: dict[str, Any] = {
        "joints": sk.n_joints,
        "channels": int(n_channels),
        "frames": n_frames,
        "frame_time": ft,
        "fps": round(1.0 / ft, 6),
        "duration": round(max(n_frames - 1, 0) * ft, 6),
        "root": sk.names[0],
        "end_sites": end_sites,
        "max_depth": int(sk.depth.max(initial=0)),
        "joint_names": list(sk.names),
    }
    pos = np.asarray(motion.root_position)
    if pos.size:
        info["root_travel"] = _round(pos.max(axis=0) - pos.min(axis=0))
    return info


def describe_mesh(mesh: Any) -> dict[str, Any]:
    """Summary of a :class:`Mesh`."""
    lo, hi = mesh.bounds()
    info: dict[str, Any] = {
        "vertices": mesh.n_vertices,
        "faces": mesh.n_faces,
        "area": round(mesh.area(), 6),
        "bbox_min": _round(lo),
        "bbox_max": _round(hi),
        "extent": _round(hi - lo),
        "normals": mesh.normals is not None,
        "uv": mesh.uv is not None,
        "vertex_colors": mesh.vertex_colors is not None,
    }
    if mesh.face_ids:
        info["face_ids"] = {k: int(len(np.unique(v))) for k, v in mesh.face_ids.items()}
    return info


def load_motion(path: PathLike) -> Any:
    """Read BVH/HTR/ASF motion through :func:`biomorph.io.read_motion`."""
    from biomorph import io as bio

    return bio.read_motion(path)


def load_mesh(path: PathLike) -> Any:
    """Read a mesh file as :class:`biomorph.core.mesh.Mesh` (PLY via plyfile, others via
    trimesh)."""
    if Path(path).suffix.lower() == ".ply":
        from biomorph.io.ply import read_mesh

        return read_mesh(path)
    from biomorph.io.obj import read_mesh

    return read_mesh(path)


def load(path: PathLike) -> tuple[str, Any]:
    """``(kind, object)``: the file read as PointCloud, BranchGraph, Motion or Mesh."""
    from biomorph import io as bio

    kind = file_kind(path)
    if kind == "points":
        return kind, bio.read_points(path)
    if kind == "graph":
        return kind, bio.read_graph(path)
    if kind == "motion":
        return kind, load_motion(path)
    return kind, load_mesh(path)


def describe_gltf(path: PathLike) -> dict[str, Any]:
    """Summary of a .glb/.gltf file from its document (no scene flattening): nodes, skins,
    joints, animations and duration (s), meshes, vertices, faces, attributes, bbox."""
    from biomorph.io.gltf import read_gltf_summary

    info = read_gltf_summary(path)
    p = Path(path)
    out: dict[str, Any] = {
        "path": os.fspath(path),
        "kind": "mesh",
        "format": p.suffix.lower().lstrip("."),
        "bytes": p.stat().st_size,
    }
    bounds = info.pop("bounds")
    info["faces"] = info.pop("triangles")
    out |= info
    if bounds is not None:
        out["bbox_min"], out["bbox_max"] = _round(np.array(bounds[0])), _round(np.array(bounds[1]))
    return out


#: LAS/LAZ files with more points are summarised from the header and the first points
LARGE_LAS_POINTS = 5_000_000


def describe_large_las(path: PathLike) -> dict[str, Any]:
    """Summary of a huge LAS/LAZ from its header (count, bbox, layout) and its first 10^6
    points (attributes, spacing), without reading the whole file."""
    from biomorph.io.las import read_head

    sample, summary = read_head(path, 1_000_000)
    lo, hi = summary["bbox_min"], summary["bbox_max"]
    return {
        "points": summary["point_count"],
        "bbox_min": _round(lo),
        "bbox_max": _round(hi),
        "extent": _round(hi - lo),
        "bbox_source": "header",
        "attributes": {k: str(v.dtype) for k, v in sample.attributes.items()},
        "spacing_median": round(median_spacing(sample.xyz), 6),
        "spacing_source": f"first {sample.n_points:,} points",
        "las_version": summary["las_version"],
        "point_format": summary["point_format"],
        "extra_dimensions": summary["extra_dimensions"],
        "scales": summary["scales"].tolist(),
        "offsets": summary["offsets"].tolist(),
    }


def describe(path: PathLike) -> dict[str, Any]:
    """What ``path`` holds: kind, format, size in bytes and a kind-specific summary."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext in (".glb", ".gltf"):
        return describe_gltf(path)
    check_regular_file(p)
    if ext in (".las", ".laz"):
        from biomorph.io.las import check_header

        if check_header(p)["point_count"] > LARGE_LAS_POINTS:
            return {
                "path": os.fspath(path),
                "kind": "points",
                "format": ext.lstrip("."),
                "bytes": p.stat().st_size,
            } | describe_large_las(p)
    kind, obj = load(path)
    head: dict[str, Any] = {
        "path": os.fspath(path),
        "kind": kind,
        "format": p.suffix.lower().lstrip("."),
        "bytes": p.stat().st_size,
    }
    if kind == "points":
        return head | describe_cloud(obj)
    if kind == "graph":
        return head | describe_graph(obj)
    if kind == "motion":
        return head | describe_motion(obj)
    return head | describe_mesh(obj)


def render_file(path: PathLike, out_png: PathLike, up: str | None = None) -> Path:
    """Render any file biomorph reads (kind by extension / PLY header) to ``out_png``.

    ``up`` defaults to ``"z"`` for clouds, graphs and meshes (``"y"`` for glTF, whose spec is
    Y-up) and to the guessed up axis for motion."""
    from biomorph.render import render_cloud, render_graph, render_mesh, render_motion

    out = Path(out_png)
    if out.suffix.lower() != ".png":
        raise ParameterError(f"output {os.fspath(out_png)!r} must end with .png")
    kind, obj = load(path)
    name = Path(path).name
    if kind == "points":
        return render_cloud(obj, out, up=up or "z", title=f"{name}: {obj.n_points:,} points")
    if kind == "graph":
        return render_graph(
            obj,
            out,
            up=up or "z",
            title=f"{name}: {obj.n_nodes:,} nodes, {obj.leaves.size:,} tips, "
            f"{obj.total_length:.2f} m",
        )
    if kind == "motion":
        return render_motion(obj, out, up=up)
    default_up = "y" if Path(path).suffix.lower() in (".glb", ".gltf") else "z"
    return render_mesh(obj, out, up=up or default_up)


__all__ = [
    "render_file",
    "describe",
    "file_kind",
    "load",
    "load_mesh",
    "load_motion",
    "describe_cloud",
    "describe_graph",
    "describe_motion",
    "describe_mesh",
    "describe_gltf",
    "describe_large_las",
    "median_spacing",
]
