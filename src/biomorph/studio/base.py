"""Shared pieces of the studio's tabs: the tab base class, error capture, latency log.

A tab builds its GUI inside its viser tab, draws into its own scene frame
(``/<key>``), and runs every user action through :meth:`StudioTab.run`, which

* serialises actions of one tab (a lock), shows the tab's 3-D scene,
* times the action (edit -> scene messages queued) into the app's :class:`LatencyLog`,
* turns any exception into a message in the page (the tab's status line and a
  notification) so the page stays usable.

Live sliders use :meth:`StudioTab.live`, which coalesces a burst of slider events into
"compute the latest value" so dragging never queues stale work.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from biomorph.errors import BiomorphError

if TYPE_CHECKING:  # pragma: no cover
    from biomorph.studio.server import StudioApp


@dataclass
class LatencyLog:
    """Wall-clock durations (seconds) of studio actions, by ``"tab/action"`` name."""

    samples: dict[str, list[float]] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def record(self, name: str, seconds: float) -> None:
        with self._lock:
            self.samples.setdefault(name, []).append(float(seconds))

    def summary(self) -> dict[str, dict[str, float]]:
        """Per action: count, median, 95th percentile and maximum in milliseconds."""
        with self._lock:
            items = {k: np.asarray(v) * 1000.0 for k, v in self.samples.items() if v}
        return {k: {"n": int(v.size), "median_ms": float(np.median(v)),
                    "p95_ms": float(np.percentile(v, 95)), "max_ms": float(v.max())}
                for k, v in sorted(items.items())}

    def markdown(self, prefix: str = "") -> str:
        """A small markdown table of :meth:`summary` for names starting with ``prefix``."""
        rows = [(k, s) for k, s in self.summary().items() if k.startswith(prefix)]
        if not rows:
            return "_no edits measured yet_"
        lines = ["| action | n | median ms | max ms |", "|---|---|---|---|"]
        lines += [f"| {k.split('/', 1)[-1]} | {s['n']} | {s['median_ms']:.1f} | "
                  f"{s['max_ms']:.1f} |" for k, s in rows]
        return "\n".join(lines)


def error_text(exc: BaseException) -> str:
    """One line for the page: the message of a user error, type and message otherwise."""
    if isinstance(exc, BiomorphError):
        return str(exc)
    if isinstance(exc, OSError):
        return f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": ")
    return f"{type(exc).__name__}: {exc}"


class StudioTab:
    """Base class of a studio tab.

    Subclasses set :attr:`key` and :attr:`label`, implement :meth:`build` (called inside
    the viser tab context) and may implement :meth:`requirement` (a reason string when
    the pillar's API is not importable yet) and :meth:`close`.
    """

    key: str = "tab"
    label: str = "Tab"
    #: Y-up content (skeletons, motion, leaves) is turned so +Y points up in viser's Z-up view.
    y_up: bool = False

    def __init__(self, app: StudioApp) -> None:
        self.app = app
        self.lock = threading.RLock()
        self.version = 0  # incremented on every redraw (tests wait on it)
        self.last_error: str | None = None
        self.status = None  # viser markdown handle, set by the app
        self._pending: dict[str, Callable[[], None]] = {}
        self._pending_lock = threading.Lock()
        self._running: set[str] = set()

    # ------------------------------------------------------------------ to override
    def requirement(self) -> str | None:
        """``None`` if the tab can be built, else why not (shown in the tab)."""
        return None

    def build(self) -> None:
        """Add the tab's GUI elements (inside the viser tab context) and initial scene."""

    def close(self) -> None:
        """Stop background work (players, jobs)."""

    # ------------------------------------------------------------------ helpers
    @property
    def scene(self):
        return self.app.server.scene

    @property
    def gui(self):
        return self.app.server.gui

    @property
    def root(self) -> str:
        """Scene-tree prefix of this tab's 3-D content."""
        return f"/{self.key}"

    def set_status(self, text: str) -> None:
        """Show ``text`` (markdown) on the tab's status line."""
        if self.status is not None:
            self.status.content = text

    def fail(self, exc: BaseException, action: str) -> None:
        """Show an error in the page (status line + notification); keep the page usable."""
        msg = error_text(exc)
        self.last_error = msg
        if not isinstance(exc, BiomorphError | OSError):
            traceback.print_exception(exc)
        self.set_status(f"**Error** ({action}): {msg}")
        self.app.notify(f"{self.label}: {action} failed", msg, color="red")

    def run(self, action: str, fn: Callable[[], Any], *, timed: bool = True,
            show: bool = True) -> Any:
        """Run ``fn`` as the user action ``action``: lock, time, show errors in the page."""
        with self.lock:
            if show:
                self.app.show_scene(self.key)
            t0 = time.perf_counter()
            try:
                result = fn()
            except Exception as exc:  # noqa: BLE001 - every failure goes to the page
                self.fail(exc, action)
                return None
            dt = time.perf_counter() - t0
            if timed:
                self.app.latency.record(f"{self.key}/{action}", dt)
            self.last_error = None
            return result

    def action(self, action: str, fn: Callable[[], Any], **kw: Any) -> Callable[[Any], None]:
        """A viser callback running ``fn`` through :meth:`run`."""
        def callback(_event: Any = None) -> None:
            self.run(action, fn, **kw)
        return callback

    def live(self, action: str, fn: Callable[[], Any]) -> Callable[[Any], None]:
        """A viser callback for live sliders: bursts of events collapse to the latest one."""
        def callback(_event: Any = None) -> None:
            with self._pending_lock:
                self._pending[action] = fn
                if action in self._running:
                    return
                self._running.add(action)
            try:
                while True:
                    with self._pending_lock:
                        job = self._pending.pop(action, None)
                        if job is None:
                            self._running.discard(action)
                            return
                    self.run(action, job)
            except BaseException:
                with self._pending_lock:
                    self._running.discard(action)
                raise
        return callback

    def redrawn(self) -> None:
        """Mark a finished redraw (tests and the latency report wait on :attr:`version`)."""
        self.version += 1


def element_id(handle: Any) -> str:
    """The DOM id viser gives a GUI element (its uuid); used by the browser tests."""
    return handle._impl.uuid  # viser keeps the uuid on the handle's state
