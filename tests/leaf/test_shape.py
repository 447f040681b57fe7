"""Leaf shape: fitting, evaluation, area convergence, bad input, presets."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import BiomorphError, InputError
from biomorph.leaf.shape import PRESET_NAMES, LeafShape, midrib_arc_length


def _simple(**kw) -> LeafShape:
    x = np.array([0.0, 5.0, 12.0, 20.0, 26.0])
    y = np.array([0.0, 8.0, 13.0, 14.0, 10.0])
    s = np.linspace(0, 1, 11)
    r = np.sin(np.pi * np.clip(s * 0.9 + 0.1, 0, 1)) * 2.0
    return LeafShape.from_points(x, y, s, r, **kw)


@pytest.mark.parametrize("twist", [0.0, np.pi / 4, np.pi / 2])
@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_area_converges_to_analytic(preset: str, twist: float) -> None:
    shape = LeafShape.from_preset(preset, twist=twist, undulation=0.0)
    m = shape.mesh(n_s=400, n_u=5)
    assert m.area() == pytest.approx(shape.area(), rel=5e-3)
    coarse = shape.mesh(n_s=4, n_u=2)
    # the test can fail: a coarse mesh misses the analytic area by more than the fine one
    assert abs(coarse.area() - shape.area()) > abs(m.area() - shape.area())


def test_midrib_length_is_exact_for_any_grid() -> None:
    shape = LeafShape.from_preset("wheat")
    for n in (2, 7, 50, 333):
        pts = shape.midrib(n)
        assert np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() == pytest.approx(
            shape.length, rel=1e-12
        )
    pts = shape.midrib(40)
    assert np.allclose(pts[:, 1], 0.0) and np.allclose(pts[0], 0.0)


def test_fit_reproduces_digitised_points_and_units() -> None:
    shape = _simple()
    x = np.array([0.0, 5.0, 12.0, 20.0, 26.0])
    y = np.array([0.0, 8.0, 13.0, 14.0, 10.0])
    assert shape.length == pytest.approx(midrib_arc_length(x, y)[-1] * 0.01)
    r_max = (np.sin(np.pi * np.clip(np.linspace(0, 1, 11) * 0.9 + 0.1, 0, 1)) * 2.0).max()
    assert shape.width == pytest.approx(0.01 * r_max)  # cm → m
    tip = shape.midrib(400)[-1]
    # smoothed corners: the tip stays within 3 % of L of the digitised tip
    assert np.hypot(tip[0] - 0.26, tip[2] - 0.10) < 0.03 * shape.length


def test_inputs_are_not_mutated() -> None:
    x = np.array([0.0, 1.0, 2.0])
    y = np.array([0.0, 1.0, 1.5])
    s = np.array([0.0, 0.5, 1.0])
    r = np.array([1.0, 2.0, 0.0])
    copies = [a.copy() for a in (x, y, s, r)]
    shape = LeafShape.from_points(x, y, s, r)
    shape.mesh(n_s=10)
    for a, c in zip((x, y, s, r), copies, strict=True):
        assert np.array_equal(a, c)
    with pytest.raises(ValueError):
        shape.phi[0] = 3.0  # stored arrays are read-only


@pytest.mark.parametrize(
    "x,y,s,r,match",
    [
        ([0.0], [0.0], [0, 1], [1, 0], "at least 2"),
        ([0.0, 1.0, 1.0], [0.0, 2.0, 2.0], [0, 1], [1, 0], "duplicates"),
        ([0.0, 1.0], [0.0, 1.0], [0, 0.5, 0.5, 1], [1, 1, 1, 0], "increase strictly"),
        ([0.0, 1.0], [0.0, 1.0], [0, 0.5, 1], [1, -0.1, 0], "negative"),
        ([0.0, np.nan], [0.0, 1.0], [0, 1], [1, 0], "finite"),
    ],
)
def test_bad_input(x, y, s, r, match) -> None:
    with pytest.raises(InputError, match=match):
        LeafShape.from_points(x, y, s, r)


def test_bad_age_and_preset() -> None:
    shape = LeafShape.from_preset("wheat")
    for age in (-0.1, 1.01, float("nan")):
        with pytest.raises(BiomorphError, match="outside"):
            shape.mesh(age=age)
    with pytest.raises(BiomorphError, match="unknown leaf preset"):
        LeafShape.from_preset("oak")


def test_presets_are_plausible() -> None:
    wheat, maize = LeafShape.from_preset("wheat"), LeafShape.from_preset("maize")
    assert 0.1 < wheat.length < 0.4 and 0.005 < wheat.width < 0.03
    assert maize.width > 3 * wheat.width
    assert wheat.collection is not None and wheat.collection.ages.size == 29
    for name in PRESET_NAMES:
        ff = LeafShape.from_preset(name).form_factor()
        assert 0.5 < ff < 0.95


def test_surface_grid_matches_mesh_vertices() -> None:
    shape = LeafShape.from_preset("grass")
    s, u = np.linspace(0, 1, 9), np.linspace(-0.5, 0.5, 3)
    grid = shape.surface(s, u)
    assert grid.shape == (9, 3, 3)
    m = shape.mesh(n_s=9, n_u=3)
    assert np.allclose(m.vertices, grid.reshape(-1, 3))
    # width across the blade at mid-leaf equals r(s)·W for an untwisted leaf
    flat = shape.with_(twist=0.0).surface([0.5, 0.6], [-0.5, 0.5])[0]
    assert np.linalg.norm(flat[1] - flat[0]) == pytest.approx(shape.width_at(0.5))


def test_parametric_leaf() -> None:
    leaf = LeafShape.parametric(
        0.6, 0.05, insertion_deg=70, bending_deg=120, base_width=0.5, widest_at=0.3, tip_power=1.5
    )
    assert leaf.r_at(0.0) == pytest.approx(0.5) and leaf.r_at(0.3) == pytest.approx(1.0)
    assert leaf.r_at(1.0) == 0.0
    assert np.degrees(leaf.phi_at(0.0)) == pytest.approx(70)
    assert np.degrees(leaf.phi_at(1.0)) == pytest.approx(-50)
    assert leaf.mesh(n_s=300).area() == pytest.approx(leaf.area(), rel=5e-3)
    with pytest.raises(BiomorphError, match="widest_at"):
        LeafShape.parametric(0.6, 0.05, widest_at=1.0)


def test_twist_profile() -> None:
    leaf = LeafShape.from_preset("maize", undulation=0.0)
    prof = leaf.with_(twist_profile=(np.array([0.0, 0.5, 1.0]), np.array([0.0, 0.0, 1.2])))
    assert prof.theta_at(0.25) == 0.0 and prof.theta_at(1.0) == pytest.approx(1.2)
    a = leaf.with_(twist=0.0).surface([0.2, 0.3], [-0.5, 0.5])
    b = prof.surface([0.2, 0.3], [-0.5, 0.5])
    assert np.allclose(a, b)  # untwisted where θ = 0
    assert prof.mesh(n_s=300).area() == pytest.approx(prof.area(), rel=5e-3)
    with pytest.raises(InputError, match="twist_profile"):
        leaf.with_(twist_profile=(np.array([0.0, 0.0]), np.array([0.0, 1.0])))


def test_sharp_fit_reproduces_the_polyline() -> None:
    x = np.array([0.0, 5.0, 12.0, 20.0, 26.0])
    y = np.array([0.0, 8.0, 13.0, 14.0, 10.0])
    leaf = LeafShape.from_points(x, y, [0, 1], [1, 0], rounding=0.0)
    s = midrib_arc_length(x, y) / midrib_arc_length(x, y)[-1]
    pts = leaf.midrib(np.unique(np.concatenate([s, np.linspace(0, 1, 2001)])))
    keep = np.isin(np.unique(np.concatenate([s, np.linspace(0, 1, 2001)])), s)
    assert np.allclose(pts[keep][:, [0, 2]], np.stack([x, y], 1) * 0.01, atol=2e-4)
