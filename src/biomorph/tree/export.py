"""Write a :class:`~biomorph.tree.pipeline.TreeSkeleton` in the formats users expect.

=====================  =====================================================================
file                   content
=====================  =====================================================================
``skeleton.ply``       nodes ``x y z radius depth tree_id weight`` + edges (parent, child)
``skeleton.mtg``       OpenAlea / plantscan3d MTG with ``XX YY ZZ radius`` (``bm.io``)
``tube.glb/.obj/.ply`` tube mesh from the radii (generalised cylinders, one ring per node)
``cylinders.csv``      TreeQSM cylinder table (TreeQSM's column order, :mod:`~.qsm`)
``branches.csv``       TreeQSM branch table (order, parent, diameter, volume L, ...)
``treedata.csv``       TreeQSM tree attributes per tree (volumes L, lengths, DBH, crown)
``summary.json``       metrics, parameters, timings, counts, offset
``points.laz``         the prepared cloud with the extra dimension ``tree_id`` per point
``tree_<id>/``         per tree of a plot: skeleton.ply/.mtg, the QSM tables, points.laz
``preview.png``        cloud + skeleton, three orthographic views and a perspective
=====================  =====================================================================

Coordinates: with ``world=True`` (default) positions are written back in the original frame
(``+ offset``) for PLY, MTG, OBJ, CSV and — when float32 can hold them to 0.06 mm
(coordinates below :data:`GLB_WORLD_LIMIT`, 1 km) — the GLB; a georeferenced GLB stays
centred and its scene ``extras`` (and ``summary.json``'s ``glb_offset``) give the offset to
add. Every file is written atomically.

The QSM tables' columns, units and sources are documented in :mod:`biomorph.tree.qsm`.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.io.atomic import atomic_path, write_text
from biomorph.tree.qsm import CYLINDER_COLUMNS

__all__ = [
    "tube_mesh",
    "cylinder_table",
    "write_cylinders",
    "write_qsm_tables",
    "write_summary",
    "write_preview",
    "export_skeleton",
    "CYLINDER_COLUMNS",
    "FORMATS",
]

from biomorph.core.types import PathLike

FORMATS = ("ply", "mtg", "glb", "obj", "mesh_ply", "csv", "las", "trees", "json", "png")


def _graph_of(obj: Any) -> BranchGraph:
    g = getattr(obj, "graph", obj)
    if not isinstance(g, BranchGraph):
        raise ParameterError(f"expected a TreeSkeleton or BranchGraph, got {type(obj).__name__}")
    return g


def tube_mesh(
    graph: BranchGraph,
    sides: int = 8,
    min_radius: float = 1e-4,
    segment: NDArray[np.int64] | None = None,
):
    """Tube mesh of a skeleton with radii (a :class:`biomorph.core.mesh.Mesh`).

    One ring of ``sides`` vertices per node, perpendicular to the node's branch direction;
    a branch that leaves a fork starts with its own ring at the fork node (its own radius,
    perpendicular to its first edge) so thin branches do not inherit the stem's radius.
    Tips, tree bases and the start of every branch leaving a fork are closed by fans, so
    each branch is a closed tube (watertight per branch; branches overlap inside their
    parent as TreeQSM's cylinders do); vertex normals are area-weighted.
    ``face_ids["tree"]`` and ``["order"]`` label the faces. Metres, same frame as the graph.
    """
    from biomorph.core.mesh import Mesh
    from biomorph.tree.order import continuation, continuation_from_segments
    from biomorph.tree.radius import _tangents, node_axes

    if sides < 3:
        raise ParameterError(f"sides must be >= 3, got {sides}")
    if graph.radius is None:
        raise ParameterError("tube_mesh needs a skeleton with radii")
    n = graph.n_nodes
    pos = graph.position
    r = np.maximum(graph.radius, min_radius)
    par = graph.parent
    cont = continuation(graph) if segment is None else continuation_from_segments(graph, segment)
    axes = node_axes(graph, continuation=cont)  # each ring along its own branch
    ch = np.flatnonzero(par >= 0)
    branch_start = ch[cont[par[ch]] != ch]  # children that start a new branch
    # ring centres, axes and radii: one per node, then one per branch start (at the parent)
    rc = np.vstack([pos, pos[par[branch_start]]])
    e = pos[branch_start] - pos[par[branch_start]]
    e /= np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
    ra = np.vstack([axes, e])
    rr = np.concatenate([r, r[branch_start]])
    t0, t1 = _tangents(ra)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = rc[:, None, :] + rr[:, None, None] * (
        np.cos(ang)[None, :, None] * t0[:, None, :] + np.sin(ang)[None, :, None] * t1[:, None, :]
    )
    verts = ring.reshape(-1, 3)
    start_ring = par.copy()  # ring each edge starts from
    start_ring[branch_start] = n + np.arange(branch_start.size)
    a = start_ring[ch]
    b = ch
    j = np.arange(sides)
    jn = (j + 1) % sides
    a0 = a[:, None] * sides + j[None, :]
    a1 = a[:, None] * sides + jn[None, :]
    b0 = b[:, None] * sides + j[None, :]
    b1 = b[:, None] * sides + jn[None, :]
    f = np.concatenate([np.stack([a0, a1, b1], -1), np.stack([a0, b1, b0], -1)], axis=1)
    faces = [f.reshape(-1, 3)]
    edge_node = [np.repeat(b, 2 * sides)]
    # caps: tips (fan to a point half a radius beyond the tip), tree bases (fan to the
    # root) and the start ring of every branch leaving a fork (fan to the fork node), so
    # every branch is a closed tube
    tips = graph.leaves[par[graph.leaves] >= 0]
    roots = graph.roots
    caps = (
        (tips, pos[tips] + axes[tips] * r[tips, None] * 0.5, tips, False),
        (roots, pos[roots], roots, True),
        (n + np.arange(branch_start.size), pos[par[branch_start]], branch_start, True),
    )
    base = verts.shape[0]
    extra = []
    for rings, centres, label, flip in caps:
        if rings.size == 0:
            continue
        centre = base + np.arange(rings.size)
        base += rings.size
        extra.append(centres)
        r0 = rings[:, None] * sides + j[None, :]
        r1 = rings[:, None] * sides + jn[None, :]
        c = np.broadcast_to(centre[:, None], r0.shape)
        tri = np.stack([r0, r1, c], -1) if not flip else np.stack([r1, r0, c], -1)
        faces.append(tri.reshape(-1, 3))
        edge_node.append(np.repeat(label, sides))
    verts = np.vstack([verts] + extra)
    faces_arr = np.concatenate(faces).astype(np.int64)
    node_of_face = np.concatenate(edge_node)
    ids = {"tree": np.asarray(graph.trees)[node_of_face].astype(np.int64)}
    if graph.depth is not None:
        ids["order"] = graph.depth[node_of_face].astype(np.int64)
    return Mesh(verts, faces_arr, normals=_vertex_normals(verts, faces_arr), face_ids=ids)


def _vertex_normals(verts: NDArray, faces: NDArray) -> NDArray:
    """Area-weighted vertex normals (unit; +Z where a vertex has no area)."""
    fn = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    vn = np.zeros_like(verts)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    ln = np.linalg.norm(vn, axis=1)
    vn[ln == 0] = (0.0, 0.0, 1.0)
    ln[ln == 0] = 1.0
    return vn / ln[:, None]


def cylinder_table(
    graph: BranchGraph,
    segment: NDArray[np.int64] | None = None,
    quality: dict[str, NDArray] | None = None,
) -> dict[str, NDArray]:
    """TreeQSM cylinders, one per edge (:func:`biomorph.tree.qsm.cylinder_table`)."""
    from biomorph.tree.qsm import cylinder_table as table

    return table(graph, segment, quality)


def _write_table(path: PathLike, tab: dict[str, NDArray], columns: tuple[str, ...]) -> Path:
    from biomorph.tree.qsm import INTEGER_COLUMNS

    buf = io.StringIO()
    buf.write(",".join(columns) + "\n")
    cols = [np.asarray(tab[c], dtype=float) for c in columns]
    fmt = ["%d" if c in INTEGER_COLUMNS else "%.6f" for c in columns]
    if cols and cols[0].size:
        data = np.column_stack(cols)
        data = np.where(np.isfinite(data), data, np.nan)
        np.savetxt(buf, data, fmt=fmt, delimiter=",")
    return write_text(path, buf.getvalue().replace("nan", ""))


def write_cylinders(
    path: PathLike,
    graph: BranchGraph,
    segment: NDArray[np.int64] | None = None,
    quality: dict[str, NDArray] | None = None,
) -> Path:
    """Write :func:`cylinder_table` as CSV (header line, metres, TreeQSM column order)."""
    return _write_table(path, cylinder_table(graph, segment, quality), CYLINDER_COLUMNS)


def write_qsm_tables(
    out: Path,
    graph: BranchGraph,
    segment: NDArray[np.int64] | None,
    quality: dict[str, NDArray] | None,
    dbh_fit: dict[int, float | None] | None = None,
) -> dict[str, Path]:
    """``cylinders.csv``, ``branches.csv`` and ``treedata.csv`` (TreeQSM's tables, see
    :mod:`biomorph.tree.qsm`; an empty field is a value that does not exist, e.g. the DBH
    of a tree lower than 1.3 m)."""
    from biomorph.tree.qsm import BRANCH_COLUMNS, TREEDATA_COLUMNS, branch_table, treedata_table

    cyl = cylinder_table(graph, segment, quality)
    return {
        "csv": _write_table(out / "cylinders.csv", cyl, CYLINDER_COLUMNS),
        "branches": _write_table(out / "branches.csv", branch_table(graph, cyl), BRANCH_COLUMNS),
        "treedata": _write_table(
            out / "treedata.csv", treedata_table(graph, cyl, quality, dbh_fit), TREEDATA_COLUMNS
        ),
    }


def _dbh_fits(skel: Any) -> dict[int, float | None]:
    """The stem circles' DBH per tree label from a run's metrics (``DBHcyl``)."""
    trees = (getattr(skel, "metrics", None) or {}).get("trees") or []
    return {int(t["tree"]): t.get("dbh_fit") for t in trees if "tree" in t}


def write_summary(path: PathLike, skel: Any, extra: dict | None = None) -> Path:
    """Write ``skel.summary()`` (plus ``extra``) as pretty JSON."""
    data = skel.summary() if hasattr(skel, "summary") else {}
    if extra:
        from biomorph.core.jsonable import to_jsonable

        data.update(to_jsonable(extra))
    return write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")


def point_tree_labels(skel: Any) -> NDArray[np.int64]:
    """Tree id of every point of ``skel.cloud``: the tree of its nearest skeleton node."""
    from scipy.spatial import cKDTree

    g = _graph_of(skel)
    _, near = cKDTree(g.position).query(skel.cloud.xyz, workers=-1)
    return np.asarray(g.trees)[near].astype(np.int64)


def write_labelled_points(path: PathLike, skel: Any, labels: NDArray | None = None) -> Path:
    """The prepared cloud (original coordinates) as LAS/LAZ with the extra dimension
    ``tree_id`` (:func:`point_tree_labels`) beside every attribute it had."""
    from biomorph.core.pointcloud import PointCloud
    from biomorph.io import write_points

    pc = skel.cloud
    lab = point_tree_labels(skel) if labels is None else labels
    out = PointCloud(
        pc.xyz,
        attributes={**pc.attributes, "tree_id": lab.astype(np.int32)},
        offset=pc.offset,
        meta=pc.meta,
    )
    return write_points(path, out)


def write_per_tree(out: Path, skel: Any, world: bool) -> dict[str, Path]:
    """One folder ``tree_<id>/`` per tree of a plot: ``skeleton.ply``, ``skeleton.mtg``, the
    QSM tables and ``points.laz`` of its points (only when there are several trees)."""
    from biomorph.io import write_graph

    g = _graph_of(skel)
    trees = np.unique(g.trees)
    if trees.size < 2:
        return {}
    offset = np.asarray(getattr(skel, "offset", np.zeros(3)), dtype=float)
    seg = getattr(skel, "segment", None)
    quality = getattr(skel, "quality", None)
    labels = point_tree_labels(skel) if getattr(skel, "cloud", None) is not None else None
    written: dict[str, Path] = {}
    for t in trees:
        keep = np.asarray(g.trees) == t
        sub = g.subgraph(keep)
        sub = sub.with_(position=sub.position + offset) if world else sub
        d = out / f"tree_{int(t)}"
        d.mkdir(parents=True, exist_ok=True)
        q = None if quality is None else {k: np.asarray(v)[keep] for k, v in quality.items()}
        s = None if seg is None else np.asarray(seg)[keep]
        written[f"tree_{int(t)}"] = write_graph(d / "skeleton.ply", sub)
        write_graph(d / "skeleton.mtg", sub)
        write_qsm_tables(d, sub, s, q, _dbh_fits(skel))
        if labels is not None:
            from biomorph.core.pointcloud import PointCloud
            from biomorph.io import write_points

            pc = skel.cloud.select(labels == t)
            write_points(
                d / "points.laz",
                PointCloud(
                    pc.xyz,
                    attributes={**pc.attributes, "tree_id": np.full(pc.n_points, int(t), np.int32)},
                    offset=pc.offset,
                    meta=pc.meta,
                ),
            )
    return written


def write_preview(path: PathLike, skel: Any, title: str | None = None) -> Path:
    """Cloud (grey) + skeleton (width by radius; coloured by branch order for one tree, by
    tree for a plot, a plot's fragments in dark grey): three views + 3-D."""
    from biomorph.render import render_graph

    g = _graph_of(skel)
    if np.unique(g.trees).size > 1:
        g = g.with_(depth=None, tree_id=g.trees)  # render_graph colours by tree then
    cloud = getattr(skel, "cloud", None)
    trees = (getattr(skel, "metrics", None) or {}).get("trees") or []
    fragments = {int(t["tree"]) for t in trees if t.get("kind") == "fragment"}
    with atomic_path(path) as tmp:
        render_graph(g, tmp, cloud=cloud, title=title, muted=fragments)
    return Path(path)


#: the GLB holds the mesh in the frame of the other files when their coordinates stay below
#: this (m): glTF stores float32, whose 24-bit mantissa resolves 0.06 mm at 1 km but only
#: 0.5 m at georeferenced easting/northing of ~10⁶–10⁷ m
GLB_WORLD_LIMIT = 1000.0


def write_tube_glb(path: Path, mesh: Any, offset: NDArray) -> tuple[Path, NDArray]:
    """Write the tube mesh as GLB (Z-up data rotated into glTF's Y-up) in the frame of the
    other outputs when float32 holds it (:data:`GLB_WORLD_LIMIT`), else centred. Either way
    the scene's ``extras`` say the frame: ``{"frame": "world" | "centred", "offset": [x, y,
    z], "up": "Z (source) -> Y (glTF)"}`` (add ``offset`` to a centred GLB's positions,
    in the source's Z-up axes). Returns the path and the offset the GLB still lacks."""
    from biomorph.core.mesh import Mesh
    from biomorph.io import write_mesh

    offset = np.asarray(offset, dtype=float)
    far = float(np.abs(mesh.vertices + offset).max()) if mesh.n_vertices else 0.0
    shift = offset if far <= GLB_WORLD_LIMIT else np.zeros(3)
    lacking = offset - shift
    m = Mesh(mesh.vertices + shift, mesh.faces, normals=mesh.normals, face_ids=mesh.face_ids)
    write_mesh(path, m, y_up=False)
    import pygltflib

    gl = pygltflib.GLTF2().load(str(path))
    frame = "world" if not lacking.any() else "centred"
    extras = {"frame": frame, "offset": [float(v) for v in lacking], "up": "Z (source) -> Y (glTF)"}
    for scene in gl.scenes:
        scene.extras = extras
    gl.asset.extras = extras
    with atomic_path(path) as tmp:
        gl.save_binary(str(tmp))
    return Path(path), lacking


def export_skeleton(
    skel: Any,
    out_dir: PathLike,
    *,
    formats: tuple[str, ...] | None = None,
    world: bool = True,
    sides: int = 8,
    stem: str = "skeleton",
    title: str | None = None,
) -> dict[str, Path]:
    """Write every output of a TreeSkeleton into ``out_dir``; returns ``{format: path}``.

    ``formats`` is a subset of :data:`FORMATS` (default all). ``world`` writes positions in
    the original coordinates (see module doc).
    """
    formats = FORMATS if formats is None else tuple(formats)
    bad = set(formats) - set(FORMATS)
    if bad:
        raise ParameterError(
            f"unknown export format(s) {sorted(bad)}; expected {', '.join(FORMATS)}"
        )
    from biomorph.io import write_graph, write_mesh

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    g = _graph_of(skel)
    offset = np.asarray(getattr(skel, "offset", np.zeros(3)), dtype=float)
    gw = g.with_(position=g.position + offset) if world else g
    seg = getattr(skel, "segment", None)
    written: dict[str, Path] = {}
    if "ply" in formats:
        written["ply"] = write_graph(out / f"{stem}.ply", gw)
    if "mtg" in formats:
        written["mtg"] = write_graph(out / f"{stem}.mtg", gw)
    if "csv" in formats:
        written.update(
            write_qsm_tables(out, gw, seg, getattr(skel, "quality", None), _dbh_fits(skel))
        )
    mesh = None
    if {"glb", "obj", "mesh_ply"} & set(formats):
        mesh = tube_mesh(g, sides=sides, segment=seg)
    glb_offset = offset if world else np.zeros(3)
    if "glb" in formats:
        written["glb"], glb_offset = write_tube_glb(out / "tube.glb", mesh, glb_offset)
    if "obj" in formats or "mesh_ply" in formats:
        from biomorph.core.mesh import Mesh

        mw = Mesh(
            mesh.vertices + (offset if world else 0.0),
            mesh.faces,
            normals=mesh.normals,
            face_ids=mesh.face_ids,
        )
        if "obj" in formats:
            written["obj"] = write_mesh(out / "tube.obj", mw)
        if "mesh_ply" in formats:
            written["mesh_ply"] = write_mesh(out / "tube.ply", mw)
    if "las" in formats and getattr(skel, "cloud", None) is not None:
        written["las"] = write_labelled_points(out / "points.laz", skel)
    if "trees" in formats:
        written.update(write_per_tree(out, skel, world))
    if "json" in formats:
        written["json"] = write_summary(
            out / "summary.json",
            skel,
            {
                "files": {k: v.name for k, v in written.items()},
                "world_coordinates": bool(world),
                "glb_offset": [float(v) for v in glb_offset],
            },
        )
    if "png" in formats:
        written["png"] = write_preview(out / "preview.png", skel, title)
    return written
