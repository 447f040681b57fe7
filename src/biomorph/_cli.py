"""Shared command-line helpers below the pillars: consoles, one JSON converter, ``emit``,
range-checked option callbacks and output-extension checks.

Every pillar's ``cli.py`` imports from here (never from :mod:`biomorph.cli`, which sits above
the pillars), so every command prints the same way:

* ``emit(summary, as_json)`` prints a summary dict as JSON (``--json``) or as one rich table;
* ``to_jsonable`` is the only JSON converter: numpy scalars/arrays, paths, dataclasses,
  and NaN/inf mapped to ``null`` (JSON has no NaN);
* ``bounded(...)`` builds a typer/click callback that refuses NaN, inf and out-of-range values
  with one line naming the option and the accepted range (a :class:`ParameterError`, exit 2);
* ``check_suffix(path, allowed, option)`` refuses an output whose extension no writer handles;
* ``check_memory(what, n_bytes)`` refuses a request estimated to need more memory than the
  machine has available (the estimate is in the message);
* ``interrupt_guard()`` is the one Ctrl-C handler of every command (see below);
* ``folder_lock(folder)`` keeps two runs out of one output folder and cleans the temporary
  files of earlier killed runs; ``file_lock(path)`` serialises appends to one file.

Ctrl-C: the first SIGINT raises ``KeyboardInterrupt`` in the main thread (atomic writers
delete their temporary files, batch runners cancel their work) and arms a watchdog thread,
woken through ``signal.set_wakeup_fd`` even while the main thread sits in C code. If the
command has not returned within ``INTERRUPT_GRACE`` (0.5 s), the watchdog deletes the
temporary files still in flight, prints the same line and exits with 130 itself, so every
command stops within a second.

This module imports only the standard library, ``rich`` and :mod:`biomorph.errors` at import
time, so ``biomorph --help`` stays fast.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from rich.console import Console

from biomorph.core.jsonable import dumps, to_jsonable
from biomorph.errors import ParameterError, UnsupportedFormatError, require_memory

err_console = Console(stderr=True, soft_wrap=True, highlight=False)
out_console = Console(soft_wrap=True, highlight=False)

__all__ = [
    "INTERRUPT_LINE",
    "bounded",
    "check_memory",
    "check_suffix",
    "check_value",
    "emit",
    "err_console",
    "file_lock",
    "folder_lock",
    "interrupt_guard",
    "out_console",
    "print_json",
    "to_jsonable",
]

INTERRUPT_LINE = "interrupted; no partial output was written"
EXIT_INTERRUPTED = 130
#: seconds between the first Ctrl-C and the watchdog's hard exit
INTERRUPT_GRACE = 0.5


def print_json(data: Any) -> None:
    """Print ``data`` as strict JSON on stdout."""
    sys.stdout.write(dumps(data) + "\n")


def emit(summary: Mapping[str, Any], as_json: bool = False, title: str | None = None) -> None:
    """Print a command's result: JSON with ``--json``, else a two-column rich table."""
    if as_json:
        print_json(summary)
        return
    from rich.table import Table

    table = Table(title=title, show_header=False, title_justify="left")
    for k, v in to_jsonable(summary).items():
        if isinstance(v, float):
            v = f"{v:.6g}"
        elif isinstance(v, dict | list):
            v = json.dumps(v)
        table.add_row(str(k), str(v))
    out_console.print(table)


def _fmt_range(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return "a finite number"


def check_value(
    name: str,
    value: float | int,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> None:
    """Raise :class:`ParameterError` unless ``value`` is finite and inside the range.

    >>> check_value("--k", 0, lo=1)
    Traceback (most recent call last):
    ...
    biomorph.errors.ParameterError: --k: got 0; expected >= 1
    """
    expected = _fmt_range(lo, hi, lo_open, hi_open)
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(f"{name}: got {value!r}; expected {expected}") from None
    bad = not math.isfinite(v)
    if lo is not None:
        bad |= v <= lo if lo_open else v < lo
    if hi is not None:
        bad |= v >= hi if hi_open else v > hi
    if bad:
        raise ParameterError(f"{name}: got {value!r}; expected {expected}")


def bounded(
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> Callable[[Any, Any, Any], Any]:
    """A typer/click option callback checking each given value with :func:`check_value`.

    ``typer.Option(..., callback=bounded(lo=0, lo_open=True))`` refuses 0, negatives, NaN and
    inf at parse time; ``None`` (option not given) passes. Lists are checked element-wise.
    """

    def callback(ctx: Any, param: Any, value: Any) -> Any:
        if value is None:
            return value
        name = "/".join(getattr(param, "opts", []) or [getattr(param, "name", "value")])
        values: Iterable[Any] = value if isinstance(value, list | tuple) else (value,)
        for v in values:
            if v is not None:
                check_value(name, v, lo, hi, lo_open=lo_open, hi_open=hi_open)
        return value

    return callback


def check_suffix(path: str | os.PathLike[str], allowed: Iterable[str], option: str) -> None:
    """Refuse an output path whose extension is not one of ``allowed`` (e.g. ``(".png",)``)."""
    allowed = tuple(a.lower() for a in allowed)
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix not in allowed:
        raise UnsupportedFormatError(
            f"{option} {os.fspath(path)}: extension {suffix or '(none)'!r} not written; "
            f"expected one of {', '.join(allowed)}"
        )


def check_memory(what: str, n_bytes: float) -> None:
    """Refuse ``what`` (e.g. ``"--points 2000000000"``) when its estimated memory
    ``n_bytes`` exceeds the share of available memory one request may take."""
    require_memory(what, n_bytes)


# --------------------------------------------------------------------------- Ctrl-C
def _kill_children() -> None:
    """SIGKILL this process's descendants (batch workers, resource trackers): a hard exit
    must not leave them running or printing."""
    with contextlib.suppress(Exception):  # best effort on the way out
        import psutil

        for child in psutil.Process().children(recursive=True):
            with contextlib.suppress(Exception):
                child.kill()


def _hard_exit() -> None:
    from biomorph.io.atomic import discard_pending

    discard_pending()
    for lock in list(_HELD_LOCKS):
        with contextlib.suppress(OSError):
            os.unlink(lock)
    _kill_children()
    with contextlib.suppress(OSError):
        os.write(2, (INTERRUPT_LINE + "\n").encode())
    os._exit(EXIT_INTERRUPTED)


@contextlib.contextmanager
def interrupt_guard(grace: float = INTERRUPT_GRACE) -> Iterator[Callable[[], bool]]:
    """Install the one Ctrl-C handler for the block; yields ``interrupted()``.

    Outside the main thread (or when signals cannot be set) the block runs unguarded.
    """
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    state = {"hit": False, "done": False}
    r, w = os.pipe()
    os.set_blocking(w, False)

    def handler(signum: int, frame: Any) -> None:
        state["hit"] = True
        raise KeyboardInterrupt

    def watchdog() -> None:
        while True:
            try:
                data = os.read(r, 64)
            except OSError:
                return
            if state["done"] or not data:
                return
            if signal.SIGINT in data:
                deadline = time.monotonic() + grace
                while time.monotonic() < deadline:
                    if state["done"]:
                        return
                    time.sleep(0.02)
                if not state["done"]:
                    _hard_exit()
                return

    try:
        previous_fd = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
        previous = signal.signal(signal.SIGINT, handler)
    except (ValueError, OSError):  # pragma: no cover - e.g. an embedded interpreter
        os.close(r)
        os.close(w)
        yield lambda: False
        return
    thread = threading.Thread(target=watchdog, name="biomorph-interrupt", daemon=True)
    thread.start()
    try:
        yield lambda: bool(state["hit"])
    finally:
        state["done"] = True
        signal.signal(signal.SIGINT, previous)
        signal.set_wakeup_fd(previous_fd)
        with contextlib.suppress(OSError):
            os.write(w, b"\0")
        thread.join(1.0)
        os.close(r)
        os.close(w)


# --------------------------------------------------------------------------- locks
LOCK_NAME = ".biomorph.lock"
_HELD_LOCKS: set[str] = set()


@contextlib.contextmanager
def file_lock(path: str | os.PathLike[str], what: str = "file") -> Iterator[None]:
    """Hold an exclusive advisory lock on ``path`` (created if missing) for the block.

    Waits up to 30 s for another run to finish with it, then refuses. The lock dies with the
    process (``flock``), so a killed run never leaves it stuck.
    """
    import fcntl

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(p, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        deadline = time.monotonic() + 30.0
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise ParameterError(
                        f"{os.fspath(path)}: {what} is locked by another "
                        "biomorph run; try again when it has finished"
                    ) from None
                time.sleep(0.05)
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike[str], option: str = "--out") -> Iterator[list[Path]]:
    """Claim the output ``folder`` for this run (refusing at once if another run holds it)
    and remove the temporary files of earlier killed runs; yields the files removed."""
    import fcntl

    from biomorph.io.atomic import clean_stale

    root = Path(folder)
    if root.exists() and not root.is_dir():
        raise ParameterError(f"{option} {os.fspath(folder)}: is a file; expected a folder")
    created = not root.exists()
    root.mkdir(parents=True, exist_ok=True)
    lock = root / LOCK_NAME
    if os.path.realpath(lock) in _HELD_LOCKS:  # held by this process (CLI, then batch)
        yield []
        return
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    locked = False
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ParameterError(
                f"{option} {os.fspath(folder)}: another biomorph run is "
                "writing into this folder; wait for it or choose another "
                "folder"
            ) from None
        locked = True
        _HELD_LOCKS.add(os.path.realpath(lock))
        yield clean_stale(root)
    finally:
        _HELD_LOCKS.discard(os.path.realpath(lock))
        if locked:  # leave no lock file behind (a waiting run then fails to lock: refused)
            with contextlib.suppress(OSError):
                lock.unlink()
        os.close(fd)
        if locked and created:  # a run that wrote nothing leaves no empty folder either
            with contextlib.suppress(OSError):
                root.rmdir()
