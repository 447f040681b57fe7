"""Reduction: correct heap, exact budgets, monotone error, real wheat leaves."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.leaf.reduction import (
    _err,
    reduce_leaf,
    reduce_profile,
    reduced_mesh,
    reduction_order,
)
from biomorph.leaf.shape import LeafShape
from tests.conftest import shared_file
from tests.leaf.oracles import reduction_order_py


def _brute_force(x, z, s, w):
    """O(n²) greedy: recompute every live error each step, remove the smallest."""
    live = list(range(len(x)))
    order = []
    while len(live) > 2:
        errs = [
            _err.py_func(live[k], live[k - 1], live[k + 1], x, z, s, w)
            for k in range(1, len(live) - 1)
        ]
        k = int(np.argmin(errs)) + 1
        order.append(live.pop(k))
    return np.array(order)


def test_heap_matches_brute_force_greedy() -> None:
    rng = np.random.default_rng(3)
    for _ in range(5):
        n = 40
        s = np.sort(rng.random(n))
        x, z, w = rng.random(n), rng.random(n), rng.random(n) * 0.1
        order, errs, _ = reduction_order(x, z, s, w)
        assert np.array_equal(order, _brute_force(x, z, s, w))
        o2, e2 = reduction_order_py(x, z, s, w)
        assert np.array_equal(order, o2) and np.allclose(errs, e2)


def test_second_and_next_to_last_points_are_not_always_dropped() -> None:
    # a hook at both ends: points 1 and n-2 carry the shape and must survive to the end
    s = np.linspace(0, 1, 12)
    x = s.copy()
    z = np.zeros(12)
    z[1], z[-2] = 0.3, -0.3
    red = reduce_profile(s, x, z, np.full(12, 0.01))
    assert set(red.order[-2:]) == {1, 10}


@pytest.mark.parametrize("preset", ["wheat", "maize", "grass"])
def test_budget_is_met_exactly_and_area_is_exact(preset: str) -> None:
    leaf = LeafShape.from_preset(preset, undulation=0.0, twist=0.0)
    for budget in (1, 2, 3, 4, 7, 15, 16, 50, 101):
        m = reduced_mesh(leaf, budget)
        assert m.n_faces == budget
        assert m.area() == pytest.approx(leaf.area(), rel=1e-9)
    with pytest.raises(ParameterError, match="below the minimum"):
        reduced_mesh(leaf, 0)


def test_budget_below_minimum_open_base() -> None:
    leaf = LeafShape.from_preset("wheat")
    assert leaf.r[0] > 0  # open base, closed tip: minimum mesh is 1 triangle
    red = reduce_leaf(leaf, 50)
    assert red.min_triangles == 1
    with pytest.raises(ParameterError, match="exceeds"):
        red.removed_for_budget(10_000)


def test_error_non_increasing_with_budget() -> None:
    red = reduce_leaf(LeafShape.from_preset("maize"), 300)
    tri, exy, bound = red.curve()
    order = np.argsort(tri)
    assert np.all(np.diff(bound[order]) <= 1e-15)
    assert np.all(np.diff(tri) < 0)
    assert exy[-1] > exy[len(exy) // 2] > exy[0] == 0.0


def test_wheat_450_median_midrib_error() -> None:
    from biomorph.leaf.data import wheat_leaves

    root = shared_file("leaves", "adel", "So99.csv").parents[1]
    leaves = wheat_leaves(root)
    assert len(leaves) == 450
    errs, area_err = [], []
    for i, leaf in enumerate(leaves):
        red = reduce_leaf(leaf, 200)
        errs.append(red.error(red.kept_for_points(9))[0])
        if i % 15 == 0:
            m = reduced_mesh(leaf, 15, reduction=red, n_points=200)  # 9 points, closed tip
            area_err.append(abs(m.area() / leaf.area() - 1))
    med = float(np.median(errs))
    assert med <= 0.0105, med
    assert max(area_err) < 1e-9


def test_polygon_budget() -> None:
    red = reduce_leaf(LeafShape.from_preset("maize"), 100)
    assert red.kept_for_polygons(5).size == 6
    with pytest.raises(ParameterError, match="polygon budget"):
        red.kept_for_polygons(0)


def test_both_ends_closed() -> None:
    leaf = LeafShape.parametric(0.5, 0.05, base_width=0.0)
    for budget in (2, 3, 6):
        m = reduced_mesh(leaf, budget)
        assert m.n_faces == budget
        assert m.area() == pytest.approx(leaf.area(), rel=1e-9)
    with pytest.raises(ParameterError, match="below the minimum"):
        reduced_mesh(leaf, 1)


def test_twisted_undulated_leaf_converges_on_its_surface() -> None:
    from biomorph.leaf.reduction import point_triangle_distance, surface_error

    maize = LeafShape.from_preset("maize")  # twist 30°, 4 mm margin undulation
    meshes = {b: reduced_mesh(maize, b) for b in (50, 120)}
    errs = [surface_error(maize, meshes[b], n_s=150, n_u=5) for b in (50, 120)]
    flat2d = surface_error(maize, reduced_mesh(maize, 120, surface=False), n_s=150, n_u=5)
    assert errs[1] < errs[0] and errs[1] < 1e-3 < 2.5e-3 < flat2d
    assert meshes[120].n_faces == 120
    # the error measure itself: exact distances to a unit right triangle
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    pts = np.array([[0.2, 0.2, 0.5], [2.0, 0, 0], [-1.0, -1.0, 0.0]])
    assert np.allclose(point_triangle_distance(pts, tri), [0.5, 1.0, np.sqrt(2)])
