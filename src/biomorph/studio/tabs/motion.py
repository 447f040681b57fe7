"""Motion tab: load BVH/HTR, play and scrub, edit with MotionLab's modules, export.

The edit pipeline is ``clip A -> [blend with clip B] -> [equalizer] -> [speed curve] ->
[cycle]``; each stage is a call into :mod:`biomorph.motion` and appears only when the
pillar provides it. Every slider edit recomputes the pipeline from the source and redraws
the current frame and the channel plot (timed into the latency log).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.errors import InputError, ParameterError
from biomorph.studio.base import StudioTab, plain
from biomorph.studio.widgets import ExportRow, FilePicker

MOTION_EXTENSIONS = (".bvh", ".htr")
CHANNELS = ("Xrotation", "Yrotation", "Zrotation", "Xposition", "Yposition", "Zposition")
PLOT_POINTS = 1500  # samples per plotted curve (decimated for long clips)
#: uPlot draws x as clock time unless told otherwise: seconds on a plain numeric axis.
SECONDS_AXIS = {
    "scales": {"x": {"time": False}},
    "axes": ({"label": "time (s)"}, {"label": "degrees / units"}),
}
TIMELINE_MARKS = 5  # labelled frame numbers under the frame slider


def parse_keys(text: str, what: str) -> tuple[np.ndarray, np.ndarray]:
    """``"0:1, 0.5:2, 1:1"`` -> (times, values); a :class:`ParameterError` names the bad key."""
    times, values = [], []
    for part in text.replace(";", ",").split(","):
        part = part.strip()
        if not part:
            continue
        if ":" not in part:
            raise ParameterError(f"{what} key {part!r} is not 'time:value'")
        t, v = part.split(":", 1)
        try:
            times.append(float(t))
            values.append(float(v))
        except ValueError:
            raise ParameterError(f"{what} key {part!r} holds a non-number") from None
    if not times:
        raise ParameterError(f"{what}: give at least one key 'time:value'")
    order = np.argsort(times)
    return np.asarray(times)[order], np.asarray(values)[order]


def _api(name: str) -> Any:
    """A function of :mod:`biomorph.motion` (``None`` if the pillar lacks it)."""
    import biomorph.motion as mo

    return getattr(mo, name, None)


class MotionTab(StudioTab):
    """MotionLab in the browser."""

    key = "motion"
    label = "Motion"
    getting_started = (
        "Getting started: open or upload a BVH/HTR clip under Clip, press "
        "Play (or Space), then move the equalizer, speed or cycle controls."
    )
    y_up = True

    def __init__(self, app: Any) -> None:
        super().__init__(app)
        self.seams: list[int] = []
        self._plot_cache: tuple[Any, Any] = (None, None)
        self.source: Any = None  # clip A as loaded
        self.clip_b: Any = None  # clip B for blending
        self.edited: Any = None  # result of the pipeline
        self.source_name = "motion"
        self.frame_index = 0
        self.unit = 1.0
        self._player: threading.Thread | None = None
        self._playing = threading.Event()
        self._closing = threading.Event()
        self._bones = None
        self._joints = None
        self.stage_errors: dict[str, str] = {}
        self._stage_cache: dict[str, tuple[Any, Any, list[int]]] = {}

    def requirement(self) -> str | None:
        try:
            from biomorph.io import read_motion  # noqa: F401
            from biomorph.motion import Motion  # noqa: F401
        except ImportError as exc:
            return f"the motion pillar cannot be imported ({exc})"
        return None

    # ------------------------------------------------------------------ GUI
    def build(self) -> None:
        gui = self.gui
        self.picker = FilePicker(
            self, "Clip", MOTION_EXTENSIONS, self.load, upload_label="Upload BVH/HTR"
        )
        self.info = gui.add_markdown("Open a BVH or HTR clip.")
        self.play = gui.add_button_group("Playback", ("Play", "Pause"))
        self.play.on_click(self._play_clicked)
        self.frame = gui.add_slider(
            "Frame",
            min=0,
            max=1,
            step=1,
            initial_value=0,
            hint="Timeline: frame numbers below; Space plays/pauses.",
        )
        self.frame.on_update(self._frame_changed)
        self.time_md = gui.add_markdown("")
        self.follow = gui.add_checkbox(
            "Follow root", initial_value=True, hint="Keep the root above the origin while playing."
        )
        self.follow.on_update(self.action("follow", lambda: self.draw_frame(self.frame_index)))

        self.stages: dict[str, Any] = {}
        eq = _api("equalize")
        with gui.add_folder("Equalizer"):
            if eq is None:
                gui.add_markdown("_waiting for `biomorph.motion.equalize`_")
                self.gains = []
            else:
                names = ("1 fine", "2", "3", "4", "5 coarse")
                self.gains = [
                    gui.add_slider(f"Band {n}", min=0.0, max=3.0, step=0.05, initial_value=1.0)
                    for n in names
                ]
                for g in self.gains:
                    g.on_update(self.live("equalizer", self.recompute))
                gui.add_button("Reset bands").on_click(
                    self.action("reset bands", self._reset_gains)
                )
        with gui.add_folder("Speed", expand_by_default=False):
            if _api("change_speed") is None:
                gui.add_markdown("_waiting for the speed-curve API_")
                self.speed = self.speed_keys = None
            else:
                self.speed = gui.add_slider("Speed", min=0.1, max=4.0, step=0.05, initial_value=1.0)
                with gui.add_form(None) as form:
                    self.speed_keys = gui.add_text(
                        "Speed keys (s:speed)",
                        initial_value="",
                        hint="Optional curve, e.g. '0:1, 2:2.5, 4:1'; overrides the slider. "
                        "Applied on Enter or Apply.",
                    )
                    gui.add_button("Apply speed keys").on_click(lambda _e: form.submit())
                form.on_submit(self.action("speed keys", self.recompute))
                self.speed.on_update(self.live("speed", self.recompute))
        with gui.add_folder("Cycle", expand_by_default=False):
            if _api("make_cycle") is None:
                gui.add_markdown("_waiting for the cycle API_")
                self.cycle_on = None
            else:
                self.cycle_on = gui.add_checkbox("Make a cycle", initial_value=False)
                self.cycle_range = gui.add_multi_slider(
                    "Range (frames)", min=0, max=1, step=1, initial_value=(0, 1)
                )
                self.cycle_transition = gui.add_slider(
                    "Transition (frames)", min=1, max=120, step=1, initial_value=20
                )
                self.cycle_repeats = gui.add_slider(
                    "Repeats", min=1, max=6, step=1, initial_value=2
                )
                for h in (
                    self.cycle_on,
                    self.cycle_range,
                    self.cycle_transition,
                    self.cycle_repeats,
                ):
                    h.on_update(self.live("cycle", self.recompute))
                self.cycle_info = gui.add_markdown("")
        with gui.add_folder("Blend", expand_by_default=False):
            if _api("blend") is None:
                gui.add_markdown("_waiting for `biomorph.motion.blending`_")
                self.blend_on = None
            else:
                self.picker_b = FilePicker(
                    self, "Clip B", MOTION_EXTENSIONS, self.load_b, upload_label="Upload clip B"
                )
                self.blend_on = gui.add_checkbox("Blend A into B", initial_value=False)
                self.blend_offset = gui.add_slider(
                    "B starts at (s)", min=0.0, max=10.0, step=0.05, initial_value=1.0
                )
                self.blend_scale = gui.add_slider(
                    "B time scale", min=0.25, max=4.0, step=0.05, initial_value=1.0
                )
                self.blend_length = gui.add_slider(
                    "Transition (s)", min=0.05, max=5.0, step=0.05, initial_value=0.5
                )
                with gui.add_form(None) as bform:
                    self.blend_keys = gui.add_text(
                        "Blend curve keys",
                        initial_value="0:0, 1:1",
                        hint="b(t) over the transition, t in 0..1; applied on Enter or Apply.",
                    )
                    gui.add_button("Apply blend keys").on_click(lambda _e: bform.submit())
                bform.on_submit(self.action("blend keys", self.recompute))
                for h in (self.blend_on, self.blend_offset, self.blend_scale, self.blend_length):
                    h.on_update(self.live("blend", self.recompute))
                gui.add_button("Auto-align B to A").on_click(
                    self.action("auto-align", self.auto_align)
                )
        with gui.add_folder("Channel plot"):
            self.plot_joint = gui.add_dropdown("Joint", options=("(no clip)",))
            self.plot_channel = gui.add_dropdown(
                "Channel", options=CHANNELS, initial_value="Xrotation"
            )
            self.plot_joint.on_update(self.action("plot", self.update_plot))
            self.plot_channel.on_update(self.action("plot", self.update_plot))
            self.plot = gui.add_uplot(
                data=(np.arange(2.0), np.zeros(2), np.zeros(2)),
                series=(
                    {"label": "s"},
                    {"label": "original", "stroke": "#999", "width": 1},
                    {"label": "edited", "stroke": "#d33", "width": 1.5},
                ),
                height=170,
                title="channel",
                **SECONDS_AXIS,
            )
            self.bands_plot = gui.add_uplot(
                data=(np.arange(2.0), np.zeros(2)),
                series=({"label": "s"}, {"label": "-"}),
                height=150,
                title="equalizer bands",
                visible=False,
                **SECONDS_AXIS,
            )
        self.exports = ExportRow(
            self,
            lambda: f"{self.source_name}_edited",
            {"BVH": self._write_bvh, "GLB": self._write_glb},
            contents={
                "BVH": "the edited motion: hierarchy, offsets and every frame's "
                "channels (Y up, the clip's units)",
                "GLB": "the skeleton as a skinned glTF with the edited animation",
            },
        )
        self.latency_md = gui.add_markdown("")

    # ------------------------------------------------------------------ loading
    def _read(self, path: Path) -> Any:
        from biomorph import io

        motion = io.read_motion(path)
        guess = _api("guess_up_axis")
        if guess is not None and guess(motion) == "z":
            from biomorph.motion.align import to_y_up

            motion = to_y_up(motion, "z")
        return motion

    def load(self, path: Path) -> None:
        """Open clip A and reset the view."""
        motion = self._read(path)
        if motion.n_frames < 2:
            raise InputError(f"{path.name}: only {motion.n_frames} frame; expected a clip")
        self.source, self.source_name = motion, path.stem
        rest = motion.world_positions(slice(0, 1))[0]
        height = float(np.ptp(rest[:, 1])) or float(np.ptp(rest)) or 1.0
        self.unit = 1.7 / height if (height > 5.0 or height < 0.3) else 1.0
        self.plot_joint.options = motion.names
        self.plot_joint.value = motion.names[min(1, motion.n_joints - 1)]
        if self.cycle_on is not None:
            self.cycle_range.max = motion.n_frames - 1
            self.cycle_range.value = (0, motion.n_frames - 1)
        self.info.content = (
            f"**{plain(path.name)}**: {motion.n_joints} joints, "
            f"{motion.n_frames} frames at {motion.fps:.1f} fps "
            f"({motion.duration:.1f} s)"
        )
        self.recompute()
        tall = height * self.unit  # Y-up clip, shown Z-up with the root over the origin
        self.app.focus(self.key, np.array([0.0, 0.0, tall / 2]), 1.6 * tall, force=True)
        self.set_status(f"Opened {plain(self.app.sandbox.relative(path))}.")

    def load_b(self, path: Path) -> None:
        """Open clip B (for blending)."""
        self.clip_b = self._read(path)
        self.set_status(f"Clip B: {plain(path.name)} ({self.clip_b.n_frames} frames).")
        if self.source is not None:
            self.recompute()

    def _need_clip(self) -> Any:
        if self.source is None:
            raise InputError("no clip loaded: open a BVH or HTR file first")
        return self.source

    # ------------------------------------------------------------------ pipeline
    def pipeline(self) -> Any:
        """Run the enabled edit stages on clip A; return the edited motion.

        A stage that fails is reported (:attr:`stage_errors`) and left out, so later edits
        keep working; export refuses while a stage fails (it would not be what is shown
        on the controls)."""
        from biomorph.studio.base import error_text

        mo = self._need_clip()
        self.stage_errors = {}
        cache = self._stage_cache
        for name, stage, params in (
            ("blend", self._blend, self._blend_params),
            ("equalizer", self._equalize, self._equalize_params),
            ("speed", self._speed, self._speed_params),
            ("cycle", self._cycle, self._cycle_params),
        ):
            key = (id(mo), id(self.clip_b), params())
            hit = cache.get(name)
            if hit is not None and hit[0] == key:  # same input, same controls: reuse
                mo, self.seams = hit[1], hit[2] if name == "cycle" else self.seams
                continue
            if name == "cycle":
                self.seams = []
            try:
                out = stage(mo)
            except Exception as exc:  # noqa: BLE001 - reported, the stage is left out
                self.stage_errors[name] = error_text(exc)
                cache.pop(name, None)
                continue
            cache[name] = (key, out, list(self.seams))
            mo = out
        return mo

    # each stage's controls, as a key of the stage cache (an edit reruns its stage and the
    # ones after it, never the ones before)
    def _blend_params(self) -> tuple:
        if self.blend_on is None or not self.blend_on.value:
            return ()
        return (
            self.blend_offset.value,
            self.blend_scale.value,
            self.blend_length.value,
            self.blend_keys.value,
        )

    def _equalize_params(self) -> tuple:
        return tuple(g.value for g in self.gains)

    def _speed_params(self) -> tuple:
        return () if self.speed is None else (self.speed.value, self.speed_keys.value)

    def _cycle_params(self) -> tuple:
        if self.cycle_on is None or not self.cycle_on.value:
            return ()
        return (self.cycle_range.value, self.cycle_transition.value, self.cycle_repeats.value)

    def _blend(self, mo: Any) -> Any:
        if self.blend_on is None or not self.blend_on.value:
            return mo
        if self.clip_b is None:
            raise InputError("blending needs clip B: open one under Blend")
        ft = mo.frame_time
        off = float(self.blend_offset.value) / ft
        trans = float(self.blend_length.value) / ft
        t, w = parse_keys(self.blend_keys.value, "blend curve")
        curve = {float(off + ti * trans): float(wi) for ti, wi in zip(t, w, strict=True)}
        return _api("blend")(
            [mo, self.clip_b],
            offsets=[0.0, off],
            scales=[1.0, float(self.blend_scale.value)],
            transition=trans,
            curve=curve if len(curve) > 1 else None,
        )

    def _equalize(self, mo: Any) -> Any:
        gains = [g.value for g in self.gains]
        if gains and any(abs(g - 1.0) > 1e-9 for g in gains):
            return _api("equalize")(mo, gains)
        return mo

    def _speed(self, mo: Any) -> Any:
        if self.speed is None:
            return mo
        fn = _api("change_speed")
        if self.speed_keys.value.strip():
            times, speeds = parse_keys(self.speed_keys.value, "speed")
            if (
                (speeds <= 0).any()
                or (speeds > self.speed.max).any()
                or (speeds < self.speed.min).any()
            ):
                raise ParameterError(
                    f"speed keys must lie in {self.speed.min:g}.."
                    f"{self.speed.max:g} (the slider's range)"
                )
            return fn(
                mo,
                {float(ti / mo.frame_time): float(v) for ti, v in zip(times, speeds, strict=True)},
            )
        if abs(self.speed.value - 1.0) > 1e-9:
            return fn(mo, float(self.speed.value))
        return mo

    def _cycle(self, mo: Any) -> Any:
        if self.cycle_on is None or not self.cycle_on.value:
            return mo
        lo, hi = (int(v) for v in self.cycle_range.value)
        trans = int(self.cycle_transition.value)
        repeats = int(self.cycle_repeats.value)
        mo = _api("make_cycle")(mo, lo, min(hi + 1, mo.n_frames), trans, cycles=repeats)
        period = mo.n_frames // repeats
        self.seams = [k * period for k in range(1, repeats)]
        return mo

    def recompute(self) -> None:
        """Recompute the edited motion, redraw the frame, the timeline and the plot."""
        self.edited = self.pipeline()
        n = self.edited.n_frames
        if self.frame.max != n - 1:
            self.frame.max = max(n - 1, 1)
            self.frame.marks = tuple(
                (int(round(v)), str(int(round(v))))
                for v in np.linspace(0, max(n - 1, 1), TIMELINE_MARKS)
            )
        self.frame_index = min(self.frame_index, n - 1)
        self.draw_frame(self.frame_index)
        self.draw_seam()
        self.update_plot()
        self.latency_md.content = "Edit → redraw (server side):\n\n" + self.app.latency.markdown(
            "motion/"
        )
        if self.stage_errors:
            raise InputError(
                "; ".join(
                    f"the {k} stage failed and is left out: {v}"
                    for k, v in self.stage_errors.items()
                )
            )

    def restore(self) -> None:
        """Redraw the edited clip after a page reload."""
        self._bones = self._joints = None
        if self.source is not None:
            self.recompute()

    def on_key(self, key: str) -> None:
        """Space: play / pause."""
        if key != "space":
            return
        if self._playing.is_set():
            self._playing.clear()
        else:
            self.start_playing()

    def _reset_gains(self) -> None:
        for g in self.gains:
            g.value = 1.0
        self.recompute()

    def auto_align(self) -> None:
        """Place clip B so the last peak of A's plotted channel meets B's first peak."""
        from biomorph.motion.blending import auto_offset

        a = self._need_clip()
        if self.clip_b is None:
            raise InputError("no clip B loaded: open one under Blend first")
        off = auto_offset(
            a,
            self.clip_b,
            "peaks",
            self.plot_joint.value,
            self.plot_channel.value,
            b_scale=float(self.blend_scale.value),
        )
        self.blend_offset.value = float(np.clip(off * a.frame_time, 0.0, self.blend_offset.max))
        self.set_status(f"Aligned: clip B starts at output frame {off:.0f}.")
        self.recompute()

    # ------------------------------------------------------------------ drawing
    def draw_frame(self, f: int) -> None:
        """Draw the edited motion's pose at frame ``f``."""
        mo = self.edited
        if mo is None:
            return
        f = int(np.clip(f, 0, mo.n_frames - 1))
        self.frame_index = f
        self.time_md.content = (
            f"Frame **{f}** of 0–{mo.n_frames - 1} · "
            f"{f * mo.frame_time:.2f} s of {mo.duration:.2f} s"
        )
        p = mo.world_positions(slice(f, f + 1))[0] * self.unit
        if self.follow.value:  # keep the character in view: root over the origin
            p = p - p[0] * np.array([1.0, 0.0, 1.0])
        p = p.astype(np.float32)
        parent = mo.skeleton.parent
        child = np.flatnonzero(parent >= 0)
        seg = np.stack([p[parent[child]], p[child]], axis=1)
        if self._bones is None or len(self._bones.points) != len(seg):
            self._bones = self.scene.add_line_segments(
                f"{self.root}/bones", seg, (40, 90, 200), thickness=0.03
            )
            self._joints = self.scene.add_point_cloud(
                f"{self.root}/joints", p, (220, 60, 60), point_size=0.045, point_shape="circle"
            )
        else:
            self._bones.points = seg
            self._joints.points = p
        self.redrawn()

    def draw_seam(self) -> None:
        """With a cycle: the pose at the first seam, in orange, and the seam frames listed."""
        self.scene.remove_by_name(f"{self.root}/seam")
        if not self.seams or self.edited is None:
            if self.cycle_on is not None:
                self.cycle_info.content = ""
            return
        mo, f = self.edited, self.seams[0]
        p = mo.world_positions(slice(f, f + 1))[0] * self.unit
        if self.follow.value:
            p = p - p[0] * np.array([1.0, 0.0, 1.0])
        parent = mo.skeleton.parent
        child = np.flatnonzero(parent >= 0)
        seg = np.stack([p[parent[child]], p[child]], axis=1).astype(np.float32)
        self.scene.add_line_segments(f"{self.root}/seam", seg, (240, 150, 20), thickness=0.015)
        self.cycle_info.content = (
            f"Seams (orange pose = first) at frames "
            f"{', '.join(map(str, self.seams))} of {mo.n_frames}"
        )

    def _frame_changed(self, event: Any) -> None:
        if event.client is None:  # moved by the player
            return
        self.live("scrub", lambda: self.draw_frame(int(self.frame.value)))(event)

    def update_plot(self) -> None:
        """Plot the chosen channel, original against edited (and its equalizer bands)."""
        if self.source is None or self.edited is None:
            return
        joint, chan = self.plot_joint.value, self.plot_channel.value
        key = (id(self.source), joint, chan)
        if self._plot_cache[0] != key:  # the original curve only changes with the clip
            self._plot_cache = (key, self.source.channel(joint, chan, degrees=True))
        a = self._plot_cache[1]
        b = self.edited.channel(joint, chan, degrees=True)
        n = max(len(a), len(b))
        t = np.arange(n) * self.edited.frame_time
        ya = np.full(n, np.nan)
        ya[: len(a)] = a
        yb = np.full(n, np.nan)
        yb[: len(b)] = b
        step = max(1, n // PLOT_POINTS)
        self.plot.data = (t[::step], ya[::step], yb[::step])
        self.plot.title = f"{joint} {chan} (deg / units)"
        bands = _api("bands")
        if bands is not None and len(b) >= 32:
            levels = np.asarray(bands(b, levels=4))
            self.bands_plot.data = (t[: len(b)][::step],) + tuple(lv[::step] for lv in levels)
            self.bands_plot.series = ({"label": "s"},) + tuple(
                {"label": f"band {k + 1}", "stroke": f"hsl({40 * k},70%,45%)", "width": 1}
                for k in range(len(levels))
            )
            self.bands_plot.visible = True

    # ------------------------------------------------------------------ playback
    def _play_clicked(self, event: Any) -> None:
        if event.target.value == "Play":
            self.run("play", self.start_playing, timed=False)
        else:
            self._playing.clear()

    def start_playing(self) -> None:
        self._need_clip()
        self._playing.set()
        if self._player is None or not self._player.is_alive():
            self._player = threading.Thread(
                target=self._play_loop, daemon=True, name="studio-motion-player"
            )
            self._player.start()

    def _play_loop(self) -> None:
        last = time.perf_counter()
        pos = float(self.frame_index)
        while not self._closing.is_set() and self._playing.is_set():
            time.sleep(1 / 30)
            now = time.perf_counter()
            mo = self.edited
            if mo is None:
                break
            pos = (pos + (now - last) / mo.frame_time) % mo.n_frames
            last = now
            with self.lock:
                try:
                    self.draw_frame(int(pos))
                    self.frame.value = int(pos)
                except Exception as exc:  # noqa: BLE001 - stop playing, show why
                    self._playing.clear()
                    self.fail(exc, "play")

    def close(self) -> None:
        self._closing.set()
        self._playing.clear()

    # ------------------------------------------------------------------ export
    def _current(self) -> Any:
        if self.edited is None:
            raise InputError("nothing to export: open a clip first")
        if self.stage_errors:
            stages = ", ".join(self.stage_errors)
            raise InputError(
                f"not exported: the {stages} stage failed, so the result is not "
                "what the controls say; fix it or turn it off first"
            )
        return self.edited

    def _write_bvh(self, path: Path) -> None:
        from biomorph import io

        io.write_bvh(path, self._current())

    def _write_glb(self, path: Path) -> None:
        from biomorph import io

        io.write_gltf(path, self._current())
