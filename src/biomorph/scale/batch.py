"""Run one function over many items on a dask.distributed cluster, robustly and resumably.

:func:`run_batch` is the scale-out runner the tree and creature batch commands call::

    from biomorph.scale import run_batch

    report = run_batch(files, skeletonize_file, key=lambda p: p.stem,
                       done=lambda p: (out / f"{p.stem}.ply").exists(), workers=4)
    print(report.summary())            # "trees: 118 ok, 2 failed, 40 skipped in 312.4 s"

* **Where it runs**: a ``LocalCluster(n_workers=workers, threads_per_worker=1,
  processes=True)`` bound to 127.0.0.1 (scheduler, workers, nannies, dashboards) by
  default (one process per core, so numba/numpy code does not fight
  over the GIL); ``scheduler="tcp://host:8786"`` connects to an existing cluster instead;
  ``workers=0`` — or a single item left to do — runs serially in this process (tests, small
  jobs, debugging with breakpoints).
* **Errors**: an exception in one item is caught where it happens and reported in
  ``BatchReport.failed`` as ``(key, "ValueError: message")`` (the traceback is kept in
  ``BatchReport.tracebacks``); the other items carry on. A worker process that dies counts
  as a failure of the items it held.
* **Resuming**: items whose ``done(item)`` is true are skipped (``BatchReport.skipped``).
  With ``out_dir`` and no ``done``, the runner keeps its own completion markers in
  ``out_dir/.batch_done/``: a marker is written only after ``func`` returned (so after every
  output of the item), and it holds a digest of the item and of ``options`` (whatever
  changes the outputs: format, method, spacing …). An item counts as done only when its
  marker exists *and* its digest matches, so a re-run with other options redoes it and a
  run killed at any point (SIGKILL included) redoes exactly the unfinished items.
  Temporary files of killed runs are removed from ``out_dir`` at the start (under the
  folder's lock, :func:`biomorph._cli.folder_lock`); ``out_dir/batch_report.json`` is
  written at the end.
* **Ctrl-C** cancels outstanding futures, closes the client and the cluster, and re-raises
  ``KeyboardInterrupt`` (the CLI exits with 130); finished items keep their markers.
* **Determinism**: ``func`` runs once per item with the item alone as input, so results are
  identical to a serial run (and returned in item order in ``BatchReport.results``).

``func`` and the items must be picklable; functions defined at module level in an
importable module are the safe choice (dask's cloudpickle also ships lambdas and closures).
"""

from __future__ import annotations

import contextlib
import gc
import logging
import os
import re
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Generic, TypeVar

from biomorph.errors import BiomorphError, ParameterError
from biomorph.progress import task

T = TypeVar("T")
R = TypeVar("R")

MARKER_DIR = ".batch_done"
#: every port of a LocalCluster started here listens on this address only
LOOPBACK = "127.0.0.1"
REPORT_NAME = "batch_report.json"


@dataclass
class BatchReport(Generic[R]):
    """Outcome of :func:`run_batch`.

    Attributes
    ----------
    ok : keys of items that finished, in item order.
    failed : ``(key, "ExceptionType: message")`` per failed item, in item order.
    skipped : keys of items skipped because ``done(item)`` was true.
    seconds : wall-clock time of the whole batch (s), cluster start-up included.
    item_seconds : ``{key: seconds}`` spent inside ``func`` per finished or failed item.
    results : ``{key: result}`` of finished items, in item order.
    tracebacks : ``{key: formatted traceback}`` of failed items.
    workers : worker processes used (0 = serial, in-process).
    scheduler : scheduler address, ``"local"`` for a LocalCluster, ``"serial"``.
    """

    description: str = "batch"
    ok: list[str] = field(default_factory=list)
    failed: list[tuple[str, str]] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    seconds: float = 0.0
    item_seconds: dict[str, float] = field(default_factory=dict)
    results: dict[str, R] = field(default_factory=dict)
    tracebacks: dict[str, str] = field(default_factory=dict)
    workers: int = 0
    scheduler: str = "serial"

    @property
    def total(self) -> int:
        return len(self.ok) + len(self.failed) + len(self.skipped)

    @property
    def exit_code(self) -> int:
        """0 when nothing failed, 1 otherwise (for CLI commands)."""
        return 1 if self.failed else 0

    def summary(self) -> str:
        """One line: ``"trees: 118 ok, 2 failed, 40 skipped in 312.4 s"``."""
        return (
            f"{self.description}: {len(self.ok)} ok, {len(self.failed)} failed, "
            f"{len(self.skipped)} skipped in {self.seconds:.1f} s"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary for ``--json`` (results are left out: they may be any type)."""
        times = list(self.item_seconds.values())
        return {
            "description": self.description,
            "total": self.total,
            "n_ok": len(self.ok),
            "n_failed": len(self.failed),
            "n_skipped": len(self.skipped),
            "ok": list(self.ok),
            "failed": [
                {"key": k, "error": msg, "traceback": self.tracebacks.get(k, "")}
                for k, msg in self.failed
            ],
            "skipped": list(self.skipped),
            "seconds": round(self.seconds, 6),
            "item_seconds": {k: round(v, 6) for k, v in self.item_seconds.items()},
            "mean_item_seconds": round(sum(times) / len(times), 6) if times else 0.0,
            "workers": self.workers,
            "scheduler": self.scheduler,
        }


# --------------------------------------------------------------------------- worker side
def _call(func: Callable[[Any], Any], item: Any) -> tuple[bool, Any, float, str]:
    """Run ``func(item)`` catching any exception: ``(ok, result_or_message, seconds, tb)``."""
    t0 = time.perf_counter()
    try:
        result = func(item)
    except Exception as exc:  # noqa: BLE001 - reported per item; the batch carries on
        return (
            False,
            f"{type(exc).__name__}: {exc}",
            time.perf_counter() - t0,
            traceback.format_exc(),
        )
    return True, result, time.perf_counter() - t0, ""


# --------------------------------------------------------------------------- client side
def _marker(out_dir: Path, key: str) -> Path:
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", key).strip(".") or "_"
    if safe != key:  # keep distinct keys distinct after sanitising
        safe = f"{safe}-{_digest(key)}"
    return out_dir / MARKER_DIR / safe


def _digest(text: str) -> str:
    import hashlib

    return hashlib.sha1(text.encode("utf-8")).hexdigest()[:10]


def fingerprint(item: Any, options: Any = None) -> str:
    """Digest of an item and the options that shape its outputs (stable across runs for
    JSON-like values, paths and dataclasses)."""
    import hashlib
    import json

    from biomorph._cli import to_jsonable

    text = json.dumps([to_jsonable(item), to_jsonable(options)], sort_keys=True, default=repr)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _marker_matches(path: Path, digest: str) -> bool:
    try:
        return path.read_text(encoding="utf-8").strip() == digest
    except (OSError, UnicodeDecodeError):
        return False


@contextlib.contextmanager
def _client(workers: int, scheduler: str | None) -> Iterator[Any]:
    """A dask client on a new LocalCluster or on ``scheduler``; both closed on exit."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - depends on the installed extras
        raise BiomorphError(
            "dask.distributed is not installed; install biomorph[scale] or "
            "run serially with workers=0"
        ) from None
    cluster = None
    client = None
    try:
        # Ctrl-C while the cluster starts would orphan half-started worker processes:
        # hold it until start-up is complete, then shut down cleanly below
        with _held_interrupt() as interrupted:
            if scheduler is not None:
                try:
                    _check_address(scheduler)
                    client = Client(scheduler, timeout="20s")
                except (OSError, ValueError, TypeError) as exc:  # unreachable or malformed
                    # a Client that failed in __init__ closes itself in __del__; let that
                    # run now: run by the garbage collector inside the next Client's loop
                    # start-up it waits for the lock that start-up holds (a hang)
                    gc.collect()
                    raise BiomorphError(
                        f"cannot reach the dask scheduler at {scheduler!r} "
                        f"({exc}); expected an address like tcp://host:8786"
                    ) from None
            else:
                try:
                    # scheduler, workers, nannies and dashboard listen on the loopback
                    # only: a batch run must not open ports to the network. The workers
                    # start with SIGINT ignored, so a Ctrl-C to the process group cannot
                    # interrupt their interpreter start-up (a traceback per worker; the
                    # blocked mask of this thread does not reach them: dask spawns them
                    # from threads whose mask is empty); here it is held and handled below.
                    with _blocked_sigint(), _workers_ignore_sigint():
                        cluster = LocalCluster(
                            n_workers=workers,
                            threads_per_worker=1,
                            processes=True,
                            host=LOOPBACK,
                            dashboard_address=f"{LOOPBACK}:0",
                            worker_dashboard_address=f"{LOOPBACK}:0",
                            silence_logs=logging.ERROR,
                        )
                except (RuntimeError, OSError) as exc:
                    if interrupted():  # Ctrl-C reached the workers while they started
                        raise KeyboardInterrupt from None
                    raise BiomorphError(
                        f"could not start a dask LocalCluster with {workers} workers ({exc}); "
                        "a script that calls run_batch must do so under "
                        "`if __name__ == '__main__':` (workers are spawned processes), "
                        "or use workers=0"
                    ) from None
                client = Client(cluster)
        if interrupted():
            raise KeyboardInterrupt
        yield client
    finally:
        with _held_interrupt() as interrupted:
            if client is not None:
                with contextlib.suppress(Exception):
                    client.close()
            if cluster is not None:
                with contextlib.suppress(Exception):
                    cluster.close()
        if interrupted():
            raise KeyboardInterrupt


def _check_address(scheduler: str) -> None:
    """ValueError unless ``scheduler`` reads as a dask address with a port
    (``tcp://host:8786``), before any Client is made for it."""
    from distributed.comm.addressing import parse_address, parse_host_port

    _, location = parse_address(scheduler)
    parse_host_port(location)


@contextlib.contextmanager
def _workers_ignore_sigint() -> Iterator[None]:
    """Worker processes spawned during the block start with SIGINT ignored.

    The blocked mask of :func:`_blocked_sigint` does not reach them: the threads dask's
    cluster spawns its workers from run with an empty mask (``SigBlk: 0`` in
    ``/proc/<pid>/status``, distributed 2026.8), so a Ctrl-C to the process group while a
    worker's interpreter was still importing printed its KeyboardInterrupt traceback.
    An ignored disposition survives ``exec`` and Python keeps it: multiprocessing's spawn
    runs a two-line ``/bin/sh`` wrapper (``trap '' INT`` then ``exec`` the interpreter)
    in a private temporary folder, removed after the block (checked by running it once: a
    folder mounted noexec leaves the spawn as it was). The workers never act on
    SIGINT; this process handles Ctrl-C and closes the cluster, which stops them. POSIX
    with ``/bin/sh`` only; elsewhere the block runs unchanged."""
    import multiprocessing.spawn as mp_spawn
    import shlex
    import shutil
    import subprocess
    import tempfile

    exe = mp_spawn.get_executable()
    if os.name != "posix" or not os.path.exists("/bin/sh") or not exe:
        yield
        return
    folder = tempfile.mkdtemp(prefix="biomorph-workers-")
    wrapper = os.path.join(folder, "python")
    with open(wrapper, "w", encoding="utf-8") as fh:
        fh.write(f"#!/bin/sh\ntrap '' INT\nexec {shlex.quote(os.fsdecode(exe))} \"$@\"\n")
    os.chmod(wrapper, 0o700)
    try:  # a temporary folder mounted noexec cannot run it: spawn as before
        usable = subprocess.run([wrapper, "-S", "-c", ""], timeout=30).returncode == 0
    except (OSError, subprocess.SubprocessError):
        usable = False
    if usable:
        mp_spawn.set_executable(wrapper)
    try:
        yield
    finally:
        if usable:
            mp_spawn.set_executable(exe)
        shutil.rmtree(folder, ignore_errors=True)


@contextlib.contextmanager
def _blocked_sigint() -> Iterator[None]:
    """Block SIGINT in this thread for the block (children started meanwhile inherit the
    mask); a Ctrl-C that arrives is delivered when the block ends."""
    import signal

    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - not POSIX
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def _held_interrupt() -> Iterator[Callable[[], bool]]:
    """Defer SIGINT (Ctrl-C) for the duration of the block; yields ``interrupted()``.

    A deferred Ctrl-C is handed on at the end to the handler that was there before (the
    CLI's interrupt guard records it and raises ``KeyboardInterrupt``; Python's default
    raises it too). Otherwise the guard never learnt of it: a Ctrl-C while the cluster
    started ended the batch with exit 130 but without the CLI's one-line message.
    Only possible in the main thread; elsewhere the block runs unprotected.
    """
    import signal
    import threading

    hits: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: hits.append(signum))
    try:
        yield lambda: bool(hits)
    finally:
        signal.signal(signal.SIGINT, previous)
        if hits and callable(previous):
            previous(signal.SIGINT, None)


def run_batch(
    items: Sequence[T],
    func: Callable[[T], R],
    *,
    out_dir: str | os.PathLike[str] | None = None,
    key: Callable[[T], str] = str,
    done: Callable[[T], bool] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    description: str = "batch",
    options: Any = None,
) -> BatchReport[R]:
    """Apply ``func`` to every item, in parallel on dask.distributed; never stop on one error.

    Parameters
    ----------
    items : the work items (paths, seeds, parameter dicts …); must be picklable.
    func : ``func(item) -> result``; picklable (module-level function). Exceptions it raises
        are reported per item.
    out_dir : optional output folder; gets ``batch_report.json`` and, when ``done`` is not
        given, the runner's own completion markers (``.batch_done/``) so re-runs resume.
    key : names each item in the report (default ``str``); keys must be unique.
    done : ``done(item) -> bool``; true items are skipped (e.g. "output file exists").
    workers : worker processes (default: CPU count, at most the number of items);
        ``0`` runs serially in this process.
    scheduler : address of a running dask scheduler (``tcp://host:8786``); ``workers`` is
        then ignored.
    progress : show a rich progress bar on stderr when it is a terminal.
    description : label for the bar and the report.
    options : what else changes the outputs (JSON-like); part of each completion marker.

    Returns a :class:`BatchReport`. ``KeyboardInterrupt`` cancels outstanding work, shuts the
    cluster down and propagates.
    """
    t_start = time.perf_counter()
    items = list(items)
    if workers is not None and (not isinstance(workers, int) or workers < 0):
        raise ParameterError(
            f"workers must be a non-negative integer (0 = serial); got {workers!r}"
        )
    keys = [str(key(item)) for item in items]
    if len(set(keys)) != len(keys):
        from collections import Counter

        dup = next(k for k, c in Counter(keys).items() if c > 1)
        raise ParameterError(f"key {dup!r} names more than one item; keys must be unique")
    out = None if out_dir is None else Path(out_dir)
    with contextlib.ExitStack() as stack:
        if out is not None:
            from biomorph._cli import folder_lock

            stack.enter_context(folder_lock(out, option="out_dir"))
        return _run_batch(
            items,
            keys,
            func,
            out,
            done,
            workers,
            scheduler,
            progress,
            description,
            options,
            t_start,
        )


def _run_batch(
    items: list[Any],
    keys: list[str],
    func: Callable[[Any], Any],
    out: Path | None,
    done: Callable[[Any], bool] | None,
    workers: int | None,
    scheduler: str | None,
    progress: bool,
    description: str,
    options: Any,
    t_start: float,
) -> BatchReport[Any]:
    markers = out is not None and done is None
    if markers:
        (out / MARKER_DIR).mkdir(exist_ok=True)  # type: ignore[operator]
    digests = [fingerprint(item, options) for item in items] if markers else []

    def is_done(i: int) -> bool:
        if done is not None:
            return bool(done(items[i]))
        return markers and _marker_matches(
            _marker(out, keys[i]),  # type: ignore[arg-type]
            digests[i],
        )

    report: BatchReport[Any] = BatchReport(description=description)
    todo = []
    for i in range(len(items)):
        if is_done(i):
            report.skipped.append(keys[i])
        else:
            todo.append(i)

    n_workers = (os.cpu_count() or 1) if workers is None else workers
    n_workers = min(n_workers, len(todo))
    serial = workers == 0 or (len(todo) <= 1 and scheduler is None)
    outcomes: dict[int, tuple[bool, Any, float, str]] = {}

    def record(i: int, outcome: tuple[bool, Any, float, str]) -> None:
        outcomes[i] = outcome
        if outcome[0] and markers:  # last: after every output of the item exists
            from biomorph.io.atomic import write_text

            write_text(_marker(out, keys[i]), digests[i] + "\n")  # type: ignore[arg-type]

    with task(description, total=len(todo), enabled=None if progress else False) as advance:
        if serial or not todo:
            report.workers, report.scheduler = 0, "serial"
            for i in todo:
                record(i, _call(func, items[i]))
                advance()
        else:
            with _client(n_workers, scheduler) as client:
                report.scheduler = scheduler or "local"
                report.workers = (
                    n_workers
                    if scheduler is None
                    else len(client.scheduler_info().get("workers", {}))
                )
                _run_distributed(client, func, items, todo, record, advance)

    for i in todo:  # item order, not completion order
        ok, value, seconds, tb = outcomes[i]
        report.item_seconds[keys[i]] = seconds
        if ok:
            report.ok.append(keys[i])
            report.results[keys[i]] = value
        else:
            report.failed.append((keys[i], value))
            report.tracebacks[keys[i]] = tb
    report.seconds = time.perf_counter() - t_start
    if out is not None:
        import json

        from biomorph.io.atomic import write_text

        write_text(out / REPORT_NAME, json.dumps(report.to_dict(), indent=2) + "\n")
    return report


def _run_distributed(
    client: Any,
    func: Callable[[Any], Any],
    items: list[Any],
    todo: list[int],
    record: Callable[[int, tuple[bool, Any, float, str]], None],
    advance: Callable[..., None],
) -> None:
    """Submit every item, collect results as they complete; cancel all on Ctrl-C."""
    from dask.distributed import as_completed

    futures = client.map(partial(_call, func), [items[i] for i in todo], pure=False)
    index = {f.key: i for f, i in zip(futures, todo, strict=True)}
    try:
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                outcome = fut.result()
            except Exception as exc:  # noqa: BLE001 - the worker died or the task was lost
                name = type(exc).__name__
                msg = (
                    f"{name}: the worker process died while running this item "
                    "(crash, os._exit or out of memory); see the dask worker log"
                    if name == "KilledWorker"
                    else f"{name}: {exc}"
                )
                outcome = (False, msg, 0.0, "")
            record(i, outcome)
            advance()
            fut.release()
    except BaseException:
        with contextlib.suppress(Exception):
            client.cancel(futures, force=True)
        raise
