"""Write a :class:`~biomorph.tree.pipeline.TreeSkeleton` in the formats users expect.

=====================  =====================================================================
file                   content
=====================  =====================================================================
``skeleton.ply``       nodes ``x y z radius depth tree_id weight`` + edges (parent, child)
``skeleton.mtg``       OpenAlea / plantscan3d MTG with ``XX YY ZZ radius`` (``bm.io``)
``tube.glb/.obj/.ply`` tube mesh from the radii (generalised cylinders, one ring per node)
``cylinders.csv``      QSM-style cylinder table (TreeQSM column names, 1-based ids)
``summary.json``       metrics, parameters, timings, counts, offset
``preview.png``        cloud + skeleton, three orthographic views and a perspective
=====================  =====================================================================

Coordinates: with ``world=True`` (default) positions are written back in the original frame
(``+ offset``) for PLY, MTG, OBJ, CSV; the GLB is always written in the centred frame
(glTF stores float32, which cannot hold georeferenced coordinates to millimetres) and
``summary.json`` records the offset. Every file is written atomically.

Cylinder table (one cylinder per skeleton edge parent → child), columns as TreeQSM's
``cylinder`` struct: ``ID`` (1-based), ``radius`` (m, the child node's radius), ``length``
(m), ``start_x/y/z`` (m), ``axis_x/y/z`` (unit), ``parent`` (ID of the cylinder ending at the
start node, 0 at a tree base), ``extension`` (ID of the cylinder continuing this one in
the same branch, 0 if none), ``branch`` (1-based branch id), ``BranchOrder`` (0 = stem),
``PositionInBranch`` (1-based), ``tree_id``.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.io.atomic import atomic_path, write_text

__all__ = ["tube_mesh", "cylinder_table", "write_cylinders", "write_summary", "write_preview",
           "export_skeleton", "CYLINDER_COLUMNS", "FORMATS"]

PathLike = str | os.PathLike[str]

CYLINDER_COLUMNS = ("ID", "radius", "length", "start_x", "start_y", "start_z", "axis_x",
                    "axis_y", "axis_z", "parent", "extension", "branch", "BranchOrder",
                    "PositionInBranch", "tree_id")

FORMATS = ("ply", "mtg", "glb", "obj", "mesh_ply", "csv", "json", "png")


def _graph_of(obj: Any) -> BranchGraph:
    g = getattr(obj, "graph", obj)
    if not isinstance(g, BranchGraph):
        raise ParameterError(f"expected a TreeSkeleton or BranchGraph, got {type(obj).__name__}")
    return g


def tube_mesh(graph: BranchGraph, sides: int = 8, min_radius: float = 1e-4,
              segment: NDArray[np.int64] | None = None):
    """Tube mesh of a skeleton with radii (a :class:`biomorph.core.mesh.Mesh`).

    One ring of ``sides`` vertices per node, perpendicular to the node's branch direction;
    a branch that leaves a fork starts with its own ring at the fork node (its own radius,
    perpendicular to its first edge) so thin branches do not inherit the stem's radius.
    Tips and tree bases are closed by fans. ``face_ids["tree"]`` and ``["order"]`` label the
    faces. Metres, same frame as the graph.
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
    axes = node_axes(graph)
    par = graph.parent
    cont = continuation(graph) if segment is None else continuation_from_segments(graph, segment)
    ch = np.flatnonzero(par >= 0)
    branch_start = ch[cont[par[ch]] != ch]          # children that start a new branch
    # ring centres, axes and radii: one per node, then one per branch start (at the parent)
    rc = np.vstack([pos, pos[par[branch_start]]])
    e = pos[branch_start] - pos[par[branch_start]]
    e /= np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
    ra = np.vstack([axes, e])
    rr = np.concatenate([r, r[branch_start]])
    t0, t1 = _tangents(ra)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = (rc[:, None, :] + rr[:, None, None] * (np.cos(ang)[None, :, None] * t0[:, None, :]
                                                  + np.sin(ang)[None, :, None] * t1[:, None, :]))
    verts = ring.reshape(-1, 3)
    start_ring = par.copy()                          # ring each edge starts from
    start_ring[branch_start] = n + np.arange(branch_start.size)
    a = start_ring[ch]
    b = ch
    j = np.arange(sides)
    jn = (j + 1) % sides
    a0 = (a[:, None] * sides + j[None, :])
    a1 = (a[:, None] * sides + jn[None, :])
    b0 = (b[:, None] * sides + j[None, :])
    b1 = (b[:, None] * sides + jn[None, :])
    f = np.concatenate([np.stack([a0, a1, b1], -1), np.stack([a0, b1, b0], -1)], axis=1)
    faces = [f.reshape(-1, 3)]
    edge_node = [np.repeat(b, 2 * sides)]
    # caps: tips (fan to the tip point) and bases (fan to the root point)
    extra = []
    tips = graph.leaves[par[graph.leaves] >= 0]
    roots = graph.roots
    base = verts.shape[0]
    cap_pts = np.vstack([pos[tips] + axes[tips] * r[tips, None] * 0.5, pos[roots]])
    extra.append(cap_pts)
    for k, (nodes, flip) in enumerate(((tips, False), (roots, True))):
        if nodes.size == 0:
            continue
        centre = base + (0 if k == 0 else tips.size) + np.arange(nodes.size)
        r0 = nodes[:, None] * sides + j[None, :]
        r1 = nodes[:, None] * sides + jn[None, :]
        c = np.broadcast_to(centre[:, None], r0.shape)
        tri = np.stack([r0, r1, c], -1) if not flip else np.stack([r1, r0, c], -1)
        faces.append(tri.reshape(-1, 3))
        edge_node.append(np.repeat(nodes, sides))
    verts = np.vstack([verts] + extra)
    faces_arr = np.concatenate(faces).astype(np.int64)
    node_of_face = np.concatenate(edge_node)
    ids = {"tree": np.asarray(graph.trees)[node_of_face].astype(np.int64)}
    if graph.depth is not None:
        ids["order"] = graph.depth[node_of_face].astype(np.int64)
    return Mesh(verts, faces_arr, face_ids=ids)


def cylinder_table(graph: BranchGraph, segment: NDArray[np.int64] | None = None
                   ) -> dict[str, NDArray]:
    """QSM-style cylinders, one per edge (see the module doc for the columns)."""
    from biomorph.tree.order import branch_order, continuation_from_segments, segments

    par = graph.parent
    ch = graph.order[par[graph.order] >= 0]          # children in topological order
    m = ch.size
    cid = np.zeros(graph.n_nodes, dtype=np.int64)    # 1-based cylinder ending at each node
    cid[ch] = np.arange(1, m + 1)
    start = graph.position[par[ch]]
    vec = graph.position[ch] - start
    length = np.linalg.norm(vec, axis=1)
    axis = vec / np.maximum(length, 1e-300)[:, None]
    radius = graph.radius[ch] if graph.radius is not None else np.zeros(m)
    seg = segments(graph) if segment is None else np.asarray(segment)
    depth = graph.depth if graph.depth is not None else branch_order(graph)
    cont = continuation_from_segments(graph, seg)
    extension = np.where(cont[ch] >= 0, cid[np.maximum(cont[ch], 0)], 0)
    # position in branch: count of cylinders from the branch start
    _, seg_rank = np.unique(seg, return_inverse=True)
    seg_rank = seg_rank.reshape(-1)
    pib = np.zeros(m, dtype=np.int64)
    s = seg_rank[ch]
    order_in = np.argsort(s, kind="stable")           # topological order kept within a branch
    counts = np.bincount(s, minlength=seg_rank.max() + 1 if seg_rank.size else 0)
    first = np.concatenate([[0], np.cumsum(counts)])[:-1]
    pib[order_in] = np.arange(m) - np.repeat(first, counts)[np.arange(m)] + 1
    return {"ID": np.arange(1, m + 1), "radius": radius, "length": length,
            "start_x": start[:, 0], "start_y": start[:, 1], "start_z": start[:, 2],
            "axis_x": axis[:, 0], "axis_y": axis[:, 1], "axis_z": axis[:, 2],
            "parent": cid[par[ch]], "extension": extension, "branch": s + 1,
            "BranchOrder": depth[ch], "PositionInBranch": pib,
            "tree_id": np.asarray(graph.trees)[ch]}


def write_cylinders(path: PathLike, graph: BranchGraph,
                    segment: NDArray[np.int64] | None = None) -> Path:
    """Write :func:`cylinder_table` as CSV (header line, metres, 1-based ids)."""
    tab = cylinder_table(graph, segment)
    buf = io.StringIO()
    buf.write(",".join(CYLINDER_COLUMNS) + "\n")
    cols = [tab[c] for c in CYLINDER_COLUMNS]
    ints = {"ID", "parent", "extension", "branch", "BranchOrder", "PositionInBranch", "tree_id"}
    fmt = ["%d" if c in ints else "%.6f" for c in CYLINDER_COLUMNS]
    if cols[0].size:
        np.savetxt(buf, np.column_stack([np.asarray(c, dtype=float) for c in cols]),
                   fmt=fmt, delimiter=",")
    return write_text(path, buf.getvalue())


def write_summary(path: PathLike, skel: Any, extra: dict | None = None) -> Path:
    """Write ``skel.summary()`` (plus ``extra``) as pretty JSON."""
    data = skel.summary() if hasattr(skel, "summary") else {}
    if extra:
        from biomorph.tree.pipeline import _jsonable

        data.update(_jsonable(extra))
    return write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")


def write_preview(path: PathLike, skel: Any, title: str | None = None) -> Path:
    """Cloud (grey) + skeleton (coloured by order, width by radius): three views + 3-D."""
    from biomorph.render import render_graph

    g = _graph_of(skel)
    cloud = getattr(skel, "cloud", None)
    with atomic_path(path) as tmp:
        render_graph(g, tmp, cloud=cloud, title=title)
    return Path(path)


def export_skeleton(skel: Any, out_dir: PathLike, *, formats: tuple[str, ...] | None = None,
                    world: bool = True, sides: int = 8, stem: str = "skeleton",
                    title: str | None = None) -> dict[str, Path]:
    """Write every output of a TreeSkeleton into ``out_dir``; returns ``{format: path}``.

    ``formats`` is a subset of :data:`FORMATS` (default all). ``world`` writes positions in
    the original coordinates (see module doc).
    """
    formats = FORMATS if formats is None else tuple(formats)
    bad = set(formats) - set(FORMATS)
    if bad:
        raise ParameterError(f"unknown export format(s) {sorted(bad)}; expected "
                             f"{', '.join(FORMATS)}")
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
        written["csv"] = write_cylinders(out / "cylinders.csv", gw, seg)
    mesh = None
    if {"glb", "obj", "mesh_ply"} & set(formats):
        mesh = tube_mesh(g, sides=sides, segment=seg)
    if "glb" in formats:
        written["glb"] = write_mesh(out / "tube.glb", mesh, y_up=False)  # Z-up data
    if "obj" in formats or "mesh_ply" in formats:
        from biomorph.core.mesh import Mesh

        mw = Mesh(mesh.vertices + (offset if world else 0.0), mesh.faces,
                  face_ids=mesh.face_ids)
        if "obj" in formats:
            written["obj"] = write_mesh(out / "tube.obj", mw)
        if "mesh_ply" in formats:
            written["mesh_ply"] = write_mesh(out / "tube.ply", mw)
    if "json" in formats:
        written["json"] = write_summary(out / "summary.json", skel,
                                        {"files": {k: v.name for k, v in written.items()},
                                         "world_coordinates": bool(world)})
    if "png" in formats:
        written["png"] = write_preview(out / "preview.png", skel, title)
    return written
