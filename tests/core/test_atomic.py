"""Atomic writes: no partial output on failure, normal permissions on success."""

from __future__ import annotations

import os
import stat

import pytest

from biomorph.io.atomic import atomic_path, write_text


def test_failure_leaves_no_file_and_no_temp(tmp_path) -> None:
    target = tmp_path / "out.txt"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("writer failed")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_existing_file_survives_a_failed_rewrite(tmp_path) -> None:
    target = tmp_path / "out.txt"
    write_text(target, "good")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("bad")
            raise KeyboardInterrupt
    assert target.read_text() == "good"


def test_permissions_follow_umask(tmp_path) -> None:
    old = os.umask(0o022)
    try:
        path = write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
