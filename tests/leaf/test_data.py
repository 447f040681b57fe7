"""Shared leaf data is located lazily (env var or documented search), never at import."""

from __future__ import annotations

import importlib

import pytest

from biomorph.errors import FormatError


def test_data_path_resolved_only_when_asked(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("BIOMORPH_SHARED_DATA", str(tmp_path / "nowhere"))
    data = importlib.reload(importlib.import_module("biomorph.leaf.data"))  # import works
    assert data.shared_leaves(required=False) is None
    with pytest.raises(FormatError, match="BIOMORPH_SHARED_DATA"):
        data.shared_leaves()
    (tmp_path / "leaves").mkdir()
    monkeypatch.setenv("BIOMORPH_SHARED_DATA", str(tmp_path))
    assert data.shared_leaves() == tmp_path / "leaves"
    assert data.SHARED_LEAVES == tmp_path / "leaves"  # compatibility name, lazy


def test_curve_helpers_live_in_core() -> None:
    from biomorph.core import curves
    from biomorph.leaf import shape

    assert shape.integrate_angles is curves.integrate_angles
    assert shape.angles_from_points is curves.angles_from_points
