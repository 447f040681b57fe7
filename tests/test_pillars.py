"""Optional per-pillar modules and the demo's pillar selection."""

from __future__ import annotations

import sys

import pytest

from biomorph.cli import run
from biomorph.pillars import PILLARS, optional_module


def test_existing_and_missing_modules() -> None:
    assert optional_module("tree", "cli") is not None
    assert optional_module("no_such_pillar", "cli") is None
    assert optional_module("tree", "no_such_module") is None


def test_import_error_inside_a_module_propagates(tmp_path, monkeypatch) -> None:
    pkg = tmp_path / "biomorph_fake"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "cli.py").write_text("import a_dependency_that_is_missing\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import biomorph

    monkeypatch.setattr(biomorph, "__path__", [*biomorph.__path__, str(tmp_path)])
    (tmp_path / "fakepillar").symlink_to(pkg)
    with pytest.raises(ModuleNotFoundError, match="a_dependency_that_is_missing"):
        optional_module("fakepillar", "cli")
    sys.modules.pop("biomorph.fakepillar", None)


def test_every_pillar_registers_a_command_group(capsys) -> None:
    assert run(["--help"]) == 0
    out = capsys.readouterr().out
    for pillar in PILLARS:
        assert pillar in out


def test_demo_rejects_unknown_pillar(tmp_path, capsys) -> None:
    assert run(["demo", "--out", str(tmp_path / "d"), "--only", "dragon"]) == 2
    assert "unknown pillar dragon" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
