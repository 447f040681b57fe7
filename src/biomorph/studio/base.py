"""Shared pieces of the studio's tabs: the tab base class, error capture, latency log.

A tab builds its GUI inside its viser tab, draws into its own scene frame
(``/<key>``), and runs every user action through :meth:`StudioTab.run`, which

* serialises actions of one tab (a lock), shows the tab's 3-D scene,
* times the action (edit -> scene messages queued) into the app's :class:`LatencyLog`,
* turns any exception into a message in the page (the tab's status line and a
  notification) so the page stays usable, and clears that message after the next action
  that succeeds,
* takes one of the page's heavy-job slots for long actions (``heavy=True``).

Every string a tab shows that comes from a user or a file goes through :func:`plain`
(the status line is markdown, and viser's markdown renders raw HTML).

Live sliders use :meth:`StudioTab.live`, which coalesces a burst of slider events into
"compute the latest value" so dragging never queues stale work.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from biomorph.errors import BiomorphError


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
        return {
            k: {
                "n": int(v.size),
                "median_ms": float(np.median(v)),
                "p95_ms": float(np.percentile(v, 95)),
                "max_ms": float(v.max()),
            }
            for k, v in sorted(items.items())
        }

    def markdown(self, prefix: str = "") -> str:
        """A small markdown table of :meth:`summary` for names starting with ``prefix``."""
        rows = [(k, s) for k, s in self.summary().items() if k.startswith(prefix)]
        if not rows:
            return "_no edits measured yet_"
        lines = ["| action | n | median ms | max ms |", "|---|---|---|---|"]
        lines += [
            f"| {k.split('/', 1)[-1]} | {s['n']} | {s['median_ms']:.1f} | {s['max_ms']:.1f} |"
            for k, s in rows
        ]
        return "\n".join(lines)


#: Characters with a meaning in markdown or HTML, escaped by :func:`plain`.
_SPECIAL = set("\\`*_{}[]()#+-.!|~>")
_HTML = {"<": "&lt;", ">": "&gt;", "&": "&amp;", '"': "&quot;", "'": "&#39;"}


def plain(text: object) -> str:
    """``text`` made inert for a markdown element: HTML characters become entities and
    markdown characters are backslash-escaped, so a file name, an error message or a
    typed key list shows as the characters it holds and never as markup or script."""
    out = []
    for ch in str(text):
        if ch in _HTML:
            out.append(_HTML[ch])
        elif ch in _SPECIAL:
            out.append("\\" + ch)
        elif ch in "\r\n\t" or ch.isprintable():
            out.append(" " if ch in "\r\n\t" else ch)
        else:
            out.append("\ufffd")
    return "".join(out)


def error_text(exc: BaseException) -> str:
    """One line for the page: the message of a user error, type and message otherwise."""
    if isinstance(exc, BiomorphError):
        return str(exc)
    if isinstance(exc, OSError):
        return f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": ")
    return f"{type(exc).__name__}: {exc}"


class StudioTab:
    """Base class of a studio tab.

    Subclasses set :attr:`key`, :attr:`label` and :attr:`getting_started`, implement
    :meth:`build` (called inside the tab's GUI container, again after a page reload),
    :meth:`restore` (redraw the content from the tab's state after a rebuild) and may
    implement :meth:`requirement` (a reason string when the pillar's API is not
    importable) and :meth:`close`. ``app`` is the tab's
    :class:`~biomorph.studio.session.Session` (one page's studio).
    """

    key: str = "tab"
    label: str = "Tab"
    #: One line telling a first-time user what to do first in this tab.
    getting_started: str = ""
    #: Y-up content (skeletons, motion, leaves) is turned so +Y points up in viser's Z-up view.
    y_up: bool = False
    #: Parameter changes Ctrl-Z can undo.
    UNDO_DEPTH = 50

    def __init__(self, app: Any) -> None:
        self.app = app
        self.lock = threading.RLock()
        self.version = 0  # incremented on every redraw (tests wait on it)
        self.last_error: str | None = None
        self.status = None  # viser markdown handle, set by the session
        self.status_text = "Ready."
        self.history: list[tuple[Any, Any]] = []
        self._status_changed = False
        self._pending: dict[str, Callable[[], None]] = {}
        self._pending_lock = threading.Lock()
        self._running: set[str] = set()

    # ------------------------------------------------------------------ to override
    def requirement(self) -> str | None:
        """``None`` if the tab can be built, else why not (shown in the tab)."""
        return None

    def build(self) -> None:
        """Add the tab's GUI elements (inside the tab's container) and initial scene."""

    def restore(self) -> None:
        """Redraw the 3-D content from the tab's state (after the page was reloaded)."""

    def close(self) -> None:
        """Stop background work (players, jobs)."""

    # ------------------------------------------------------------------ helpers
    @property
    def scene(self):
        return self.app.scene

    @property
    def gui(self):
        return self.app.gui

    @property
    def root(self) -> str:
        """Scene-tree prefix of this tab's 3-D content."""
        return f"/{self.key}"

    def set_status(self, text: str) -> None:
        """Show ``text`` (markdown: user/file strings must be passed through
        :func:`plain`) on the tab's status line."""
        self.status_text = text
        self._status_changed = True
        if self.status is not None:
            self.status.content = text

    def fail(self, exc: BaseException, action: str) -> None:
        """Show an error in the page (status line + notification); keep the page usable."""
        msg = error_text(exc)
        self.last_error = msg
        if not isinstance(exc, BiomorphError | OSError):
            traceback.print_exception(exc)
        self.set_status(f"**Error** ({plain(action)}): {plain(msg)}")
        self.app.notify(f"{self.label}: {action} failed", msg, color="red")

    def remember(self, handle: Any, old: Any) -> None:
        """Record a parameter change (``handle`` had ``old``) for :meth:`undo_parameter`."""
        self.history.append((handle, old))
        del self.history[: -self.UNDO_DEPTH]

    def undo_parameter(self) -> None:
        """Put the last changed parameter back (its callbacks redraw)."""
        from biomorph.errors import InputError

        if not self.history:
            raise InputError("nothing to undo in this tab")
        handle, old = self.history.pop()
        handle.value = old
        self.set_status(
            f"Undone: {plain(getattr(handle, 'label', 'value'))} is back to {plain(old)}."
        )

    def run(
        self,
        action: str,
        fn: Callable[[], Any],
        *,
        timed: bool = True,
        show: bool = True,
        heavy: bool = False,
    ) -> Any:
        """Run ``fn`` as the user action ``action``: lock, time, show errors in the page;
        ``heavy`` actions take one of the page's job slots (refused when all are busy)."""
        with self.lock:
            if show:
                self.app.show_scene(self.key)
            self._status_changed = False
            t0 = time.perf_counter()
            release = None
            try:
                if heavy:
                    release = self.app.job_slot()
                result = fn()
            except Exception as exc:  # noqa: BLE001 - every failure goes to the page
                self.fail(exc, action)
                return None
            finally:
                if release is not None:
                    release()
            dt = time.perf_counter() - t0
            if timed:
                self.app.latency.record(f"{self.key}/{action}", dt)
            if self.last_error is not None and not self._status_changed:
                self.set_status("Ready.")
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
