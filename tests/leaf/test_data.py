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


def test_basal_backstep_dropped_only_when_the_midrib_reverses() -> None:
    import numpy as np

    from biomorph.leaf.data import drop_basal_backstep

    # So99 1,35: the first point steps back over the stem, then the blade rises to +x
    x = np.array([0.0, -0.53, 1.08, 2.76, 4.10])
    y = np.array([0.0, 0.67, 1.41, 2.34, 2.69])
    bx, by = drop_basal_backstep(x, y)
    assert bx.tolist() == [0.0, 1.08, 2.76, 4.10] and by.tolist() == [0.0, 1.41, 2.34, 2.69]
    # a blade that rises and bends (turns < 90°) keeps every point
    x2, y2 = np.array([0.0, 0.1, 0.6, 1.5, 2.5]), np.array([0.0, 1.0, 1.8, 2.3, 2.4])
    kx, ky = drop_basal_backstep(x2, y2)
    assert kx.tolist() == x2.tolist() and ky.tolist() == y2.tolist()


@pytest.mark.parametrize("n", [12, 16, 20])
def test_mature_maize_blades_follow_the_bell_for_any_leaf_count(n) -> None:
    import numpy as np

    from biomorph.leaf.data import bell_leaf_fractions, mature_maize_blades

    f = bell_leaf_fractions(n, n - 5)
    assert f.sum() == pytest.approx(1.0, abs=1e-9) and int(np.argmax(f)) + 1 == n - 5
    f0 = f.max()  # Yang & Alley 2005: F = F0 exp(-(F0 (n - n0))^2 / 0.3542)
    ranks = np.arange(1, n + 1)
    assert np.allclose(f, f0 * np.exp(-((f0 * (ranks - (n - 5))) ** 2) / 0.3542))
    ff = np.full(n, 0.75)
    d = mature_maize_blades(ff, 0.96, {"n_ranks": n, "plant_leaf_area_m2": 0.6})
    area = d["L_blade"] * d["W_blade"] * ff
    assert area.sum() == pytest.approx(0.6, rel=1e-9)
    k = int(np.argmax(area))
    assert d["L_blade"][k] / d["W_blade"][k] == pytest.approx(10.0)
    # W ∝ L^β along the stem
    beta = np.polyfit(np.log(d["L_blade"]), np.log(d["W_blade"]), 1)[0]
    assert beta == pytest.approx(0.96, abs=1e-6)
