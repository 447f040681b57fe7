"""One studio session: the tabs, their state, downloads, errors and jobs of one page.

By default every page gets its own :class:`Session` (its address ``/s/<id>/`` names it);
a reload of that address re-attaches the page to it: the controls come back with their
values (:class:`RestoringGui`) and each tab redraws its content from its state. With
``--shared`` one session serves every page (the old behaviour: all pages see and move
the same controls).

A session draws into its page's own scene and GUI (``client.scene``/``client.gui``), so
nothing of one page — notifications, downloads, camera moves, errors — reaches another.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from biomorph.errors import InputError
from biomorph.studio.base import LatencyLog, StudioTab, error_text, plain
from biomorph.studio.guard import InputGuard
from biomorph.studio.sandbox import Sandbox, SandboxError

#: Quaternion (w, x, y, z) turning Y-up content into viser's Z-up world (+90 deg about X).
Y_UP_WXYZ = (0.7071067811865476, 0.7071067811865476, 0.0, 0.0)
#: Heavy jobs (skeletonisation, synthesis, file reading) one page may run at once.
MAX_JOBS = 2
#: Inputs whose values a reload restores.
RESTORED = (
    "add_slider",
    "add_number",
    "add_multi_slider",
    "add_dropdown",
    "add_checkbox",
    "add_text",
)


class RestoringGui:
    """A viser ``GuiApi`` that remembers the inputs a tab creates and, when the tab is
    built again for a reloaded page, creates them with the previous values (and the
    previous options / ranges), so a rebuild fires no callbacks and loses nothing."""

    def __init__(self, gui: Any, previous: list[tuple[str, str, Any]] | None = None) -> None:
        self._gui = gui
        self._previous = list(previous or [])
        self.created: list[tuple[str, str, Any]] = []

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._gui, name)
        if name not in RESTORED:
            return attr

        def add(label: str, *args: Any, **kw: Any) -> Any:
            i = len(self.created)
            old = self._previous[i] if i < len(self._previous) else None
            if old is not None and old[0] == name and old[1] == label:
                kw = _restored_kwargs(name, old[2], kw)
            handle = attr(label, *args, **kw)
            self.created.append((name, label, handle))
            return handle

        return add


def _restored_kwargs(kind: str, old: Any, kw: dict[str, Any]) -> dict[str, Any]:
    kw = dict(kw)
    if kind == "add_dropdown":
        kw["options"] = tuple(old.options)
    if kind in ("add_slider", "add_multi_slider", "add_number"):
        for prop in ("min", "max"):
            if getattr(old, prop, None) is not None:
                kw[prop] = getattr(old, prop)
    kw["initial_value"] = old.value
    kw["visible"] = old.visible
    return kw


class Session:
    """The studio of one page (or, ``shared``, of every page)."""

    def __init__(self, app: Any, sid: str, shared: bool = False) -> None:
        self.app = app
        self.sid = sid
        self.shared = shared
        self.sandbox: Sandbox = app.sandbox
        self.latency: LatencyLog = app.latency
        self.client: Any = None  # the page's ClientHandle (None when shared / detached)
        self.tabs: dict[str, StudioTab] = {}
        self.unavailable: dict[str, str] = {}
        self.idle_since = self.attached_at = time.monotonic()
        self._classes = [cls(self) for cls in app.tab_classes]
        self._frames: dict[str, Any] = {}
        self._focus: dict[str, tuple[Any, float]] = {}
        self._owner: dict[str, StudioTab] = {}
        self._widgets: dict[str, list[tuple[str, str, Any]]] = {}
        self._jobs = threading.BoundedSemaphore(MAX_JOBS)
        self._build_lock = threading.RLock()
        self.ready = threading.Event()  # set when the page's GUI is built
        self.gui: Any = None
        self.scene: Any = None
        self._current = self._classes[0].key if self._classes else ""
        self._containers: dict[str, Any] = {}
        self._tab_bar: Any = None

    # ------------------------------------------------------------------ attaching pages
    @property
    def host(self) -> Any:
        """What the session draws into: the page's client handle, or the server if shared."""
        return self.app.server if self.shared else self.client

    def attach(self, client: Any) -> None:
        """Build (or rebuild, after a reload) the GUI and the scene in ``client``'s page."""
        with self._build_lock:
            self.ready.clear()
            self.client = None if self.shared else client
            host = self.host
            self.scene = host.scene
            InputGuard(
                host.gui,
                lambda: self.sandbox.max_upload_bytes,
                self._refused,
                self.app.close_client,
                self._changed,
            ).install()
            self._build(host)
            self.ready.set()

    def detach(self) -> None:
        self.client = None
        self.idle_since = time.monotonic()

    def _build(self, host: Any) -> None:
        restoring = bool(self._widgets)
        gui = host.gui
        gui.add_markdown(
            "**biomorph studio** — pick a tab; the 3-D view shows its content. Ctrl-Z "
            "undoes the open tab's last parameter change."
        )
        labels = tuple(t.label for t in self._classes)
        self._tab_bar = gui.add_button_group("Tab", labels)
        self._tab_bar.on_click(lambda e: self.show_scene(self._key_of(e.target.value)))
        self._containers = {}
        self._owner.clear()
        current = self._current
        for tab in self._classes:
            self._frames[tab.key] = self.scene.add_frame(
                tab.root,
                show_axes=False,
                wxyz=Y_UP_WXYZ if tab.y_up else (1.0, 0, 0, 0),
                visible=tab.key == current,
            )
            box = self._containers[tab.key] = gui.add_folder(tab.label, visible=tab.key == current)
            with box:
                self.gui = RestoringGui(gui, self._widgets.get(tab.key))
                tab.status = self.gui.add_markdown(tab.status_text)
                if tab.key in self.unavailable and tab.key not in self.tabs:
                    continue
                reason = tab.requirement()
                if reason is not None:
                    self.unavailable[tab.key] = reason
                    tab.set_status(f"**Not available yet:** {plain(reason)}")
                    continue
                if tab.getting_started:
                    self.gui.add_markdown(f"_{tab.getting_started}_")
                with tab.lock:
                    try:
                        tab.build()
                        if restoring and tab.key in self.tabs:
                            tab.restore()
                    except Exception as exc:  # noqa: BLE001 - a broken tab must not kill the page
                        self.unavailable[tab.key] = error_text(exc)
                        tab.fail(exc, "building the tab")
                        continue
                self._widgets[tab.key] = self.gui.created
                for _, _, handle in self.gui.created:
                    self._owner[handle._impl.uuid] = tab
                self.tabs[tab.key] = tab
        self.gui = gui
        self._install_keys(gui)

    def _key_of(self, label: str) -> str:
        return next((t.key for t in self._classes if t.label == label), self._current)

    def _install_keys(self, gui: Any) -> None:
        """Ctrl-Z / Cmd-Z undo the open tab's last parameter change; Space plays/pauses
        the motion (viser commands with hotkeys)."""
        add = getattr(gui, "add_command", None)
        if add is None:  # pragma: no cover - an older viser
            return
        add("Undo the last parameter change", hotkey="Z", modifier="cmd/ctrl").on_trigger(
            lambda _e: self.undo()
        )
        add("Play / pause the motion", hotkey="space").on_trigger(lambda _e: self.hotkey("space"))

    def hotkey(self, key: str) -> None:
        tab = self.tabs.get(self._current)
        if tab is not None and hasattr(tab, "on_key"):
            tab.run(f"key {key}", lambda: tab.on_key(key), timed=False, show=False)

    def undo(self) -> None:
        tab = self.tabs.get(self._current)
        if tab is not None:
            tab.run("undo", tab.undo_parameter, timed=False, show=False)

    def _changed(self, uuid: str, handle: Any, old: Any) -> None:
        tab = self._owner.get(uuid)
        if tab is not None:
            tab.remember(handle, old)

    def close(self) -> None:
        for tab in self._classes:
            try:
                tab.close()
            except Exception:  # noqa: BLE001, S110 - shutting down regardless
                pass

    # ------------------------------------------------------------------ page helpers
    def _clients(self) -> list[Any]:
        if self.shared:
            server = self.app.server
            return [] if server is None else list(server.get_clients().values())
        return [] if self.client is None else [self.client]

    def notify(
        self, title: str, body: str, color: str = "blue", seconds: float | None = 8.0
    ) -> None:
        """A notification in this session's page (plain text: never rendered as HTML)."""
        for client in self._clients():
            try:
                client.add_notification(title, body, color=color, auto_close_seconds=seconds)
            except Exception:  # noqa: BLE001, S112 - a client that just left
                continue

    def _refused(self, uuid: str | None, message: str) -> None:
        """An input or upload the guard refused: say so on the owning tab's status line."""
        tab = self._owner.get(uuid or "")
        if tab is None:
            self.notify("Input refused", message, color="red")
            return
        tab.fail(InputError(message), "input")

    def focus(self, key: str, centre: Any, size: float, force: bool = True) -> None:
        """Remember where tab ``key``'s content is (world frame, Z up) and frame the
        camera on it when that tab is shown."""
        import numpy as np

        centre = np.asarray(centre, dtype=float).reshape(3)
        size = float(max(size, 1e-3))
        self._focus[key] = (centre, size)
        if key == self._current:
            self._aim(centre, size)

    def _aim(self, centre: Any, size: float) -> None:
        import numpy as np

        eye = centre + np.array([0.6, -0.9, 0.45]) * size
        for client in self._clients():
            try:
                with client.atomic():  # position first: viser moves look_at with it
                    client.camera.position = eye
                    client.camera.look_at = centre
            except Exception:  # noqa: BLE001, S112 - a client that just left
                continue

    def show_scene(self, key: str) -> None:
        """Open tab ``key``: its controls, its 3-D content, the camera framed on it."""
        if key not in self._frames:
            return
        switched = key != self._current
        self._current = key
        for k, frame in self._frames.items():
            if frame.visible != (k == key):
                frame.visible = k == key
        for k, box in self._containers.items():
            if box.visible != (k == key):
                box.visible = k == key
        if switched and key in self._focus:
            self._aim(*self._focus[key])

    # ------------------------------------------------------------------ jobs
    def job_slot(self) -> Callable[[], None]:
        """Take one of the page's :data:`MAX_JOBS` heavy-job slots; returns its release.
        Raises :class:`InputError` when all are busy (the page keeps working)."""
        if not self._jobs.acquire(blocking=False):
            raise InputError(
                f"{MAX_JOBS} long jobs are already running in this page; "
                "wait for one to finish or cancel it"
            )
        released = threading.Event()

        def release() -> None:
            if not released.is_set():
                released.set()
                self._jobs.release()

        return release

    # ------------------------------------------------------------------ files
    def add_upload(
        self,
        tab: StudioTab,
        label: str,
        on_file: Callable[[Path], Any],
        extensions: Sequence[str],
        hint: str | None = None,
    ) -> Any:
        """An upload button whose file is size-checked (while it streams, by the
        :class:`~biomorph.studio.guard.InputGuard`, and after assembly), saved into
        ``uploads/`` and passed (as a sandboxed path) to ``on_file`` inside ``tab.run``."""
        exts = tuple(e.lower() for e in extensions)
        button = self.gui.add_upload_button(
            label,
            icon=None,
            mime_type=",".join(exts) if exts else "*/*",
            hint=hint
            or f"Upload a file ({', '.join(exts)}; at most "
            f"{self.sandbox.max_upload_bytes / 1e6:.0f} MB) into the data folder.",
        )
        self._owner[button._impl.uuid] = tab

        def handle(_event: Any) -> None:
            upload = button.value

            def job() -> Any:
                self.sandbox.check_upload_size(len(upload.content), upload.name)
                name = self.sandbox.safe_name(upload.name)
                if exts and Path(name).suffix.lower() not in exts:
                    raise SandboxError(
                        f"{name}: unsupported file type; expected one of {' '.join(exts)}"
                    )
                path = self.sandbox.save_upload(name, upload.content)
                tab.set_status(f"Reading {plain(name)} ({len(upload.content) / 1e6:.1f} MB) …")
                return on_file(path)

            tab.run("upload", job, timed=False, heavy=True)

        button.on_upload(handle)
        return button

    def export(self, tab: StudioTab, filename: str, write: Callable[[Path], Any]) -> Path:
        """Write ``exports/<filename>`` inside the data folder with ``write(path)``, check it is
        not empty, show where it went and offer it as a download in this page."""
        path = self.sandbox.output_path(filename)
        write(path)
        if not path.is_file() or path.stat().st_size == 0:
            raise SandboxError(f"export {filename} produced no data")
        rel = self.sandbox.relative(path)
        tab.set_status(
            f"Wrote `{plain(rel)}` ({path.stat().st_size / 1024:.1f} kB) in the data folder."
        )
        host = self.host
        if host is not None and path.stat().st_size <= 64 * 1024 * 1024:
            host.send_file_download(path.name, path.read_bytes(), save_immediately=False)
        return path
