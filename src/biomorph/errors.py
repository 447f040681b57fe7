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

    def __init__(self, path: str | os.PathLike[str] | None, message: str,
                 line: int | None = None) -> None:
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


def check_finite(path: str | os.PathLike[str] | None, name: str, values: object) -> None:
    """Raise :class:`FormatError` naming the first row holding NaN or inf in ``values``."""
    import numpy as np

    arr = np.asarray(values)
    if arr.size == 0 or np.isfinite(arr).all():
        return
    bad = np.argwhere(~np.isfinite(arr))[0]
    raise FormatError(path, f"{name} holds a non-finite value (NaN or inf) at row {int(bad[0])}; "
                            "expected finite numbers")
