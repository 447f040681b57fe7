"""The studio application: one viser server, one :class:`Session` per page, one tab per
pillar.

>>> app = StudioApp("data", port=0)          # doctest: +SKIP
>>> url = app.start(); ...; app.stop()       # doctest: +SKIP

Every request passes the :mod:`~biomorph.studio.guard` (Host, Origin, optional token);
every page gets its own session (``/s/<id>/``; ``shared=True`` for one session for all);
files come from and go to the :class:`~biomorph.studio.sandbox.Sandbox` (``--data``).
"""

from __future__ import annotations

import asyncio
import os
import socket
import threading
import time
from collections.abc import Sequence
from typing import Any

from biomorph.errors import ParameterError
from biomorph.studio.base import LatencyLog, StudioTab
from biomorph.studio.guard import (
    MAX_MESSAGE,
    AccessPolicy,
    install_http_guard,
    new_session_id,
    session_of,
)
from biomorph.studio.sandbox import DEFAULT_MAX_UPLOAD, Sandbox
from biomorph.studio.session import Session
from biomorph.studio.tabs.creature import CreatureTab
from biomorph.studio.tabs.files import FilesTab
from biomorph.studio.tabs.leaf import LeafTab
from biomorph.studio.tabs.motion import MotionTab
from biomorph.studio.tabs.tree import TreeTab

#: Tabs in display order.
TAB_CLASSES: tuple[type[StudioTab], ...] = (FilesTab, CreatureTab, MotionTab, TreeTab, LeafTab)
#: A page's session is kept this long after its page closed (a reload comes back to it).
SESSION_IDLE_SECONDS = 15 * 60
#: At most this many sessions are kept; the longest idle ones are closed first.
MAX_SESSIONS = 16


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
    token : when set, every request must carry it (the printed URL does).
    shared : one session for every page (the old behaviour) instead of one per page.
    """

    def __init__(
        self,
        data_dir: str | os.PathLike[str] = ".",
        host: str = "127.0.0.1",
        port: int = 8080,
        max_upload_bytes: int = DEFAULT_MAX_UPLOAD,
        tabs: Sequence[str] | None = None,
        token: str | None = None,
        shared: bool = False,
    ) -> None:
        if token is not None and (len(token) < 8 or not token.isprintable() or " " in token):
            raise ParameterError("--token must be at least 8 printable characters, no spaces")
        self.sandbox = Sandbox(data_dir, max_upload_bytes)
        self.host = host
        self.port = int(port) if port else free_port(host)
        self.token = token
        self.shared = shared
        self.latency = LatencyLog()
        keys = tuple(tabs) if tabs is not None else tuple(c.key for c in TAB_CLASSES)
        unknown = set(keys) - {c.key for c in TAB_CLASSES}
        if unknown:
            raise ParameterError(f"unknown studio tab(s) {', '.join(sorted(unknown))}")
        self.tab_classes = tuple(c for c in TAB_CLASSES if c.key in keys)
        self.sessions: dict[str, Session] = {}
        self.server: Any = None
        self.policy: AccessPolicy | None = None
        self._by_client: dict[int, Session] = {}
        self._lock = threading.RLock()
        self._stopped = threading.Event()

    # ------------------------------------------------------------------ lifecycle
    @property
    def url(self) -> str:
        """The address to open in a browser (with the token when there is one)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}" + (f"/?token={self.token}" if self.token else "")

    @property
    def tabs(self) -> dict[str, StudioTab]:
        """Tabs of the shared session, or of the page that connected last."""
        session = self.latest_session()
        return {} if session is None else session.tabs

    @property
    def unavailable(self) -> dict[str, str]:
        session = self.latest_session()
        return {} if session is None else session.unavailable

    def latest_session(self) -> Session | None:
        with self._lock:
            if not self.sessions:
                return None
            return max(self.sessions.values(), key=lambda s: s.attached_at)

    def start(self) -> str:
        """Start the web server (guarded), build the shared session if any; return the URL."""
        import viser

        self.server = viser.ViserServer(
            host=self.host, port=self.port, label="biomorph studio", verbose=False
        )
        self.port = int(self.server.get_port())
        self.policy = AccessPolicy(self.host, self.port, self.token)
        self._guard_connections()
        install_http_guard(self.server, self.policy, self.shared)
        self.server.scene.set_up_direction("+z")
        self.server.scene.add_grid(
            "/grid", width=10.0, height=10.0, cell_size=0.5, plane="xy", position=(0.0, 0.0, 0.0)
        )
        self.server.initial_camera.position = (3.0, -4.0, 2.5)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.8)
        if self.shared:
            session = self.sessions["shared"] = Session(self, "shared", shared=True)
            session.attach(None)
        else:
            self.server.on_client_connect(self._on_connect)
            self.server.on_client_disconnect(self._on_disconnect)
        self._stopped.clear()
        return self.url

    def _guard_connections(self) -> None:
        """Second line behind the HTTP guard: check every websocket before viser sends it
        anything, and cap the size of one incoming message."""
        websock = self.server._websock_server  # viser keeps its websocket server here
        policy = self.policy

        async def check(conn: Any) -> None:
            raw = websock._live_connections.get(conn.client_id)
            if raw is None:
                return
            req = raw.request
            why = policy.refusal(req.headers, req.path, websocket=True)
            if why is not None:
                await raw.close(1008, why[:120])
                return
            raw.protocol.max_message_size = MAX_MESSAGE

        websock._client_connect_cb.insert(0, check)
        websock.disconnect_all_clients()  # any page that connected before the guard

    def close_client(self, client_id: int) -> None:
        """Drop a page's connection (it sent more than it declared): nothing more is read."""
        websock = self.server._websock_server
        raw = websock._live_connections.get(client_id)
        loop = websock._background_event_loop
        if raw is not None and loop is not None:
            asyncio.run_coroutine_threadsafe(raw.close(1009, "upload over the limit"), loop)

    # ------------------------------------------------------------------ sessions
    def _on_connect(self, client: Any) -> None:
        websock = self.server._websock_server
        raw = websock._live_connections.get(client.client_id)
        sid = session_of(raw.request.path) if raw is not None else None
        with self._lock:
            session = self.sessions.get(sid) if sid else None
            if session is None or session.client is not None:
                sid = sid if sid and sid not in self.sessions else new_session_id()
                session = self.sessions[sid] = Session(self, sid)
            session.attached_at = time.monotonic()
            session.client = client
            self._by_client[client.client_id] = session
            self._reap()
        session.attach(client)

    def _on_disconnect(self, client: Any) -> None:
        with self._lock:
            session = self._by_client.pop(client.client_id, None)
            if session is not None and session.client is client:
                session.detach()

    def _reap(self) -> None:
        """Close sessions idle too long, and the longest idle beyond :data:`MAX_SESSIONS`."""
        now = time.monotonic()
        idle = sorted(
            (s for s in self.sessions.values() if s.client is None), key=lambda s: s.idle_since
        )
        excess = max(0, len(self.sessions) - MAX_SESSIONS)
        for i, s in enumerate(idle):
            if i < excess or now - s.idle_since > SESSION_IDLE_SECONDS:
                s.close()
                self.sessions.pop(s.sid, None)

    def session_of_client(self, client: Any) -> Session | None:
        return self._by_client.get(client.client_id)

    def stop(self, timeout: float | None = None) -> None:
        """Stop background work and the web server (idempotent). ``timeout`` (s): wait at
        most this long for the web server's own teardown (viser joins its event loop for
        up to 1 + 5 s; on a loaded machine that outlasts Ctrl-C's grace,
        :data:`biomorph._cli.INTERRUPT_GRACE`), which then finishes in a daemon thread or
        ends with the process; None waits for it."""
        with self._lock:
            sessions = list(self.sessions.values())
        for s in sessions:
            s.close()
        server, self.server = self.server, None
        if server is not None:
            if timeout is None:
                server.stop()
            else:
                t = threading.Thread(target=server.stop, name="studio-stop", daemon=True)
                t.start()
                t.join(timeout)
        self._stopped.set()

    def wait(self) -> None:
        """Block until :meth:`stop` is called (Ctrl-C raises ``KeyboardInterrupt`` here)."""
        while not self._stopped.wait(0.5):
            pass

    # ------------------------------------------------------------------ compatibility
    def export(self, tab: StudioTab, filename: str, write: Any) -> Any:
        """Export through ``tab``'s session (see :meth:`Session.export`)."""
        return tab.app.export(tab, filename, write)
