"""Curves: Bézier evaluation/derivatives/split/arc length, polylines, splines."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from biomorph.core import curves
from biomorph.errors import ParameterError

ctrl_strategy = arrays(np.float64, (4, 2), elements=st.floats(-10, 10))


def _dense_length(ctrl: np.ndarray, n: int = 200_001) -> float:
    p = curves.bezier_eval(ctrl, np.linspace(0, 1, n))
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def test_bezier_endpoints_and_straight_line_length() -> None:
    ctrl = np.array([[0, 0], [1, 0], [2, 0], [3, 0]], float)
    assert np.allclose(curves.bezier_eval(ctrl, 0.0), [0, 0])
    assert np.allclose(curves.bezier_eval(ctrl, 1.0), [3, 0])
    assert curves.bezier_arc_length(ctrl) == pytest.approx(3.0, rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(ctrl_strategy, st.floats(0.05, 0.95))
def test_derivative_matches_finite_difference(ctrl: np.ndarray, t: float) -> None:
    h = 1e-6
    fd = (curves.bezier_eval(ctrl, t + h) - curves.bezier_eval(ctrl, t - h)) / (2 * h)
    assert np.allclose(curves.bezier_derivative(ctrl, t), fd, atol=1e-4)
    fd2 = (curves.bezier_derivative(ctrl, t + h) - curves.bezier_derivative(ctrl, t - h)) / (2 * h)
    assert np.allclose(curves.bezier_derivative(ctrl, t, order=2), fd2, atol=1e-3)


@settings(max_examples=40, deadline=None)
@given(ctrl_strategy, st.floats(0.0, 1.0))
def test_split_reproduces_curve(ctrl: np.ndarray, t: float) -> None:
    left, right = curves.bezier_split(ctrl, t)
    u = np.linspace(0, 1, 7)
    assert np.allclose(curves.bezier_eval(left, u), curves.bezier_eval(ctrl, t * u), atol=1e-9)
    assert np.allclose(
        curves.bezier_eval(right, u), curves.bezier_eval(ctrl, t + (1 - t) * u), atol=1e-9
    )


def test_arc_length_matches_dense_polyline() -> None:
    ctrl = np.array([[0, 0, 0], [1, 2, 0], [3, -1, 1], [4, 0, 2]], float)
    assert curves.bezier_arc_length(ctrl) == pytest.approx(_dense_length(ctrl), rel=1e-7)


def test_arclength_params_give_equal_spacing_batched() -> None:
    ctrl = np.array([[[0, 0], [0, 3], [4, 3], [4, 0]], [[0, 0], [1, 0], [1, 1], [5, 5]]], float)
    t = curves.bezier_arclength_params(ctrl, 11, samples=2048)
    assert t.shape == (2, 11)
    for b in range(2):
        pts = curves.bezier_eval(ctrl[b], t[b])
        # chord lengths between consecutive equal-arc points are nearly equal
        chords = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        assert chords.std() / chords.mean() < 0.02
        assert np.all(np.diff(t[b]) > 0)


def test_degenerate_curve_params_are_uniform() -> None:
    ctrl = np.zeros((4, 3))
    assert np.allclose(curves.bezier_arclength_params(ctrl, 5), np.linspace(0, 1, 5))


def test_resample_polyline_equal_steps() -> None:
    pts = np.array([[0, 0], [1, 0], [1, 0], [1, 2]], float)  # duplicate point tolerated
    out = curves.resample_polyline(pts, n=7)
    steps = np.linalg.norm(np.diff(out, axis=0), axis=1)
    assert np.allclose(steps, 0.5)
    assert np.allclose(curves.polyline_arc_length(out)[-1], 3.0)


@pytest.mark.parametrize(
    "cls", [curves.NaturalCubicSpline, curves.MonotoneSpline, curves.CatmullRomSpline]
)
def test_splines_interpolate_keys_and_clamp(cls) -> None:
    x = np.array([0.0, 1.0, 2.5, 4.0])
    y = np.array([0.0, 2.0, 1.0, 3.0])
    sp = cls(x, y)
    assert np.allclose(sp(x), y)
    assert sp(-5.0) == pytest.approx(0.0) and sp(10.0) == pytest.approx(3.0)
    assert sp.derivative()(10.0) == pytest.approx(0.0)
    vec = cls(x, np.stack([y, -y], axis=1))
    assert vec(np.array([0.5, 1.5])).shape == (2, 2)


def test_natural_spline_has_zero_curvature_at_ends() -> None:
    sp = curves.NaturalCubicSpline([0, 1, 2, 3], [0, 1, 0, 1])
    assert abs(float(sp.derivative(2)(0.0))) < 1e-9
    assert abs(float(sp.derivative(2)(3.0))) < 1e-9


def test_monotone_spline_does_not_overshoot() -> None:
    x = np.arange(6.0)
    y = np.array([0, 0, 0, 1, 1, 1], float)
    t = np.linspace(0, 5, 501)
    v = curves.MonotoneSpline(x, y)(t)
    assert v.min() >= -1e-12 and v.max() <= 1 + 1e-12
    assert np.all(np.diff(v) >= -1e-12)
    # the natural spline does overshoot on the same data: the test can tell them apart
    assert curves.NaturalCubicSpline(x, y)(t).max() > 1.01


def test_catmull_rom_tangent_is_centred_difference() -> None:
    x = np.array([0.0, 1.0, 3.0])
    y = np.array([0.0, 1.0, 5.0])
    sp = curves.CatmullRomSpline(x, y)
    assert float(sp.derivative()(1.0)) == pytest.approx((5.0 - 0.0) / 3.0)


@pytest.mark.parametrize(
    "x,y", [([0, 0, 1], [1, 2, 3]), ([0], [1]), ([0, 1], [1, np.nan]), ([0, 1, 2], [1, 2])]
)
def test_bad_keys_raise(x, y) -> None:
    with pytest.raises(ParameterError):
        curves.NaturalCubicSpline(x, y)


def test_segment_projection_clips_to_the_segment_and_broadcasts() -> None:
    a, b = np.array([0.0, 0.0, 0.0]), np.array([10.0, 0.0, 0.0])
    t, d = curves.segment_projection(np.array([[5, 3, 4], [-3, 4, 0], [12, 0, 0]]), a, b)
    np.testing.assert_allclose(t, [0.5, 0.0, 1.0])
    np.testing.assert_allclose(d, [5, 5, 2])
    # points (n, 1, 3) against per-point candidate segments (n, k, 3)
    p = np.array([[[1.0, 1.0, 0.0]], [[0.0, 0.0, 2.0]]])
    sa = np.zeros((2, 2, 3))
    sb = np.array([[[2.0, 0, 0], [0, 2.0, 0]], [[0, 0, 4.0], [1.0, 0, 0]]])
    t, d = curves.segment_projection(p, sa, sb)
    assert t.shape == d.shape == (2, 2)
    np.testing.assert_allclose(t, [[0.5, 0.5], [0.5, 0.0]])
    np.testing.assert_allclose(d, [[1.0, 1.0], [0.0, 2.0]])
    # a zero-length segment is its point
    t, d = curves.segment_projection(np.array([3.0, 4.0, 0.0]), a, a)
    assert t == 0.0 and d == pytest.approx(5.0)


def test_kasa_circle_recovers_a_circle_from_an_arc() -> None:
    a = np.linspace(0.2, 2.4, 40)  # a third of the way round
    xy = np.column_stack([3.0 + 0.5 * np.cos(a), -1.0 + 0.5 * np.sin(a)])
    u, c, r2 = curves.kasa_circle(xy)
    np.testing.assert_allclose(u, xy - xy.mean(axis=0))
    np.testing.assert_allclose(xy.mean(axis=0) + c, [3.0, -1.0], atol=1e-9)
    assert r2 == pytest.approx(0.25)
