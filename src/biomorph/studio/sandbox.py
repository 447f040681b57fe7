"""File sandbox of the studio: every file the page opens or saves lies inside one folder.

The browser only ever names files *relative* to the data folder (``--data``). A name that is
absolute, climbs out with ``..``, or reaches outside through a symbolic link is rejected
with :class:`SandboxError`; uploads are limited in size and stored under ``uploads/`` with a
sanitised name; exports go to ``exports/``.

Example
-------
>>> import tempfile
>>> box = Sandbox(tempfile.mkdtemp())
>>> box.resolve("../etc/passwd")
Traceback (most recent call last):
...
biomorph.studio.sandbox.SandboxError: '../etc/passwd' lies outside the data folder ...
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path, PurePosixPath

from biomorph.errors import BiomorphError
from biomorph.io.atomic import write_bytes

#: Default upload limit (bytes); the CLI exposes ``--max-upload-mb``.
DEFAULT_MAX_UPLOAD = 64 * 1024 * 1024

_SAFE_NAME = re.compile(r"[^A-Za-z0-9._-]+")


class SandboxError(BiomorphError):
    """A path outside the data folder, a forbidden name, or an upload that is too large."""


class Sandbox:
    """The data folder the studio may read from and write to.

    Parameters
    ----------
    root : the data folder (created if missing).
    max_upload_bytes : largest accepted upload in bytes.
    """

    def __init__(
        self, root: str | os.PathLike[str], max_upload_bytes: int = DEFAULT_MAX_UPLOAD
    ) -> None:
        root_path = Path(root).expanduser()
        root_path.mkdir(parents=True, exist_ok=True)
        self.root = root_path.resolve()
        self.max_upload_bytes = int(max_upload_bytes)

    # ------------------------------------------------------------------ paths
    def resolve(self, relative: str | os.PathLike[str]) -> Path:
        """Absolute path of ``relative`` inside the data folder.

        Raises :class:`SandboxError` for empty, absolute or escaping names (including
        escapes through symbolic links) and for names holding NUL bytes.
        """
        text = os.fspath(relative).strip()
        if not text or "\x00" in text:
            raise SandboxError(f"{text!r} is not a valid file name")
        pure = PurePosixPath(text.replace("\\", "/"))
        if pure.is_absolute() or re.match(r"^[A-Za-z]:", text):
            raise SandboxError(
                f"{text!r} is an absolute path; name files relative to the data folder {self.root}"
            )
        candidate = (self.root / Path(*pure.parts)).resolve()
        if candidate != self.root and not candidate.is_relative_to(self.root):
            raise SandboxError(
                f"{text!r} lies outside the data folder {self.root}; "
                "files are opened and saved only inside it"
            )
        return candidate

    def relative(self, path: str | os.PathLike[str]) -> str:
        """The name of an absolute path inside the folder, as shown in the page."""
        return Path(path).resolve().relative_to(self.root).as_posix()

    def list_files(
        self, extensions: Iterable[str] | None = None, limit: int = 500, max_depth: int = 4
    ) -> list[str]:
        """Relative names of files under the folder (hidden entries skipped), sorted.

        ``extensions`` (lower case, with the dot) filters by suffix; at most ``limit``
        names are returned and folders deeper than ``max_depth`` are not visited.
        """
        exts = None if extensions is None else {e.lower() for e in extensions}
        found: list[str] = []
        for dirpath, dirnames, filenames in os.walk(self.root, followlinks=False):
            rel_dir = Path(dirpath).relative_to(self.root)
            depth = 0 if rel_dir == Path(".") else len(rel_dir.parts)
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and depth < max_depth)
            for name in sorted(filenames):
                if name.startswith("."):
                    continue
                if exts is not None and Path(name).suffix.lower() not in exts:
                    continue
                full = Path(dirpath) / name
                try:
                    self.resolve((rel_dir / name).as_posix())
                except SandboxError:
                    continue  # a symlink pointing outside
                if full.is_file():
                    found.append((rel_dir / name).as_posix())
                if len(found) >= limit:
                    return sorted(found)
        return sorted(found)

    # ------------------------------------------------------------------ writing
    @staticmethod
    def safe_name(name: str) -> str:
        """A file name without folders or unusual characters (``"../a b.bvh"`` -> ``a_b.bvh``)."""
        base = PurePosixPath(str(name).replace("\\", "/")).name
        cleaned = _SAFE_NAME.sub("_", base).lstrip(".")
        if not cleaned or cleaned in {".", ".."}:
            raise SandboxError(f"{name!r} is not a usable file name")
        return cleaned[:120]

    def check_upload_size(self, size: int, name: str = "upload") -> None:
        """Raise :class:`SandboxError` if an upload of ``size`` bytes exceeds the limit."""
        if size > self.max_upload_bytes:
            raise SandboxError(
                f"{name}: {size / 1e6:.1f} MB exceeds the upload limit of "
                f"{self.max_upload_bytes / 1e6:.1f} MB"
            )

    def save_upload(self, name: str, content: bytes) -> Path:
        """Store an uploaded file as ``uploads/<safe name>`` (atomically) and return its path."""
        self.check_upload_size(len(content), name)
        target = self.resolve(f"uploads/{self.safe_name(name)}")
        return write_bytes(target, content)

    def output_path(self, name: str) -> Path:
        """Path for an export ``exports/<safe name>`` inside the folder (folder created)."""
        target = self.resolve(f"exports/{self.safe_name(name)}")
        target.parent.mkdir(parents=True, exist_ok=True)
        return target
