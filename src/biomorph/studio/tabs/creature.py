"""Creature tab: the generator's parameters, its steps as buttons (next, undo, re-roll a
part, change a limb type, neck/tail edits), the skeleton with centre of mass, support
polygon and stability margin, and export GLB / BVH / OSIM — over :mod:`biomorph.creature`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

import biomorph.studio.draw as draw
from biomorph.errors import InputError
from biomorph.studio.base import StudioTab, plain
from biomorph.studio.widgets import ExportRow

AUTO = "auto"
#: PCA components with a score slider (PC1 … PC6); 0 on a slider = sampled.
N_PC_SLIDERS = 6
LIMB_KINDS = ("leg", "arm", "wing", "fin")
#: Bone colour of each kind (palette index = position in LIMB_KINDS + 1, body 0, + 4).
KIND_COLOURS = {
    kind: draw.hex_colour(draw.palette(np.array([i + 4]))[0])
    for i, kind in enumerate(("body", *LIMB_KINDS))
}
STABLE, UNSTABLE, SUPPORT = (30, 160, 60), (220, 40, 40), (240, 150, 20)
LEGEND = (
    "Bones by kind: "
    + ", ".join(f"{k} `{c}`" for k, c in KIND_COLOURS.items())
    + f"; centre of mass `{draw.hex_colour(STABLE)}` stable / "
    f"`{draw.hex_colour(UNSTABLE)}` tips over; support polygon "
    f"`{draw.hex_colour(SUPPORT)}` (sizes in metres)."
)


class CreatureTab(StudioTab):
    """Procedural vertebrates, step by step."""

    key = "creature"
    label = "Creature"
    getting_started = (
        "Getting started: change the seed or any parameter and the animal is "
        "generated again; Next step rebuilds it step by step."
    )
    y_up = True

    def __init__(self, app: Any) -> None:
        super().__init__(app)
        self.generator: Any = None
        self.creature: Any = None

    def requirement(self) -> str | None:
        try:
            from biomorph.creature import STEPS, Generator, Options, export  # noqa: F401
        except ImportError as exc:
            return f"the creature pillar cannot be imported ({exc})"
        return None

    # ------------------------------------------------------------------ GUI
    def build(self) -> None:
        from biomorph.creature import STEPS
        from biomorph.creature.generator import CLASSES, LEG_COUNTS

        gui = self.gui
        with gui.add_folder("Parameters"):
            self.seed = gui.add_number("Seed", initial_value=7, min=0, max=2**31 - 1, step=1)
            self.cls = gui.add_dropdown("Class", options=(AUTO, *CLASSES), initial_value=AUTO)
            self.legs = gui.add_dropdown(
                "Legs", options=(AUTO, *map(str, LEG_COUNTS)), initial_value="4"
            )
            self.wings = gui.add_dropdown("Wings", options=(AUTO, "yes", "no"), initial_value="no")
            self.arms = gui.add_checkbox("Arms", initial_value=False)
            self.centaur = gui.add_checkbox("Centaur girdle", initial_value=False)
            self.weight = gui.add_number(
                "Weight kg (0 = sample)",
                initial_value=0.0,
                min=0.0,
                max=200000.0,
                step=1.0,
                hint="Body mass in kg, up to a blue whale (2e5).",
            )
            self.neck = gui.add_slider(
                "Neck length (-0.1 = sample)",
                min=-0.1,
                max=1.5,
                step=0.01,
                initial_value=-0.1,
                hint="Neck chord in frame units (1 = the largest "
                "extent); below 0 the neck is sampled.",
            )
            self.tail = gui.add_slider(
                "Tail length (-0.1 = sample)", min=-0.1, max=1.5, step=0.01, initial_value=-0.1
            )
            self.k = gui.add_slider(
                "PCA components",
                min=1,
                max=29,
                step=1,
                initial_value=29,
                hint="Sample from the top k principal components.",
            )
            self.temperature = gui.add_slider(
                "PCA temperature",
                min=0.0,
                max=2.0,
                step=0.05,
                initial_value=1.0,
                hint="Variance scale of the PCA sample (0 = the mean animal).",
            )
            self.pcs = tuple(
                gui.add_slider(
                    f"PC{i + 1} score (0 = sampled)",
                    min=-3.0,
                    max=3.0,
                    step=0.1,
                    initial_value=0.0,
                    hint=f"Fix principal component {i + 1} at this many standard "
                    "deviations; 0 leaves it sampled.",
                )
                for i in range(N_PC_SLIDERS)
            )
            params = (
                self.seed,
                self.cls,
                self.legs,
                self.wings,
                self.arms,
                self.centaur,
                self.weight,
                self.neck,
                self.tail,
                self.k,
                self.temperature,
                *self.pcs,
            )
            for h in params:
                h.on_update(self.live("parameters", self.generate))
        self.steps = gui.add_button_group("Steps", ("Next step", "Undo", "All steps"))
        self.steps.on_click(self._step_clicked)
        with gui.add_folder("Edit a part"):
            self.reroll_step = gui.add_dropdown("Part", options=STEPS, initial_value="limbs")
            gui.add_button("Re-roll this part").on_click(self.action("re-roll", self.reroll))
            self.limb_slot = gui.add_dropdown("Limb pair", options=("(generate first)",))
            self.limb_kind = gui.add_dropdown("Limb type", options=LIMB_KINDS, initial_value="arm")
            self.limb_buttons = gui.add_button_group("", ("Change limb type", "Add limb pair"))
            self.limb_buttons.on_click(self._limb_clicked)
            self.neck_factor = gui.add_slider(
                "Scale neck / tail by", min=0.25, max=3.0, step=0.05, initial_value=1.5
            )
            self.part_buttons = gui.add_button_group("", ("Scale neck", "Scale tail"))
            self.part_buttons.on_click(self._part_clicked)
        self.bone_models = gui.add_checkbox(
            "Bone models (shaded)",
            initial_value=False,
            hint="Draw the procedural bone models (creature.bones, lowest LOD) coloured by "
            "limb kind; adds about 0.1-0.2 s to every edit.",
        )
        self.bone_models.on_update(self.action("bone models", self.redraw))
        self.info = gui.add_markdown("")
        self.exports = ExportRow(
            self,
            lambda: f"creature_{int(self.seed.value)}",
            {
                "GLB": self._writer(".glb"),
                "BVH": self._writer(".bvh"),
                "OSIM": self._writer(".osim"),
            },
            contents={
                "GLB": "skinned bone meshes with the skeleton (Y up, metres)",
                "BVH": "the skeleton's hierarchy and rest pose (one frame)",
                "OSIM": "OpenSim model: bodies with masses and inertias, joints",
            },
        )
        self.latency_md = gui.add_markdown("")
        if self.generator is None:
            self.run("initial", self.generate, timed=False, show=False)

    def restore(self) -> None:
        """Redraw the generator's state after a page reload."""
        if self.generator is not None:
            self.redraw()

    # ------------------------------------------------------------------ generator
    def options(self) -> Any:
        """:class:`biomorph.creature.Options` from the controls (validated by the pillar)."""
        from biomorph.creature import Options

        def opt(v: str) -> Any:
            return None if v == AUTO else v

        wings = {"yes": True, "no": False}.get(self.wings.value)
        legs = opt(self.legs.value)
        scores = {i: float(h.value) for i, h in enumerate(self.pcs) if float(h.value) != 0.0}
        return Options(
            seed=int(self.seed.value),
            cls=opt(self.cls.value),
            legs=None if legs is None else int(legs),
            wings=wings,
            arms=bool(self.arms.value),
            centaur=bool(self.centaur.value),
            weight=float(self.weight.value) or None,
            neck_length=None if self.neck.value < 0 else float(self.neck.value),
            tail_length=None if self.tail.value < 0 else float(self.tail.value),
            k=None if int(self.k.value) >= 29 else int(self.k.value),
            temperature=float(self.temperature.value),
            scores=scores or None,
        ).validate()

    def generate(self) -> None:
        """A new generator from the parameters, run to the end, drawn."""
        from biomorph.creature import Generator

        gen = Generator(self.options())
        gen.run()
        self.generator = gen
        self.redraw()

    def _gen(self) -> Any:
        if self.generator is None:
            raise InputError("no creature yet: set the parameters first")
        return self.generator

    def _step_clicked(self, event: Any) -> None:
        which = event.target.value
        if which == "Next step":
            self.run("next step", self.next_step)
        elif which == "Undo":
            self.run("undo", self.undo)
        else:
            self.run("all steps", self.all_steps)

    def next_step(self) -> None:
        """Run one more step; after the last one, start again from the spine."""
        gen = self._gen()
        if gen.next_step is None:  # finished: begin a stepwise rebuild with these options
            from biomorph.creature import Generator

            gen = self.generator = Generator(gen.options)
        gen.step()
        self.redraw()

    def undo(self) -> None:
        self._gen().undo()
        self.redraw()

    def all_steps(self) -> None:
        self._gen().run()
        self.redraw()

    def reroll(self) -> None:
        self._gen().reroll(self.reroll_step.value)
        self.redraw()

    def _limb_clicked(self, event: Any) -> None:
        if event.target.value == "Add limb pair":
            self.run("add limb pair", self.add_limb_pair)
        else:
            self.run("change limb type", self.change_limb)

    def _slot(self) -> tuple[str, int]:
        girdle, _, pair = self.limb_slot.value.rpartition(" ")
        if not girdle or not pair.isdigit():
            raise InputError("no limb pair chosen: run the girdles step first")
        return girdle, int(pair) - 1

    def change_limb(self) -> None:
        """Give the chosen limb pair another type (rules re-run the later steps)."""
        girdle, pair = self._slot()
        self._gen().set_limb(girdle, pair, self.limb_kind.value)
        self.redraw()

    def add_limb_pair(self) -> None:
        girdle, _ = self._slot()
        self._gen().add_limb_pair(girdle, self.limb_kind.value)
        self.redraw()

    def _part_clicked(self, event: Any) -> None:
        part = "neck" if event.target.value == "Scale neck" else "tail"
        self.run(f"scale {part}", lambda: self.scale_part(part))

    def scale_part(self, part: str) -> None:
        gen = self._gen()
        factor = float(self.neck_factor.value)
        (gen.set_neck_length if part == "neck" else gen.set_tail_length)(factor)
        self.redraw()

    # ------------------------------------------------------------------ drawing
    def redraw(self) -> None:
        """Draw whatever the generator has: the finished creature or the spine so far."""
        gen = self._gen()
        self._update_slots()
        for node in ("bones", "joints", "com", "com_line", "support", "spine", "models"):
            self.scene.remove_by_name(f"{self.root}/{node}")
        done = gen.done
        if "finish" in done:
            self.creature = gen.creature
            self._draw_creature(self.creature)
        else:
            self.creature = None
            if "spine" in done:
                self._draw_spine(gen.state("spine"))
        nxt = gen.next_step
        self.info.content = self._describe(done, nxt) + "\n\n" + LEGEND
        self.latency_md.content = "Edit → redraw (server side):\n\n" + self.app.latency.markdown(
            "creature/"
        )
        self.redrawn()

    def _update_slots(self) -> None:
        gen = self.generator
        slots: list[str] = []
        if gen is not None and "girdles" in gen.done:
            for g in gen.state("girdles"):
                slots += [f"{g.name} {i + 1}" for i in range(len(g.pairs))]
                if not g.pairs:
                    slots.append(f"{g.name} 1")
        options = tuple(slots) or ("(generate first)",)
        if tuple(self.limb_slot.options) != options:
            self.limb_slot.options = options

    def _draw_creature(self, c: Any) -> None:
        p = c.joint_positions.astype(np.float32)
        ends = c.bone_ends.astype(np.float32)
        seg = np.stack([p, ends], axis=1)
        kinds = np.array([LIMB_KINDS.index(k) + 1 if k in LIMB_KINDS else 0 for k in c.kind])
        colors = np.repeat(draw.palette(kinds + 4)[:, None, :], 2, axis=1)
        size = max(c.length, c.height, 0.05)
        self.scene.add_line_segments(
            f"{self.root}/bones", seg, colors, thickness=max(size / 120, 0.002)
        )
        self.scene.add_point_cloud(
            f"{self.root}/joints",
            p,
            (40, 40, 40),
            point_size=max(size / 80, 0.003),
            point_shape="circle",
        )
        if self.bone_models.value:
            self._draw_models(c, kinds)
        com = np.asarray(c.center_of_mass, dtype=np.float32)
        b = c.balance
        ok = b is None or not b.applicable or b.stable
        com_colour = STABLE if ok else UNSTABLE
        self.scene.add_icosphere(
            f"{self.root}/com", radius=max(size / 40, 0.005), color=com_colour, position=tuple(com)
        )
        ground = np.array([com, [com[0], 0.0, com[2]]], dtype=np.float32)[None]
        self.scene.add_line_segments(
            f"{self.root}/com_line", ground, com_colour, thickness=max(size / 300, 0.001)
        )
        if b is not None and len(b.support) >= 2:
            poly = np.array([[x, 0.001, z] for x, z in b.support])
            self.scene.add_line_segments(
                f"{self.root}/support",
                draw.polygon_loop(poly).astype(np.float32),
                SUPPORT,
                thickness=max(size / 200, 0.002),
            )
        lo = np.minimum(p.min(axis=0), ends.min(axis=0))
        hi = np.maximum(p.max(axis=0), ends.max(axis=0))
        centre = (lo + hi) / 2  # Y-up creature frame -> Z-up view: (x, y, z) -> (x, -z, y)
        self.app.focus(
            self.key, np.array([centre[0], -centre[2], centre[1]]), float(np.linalg.norm(hi - lo))
        )

    def _draw_models(self, c: Any, kinds: np.ndarray) -> None:
        """Shaded bone models, one mesh per limb kind (same colours as the bone lines)."""
        from biomorph.creature.bones import world_mesh

        mesh = world_mesh(c, lod=0)
        face_kind = kinds[mesh.face_ids["bone"]]
        for k in np.unique(face_kind):
            faces = mesh.faces[face_kind == k]
            used, inv = np.unique(faces, return_inverse=True)
            colour = tuple(int(v) for v in draw.palette(np.array([k + 4]))[0])
            self.scene.add_mesh_simple(
                f"{self.root}/models/k{int(k)}",
                mesh.vertices[used].astype(np.float32),
                inv.reshape(-1, 3).astype(np.int32),
                color=colour,
            )

    def _draw_spine(self, spine: Any) -> None:
        """The sampled spine's control polygon (frame px, shown at 1 px = 2 mm)."""
        pts = spine.get("points") if isinstance(spine, dict) else getattr(spine, "points", None)
        pts = np.asarray(np.zeros((0, 2)) if pts is None else pts, dtype=float).reshape(-1, 2)
        if len(pts) < 2:
            return
        xyz = np.column_stack([500.0 - pts[:, 0], pts[:, 1], np.zeros(len(pts))]) * 0.002
        seg = np.stack([xyz[:-1], xyz[1:]], axis=1).astype(np.float32)
        self.scene.add_line_segments(f"{self.root}/spine", seg, (120, 60, 200), thickness=0.01)

    def _describe(self, done: tuple[str, ...], nxt: str | None) -> str:
        steps = " → ".join(f"**{s}**" if s in done else s for s in self._all_steps())
        lines = [f"Steps: {steps}" + ("" if nxt is None else f" (next: {nxt})")]
        c = self.creature
        if c is not None:
            b = c.balance
            lines.append(
                f"{len(c)} joints, {c.total_mass:.3g} kg, height {c.height:.2f} m, "
                f"length {c.length:.2f} m, class {plain(c.params.get('class', '?'))}, "
                f"nearest species {plain(c.params.get('nearest_species', '?'))}"
            )
            if b is None or not b.applicable:
                lines.append("Balance: not applicable (no legs on the ground)")
            else:
                lines.append(
                    f"Balance: {'**stable**' if b.stable else '**tips over**'}, "
                    f"margin {b.margin * 100:.1f} cm ({b.margin_fraction * 100:.1f} % "
                    f"of the length), restoring torque {b.tipping_torque:.3g} N·m"
                )
        return "\n\n".join(lines)

    @staticmethod
    def _all_steps() -> tuple[str, ...]:
        from biomorph.creature import STEPS

        return tuple(STEPS)

    # ------------------------------------------------------------------ export
    def _writer(self, ext: str):
        def write(path: Path) -> None:
            from biomorph.creature import export

            if self.creature is None:
                raise InputError("the creature is not finished: run all steps before export")
            export(self.creature, path.with_suffix(ext) if path.suffix != ext else path)

        return write
