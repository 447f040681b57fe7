"""Error types. Every failure a user can cause raises a :class:`BiomorphError` subclass.

The CLI maps any ``BiomorphError`` to exit code 2 and prints its message on one line, so the
message must say *what* was wrong, *where* (file, line, value) and *what was expected*.
"""

from __future__ import annotations

import os


class BiomorphError(Exception):
    """Base class of all errors a user can cause (bad input, impossible parameters)."""


class FormatError(BiomorphError):
    """A file could not be parsed: malformed, truncated, wrong counts, non-numeric tokens.

    ``FormatError(path, "expected 6 channels, got 5", line=12)`` renders as
    ``walk.bvh:12: expected 6 channels, got 5``.
    """

    def __init__(
        self, path: str | os.PathLike[str] | None, message: str, line: int | None = None
    ) -> None:
        self.path = None if path is None else os.fspath(path)
        self.line = line
        self.detail = message
        where = self.path or "<input>"
        if line is not None:
            where = f"{where}:{line}"
        super().__init__(f"{where}: {message}")


class InputError(BiomorphError):
    """Data that parsed but cannot be used (empty cloud, NaN coordinates, degenerate shape)."""


class ParameterError(BiomorphError):
    """A parameter value outside what the method accepts (names the parameter and range)."""


class UnsupportedFormatError(BiomorphError):
    """A file extension no reader or writer handles."""


#: share of the currently available memory one request may take (the rest is headroom for
#: the interpreter, the libraries and the copies numpy makes while it computes)
MEMORY_SHARE = 0.8


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} PB"  # pragma: no cover


def available_memory() -> int:
    """Bytes of memory available to this process now (psutil; 8 GB when psutil is absent)."""
    try:
        import psutil
    except ImportError:  # pragma: no cover - psutil is a core dependency
        return 8 * 10**9
    return int(psutil.virtual_memory().available)


def require_memory(what: str, n_bytes: float, available: int | None = None) -> None:
    """Refuse a request whose estimated working memory exceeds what the machine has.

    ``what`` names the request, e.g. ``"--points 1000000000 (48 B per point)"``. Raises a
    :class:`ParameterError` with the estimate and the available memory, before anything is
    allocated. A request may take at most :data:`MEMORY_SHARE` of the available memory.

    >>> require_memory("--points 10**12", 4.8e13, available=16 * 10**9)
    Traceback (most recent call last):
    ...
    biomorph.errors.ParameterError: --points 10**12 needs about 48 TB of memory; 16 GB available
    """
    avail = available_memory() if available is None else int(available)
    if not n_bytes <= MEMORY_SHARE * avail:  # also refuses NaN
        raise ParameterError(
            f"{what} needs about {_fmt_bytes(float(n_bytes))} of memory; "
            f"{_fmt_bytes(avail)} available"
        )


def check_regular_file(path: str | os.PathLike[str]) -> None:
    """Raise :class:`FormatError` unless ``path`` is an existing regular file (or a link to
    one). Named pipes, sockets and device files would block or never end; directories are
    not files."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise FormatError(path, "file does not exist") from None
    except OSError as exc:
        raise FormatError(path, f"cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(mode):
        raise FormatError(path, "is a directory; expected a file")
    if not stat.S_ISREG(mode):
        kind = (
            "a named pipe"
            if stat.S_ISFIFO(mode)
            else "a socket"
            if stat.S_ISSOCK(mode)
            else "a device file"
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "not a regular file"
        )
        raise FormatError(path, f"is {kind}; expected a regular file")
