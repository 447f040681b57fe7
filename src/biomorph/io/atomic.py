"""Atomic file writing: write to a temporary file beside the target, then rename.

A failure (exception, Ctrl-C) never leaves a partial or truncated output file behind:

* the temporary file is ``.<name>.tmp-XXXXXXXX<suffix>`` in the target's folder (same file
  system, so the final ``os.replace`` is atomic);
* every temporary file in flight is kept in a registry so the CLI's Ctrl-C watchdog can
  delete them before a hard exit (:func:`discard_pending`);
* a run killed with SIGKILL cannot clean up: :func:`clean_stale` removes such leftovers from
  an output folder once the caller holds that folder's lock (``biomorph._cli.folder_lock``);
* an ``OSError`` (permission denied, disk full) names the *target*, never the hidden
  temporary file;
* a path registered with :func:`protect` (the inputs of the running command) is never
  overwritten: writing onto it raises :class:`biomorph.errors.InputError`.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

from biomorph.errors import InputError

TMP_MARK = ".tmp-"
#: ``mkstemp`` names: ``.<target name>.tmp-`` + 8 random characters + suffix
_STALE = re.compile(r"^\..+\.tmp-[a-z0-9_]{8}(\.[^.]*)?$")
_PENDING: set[Path] = set()
_PROTECTED: set[str] = set()
_LOCK = threading.Lock()


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _key(path: str | os.PathLike[str]) -> str:
    return os.path.realpath(os.fspath(path))


def protect(paths: Iterable[str | os.PathLike[str]]) -> None:
    """Refuse, until :func:`unprotect`, any atomic write onto one of ``paths``."""
    with _LOCK:
        _PROTECTED.update(_key(p) for p in paths)


def unprotect(paths: Iterable[str | os.PathLike[str]]) -> None:
    with _LOCK:
        _PROTECTED.difference_update(_key(p) for p in paths)


def _renamed(exc: OSError, tmp: Path, target: Path) -> OSError:
    """``exc`` re-targeted at ``target`` when it names the temporary file or nothing."""
    named = None if exc.filename is None else os.fspath(exc.filename)
    if named not in (None, os.fspath(tmp)):
        return exc
    return type(exc)(exc.errno, exc.strerror or str(exc), os.fspath(target))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; on success rename it onto ``path``.

    ``suffix`` defaults to the target's own suffix so libraries that choose behaviour by
    extension (laspy, trimesh) see the right one.
    """
    target = Path(path)
    if _PROTECTED and _key(target) in _PROTECTED:
        raise InputError(
            f"{os.fspath(target)}: is an input of this command and would be "
            "overwritten; choose another output path or folder"
        )
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}{TMP_MARK}",
            suffix=suffix or target.suffix or ".tmp",
            dir=target.parent,
        )
    except OSError as exc:
        raise _renamed(exc, Path(exc.filename or ""), target) from None
    os.close(fd)
    tmp_path = Path(tmp)
    with _LOCK:
        _PENDING.add(tmp_path)
    # mkstemp creates 0600 files; give outputs the permissions a plain open() would
    os.chmod(tmp_path, 0o666 & ~_current_umask())
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise _renamed(exc, tmp_path, target) from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise
    finally:
        with _LOCK:
            _PENDING.discard(tmp_path)


def discard_pending() -> list[Path]:
    """Delete every temporary file still in flight (used before a hard exit); return them."""
    with _LOCK:
        pending = list(_PENDING)
        _PENDING.clear()
    for p in pending:
        with contextlib.suppress(OSError):
            p.unlink()
    return pending


def clean_stale(folder: str | os.PathLike[str], recursive: bool = True) -> list[Path]:
    """Remove the temporary files of earlier, killed runs from ``folder``; return them.

    Only names this module creates are touched. Call it only while holding the folder's
    lock, so another run's files in flight are never removed.
    """
    root = Path(folder)
    if not root.is_dir():
        return []
    removed = []
    walker = os.walk(root) if recursive else [(os.fspath(root), [], os.listdir(root))]
    for dirpath, _dirs, names in walker:
        for name in names:
            if TMP_MARK in name and _STALE.match(name):
                p = Path(dirpath, name)
                with _LOCK:
                    busy = p in _PENDING
                if not busy and p.is_file():
                    with contextlib.suppress(OSError):
                        p.unlink()
                        removed.append(p)
    return removed


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Atomically write ``data`` to ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Atomically write UTF-8 ``text`` to ``path``."""
    return write_bytes(path, text.encode("utf-8"))
