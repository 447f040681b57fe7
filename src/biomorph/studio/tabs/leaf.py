"""Leaf tab: preset and shape parameters, growth (age), a plastic operator, level of detail,
a small canopy, export OBJ/GLB — all through :mod:`biomorph.leaf`."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.studio.base import StudioTab, plain
from biomorph.studio.widgets import ExportRow, FilePicker

LEAF_GREEN = (70, 150, 60)
N_POINTS = 200  # discretisation the reduction starts from


class LeafTab(StudioTab):
    """A grass leaf you can grow, bend and reduce."""

    key = "leaf"
    label = "Leaf"
    getting_started = (
        "Getting started: pick a preset, then move Age to grow the leaf, "
        "the operator to bend it and Triangles to reduce it."
    )

    def __init__(self, app: Any) -> None:
        super().__init__(app)
        self.shape: Any = None
        self.mesh: Any = None
        self.triangles = 0
        self.error = (0.0, 0.0)
        self._animating = threading.Event()
        self._closing = threading.Event()

    def requirement(self) -> str | None:
        try:
            from biomorph.leaf.plastic import apply_ops  # noqa: F401
            from biomorph.leaf.reduction import reduce_leaf, reduced_mesh  # noqa: F401
            from biomorph.leaf.shape import LeafShape, load_presets  # noqa: F401
        except ImportError as exc:
            return f"the leaf pillar cannot be imported ({exc})"
        return None

    # ------------------------------------------------------------------ GUI
    def build(self) -> None:
        from biomorph.leaf.shape import LeafShape, load_presets

        gui = self.gui
        presets = tuple(sorted(load_presets()))
        first = "maize" if "maize" in presets else presets[0]
        self.preset = gui.add_dropdown("Preset", options=presets, initial_value=first)
        self.custom: Any = None  # a shape uploaded/opened as JSON replaces the preset
        self.shape_picker = FilePicker(
            self,
            "Shape JSON",
            (".json",),
            self.open_shape,
            upload_label="Upload leaf shape (.json)",
        )
        base = LeafShape.from_preset(first)
        with gui.add_folder("Shape"):
            self.length = gui.add_slider(
                "Length (m)", min=0.05, max=1.5, step=0.01, initial_value=round(base.length, 2)
            )
            self.width = gui.add_slider(
                "Width (cm)", min=0.2, max=15.0, step=0.1, initial_value=round(base.width * 100, 1)
            )
            self.twist = gui.add_slider(
                "Twist (deg)",
                min=-180.0,
                max=180.0,
                step=1.0,
                initial_value=round(float(np.degrees(base.twist))),
            )
            self.undulation = gui.add_slider(
                "Undulation (mm)",
                min=0.0,
                max=15.0,
                step=0.5,
                initial_value=round(base.undulation * 1000, 1),
            )
        with gui.add_folder("Growth"):
            self.age = gui.add_slider(
                "Age",
                min=0.02,
                max=1.0,
                step=0.01,
                initial_value=1.0,
                hint="Physiological age: 0 emerging, 1 mature.",
            )
            gui.add_button("Animate growth").on_click(
                self.action("animate", self.animate, timed=False)
            )
        with gui.add_folder("Plastic operator"):
            self.op_kind = gui.add_dropdown(
                "Operator",
                options=("none", "bend", "curvature", "scale_width"),
                initial_value="none",
            )
            self.op_range = gui.add_multi_slider(
                "Interval s", min=0.0, max=1.0, step=0.01, initial_value=(0.4, 0.8)
            )
            self.op_value = gui.add_slider(
                "Strength",
                min=-2.0,
                max=3.0,
                step=0.05,
                initial_value=0.6,
                hint="bend: radians; curvature / scale_width: factor (>= 0).",
            )
        with gui.add_folder("Level of detail"):
            self.lod = gui.add_slider("Triangles", min=2, max=400, step=1, initial_value=120)
            self.lod_info = gui.add_markdown("")
        self.canopy = gui.add_checkbox("Small canopy (3 x 3 plants)", initial_value=False)
        self.exports = ExportRow(
            self,
            lambda: f"leaf_{self.preset.value}",
            {"OBJ": self._write_obj, "GLB": self._write_glb},
            contents={
                "OBJ": "the leaf (or canopy) mesh as drawn: vertices and triangles, Z up, metres",
                "GLB": "the same mesh as binary glTF (Z up kept, metres)",
            },
        )
        self.latency_md = gui.add_markdown("")

        self.preset.on_update(self.action("preset", self.load_preset))
        for h in (self.length, self.width, self.twist, self.undulation):
            h.on_update(self.live("shape", self.redraw))
        self.age.on_update(self.live("age", self.redraw))
        for h in (self.op_kind, self.op_range, self.op_value):
            h.on_update(self.live("plastic", self.redraw))
        self.lod.on_update(self.live("lod", self.redraw))
        self.canopy.on_update(self.action("canopy", self.redraw))
        self.run("initial", self.redraw, timed=False, show=False)

    def restore(self) -> None:
        """Nothing to restore beyond the controls: :meth:`build` redrew from them."""

    # ------------------------------------------------------------------ model
    def current_shape(self) -> Any:
        """The preset with the slider values and the plastic operator applied."""
        from biomorph.leaf.plastic import PlasticOp, apply_ops
        from biomorph.leaf.shape import LeafShape

        base = self.custom if self.custom is not None else LeafShape.from_preset(self.preset.value)
        shape = base.with_(
            length=float(self.length.value),
            width=float(self.width.value) / 100.0,
            twist=float(np.radians(self.twist.value)),
            undulation=float(self.undulation.value) / 1000.0,
        )
        if self.op_kind.value != "none":
            s0, s1 = (float(v) for v in self.op_range.value)
            shape = apply_ops(
                shape, [PlasticOp(self.op_kind.value, s0, s1, float(self.op_value.value))]
            )
        return shape

    def open_shape(self, path: Path) -> None:
        """Use a leaf shape stored as JSON (the preset format: ``s``, ``phi``, ``s_r``, ``r``,
        ``length``, ``width``; optional ``twist_deg``, ``undulation``, ``wavelength``)."""
        import json

        from biomorph.errors import FormatError
        from biomorph.leaf.shape import LeafShape

        try:
            data = json.loads(path.read_text("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise FormatError(path, f"not a JSON leaf shape ({exc})") from None
        need = ("s", "phi", "s_r", "r", "length", "width")
        if not isinstance(data, dict) or any(k not in data for k in need):
            raise FormatError(path, f"a leaf shape needs the keys {', '.join(need)}")
        try:
            shape = LeafShape(
                np.asarray(data["s"], float),
                np.asarray(data["phi"], float),
                np.asarray(data["s_r"], float),
                np.asarray(data["r"], float),
                float(data["length"]),
                float(data["width"]),
                twist=float(np.radians(data.get("twist_deg", 0.0))),
                undulation=float(data.get("undulation", 0.0)),
                wavelength=float(data.get("wavelength", 0.05)),
                name=path.stem,
            )
        except (TypeError, ValueError) as exc:
            raise FormatError(path, f"leaf shape values are not numbers ({exc})") from None
        self.custom = None
        self._set_sliders(shape)
        self.custom = shape
        self.redraw()
        self.set_status(f"Leaf shape {plain(path.name)} in use (choose a preset to go back).")

    def load_preset(self) -> None:
        """Put the preset's own values on the sliders, then redraw."""
        from biomorph.leaf.shape import LeafShape

        self.custom = None
        self._set_sliders(LeafShape.from_preset(self.preset.value))
        self.redraw()

    def _set_sliders(self, base: Any) -> None:
        self.length.value = round(base.length, 2)
        self.width.value = round(base.width * 100, 1)
        self.twist.value = round(float(np.degrees(base.twist)))
        self.undulation.value = round(base.undulation * 1000, 1)

    def build_mesh(self) -> Any:
        """Leaf (or canopy) mesh at the current age and triangle budget; sets the LOD info."""
        from biomorph.leaf.reduction import reduce_leaf, reduced_mesh

        self.shape = shape = self.current_shape()
        age = float(self.age.value)
        red = reduce_leaf(shape, n_points=N_POINTS, age=age)
        lo, hi = red.min_triangles, red.full_triangles
        if self.lod.max != hi:
            self.lod.max = hi
        tri = int(np.clip(int(self.lod.value), max(lo, 1), hi))
        kept = red.kept(red.removed_for_budget(tri))
        self.error = red.error(kept)
        leaf = reduced_mesh(shape, tri, age=age, reduction=red)
        self.triangles = int(leaf.n_faces)
        self.lod_info.content = (
            f"**{self.triangles} triangles** (full {hi}); error: midrib "
            f"{self.error[0] * shape.length * 1000:.3f} mm, width "
            f"{self.error[1] * shape.length * 1000:.3f} mm ({self.error[0] * 100:.3f} % / "
            f"{self.error[1] * 100:.3f} % of the length)"
        )
        if not self.canopy.value:
            return leaf
        return self._canopy(shape, age, tri)

    def _canopy(self, shape: Any, age: float, triangles: int) -> Any:
        """A small field (3 rows x 3 plants) from :mod:`biomorph.leaf.canopy`."""
        from biomorph.leaf.canopy import FieldSpec, PlantSpec, build_field, field_mesh

        overrides = {
            "length": shape.length,
            "width": shape.width,
            "twist": shape.twist,
            "undulation": shape.undulation,
            "s": shape.s,
            "phi": shape.phi,
            "s_r": shape.s_r,
            "r": shape.r,
        }
        spec = FieldSpec(
            plants=9,
            rows=3,
            row_spacing=max(0.15, shape.length * 0.6),
            plant=PlantSpec(preset=self.preset.value, leaves=6, age=age, shape_overrides=overrides),
        )
        fld = build_field(spec, seed=0)
        mesh = field_mesh(fld, triangles_per_leaf=max(1, min(triangles, 60)))
        self.lod_info.content += f"; canopy: {mesh.n_faces:,} triangles"
        return mesh

    # ------------------------------------------------------------------ drawing
    def redraw(self) -> None:
        self.mesh = mesh = self.build_mesh()
        self.scene.add_mesh_simple(
            f"{self.root}/mesh",
            np.asarray(mesh.vertices, np.float32),
            np.asarray(mesh.faces, np.int32),
            color=LEAF_GREEN,
            side="double",
            flat_shading=False,
        )
        # the midrib line of the surface at this age (u = 0), so it grows with the leaf
        mid = (
            self.shape.surface(np.linspace(0.0, 1.0, 101), [0.0], age=float(self.age.value))[:, 0]
            if not self.canopy.value
            else np.zeros((2, 3))
        )
        seg = np.stack([mid[:-1], mid[1:]], axis=1).astype(np.float32)
        self.scene.add_line_segments(
            f"{self.root}/midrib",
            seg,
            (200, 40, 40),
            thickness=0.002,
            visible=not self.canopy.value,
        )
        lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
        self.app.focus(self.key, (lo + hi) / 2, float(np.linalg.norm(hi - lo)))
        self.latency_md.content = "Edit → redraw (server side):\n\n" + self.app.latency.markdown(
            "leaf/"
        )
        self.redrawn()

    def animate(self) -> None:
        """Play the growth from age 0.05 to the slider's age in a background thread."""
        if self._animating.is_set():
            return
        target = float(self.age.value)
        self._animating.set()

        def loop() -> None:
            try:
                for a in np.linspace(0.05, max(target, 0.06), 30):
                    if self._closing.is_set():
                        return
                    self.age.value = round(float(a), 3)  # triggers a redraw
                    time.sleep(0.05)
            finally:
                self._animating.clear()

        threading.Thread(target=loop, daemon=True, name="studio-leaf-growth").start()

    def close(self) -> None:
        self._closing.set()

    # ------------------------------------------------------------------ export
    def _write_obj(self, path: Path) -> None:
        from biomorph import io

        io.write_mesh(path, self.mesh)

    def _write_glb(self, path: Path) -> None:
        from biomorph import io

        io.write_gltf(path, self.mesh, y_up=False)
