"""The sandbox keeps every file inside the data folder and limits uploads."""

from __future__ import annotations

import os

import pytest

from biomorph.errors import BiomorphError
from biomorph.studio.sandbox import Sandbox, SandboxError


@pytest.fixture
def box(tmp_path):
    (tmp_path / "data").mkdir()
    (tmp_path / "secret.txt").write_text("outside")
    (tmp_path / "data" / "walk.bvh").write_text("x")
    (tmp_path / "data" / "sub").mkdir()
    (tmp_path / "data" / "sub" / "tree.xyz").write_text("0 0 0\n")
    (tmp_path / "data" / ".hidden.xyz").write_text("0 0 0\n")
    return Sandbox(tmp_path / "data", max_upload_bytes=100)


@pytest.mark.parametrize(
    "name",
    [
        "../secret.txt",
        "sub/../../secret.txt",
        "/etc/passwd",
        "..",
        "",
        "a\x00b",
        "C:\\Windows\\x",
        "..\\secret.txt",
    ],
)
def test_escaping_names_are_rejected(box, name):
    with pytest.raises(SandboxError):
        box.resolve(name)


def test_sandbox_error_is_a_user_error():
    assert issubclass(SandboxError, BiomorphError)


def test_inside_names_resolve(box):
    assert box.resolve("walk.bvh") == box.root / "walk.bvh"
    assert box.resolve("sub/../walk.bvh") == box.root / "walk.bvh"
    assert box.relative(box.resolve("sub/tree.xyz")) == "sub/tree.xyz"


def test_symlink_out_of_the_folder_is_rejected(box, tmp_path):
    os.symlink(tmp_path / "secret.txt", box.root / "link.txt")
    with pytest.raises(SandboxError, match="outside"):
        box.resolve("link.txt")
    assert "link.txt" not in box.list_files()


def test_listing_filters_and_skips_hidden(box):
    assert box.list_files() == ["sub/tree.xyz", "walk.bvh"]
    assert box.list_files([".bvh"]) == ["walk.bvh"]


def test_upload_limit_and_safe_names(box):
    path = box.save_upload("../../evil name.bvh", b"HIERARCHY")
    assert path == box.root / "uploads" / "evil_name.bvh"
    assert path.read_bytes() == b"HIERARCHY"
    with pytest.raises(SandboxError, match="upload limit"):
        box.save_upload("big.bvh", b"x" * 101)
    assert not (box.root / "uploads" / "big.bvh").exists()
    with pytest.raises(SandboxError):
        box.safe_name("..")


def test_exports_stay_inside(box):
    out = box.output_path("../../x.glb")
    assert out == box.root / "exports" / "x.glb"
    assert out.parent.is_dir()
