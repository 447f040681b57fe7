"""The studio application: one viser server, one session state, one tab per pillar.

>>> app = StudioApp("data", port=0)          # doctest: +SKIP
>>> url = app.start(); ...; app.stop()       # doctest: +SKIP

Everything the page can do goes through a :class:`~biomorph.studio.base.StudioTab`; files
come from and go to the :class:`~biomorph.studio.sandbox.Sandbox` (the ``--data`` folder).
"""

from __future__ import annotations

import importlib
import os
import socket
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from biomorph.studio.base import LatencyLog, StudioTab, error_text
from biomorph.studio.sandbox import DEFAULT_MAX_UPLOAD, Sandbox, SandboxError

#: Tabs in display order: (module under ``biomorph.studio.tabs``, class name).
TAB_CLASSES: tuple[tuple[str, str], ...] = (
    ("files", "FilesTab"),
    ("creature", "CreatureTab"),
    ("motion", "MotionTab"),
    ("tree", "TreeTab"),
    ("leaf", "LeafTab"),
)

#: Quaternion (w, x, y, z) turning Y-up content into viser's Z-up world (+90 deg about X).
Y_UP_WXYZ = (0.7071067811865476, 0.7071067811865476, 0.0, 0.0)


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free on ``host`` right now (for tests and ``--port 0``)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class StudioApp:
    """The biomorph studio: a viser web app over the four pillars.

    Parameters
    ----------
    data_dir : the only folder files are opened from and saved to (created if missing).
    host : interface to bind; loopback by default. Binding anything else exposes the
        studio (and the data folder) to the network.
    port : TCP port; 0 picks a free one.
    max_upload_bytes : largest accepted upload.
    tabs : keys of the tabs to build (default: all of :data:`TAB_CLASSES`).
    """

    def __init__(self, data_dir: str | os.PathLike[str] = ".", host: str = "127.0.0.1",
                 port: int = 8080, max_upload_bytes: int = DEFAULT_MAX_UPLOAD,
                 tabs: Sequence[str] | None = None) -> None:
        self.sandbox = Sandbox(data_dir, max_upload_bytes)
        self.host = host
        self.port = int(port) if port else free_port(host)
        self.latency = LatencyLog()
        self.tab_keys = tuple(tabs) if tabs is not None else tuple(k for k, _ in TAB_CLASSES)
        self.tabs: dict[str, StudioTab] = {}
        self.unavailable: dict[str, str] = {}
        self.server: Any = None
        self._frames: dict[str, Any] = {}
        self._upload_owner: dict[str, StudioTab] = {}
        self._view = None
        self._focus: dict[str, tuple[Any, float]] = {}
        self._stopped = threading.Event()

    # ------------------------------------------------------------------ lifecycle
    @property
    def url(self) -> str:
        """The address to open in a browser."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def start(self) -> str:
        """Start the web server and build every tab; return the URL."""
        import viser

        self.server = viser.ViserServer(host=self.host, port=self.port, label="biomorph studio",
                                        verbose=False)
        self.port = int(self.server.get_port())
        self._install_upload_guard()
        self.server.scene.set_up_direction("+z")
        self.server.scene.add_grid("/grid", width=10.0, height=10.0, cell_size=0.5,
                                   plane="xy", position=(0.0, 0.0, 0.0))
        self.server.initial_camera.position = (3.0, -4.0, 2.5)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.8)

        classes = []
        for key, cls_name in TAB_CLASSES:
            if key not in self.tab_keys:
                continue
            mod = importlib.import_module(f"biomorph.studio.tabs.{key}")
            classes.append(getattr(mod, cls_name)(self))

        gui = self.server.gui
        labels = [t.label for t in classes]
        self._view = gui.add_dropdown("3-D view", options=labels, initial_value=labels[0],
                                      hint="Which tab's content the 3-D view shows; using a "
                                           "tab's controls switches to it.")
        self._view.on_update(self._on_view)
        group = gui.add_tab_group()
        for tab in classes:
            self._frames[tab.key] = self.server.scene.add_frame(
                tab.root, show_axes=False, wxyz=Y_UP_WXYZ if tab.y_up else (1.0, 0, 0, 0),
                visible=tab.key == classes[0].key)
            with group.add_tab(tab.label):
                tab.status = gui.add_markdown("Ready.")
                reason = tab.requirement()
                if reason is not None:
                    self.unavailable[tab.key] = reason
                    tab.set_status(f"**Not available yet:** {reason}")
                    continue
                try:
                    tab.build()
                except Exception as exc:  # noqa: BLE001 - a broken tab must not kill the app
                    self.unavailable[tab.key] = error_text(exc)
                    tab.fail(exc, "building the tab")
                    continue
            self.tabs[tab.key] = tab
        self._stopped.clear()
        return self.url

    def stop(self) -> None:
        """Stop background work and the web server (idempotent)."""
        for tab in self.tabs.values():
            try:
                tab.close()
            except Exception:  # noqa: BLE001, S110 - shutting down regardless
                pass
        if self.server is not None:
            self.server.stop()
            self.server = None
        self._stopped.set()

    def wait(self) -> None:
        """Block until :meth:`stop` is called (Ctrl-C raises ``KeyboardInterrupt`` here)."""
        while not self._stopped.wait(0.5):
            pass

    # ------------------------------------------------------------------ page helpers
    def notify(self, title: str, body: str, color: str = "blue",
               seconds: float | None = 8.0) -> None:
        """Show a notification in every connected page."""
        if self.server is None:
            return
        for client in list(self.server.get_clients().values()):
            try:
                client.add_notification(title, body, color=color, auto_close_seconds=seconds)
            except Exception:  # noqa: BLE001, S112 - a client that just left
                continue

    def focus(self, key: str, centre: Any, size: float, force: bool = False) -> None:
        """Remember where tab ``key``'s content is (world frame, Z up) and point the cameras
        at it if that tab is shown and the extent changed a lot (or ``force``)."""
        import numpy as np

        centre = np.asarray(centre, dtype=float).reshape(3)
        size = float(max(size, 1e-3))
        old = self._focus.get(key)
        self._focus[key] = (centre, size)
        changed = old is None or not (0.5 < size / old[1] < 2.0) or \
            float(np.linalg.norm(centre - old[0])) > 0.5 * size
        if (changed or force) and self._frames.get(key) is not None and \
                self._frames[key].visible:
            self._aim(centre, size)

    def _aim(self, centre: Any, size: float) -> None:
        import numpy as np

        eye = centre + np.array([0.6, -0.9, 0.45]) * size
        self.server.initial_camera.look_at = tuple(centre)
        self.server.initial_camera.position = tuple(eye)
        for client in list(self.server.get_clients().values()):
            try:
                with client.atomic():  # position first: viser moves look_at with it
                    client.camera.position = eye
                    client.camera.look_at = centre
            except Exception:  # noqa: BLE001, S112 - a client that just left
                continue

    def show_scene(self, key: str) -> None:
        """Make tab ``key``'s 3-D content the visible one (and aim the cameras at it)."""
        switched = False
        for k, frame in self._frames.items():
            visible = k == key
            if frame.visible != visible:
                frame.visible = visible
                switched = switched or visible
        if switched and key in self._focus:
            self._aim(*self._focus[key])
        if self._view is not None:
            label = next((t.label for t in self.tabs.values() if t.key == key), None)
            if label is not None and self._view.value != label:
                self._view.value = label

    def _on_view(self, event: Any) -> None:
        if event.client is None:  # set by show_scene itself
            return
        for tab in self.tabs.values():
            if tab.label == self._view.value:
                self.show_scene(tab.key)
        for key in self.unavailable:
            if key in self._frames and self._view.value.lower() == key:
                self.show_scene(key)

    # ------------------------------------------------------------------ files
    def add_upload(self, tab: StudioTab, label: str, on_file: Callable[[Path], Any],
                   extensions: Sequence[str], hint: str | None = None) -> Any:
        """An upload button whose file is size-checked, saved into ``uploads/`` and then
        passed (as a sandboxed path) to ``on_file`` inside ``tab.run``."""
        exts = tuple(e.lower() for e in extensions)
        button = self.server.gui.add_upload_button(
            label, icon=None, mime_type=",".join(exts) if exts else "*/*",
            hint=hint or f"Upload a file ({', '.join(exts)}; at most "
                         f"{self.sandbox.max_upload_bytes / 1e6:.0f} MB) into the data folder.")
        self._upload_owner[button._impl.uuid] = tab

        def handle(_event: Any) -> None:
            upload = button.value

            def job() -> Any:
                self.sandbox.check_upload_size(len(upload.content), upload.name)
                name = self.sandbox.safe_name(upload.name)
                if exts and Path(name).suffix.lower() not in exts:
                    raise SandboxError(f"{name}: unsupported file type; expected one of "
                                       f"{' '.join(exts)}")
                path = self.sandbox.save_upload(name, upload.content)
                return on_file(path)

            tab.run("upload", job, timed=False)

        button.on_upload(handle)
        return button

    def _install_upload_guard(self) -> None:
        """Refuse over-size uploads when they *start*, before any byte is buffered."""
        from viser import _messages

        gui = self.server.gui
        websock = self.server._websock_server  # viser keeps handlers on its websocket server

        def guard(_client_id: int, message: Any) -> None:
            limit = self.sandbox.max_upload_bytes
            if message.size_bytes <= limit:
                return
            states = getattr(gui, "_current_file_upload_states", {})
            states.pop(message.transfer_uuid, None)
            tab = self._upload_owner.get(message.source_component_uuid)
            exc = SandboxError(f"{message.filename}: {message.size_bytes / 1e6:.1f} MB exceeds "
                               f"the upload limit of {limit / 1e6:.1f} MB")
            if tab is not None:
                tab.fail(exc, "upload")
            else:
                self.notify("Upload refused", str(exc), color="red")

        websock.register_handler(_messages.FileTransferStartUpload, guard)

    def export(self, tab: StudioTab, filename: str, write: Callable[[Path], Any]) -> Path:
        """Write ``exports/<filename>`` inside the data folder with ``write(path)``, check it is
        not empty, show where it went and offer it as a download in the page."""
        path = self.sandbox.output_path(filename)
        write(path)
        if not path.is_file() or path.stat().st_size == 0:
            raise SandboxError(f"export {filename} produced no data")
        rel = self.sandbox.relative(path)
        tab.set_status(f"Wrote `{rel}` ({path.stat().st_size / 1024:.1f} kB) in the data folder.")
        if self.server is not None and path.stat().st_size <= 64 * 1024 * 1024:
            self.server.send_file_download(path.name, path.read_bytes(), save_immediately=False)
        return path
