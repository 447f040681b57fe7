"""Tree tab: load a LiDAR cloud or synthesise one, skeletonise it (graph or voxel method)
with a progress bar and cancel, show cloud / skeleton by branch order / tubes by radius,
the metrics, and export PLY / GLB / CSV — all through :mod:`biomorph.tree`."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

import biomorph.studio.draw as draw
from biomorph.errors import BiomorphError, InputError
from biomorph.studio.base import StudioTab, plain
from biomorph.studio.widgets import ExportRow, FilePicker

CLOUD_EXTENSIONS = (".las", ".laz", ".ply", ".xyz", ".txt", ".csv", ".asc", ".pts", ".npy")
#: Colour classes of the tubes (log-spaced radius bins between the 2nd and 98th percentile).
RADIUS_BINS = 6


class Cancelled(BiomorphError):
    """The user pressed Cancel while a skeletonisation was running."""


class TreeTab(StudioTab):
    """Tree skeletons from point clouds."""

    key = "tree"
    label = "Tree"
    getting_started = (
        "Getting started: press Synthesise and scan (or open a LAS/PLY/XYZ "
        "cloud), then Run; the skeleton is coloured by branch order."
    )

    def __init__(self, app: Any) -> None:
        super().__init__(app)
        self.cloud: Any = None
        self.cloud_name = "tree"
        self.result: Any = None
        self.truth: Any = None
        self.job: threading.Thread | None = None
        self._cancel = threading.Event()
        self.ticks: list[str] = []
        self.generation = 0  # bumped by every new cloud: a job for an older one is dropped
        self._phase = 0
        self._tubes: list[tuple[Any, Any, tuple[int, int, int]]] = []
        self._tube_handles: list[Any] = []
        self._tube_range = (0.001, 0.01)
        self._cloud_node: Any = None
        self._skeleton_node: Any = None

    def requirement(self) -> str | None:
        try:
            from biomorph.tree import pipeline  # noqa: F401
            from biomorph.tree.synthetic import PRESETS, generate_tree  # noqa: F401
        except ImportError as exc:
            return f"the tree pillar cannot be imported ({exc})"
        return None

    # ------------------------------------------------------------------ GUI
    def build(self) -> None:
        from biomorph.tree.synthetic import PRESETS

        gui = self.gui
        with gui.add_folder("Cloud"):
            self.picker = FilePicker(
                self,
                "Point cloud",
                CLOUD_EXTENSIONS,
                self.load,
                upload_label="Upload cloud (LAS/LAZ/PLY/XYZ)",
            )
            self.preset = gui.add_dropdown(
                "Synthetic tree",
                options=tuple(PRESETS),
                initial_value="aspen" if "aspen" in PRESETS else tuple(PRESETS)[0],
            )
            self.seed = gui.add_number("Seed", initial_value=1, min=0, max=2**31 - 1, step=1)
            self.n_points = gui.add_slider(
                "Scan points", min=2000, max=100000, step=1000, initial_value=8000
            )
            gui.add_button("Synthesise and scan").on_click(
                self.action("synthesise", self.synthesise, timed=False, heavy=True)
            )
            self.cloud_info = gui.add_markdown("")
        with gui.add_folder("Method"):
            self.method = gui.add_dropdown(
                "Method", options=("graph", "voxel"), initial_value="graph"
            )
            self.k = gui.add_slider("Neighbours k (graph)", min=4, max=30, step=1, initial_value=10)
            self.node_spacing = gui.add_number(
                "Node spacing m (0 = auto)", initial_value=0.0, min=0.0, max=1.0, step=0.01
            )
            self.max_iter = gui.add_slider(
                "Iterations (graph)", min=1, max=10, step=1, initial_value=5
            )
            self.cell = gui.add_number(
                "Voxel cell m (voxel)", initial_value=0.05, min=0.005, max=1.0, step=0.005
            )
            self.radius = gui.add_dropdown(
                "Radius", options=("fit", "allometric"), initial_value="fit"
            )
            self.cleanup = gui.add_checkbox("Cleanup", initial_value=True)
            # a cloud in cm or mm (plant scanners, photogrammetry) read as metres is a
            # tree kilometres tall: the run stops and names the units it looks like
            self.units = gui.add_dropdown(
                "Cloud units", options=("m", "cm", "mm", "ft"), initial_value="m"
            )
            # a Y-up export (glTF-style PLY, photogrammetry) shows lying on its side: turn
            # it Z-up (tree.cloud.to_z_up); the cloud is redrawn turned before the run
            from biomorph.tree.options import UP_AXES

            self.up = gui.add_dropdown("Cloud up axis", options=UP_AXES, initial_value="z")
            self.up.on_update(self.live("cloud up axis", self.up_changed))
            self.models = gui.add_slider(
                "Models (nearest kept)", min=1, max=9, step=1, initial_value=1
            )
        self.buttons = gui.add_button_group("Skeleton", ("Run", "Cancel"))
        self.buttons.on_click(self._run_clicked)
        self.progress = gui.add_progress_bar(0.0, animated=False)
        with gui.add_folder("Display"):
            self.show_cloud = gui.add_checkbox("Cloud", initial_value=True)
            self.show_skeleton = gui.add_checkbox("Skeleton (by order)", initial_value=True)
            self.show_tubes = gui.add_checkbox("Tubes (by radius)", initial_value=True)
            self.max_display = gui.add_slider(
                "Cloud points shown", min=5000, max=200000, step=5000, initial_value=50000
            )
            for h in (self.show_cloud, self.show_skeleton, self.show_tubes):
                h.on_update(self.action("display", self.update_visibility))
            self.max_display.on_update(self.live("display points", self.draw_cloud))
        self.legend_md = gui.add_markdown("")
        self.metrics_md = gui.add_markdown("")
        self.exports = ExportRow(
            self,
            lambda: f"{self.cloud_name}_skeleton",
            {"PLY": self._write_ply, "GLB": self._write_glb, "CSV": self._write_csv},
            contents={
                "PLY": "skeleton graph: nodes (x y z radius, parent, order), "
                "in the cloud's own coordinates",
                "GLB": "tube mesh of the branches (Z up, metres)",
                "CSV": "QSM cylinder table: one cylinder per edge with radius, "
                "length, branch and order",
            },
        )

    def restore(self) -> None:
        """Redraw the cloud and the skeleton after a page reload."""
        if self.result is not None:
            self.draw_result()
        elif self.cloud is not None:
            self.draw_cloud()

    # ------------------------------------------------------------------ cloud
    def load(self, path: Path) -> None:
        """Open a cloud from the data folder."""
        from biomorph import io

        cloud = io.read_points(path)
        if cloud.n_points < 10:
            raise InputError(f"{path.name}: {cloud.n_points} points; expected a tree scan")
        self.set_cloud(cloud, path.stem)
        self.truth = None
        self.set_status(f"Opened {plain(self.app.sandbox.relative(path))}.")

    def synthesise(self) -> None:
        """Grow a synthetic tree (preset, seed) and simulate a LiDAR scan of it."""
        from biomorph.tree.synthetic import generate_tree, simulate_scan

        seed, preset = int(self.seed.value), self.preset.value
        self.progress.value, self.progress.animated = 5.0, True
        try:
            self.set_status(f"Growing a synthetic {plain(preset)} (1/2) …")
            truth = generate_tree(preset, seed=seed)
            self.progress.value = 50.0
            self.set_status(f"Scanning it with {int(self.n_points.value):,} points (2/2) …")
            cloud = simulate_scan(truth, n_points=int(self.n_points.value), seed=seed)
        finally:
            self.progress.animated = False
        self.set_cloud(cloud, f"{preset}_{seed}")
        self.truth = truth
        self.progress.value = 100.0
        self.set_status(
            f"Synthetic {plain(preset)} (seed {seed}): "
            f"{truth.n_nodes} true nodes, {len(truth.leaves)} tips. Press Run."
        )

    def set_cloud(self, cloud: Any, name: str) -> None:
        """Use ``cloud`` from now on; a run on the previous cloud is cancelled and its
        result dropped (never drawn or exported under the new name)."""
        self.cloud, self.cloud_name = cloud, name
        self._drop_result()
        lo, hi = cloud.bounds()
        self.cloud_info.content = (
            f"**{cloud.n_points:,} points**, extent {np.round(hi - lo, 2).tolist()} m"
        )
        self.draw_cloud()

    def _drop_result(self) -> None:
        """Cancel a run and drop the last result (its skeleton, tubes, legend and
        figures): it no longer belongs to the cloud as set up."""
        self.generation += 1
        if self.job is not None and self.job.is_alive():
            self._cancel.set()
        self.result = None
        self.legend_md.content = ""
        for node in ("skeleton", "tubes"):
            self.scene.remove_by_name(f"{self.root}/{node}")
        self._skeleton_node = None
        self._tubes, self._tube_handles = [], []
        self.metrics_md.content = ""
        self.progress.value = 0.0

    def up_changed(self) -> None:
        """The cloud's up axis changed: a skeleton run with the other axis (or running)
        is dropped -- it lies in the other frame -- and the cloud is redrawn turned."""
        if self.cloud is None:
            return
        running = self.job is not None and self.job.is_alive()
        stale = self.result is not None and self.result.params.get("up", "z") != self.up.value
        if running or stale:
            self._drop_result()
            self.set_status(
                f"Cloud up axis {self.up.value}: the last skeleton was dropped. Press Run."
            )
        self.draw_cloud()

    def _display_xyz(self) -> np.ndarray:
        """Cloud coordinates as drawn: bottom centre of the bounding box at the origin."""
        from biomorph.tree.cloud import to_z_up

        xyz = to_z_up(self.cloud, self.up.value).xyz
        lo, hi = xyz.min(axis=0), xyz.max(axis=0)
        return xyz - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])

    def draw_cloud(self) -> None:
        if self.cloud is None:
            return
        if self.result is not None and self.result.cloud is not None:
            xyz = self.result.cloud.xyz  # prepared cloud: same frame as the skeleton
        else:
            xyz = self._display_xyz()
        shown, _ = draw.subsample(xyz, int(self.max_display.value))
        centre, size = draw.fit_camera(shown)
        self._cloud_node = self.scene.add_point_cloud(
            f"{self.root}/cloud",
            shown.astype(np.float32),
            draw.height_colors(shown),
            point_size=size / 500,
            point_shape="circle",
            visible=self.show_cloud.value,
        )
        self.app.focus(self.key, centre, size)
        self.redrawn()

    # ------------------------------------------------------------------ running
    def _run_clicked(self, event: Any) -> None:
        if event.target.value == "Cancel":
            self.cancel()
        else:
            self.run("run", self.start, timed=False)

    def start(self) -> None:
        """Start skeletonising the current cloud in a background thread."""
        if self.cloud is None:
            raise InputError("no cloud: open or synthesise one first")
        if self.job is not None and self.job.is_alive():
            self._cancel.set()  # a new run replaces the running one (never mixes them)
        opts = self.options()
        release = self.app.job_slot()
        self._cancel = threading.Event()  # a fresh event: an old job keeps its own
        self.ticks = []
        self._phase = 0
        self.progress.value = 2.0
        self.progress.animated = True
        self.set_status(f"Running the {opts.method} method …")
        self.job = threading.Thread(
            target=self._work,
            daemon=True,
            name="studio-tree-job",
            args=(self.cloud, opts, self.generation, self._cancel, release, int(self.models.value)),
        )
        self.job.start()

    def cancel(self) -> None:
        """Ask the running job to stop at its next progress step."""
        if self.job is not None and self.job.is_alive():
            self._cancel.set()
            self.set_status("Cancelling at the next step …")

    def options(self) -> Any:
        """:class:`biomorph.tree.options.SkeletonizeOptions` from the controls (the same
        typed options the Python API, the CLI and ``tree batch`` use)."""
        from biomorph.tree.options import (
            CleanupOptions,
            GraphOptions,
            PrepareOptions,
            RadiusOptions,
            SkeletonizeOptions,
            VoxelOptions,
        )

        spacing = float(self.node_spacing.value)
        return SkeletonizeOptions(
            method=self.method.value,
            seed=int(self.seed.value),
            graph=GraphOptions(
                k=int(self.k.value),
                max_iter=int(self.max_iter.value),
                node_spacing=spacing if spacing > 0 else None,
            ),
            voxel=VoxelOptions(cell_size=float(self.cell.value)),
            cleanup=CleanupOptions(enabled=bool(self.cleanup.value)),
            radius=RadiusOptions(method=self.radius.value),
            # metres: checked (tree.cloud.check_units); other units converted to metres
            prepare=PrepareOptions(
                units=None if self.units.value == "m" else self.units.value,
                up=None if self.up.value == "z" else self.up.value,
            ),
        )

    def _progress(self, cancel: threading.Event) -> Any:
        """The pipeline's progress callback: one step of the bar per finished phase of
        :data:`biomorph.tree.pipeline.PHASES` (``n = 1``); the skeleton method's own
        sub-phases (``n = 0``) move the bar within the skeleton phase (each halves the
        distance to its end). With several models each spans 1/n of the bar."""
        from biomorph.tree.models import model_step
        from biomorph.tree.pipeline import PHASES

        n = len(PHASES)
        state = {"model": 1, "value": 0.0}  # value: % of the current model

        def advance(step: float = 1, description: str | None = None) -> None:
            if cancel.is_set():
                raise Cancelled("skeletonisation cancelled")
            i, of, description = model_step(description)
            if i != state["model"]:  # a new model: its phases count from 0 again
                self._phase = 0
                self.ticks = []
                state.update(model=i, value=0.0)
            self.ticks.append(description or "")
            if step > 0:
                self._phase = min(self._phase + 1, n)
                value = 100.0 * self._phase / n
            else:  # a sub-phase of the skeleton method
                value = state["value"] + (100.0 * 2 / n - state["value"]) / 2
            state["value"] = value
            self.progress.value = min(99.0, (i - 1 + value / 100.0) / of * 100.0)
            label = PHASES[self._phase - 1] if step > 0 else description
            which = f"model {i}/{of} " if of > 1 else ""
            self.set_status(f"Running {which}… {plain(label)} ({self._phase}/{n} phases done)")

        return advance

    def _work(
        self,
        cloud: Any,
        opts: Any,
        generation: int,
        cancel: threading.Event,
        release: Any,
        models: int = 1,
    ) -> None:
        from biomorph.tree.pipeline import skeletonize

        t0 = time.perf_counter()
        try:
            if models > 1:
                from biomorph.tree.models import reconstruct_models

                result = reconstruct_models(
                    cloud, models, options=opts, progress=self._progress(cancel)
                ).skeleton
            else:
                result = skeletonize(cloud, options=opts, progress=self._progress(cancel))
            with self.lock:
                if cancel.is_set() or generation != self.generation:
                    raise Cancelled("skeletonisation cancelled")
                self.result = result
                self.draw_result()
                self.progress.value = 100.0
                self.set_status(
                    f"Done in {time.perf_counter() - t0:.1f} s ({result.graph.n_nodes} nodes)."
                )
                self.last_error = None
        except Cancelled:
            if generation == self.generation:
                self.progress.value = 0.0
                self.set_status("Cancelled; the previous result is kept.")
                self.app.notify("Tree", "skeletonisation cancelled", color="yellow")
        except Exception as exc:  # noqa: BLE001 - shown in the page
            # under the tab's lock: a job failing at once (a cloud in other units) must not
            # report before the Run action that started it has finished (which clears
            # the tab's last error)
            with self.lock:
                if generation == self.generation:
                    self.progress.value = 0.0
                    self.fail(exc, "skeletonisation")
        finally:
            release()
            if generation == self.generation:
                self.progress.animated = False

    # ------------------------------------------------------------------ drawing
    def draw_result(self) -> None:
        skel = self.result
        g = skel.graph
        self.draw_cloud()
        seg, child = draw.graph_segments(g.position, g.parent)
        depth = g.depth if g.depth is not None else np.zeros(g.n_nodes, np.int64)
        colors = np.repeat(draw.palette(depth[child])[:, None, :], 2, axis=1)
        _, size = draw.fit_camera(g.position)
        self._skeleton_node = self.scene.add_line_segments(
            f"{self.root}/skeleton",
            seg.astype(np.float32),
            colors,
            thickness=max(size / 400, 0.004),
            visible=self.show_skeleton.value,
        )
        self._tubes = self.tube_parts()
        self.draw_tubes()
        legend = draw.order_legend(depth[child]) + " (skeleton lines)"
        if self._tubes:
            legend += "\n\n" + draw.radius_legend(*self._tube_range)
        self.legend_md.content = legend
        self.metrics_md.content = self.metrics_table()
        _, size = draw.fit_camera(g.position)
        centre = (g.position.min(axis=0) + g.position.max(axis=0)) / 2
        self.app.focus(self.key, centre, size)
        self.redrawn()

    def tube_parts(self) -> list[tuple[np.ndarray, np.ndarray, tuple[int, int, int]]]:
        """The tube mesh split into :data:`RADIUS_BINS` parts by branch radius (log
        bins), each with its colour of :func:`draw.radius_colors`."""
        from scipy.spatial import cKDTree

        from biomorph.tree.export import tube_mesh

        g = self.result.graph
        if g.radius is None or g.n_nodes < 2:
            return []
        mesh = tube_mesh(g)
        lo, hi = self._tube_range = draw.radius_scale(g.radius)
        # every tube ring is centred on its node: a vertex's nearest node gives its radius
        _, node = cKDTree(g.position).query(mesh.vertices)
        face_r = np.asarray(g.radius)[node][mesh.faces].mean(axis=1)
        edges = np.geomspace(lo, hi, RADIUS_BINS + 1)
        which = np.clip(np.searchsorted(edges, face_r) - 1, 0, RADIUS_BINS - 1)
        parts = []
        for b in range(RADIUS_BINS):
            faces = mesh.faces[which == b]
            if len(faces) == 0:
                continue
            used, inv = np.unique(faces, return_inverse=True)
            mid = float(np.sqrt(edges[b] * edges[b + 1]))
            colour = tuple(int(c) for c in draw.radius_colors(np.array([mid]), lo, hi)[0])
            parts.append(
                (
                    mesh.vertices[used].astype(np.float32),
                    inv.reshape(-1, 3).astype(np.int32),
                    colour,
                )
            )
        return parts

    def draw_tubes(self) -> None:
        """Shaded tubes, coloured by radius (legend in the tab)."""
        self.scene.remove_by_name(f"{self.root}/tubes")
        self._tube_handles = [
            self.scene.add_mesh_simple(
                f"{self.root}/tubes/r{i}", verts, faces, color=colour, visible=self.show_tubes.value
            )
            for i, (verts, faces, colour) in enumerate(self._tubes)
        ]

    def update_visibility(self) -> None:
        for handle, box in (
            (self._cloud_node, self.show_cloud),
            (self._skeleton_node, self.show_skeleton),
        ):
            if handle is not None:
                handle.visible = box.value
        for handle in self._tube_handles:
            handle.visible = self.show_tubes.value
        self.redrawn()

    def metrics_table(self) -> str:
        m, t = self.result.metrics, self.result.timings

        def fmt(v: Any) -> str:
            if isinstance(v, float):
                return f"{v:.4g}"
            if isinstance(v, list):
                return ", ".join(fmt(x) for x in v[:4]) + (" …" if len(v) > 4 else "")
            return str(v)

        from biomorph.tree.metrics import scan_rows, summary_rows
        from biomorph.tree.models import summary_rows as models_summary_rows

        rows = [
            ("method", self.result.method),
            ("nodes", m.get("n_nodes")),
            ("trees", m.get("n_trees")),
            ("NOB (tips)", m.get("nob")),
            ("TBL (m)", m.get("tbl")),
            ("MSE (m²)", m.get("mse")),
            ("DBH (m)", m.get("dbh")),
            ("trunk radius (m)", m.get("trunk_radius")),
            ("max order", m.get("max_order")),
            *summary_rows(m),
            *models_summary_rows(self.result.info.get("models")),
            *scan_rows(self.result.params, self.result.info),
            ("time (s)", t.get("total")),
        ]
        if self.truth is not None:
            rows += [
                ("true NOB", len(self.truth.leaves)),
                ("true TBL (m)", self.truth.total_length),
            ]
        return "| metric | value |\n|---|---|\n" + "\n".join(
            f"| {k} | {fmt(v)} |" for k, v in rows if v is not None
        )

    # ------------------------------------------------------------------ export
    def _need_result(self) -> Any:
        if self.result is None:
            raise InputError("nothing to export: run the skeletonisation first")
        return self.result

    def _write_ply(self, path: Path) -> None:
        from biomorph import io

        io.write_graph(path, self._need_result().world_graph())

    def _write_glb(self, path: Path) -> None:
        from biomorph import io
        from biomorph.tree.export import tube_mesh

        io.write_gltf(path, tube_mesh(self._need_result().graph), y_up=False)

    def _write_csv(self, path: Path) -> None:
        from biomorph.tree.export import write_cylinders

        skel = self._need_result()
        write_cylinders(path, skel.world_graph(), skel.segment)

    def close(self) -> None:
        self._cancel.set()
