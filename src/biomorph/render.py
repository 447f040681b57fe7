"""Headless PNG previews (matplotlib Agg): three orthographic views and one perspective view.

Every ``render_*`` function takes the object, the output ``.png`` path and ``up``
(``"z"`` for trees and leaves, ``"y"`` for creatures and motion) so the subject stands
upright; it writes the PNG atomically and returns its path. Views (after turning the data
Z-up): *front* looks along +y (x right, z up), *side* looks along -x (y right, z up),
*top* looks down -z (x right, y up); the fourth panel is a perspective view from the
front-left-above. Clouds are subsampled (default at most 200 000 points drawn in the
orthographic views, 40 000 in the perspective one, seeded) so previews of 10^7-point scans
stay fast; meshes above 300 000 faces (20 000 in the perspective view) are drawn from a
seeded subset of their faces.

Example
-------
>>> from biomorph.inspect import render_file   # any file by kind  # doctest: +SKIP
>>> render_file("scan.laz", "preview.png")                         # doctest: +SKIP

``figure``/``subplots``/``save_png`` are pyplot's helpers on matplotlib's ``Figure`` API for
the pillars' plots: no global backend or pyplot state is touched.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core.types import PathLike
from biomorph.errors import InputError, ParameterError
from biomorph.io.atomic import atomic_path

#: screen-right, screen-up and toward-viewer axes of each orthographic view (Z-up frame)
_VIEWS: dict[str, NDArray[np.float64]] = {
    "front": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
    "side": np.array([[0, 1.0, 0], [0, 0, 1], [1, 0, 0]]),
    "top": np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1]]),
}
_MAX_3D_POINTS = 40_000
_MAX_3D_FACES = 20_000
_MAX_2D_FACES = 300_000


def _to_zup(xyz: ArrayLike, up: str) -> NDArray[np.float64]:
    """Coordinates in a Z-up frame: Y-up data ``(x, y, z)`` become ``(x, -z, y)``."""
    p = np.asarray(xyz, dtype=np.float64)
    u = up.lower()
    if u == "z":
        return p
    if u == "y":
        return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)
    raise ParameterError(f"up={up!r}; expected 'z' (trees, leaves) or 'y' (creatures, motion)")


@dataclass
class _Scene:
    """Primitives to draw, already in the Z-up frame."""

    points: list[tuple[NDArray, NDArray, float]] = field(default_factory=list)
    segments: list[tuple[NDArray, NDArray, NDArray]] = field(default_factory=list)
    triangles: list[tuple[NDArray, NDArray]] = field(default_factory=list)
    #: (label, rgba) entries of the figure legend (what a colour means)
    legend: list[tuple[str, Any]] = field(default_factory=list)
    #: indices into ``segments`` whose widths show radii at true scale (:func:`_width_pt`,
    #: for a panel half the figure high): a taller panel widens them alike
    true_scale: list[int] = field(default_factory=list)

    def all_xyz(self) -> NDArray[np.float64]:
        parts = [p for p, _, _ in self.points] + [s.reshape(-1, 3) for s, _, _ in self.segments]
        parts += [t.reshape(-1, 3) for t, _ in self.triangles]
        parts = [p for p in parts if p.size]
        if not parts:
            raise InputError("nothing to render: the object has no points, bones or faces")
        return np.concatenate(parts)


def _rgba(values: NDArray, cmap: str = "viridis") -> NDArray[np.float64]:
    import matplotlib

    v = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(v)
    lo = v[finite].min() if finite.any() else 0.0
    hi = v[finite].max() if finite.any() else 1.0
    t = (v - lo) / (hi - lo) if hi > lo else np.full_like(v, 0.5)
    return matplotlib.colormaps[cmap](np.nan_to_num(t, nan=0.5))


def _bounds(uv: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lower and upper corner of 2-D points: the 0.1-99.9 % quantiles above 1,000 points,
    so a few stray points (outliers, a far scanner hit) cannot shrink the object to a dot."""
    if uv.shape[0] > 1000:
        lo, hi = np.quantile(uv, [0.001, 0.999], axis=0)
        return lo, hi
    return uv.min(axis=0), uv.max(axis=0)


def _frame(proj: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Centre and half-width of a square window framing one view's projected points.

    Each view is framed to its own extent (a 20 m pine fills its side views and its 5 m crown
    fills the top view). Above 1,000 points the 0.1-99.9 % quantiles are used, so a few stray
    points (outliers, a far scanner hit) cannot shrink the object to a dot.
    """
    uv = proj[:, :2]
    lo, hi = _bounds(uv)
    half = 0.55 * float(np.max(hi - lo))
    if not np.isfinite(half) or half <= 0:
        half = 0.55 * (float(np.max(np.abs(uv))) or 1.0)
    return 0.5 * (lo + hi), half


#: the side views of an object this many times taller than wide (a conifer, a standing
#: biped) get panels as tall as the figure, side by side, beside the top view and the
#: perspective (a 17 m spruce 2.5 m wide filled 15 % of a square panel's width)
TALL_RATIO = 2.0


def _extent2(proj: NDArray[np.float64]) -> NDArray[np.float64]:
    """Width and height of one view's projected points (:func:`_bounds`)."""
    lo, hi = _bounds(proj[:, :2])
    return np.asarray(hi - lo, dtype=float)


def _layout(fig: Any, xyz: NDArray[np.float64]) -> tuple[list[Any], Any, bool]:
    """Where the three views and the perspective go: a 2 x 2 grid, or, for an object over
    :data:`TALL_RATIO` times taller than wide in the front and side views, those two as
    tall as the figure and each as wide as its view, the top view and the perspective
    stacked beside them. Returns the views' slots, the perspective's and whether tall."""
    ext = [_extent2(xyz @ _VIEWS[name].T) for name in ("front", "side")]
    if not all(e[1] > TALL_RATIO * max(e[0], 1e-12) for e in ext):
        return [221, 222, 223], 224, False
    ratios = [max(e[0] / e[1], 0.05) for e in ext]
    gs = fig.add_gridspec(2, 3, width_ratios=[*ratios, max(0.5, sum(ratios))])
    return [gs[:, 0], gs[:, 1], gs[0, 2]], gs[1, 2], True


def _draw_view(ax: Any, scene: _Scene, name: str, rot: NDArray, widen: bool = False) -> None:
    """One orthographic view of the scene: shaded faces far first, segments, points.
    ``widen``: the panel is as tall as the figure, twice a grid panel's height (the
    true-scale widths, :attr:`_Scene.true_scale`, doubled)."""
    from matplotlib.collections import LineCollection, PolyCollection

    light = np.array([0.3, -0.5, 0.8])
    light /= np.linalg.norm(light)
    ax.set_title(name, fontsize=9)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)
    for tri, colors in scene.triangles:
        if tri.shape[0] > _MAX_2D_FACES:  # bounded preview time for huge meshes
            pick = np.random.default_rng(0).choice(tri.shape[0], _MAX_2D_FACES, replace=False)
            tri, colors = tri[pick], colors[pick]
        proj = tri @ rot.T  # (m, 3, 3): right, up, toward viewer
        depth = proj[:, :, 2].mean(axis=1)
        order = np.argsort(depth)  # far first (painter's algorithm)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nlen = np.linalg.norm(normal, axis=1, keepdims=True)
        normal = np.divide(normal, nlen, out=np.zeros_like(normal), where=nlen > 0)
        shade = 0.35 + 0.65 * np.abs(normal @ (rot[2] * 0.6 + light * 0.4))
        fc = colors.copy()
        fc[:, :3] *= np.clip(shade, 0, 1)[:, None]
        ax.add_collection(
            PolyCollection(
                proj[order][:, :, :2],
                facecolors=fc[order],
                edgecolors="none",
                antialiased=False,
            )
        )
    for i, (segs, colors, widths) in enumerate(scene.segments):
        proj = segs @ rot.T
        order = np.argsort(proj[:, :, 2].mean(axis=1))
        if widen and i in scene.true_scale:
            widths = np.clip(2.0 * widths, 0.4, 30.0)
        ax.add_collection(
            LineCollection(
                proj[order][:, :, :2],
                colors=colors[order],
                linewidths=widths[order],
                capstyle="round",
            )
        )
    for pts, colors, size_pt in scene.points:
        proj = pts @ rot.T
        order = np.argsort(proj[:, 2])
        ax.scatter(
            proj[order, 0],
            proj[order, 1],
            s=size_pt,
            c=colors[order],
            linewidths=0,
            rasterized=True,
        )
    ax.set_xlabel("m", fontsize=7, labelpad=1)
    ax.set_ylabel("m", fontsize=7, labelpad=1)


def _draw(
    scene: _Scene, out_png: PathLike, title: str | None, dpi: int = 100, size: float = 10.0
) -> Path:
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401 - registers the 3d projection
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    out = Path(out_png)
    if out.suffix.lower() != ".png":
        raise ParameterError(f"output {os.fspath(out_png)!r} must end with .png")
    xyz = scene.all_xyz()
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    centre = 0.5 * (lo + hi)
    extent = float(np.max(hi - lo)) or 1.0
    fig = Figure(figsize=(size, size), dpi=dpi, layout="constrained")
    slots, slot3, tall = _layout(fig, xyz)
    for k, (name, rot) in enumerate(_VIEWS.items()):
        ax = fig.add_subplot(slots[k])
        _draw_view(ax, scene, name, rot, widen=tall and name != "top")
        proj = xyz @ rot.T
        c2, half = _frame(proj)
        # a tall object's front and side: as wide as the view, not square
        hw = max(0.55 * float(_extent2(proj)[0]), 0.05 * half) if tall and name != "top" else half
        ax.set_xlim(c2[0] - hw, c2[0] + hw)
        ax.set_ylim(c2[1] - half, c2[1] + half)
    ax3 = fig.add_subplot(slot3, projection="3d")
    ax3.set_title("perspective", fontsize=9)
    ax3.set_proj_type("persp", focal_length=0.6)
    for tri, colors in scene.triangles:
        if tri.shape[0] > _MAX_3D_FACES:
            pick = np.random.default_rng(0).choice(tri.shape[0], _MAX_3D_FACES, replace=False)
            tri, colors = tri[pick], colors[pick]
        ax3.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors="none"))
    for segs, colors, widths in scene.segments:
        ax3.add_collection3d(Line3DCollection(segs, colors=colors, linewidths=widths))
    for pts, colors, size_pt in scene.points:
        if pts.shape[0] > _MAX_3D_POINTS:
            pick = np.random.default_rng(0).choice(pts.shape[0], _MAX_3D_POINTS, replace=False)
            pts, colors = pts[pick], colors[pick]
        ax3.scatter(
            pts[:, 0], pts[:, 1], pts[:, 2], s=size_pt, c=colors, linewidths=0, depthshade=False
        )
    # equal scale on all axes, box shaped like the data (a tall tree gets a tall box)
    half3 = 0.5 * np.maximum(hi - lo, 0.08 * extent) * 1.04
    ax3.set_xlim(centre[0] - half3[0], centre[0] + half3[0])
    ax3.set_ylim(centre[1] - half3[1], centre[1] + half3[1])
    ax3.set_zlim(centre[2] - half3[2], centre[2] + half3[2])
    ax3.set_box_aspect(tuple(half3 / half3.max()))
    ax3.view_init(elev=20, azim=-60)
    ax3.tick_params(labelsize=6)
    if title:
        fig.suptitle(title, fontsize=11)
    if scene.legend:
        from matplotlib.lines import Line2D

        handles = [Line2D([], [], color=c, lw=3, label=lab) for lab, c in scene.legend]
        fig.legend(
            handles=handles,
            loc="outside lower center",
            ncols=min(len(handles), 6),
            fontsize=8,
            frameon=False,
        )
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return out


def _width_pt(radius: NDArray, extent: float, size: float = 10.0) -> NDArray[np.float64]:
    """Line width in points showing a branch of ``radius`` (m) at true scale (min 0.4 pt)."""
    panel_pt = size * 72.0 / 2.0
    return np.clip(2.0 * np.asarray(radius, float) / (1.1 * extent) * panel_pt, 0.4, 30.0)


# --------------------------------------------------------------------------- public API
def render_cloud(
    cloud: Any,
    out_png: PathLike,
    up: str = "z",
    color_by: str | None = None,
    max_points: int = 200_000,
    seed: int = 0,
    title: str | None = None,
    graph: Any = None,
) -> Path:
    """Preview a point cloud (``PointCloud`` or ``(n, 3)`` array), coloured by height or by
    attribute ``color_by`` (RGB when the cloud has ``red green blue``); optionally with a
    BranchGraph drawn on top. At most ``max_points`` points are drawn (seeded subsample)."""
    from biomorph.core.pointcloud import PointCloud

    if not isinstance(cloud, PointCloud):
        cloud = PointCloud(np.asarray(cloud, dtype=float))
    n = cloud.n_points
    if n == 0:
        raise InputError("point cloud is empty; nothing to render")
    idx = np.arange(n)
    if n > max_points:
        idx = np.sort(np.random.default_rng(seed).choice(n, max_points, replace=False))
    pts = _to_zup(cloud.xyz[idx], up)
    attrs = cloud.attributes
    if color_by is not None:
        if color_by not in attrs:
            raise ParameterError(
                f"color_by={color_by!r} is not an attribute of the cloud; "
                f"attributes: {', '.join(attrs) or 'none'}"
            )
        colors = _rgba(np.asarray(attrs[color_by])[idx])
    elif all(c in attrs for c in ("red", "green", "blue")):
        rgb = np.stack([np.asarray(attrs[c], float)[idx] for c in ("red", "green", "blue")], 1)
        rgb /= 65535.0 if rgb.max(initial=0) > 255 else 255.0
        colors = np.concatenate([np.clip(rgb, 0, 1), np.ones((rgb.shape[0], 1))], axis=1)
    else:
        colors = _rgba(pts[:, 2], "viridis")
    size_pt = float(np.clip(4000.0 / max(pts.shape[0], 1), 0.05, 6.0))
    scene = _Scene(points=[(pts, colors, size_pt)])
    if graph is not None:
        _add_graph(
            scene, graph, up, extent=float(np.ptp(pts, axis=0).max()) or 1.0, color="crimson"
        )
    label = title or f"{cloud.source or 'point cloud'}: {n:,} points" + (
        f" ({pts.shape[0]:,} drawn)" if pts.shape[0] < n else ""
    )
    return _draw(scene, out_png, label)


def _add_graph(
    scene: _Scene,
    graph: Any,
    up: str,
    extent: float | None = None,
    color: str | None = None,
    muted: Any = None,
) -> None:
    from biomorph.core.graph import BranchGraph

    if not isinstance(graph, BranchGraph):
        graph = getattr(graph, "graph", graph)
    if not isinstance(graph, BranchGraph):
        raise InputError(f"expected a BranchGraph, got {type(graph).__name__}")
    pos = _to_zup(graph.position, up)
    e = graph.edges
    if extent is None:
        extent = float(np.ptp(pos, axis=0).max()) if graph.n_nodes else 1.0
        extent = extent or 1.0
    if e.shape[0] == 0:
        scene.points.append((pos, _rgba(np.zeros(graph.n_nodes)), 8.0))
        return
    segs = np.stack([pos[e[:, 0]], pos[e[:, 1]]], axis=1)
    if graph.radius is not None:
        widths = _width_pt(graph.radius[e[:, 1]], extent)
        if color is None:
            scene.true_scale.append(len(scene.segments))
    else:
        widths = np.full(e.shape[0], 1.2)
    if color is not None:
        import matplotlib.colors as mcolors

        colors = np.tile(mcolors.to_rgba(color), (e.shape[0], 1))
        widths = np.clip(0.3 * widths, 0.3, 1.5)  # an overlay must not hide what is beneath
    elif graph.depth is not None:
        colors = _rgba(graph.depth[e[:, 1]], "plasma")
        _legend_of(scene, graph.depth[e[:, 1]], colors, "order {}")
    elif graph.roots.size > 1:
        tree = graph.trees[e[:, 1]]
        colors = _rgba(tree % 10, "tab10")
        off = np.isin(tree, np.asarray(list(muted or ()), dtype=tree.dtype))
        _legend_of(scene, tree[~off], colors[~off], "tree {}")
        if off.any():  # fragments (no tree: understorey, stumps, crown pieces) in dark grey
            colors[off] = (0.25, 0.25, 0.25, 1.0)
            n_off = np.unique(tree[off]).size
            scene.legend.append(
                (f"{n_off} fragment{'' if n_off == 1 else 's'}", tuple(colors[off][0]))
            )
    else:
        colors = _rgba(graph.node_depth[e[:, 1]], "plasma")
    scene.segments.append((segs, colors, widths))


def _legend_of(scene: _Scene, values: NDArray, colors: NDArray, fmt: str, most: int = 10) -> None:
    """Legend entries for integer ``values`` drawn in ``colors`` (the first ``most``)."""
    vals, first = np.unique(np.asarray(values), return_index=True)
    for v, i in list(zip(vals.tolist(), first.tolist(), strict=True))[:most]:
        scene.legend.append((fmt.format(v), tuple(colors[i])))
    if vals.size > most:
        scene.legend.append((f"… {vals.size - most} more", (0.5, 0.5, 0.5, 1.0)))


def render_graph(
    graph: Any,
    out_png: PathLike,
    up: str = "z",
    title: str | None = None,
    cloud: Any = None,
    muted: Any = None,
) -> Path:
    """Preview a BranchGraph: line width by radius (true scale), colour by branch order
    (``depth``; else tree, else topological depth); optionally over a point cloud (grey).
    ``muted``: tree labels drawn in dark grey under one legend entry (a plot's fragments)."""
    scene = _Scene()
    if cloud is not None:
        from biomorph.core.pointcloud import PointCloud

        xyz = cloud.xyz if isinstance(cloud, PointCloud) else np.asarray(cloud, float)
        if xyz.shape[0] > 100_000:
            xyz = xyz[np.random.default_rng(0).choice(xyz.shape[0], 100_000, replace=False)]
        scene.points.append(
            (_to_zup(xyz, up), np.tile([0.6, 0.6, 0.6, 0.35], (xyz.shape[0], 1)), 0.3)
        )
    _add_graph(scene, graph, up, muted=muted)
    g = getattr(graph, "graph", graph)
    label = title or (
        f"skeleton graph: {g.n_nodes:,} nodes, {g.leaves.size:,} tips, {g.total_length:.2f} m"
    )
    return _draw(scene, out_png, label)


def _skeleton_segments(parent: NDArray, pos: NDArray) -> NDArray:
    child = np.flatnonzero(parent >= 0)
    return np.stack([pos[..., parent[child], :], pos[..., child, :]], axis=-2)


def render_skeleton(
    skeleton: Any,
    out_png: PathLike,
    rotation: ArrayLike | None = None,
    root_position: ArrayLike | None = None,
    up: str = "y",
    title: str | None = None,
) -> Path:
    """Preview a JointSkeleton in rest pose or in the pose ``rotation (n, 4)`` /
    ``root_position (3,)``: bones coloured by hierarchy depth, joints as dots, root red."""
    pos = skeleton.world_positions(rotation, root_position)
    pos = _to_zup(pos, up)
    segs = _skeleton_segments(skeleton.parent, pos)
    depth = skeleton.depth
    child = np.flatnonzero(skeleton.parent >= 0)
    scene = _Scene()
    if segs.shape[0]:
        scene.segments.append((segs, _rgba(depth[child], "viridis"), np.full(segs.shape[0], 2.5)))
    colors = np.tile([0.1, 0.1, 0.1, 1.0], (pos.shape[0], 1))
    colors[skeleton.parent < 0] = [0.85, 0.1, 0.1, 1.0]
    scene.points.append((pos, colors, 10.0))
    label = title or f"skeleton: {skeleton.n_joints} joints"
    return _draw(scene, out_png, label)


def render_motion(
    motion: Any,
    out_png: PathLike,
    n_poses: int = 5,
    up: str | None = None,
    title: str | None = None,
) -> Path:
    """Preview a Motion: ``n_poses`` poses evenly spaced in time, coloured early (dark) to
    late (yellow). ``up`` defaults to the motion's guessed up axis (Y for most files)."""
    if n_poses < 1:
        raise ParameterError(f"n_poses={n_poses}; expected at least 1")
    n_frames = int(np.asarray(motion.rotation).shape[0])
    if n_frames == 0:
        raise InputError("motion has no frames; nothing to render")
    if up is None:
        up = "y"
        try:
            from biomorph.core.motion import guess_up_axis

            up = guess_up_axis(motion)
        except (ImportError, AttributeError, InputError):
            pass
    frames = np.unique(np.linspace(0, n_frames - 1, min(n_poses, n_frames)).round().astype(int))
    if hasattr(motion, "world_positions"):
        pos = np.asarray(motion.world_positions(frames))
    else:
        pos = motion.skeleton.world_positions(
            np.asarray(motion.rotation)[frames], np.asarray(motion.root_position)[frames]
        )
    pos = _to_zup(pos, up)
    parent = motion.skeleton.parent
    scene = _Scene()
    tcol = _rgba(frames if frames.size > 1 else np.zeros(1), "plasma")
    for k in range(frames.size):
        segs = _skeleton_segments(parent, pos[k])
        if segs.shape[0]:
            scene.segments.append(
                (segs, np.tile(tcol[k], (segs.shape[0], 1)), np.full(segs.shape[0], 2.0))
            )
        scene.points.append((pos[k], np.tile(tcol[k], (pos.shape[1], 1)), 4.0))
    step = max(1, n_frames // 500)
    root_path = _to_zup(np.asarray(motion.root_position)[::step], up)
    if root_path.shape[0] > 1:
        path_segs = np.stack([root_path[:-1], root_path[1:]], axis=1)
        scene.segments.append(
            (
                path_segs,
                np.tile([0.5, 0.5, 0.5, 0.6], (len(path_segs), 1)),
                np.full(len(path_segs), 0.8),
            )
        )
    ft = float(motion.frame_time)
    label = title or (
        f"motion: {motion.skeleton.n_joints} joints, {n_frames} frames "
        f"({(n_frames - 1) * ft:.2f} s), poses at "
        + ", ".join(f"{f * ft:.2f}" for f in frames)
        + " s"
    )
    return _draw(scene, out_png, label)


def render_mesh(
    mesh: Any,
    out_png: PathLike,
    up: str = "z",
    title: str | None = None,
    color_by: str | None = None,
) -> Path:
    """Preview a mesh (anything ``Mesh.from_any`` accepts), Lambert-shaded, faces coloured
    by ``face_ids[color_by]`` (default: the first face id key), else vertex colours, else
    one colour."""
    from biomorph.core.mesh import Mesh

    m = Mesh.from_any(mesh)
    if m.n_faces == 0:
        raise InputError("mesh has no faces; nothing to render")
    tri = _to_zup(m.vertices[m.faces], up)
    key = color_by if color_by is not None else next(iter(m.face_ids), None)
    if key is not None:
        if key not in m.face_ids:
            raise ParameterError(
                f"color_by={key!r} is not a face id of the mesh; face ids: "
                f"{', '.join(m.face_ids) or 'none'}"
            )
        colors = _rgba(m.face_ids[key] % 20, "tab20")
    elif m.vertex_colors is not None:
        colors = m.vertex_colors[m.faces].astype(float).mean(axis=1) / 255.0
        colors[:, 3] = 1.0
    else:
        colors = np.tile([0.55, 0.7, 0.45, 1.0], (m.n_faces, 1))
    label = title or f"mesh: {m.n_vertices:,} vertices, {m.n_faces:,} faces, {m.area():.4g} m²"
    return _draw(_Scene(triangles=[(tri, colors)]), out_png, label)


# --------------------------------------------------------------------------- Figure API
_FIG_KW = ("figsize", "dpi", "layout", "constrained_layout", "tight_layout", "facecolor")


def figure(**kw: Any) -> Any:
    """A new ``Figure`` (``figsize``, ``dpi``, ``layout`` … as for ``pyplot.figure``)."""
    from matplotlib.figure import Figure

    return Figure(**{k: v for k, v in kw.items() if k in _FIG_KW})


def subplots(nrows: int = 1, ncols: int = 1, **kw: Any) -> tuple[Any, Any]:
    """``(fig, axes)`` like ``pyplot.subplots``, without pyplot."""
    fig = figure(**kw)
    axes = fig.subplots(nrows, ncols, **{k: v for k, v in kw.items() if k not in _FIG_KW})
    return fig, axes


def close(fig: Any) -> None:
    """Nothing to release: a ``Figure`` outside pyplot is freed with its last reference."""


def save_png(fig: Any, path: PathLike, dpi: int = 110, **kw: Any) -> Path:
    """Write ``fig`` as PNG through a temporary file and rename (no partial file)."""
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, **kw)
    return Path(path)


__all__ = [
    "render_cloud",
    "render_graph",
    "render_skeleton",
    "render_mesh",
    "render_motion",
    "close",
    "figure",
    "save_png",
    "subplots",
]
