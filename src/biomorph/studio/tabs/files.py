"""Files tab: open any file of the data folder with :mod:`biomorph.io` and show it in 3-D."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

import biomorph.studio.draw as draw
from biomorph.errors import FormatError, UnsupportedFormatError
from biomorph.studio.base import StudioTab, plain

NO_FILE = "(no files in the data folder)"
MAX_DISPLAY_POINTS = 200_000


def _extensions() -> tuple[str, ...]:
    from biomorph import io

    exts = set(io.POINT_FORMATS) | set(io.GRAPH_FORMATS) | set(io.MOTION_FORMATS)
    return tuple(sorted(exts | {".obj", ".glb"}))


def y_up_to_z_up(p: np.ndarray) -> np.ndarray:
    """Turn Y-up coordinates (BVH, glTF) into the Z-up view: (x, y, z) -> (x, -z, y)."""
    p = np.asarray(p, dtype=float)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


class FilesTab(StudioTab):
    """Open a point cloud, skeleton graph, motion or mesh from the data folder."""

    key = "files"
    label = "Files"
    getting_started = (
        "Getting started: choose a file of the data folder and press Open, "
        "or upload one; clouds are coloured by height, graphs by branch order."
    )

    def __init__(self, app: Any) -> None:
        super().__init__(app)
        self.loaded: Any = None
        self.loaded_kind: str | None = None
        self.loaded_path: Path | None = None
        self._motion_frame = None

    def build(self) -> None:
        gui = self.gui
        gui.add_markdown(f"Files of the data folder {plain(self.app.sandbox.root)}.")
        self.file = gui.add_dropdown("File", options=self._options(), hint="A file to open.")
        refresh = gui.add_button("Refresh list")
        refresh.on_click(self.action("refresh", self.refresh, timed=False, show=False))
        opener = gui.add_button("Open")
        opener.on_click(self.action("open", lambda: self.open(self.file.value), heavy=True))
        self.upload = self.app.add_upload(
            self, "Upload and open", self._opened_upload, _extensions()
        )
        self.frame = gui.add_slider("Frame", min=0, max=1, step=1, initial_value=0, visible=False)
        self.frame.on_update(self.live("frame", self._draw_motion_frame))
        self.info = gui.add_markdown("")

    def restore(self) -> None:
        """Redraw the opened file after a page reload."""
        if self.loaded is not None:
            self._clear()
            getattr(self, f"_draw_{self.loaded_kind}")(self.loaded)
            self._focus_content()

    def _options(self) -> tuple[str, ...]:
        files = self.app.sandbox.list_files(_extensions())
        return tuple(files) if files else (NO_FILE,)

    def refresh(self) -> None:
        """Re-read the folder listing."""
        self.file.options = self._options()
        self.set_status(f"{len(self.file.options)} file(s) listed.")

    def _opened_upload(self, path: Path) -> None:
        self.refresh()
        rel = self.app.sandbox.relative(path)
        self.open(rel)
        self.file.value = rel

    # ------------------------------------------------------------------ opening
    def open(self, name: str) -> None:
        """Read ``name`` (relative to the data folder) and draw it."""
        from biomorph import io

        if name == NO_FILE:
            raise FormatError(None, "the data folder holds no readable file; upload one")
        path = self.app.sandbox.resolve(name)
        ext = path.suffix.lower()
        self.set_status(f"Reading {plain(name)} ({path.stat().st_size / 1e6:.1f} MB) …")
        if ext in io.MOTION_FORMATS:
            obj, kind = io.read_motion(path), "motion"
        elif ext in io.GRAPH_FORMATS:
            try:
                obj, kind = io.read_graph(path), "graph"
            except FormatError:
                if ext not in io.POINT_FORMATS:
                    raise
                obj, kind = io.read_points(path), "points"
        elif ext in io.POINT_FORMATS:
            obj, kind = io.read_points(path), "points"
        elif ext in (".obj", ".glb"):
            obj, kind = self._read_mesh(path), "mesh"
        else:
            known = " ".join(_extensions())
            raise UnsupportedFormatError(
                f"{name}: no reader for extension {ext or '(none)'}; expected one of {known}"
            )
        self.loaded, self.loaded_kind, self.loaded_path = obj, kind, path
        self._clear()
        getattr(self, f"_draw_{kind}")(obj)
        self._focus_content()
        self.set_status(f"Opened {plain(name)} ({kind}).")
        self.redrawn()

    def _focus_content(self) -> None:
        """Aim the cameras at what was drawn."""
        pts = []
        for name in ("points", "edges", "joints", "mesh"):
            handle = self.scene._handle_from_node_name.get(f"{self.root}/{name}")
            for attr in ("points", "vertices"):
                arr = getattr(handle, attr, None) if handle is not None else None
                if arr is not None:
                    pts.append(np.asarray(arr, dtype=float).reshape(-1, 3))
        if pts:
            centre, size = draw.fit_camera(np.concatenate(pts))
            self.app.focus(self.key, centre, size, force=True)

    @staticmethod
    def _read_mesh(path: Path):
        import trimesh

        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception as exc:
            raise FormatError(path, f"cannot read mesh: {exc}") from exc
        if len(mesh.faces) == 0:
            raise FormatError(path, "mesh has no faces")
        return mesh

    def _clear(self) -> None:
        for name in ("points", "edges", "joints", "mesh"):
            try:
                self.scene.remove_by_name(f"{self.root}/{name}")
            except Exception:  # noqa: BLE001, S112 - absent is fine
                continue
        self.frame.visible = False

    def _draw_points(self, cloud: Any) -> None:
        xyz = np.asarray(cloud.xyz)
        shown, _ = draw.subsample(
            xyz - xyz.mean(axis=0) * [1, 1, 0] - [0, 0, xyz[:, 2].min()], MAX_DISPLAY_POINTS
        )
        _, size = draw.fit_camera(shown)
        self.scene.add_point_cloud(
            f"{self.root}/points",
            shown.astype(np.float32),
            draw.height_colors(shown),
            point_size=size / 400,
            point_shape="circle",
        )
        lo, hi = cloud.bounds()
        self.info.content = (
            f"**{cloud.n_points:,} points** (showing {len(shown):,}; colour: "
            f"height, brown low → green high); extent "
            f"{np.round(hi - lo, 3).tolist()} m; attributes: "
            f"{plain(', '.join(cloud.attributes) or 'none')}"
        )

    def _draw_graph(self, graph: Any) -> None:
        pos = np.asarray(graph.position)
        shift = pos.mean(axis=0) * [1, 1, 0] + [0, 0, pos[:, 2].min()]
        seg, child = draw.graph_segments(pos - shift, graph.parent)
        depth = graph.depth if graph.depth is not None else np.zeros(len(pos), int)
        colors = np.repeat(draw.palette(np.asarray(depth)[child])[:, None, :], 2, axis=1)
        _, size = draw.fit_camera(pos)
        self.scene.add_line_segments(
            f"{self.root}/edges", seg.astype(np.float32), colors, thickness=max(size / 300, 1e-4)
        )
        self.info.content = (
            f"**{graph.n_nodes:,} nodes**, {len(graph.roots)} tree(s), "
            f"{len(graph.leaves)} tips, total length {graph.total_length:.2f} m"
            f"; colour: branch order\n\n{draw.order_legend(depth)}"
        )

    def _draw_motion(self, motion: Any) -> None:
        n_frames = int(np.asarray(motion.rotation).shape[0])
        self.frame.max = max(n_frames - 1, 1)
        self.frame.value = 0
        self.frame.visible = True
        self._draw_motion_frame()
        skel = motion.skeleton
        self.info.content = (
            f"**{skel.n_joints} joints**, {n_frames} frames at "
            f"{1.0 / float(motion.frame_time):.1f} fps"
        )

    def _draw_motion_frame(self) -> None:
        motion = self.loaded
        if self.loaded_kind != "motion":
            return
        f = int(min(self.frame.value, np.asarray(motion.rotation).shape[0] - 1))
        skel = motion.skeleton
        if hasattr(motion, "world_positions"):  # handles per-joint translations too
            world = motion.world_positions(slice(f, f + 1))[0]
        else:
            world = skel.world_positions(
                np.asarray(motion.rotation)[f], np.asarray(motion.root_position)[f]
            )
        _, size = draw.fit_camera(skel.world_positions())
        scale = 1.7 / size if size > 5 else 1.0  # centimetre BVH files -> about human size
        p = y_up_to_z_up(world) * scale
        child = np.flatnonzero(skel.parent >= 0)
        seg = np.stack([p[skel.parent[child]], p[child]], axis=1)
        self.scene.add_line_segments(
            f"{self.root}/edges", seg.astype(np.float32), (230, 230, 240), thickness=0.02
        )
        self.scene.add_point_cloud(
            f"{self.root}/joints",
            p.astype(np.float32),
            (220, 60, 60),
            point_size=0.04,
            point_shape="circle",
        )
        self.redrawn()

    def _draw_mesh(self, mesh: Any) -> None:
        v = np.asarray(mesh.vertices, dtype=np.float32)
        self.scene.add_mesh_simple(
            f"{self.root}/mesh",
            v,
            np.asarray(mesh.faces, np.int32),
            color=(120, 190, 120),
            side="double",
        )
        self.info.content = f"**mesh**: {len(v):,} vertices, {len(mesh.faces):,} triangles"
