"""Plastic operators: local curvature change, length conservation, composition."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.leaf.plastic import apply_ops, bend, curvature, scale_width
from biomorph.leaf.shape import LeafShape

S = np.linspace(0, 1, 2001)


def _curv(shape: LeafShape) -> np.ndarray:
    mid = 0.5 * (S[1:] + S[:-1])
    return np.diff(shape.phi_at(S)) / np.diff(S), mid


@pytest.mark.parametrize(
    "op",
    [bend(0.3, 0.6, 0.8), bend(0.1, 0.2, -0.5), curvature(0.4, 0.9, 0.0), curvature(0.2, 0.5, 2.5)],
)
def test_curvature_changes_only_inside_and_length_is_kept(op) -> None:
    leaf = LeafShape.from_preset("wheat")
    out = apply_ops(leaf, [op])
    k0, mid = _curv(leaf)
    k1, _ = _curv(out)
    outside = (mid < op.s0 - 1e-3) | (mid > op.s1 + 1e-3)
    assert np.allclose(k0[outside], k1[outside], atol=1e-9)
    inside = (mid > op.s0 + 1e-3) & (mid < op.s1 - 1e-3)
    assert not np.allclose(k0[inside], k1[inside], atol=1e-6)  # the operator did something
    for n in (20, 300):
        pts = out.midrib(n)
        assert np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() == pytest.approx(leaf.length)
    # growing leaves feel it too, and the input is untouched
    assert not np.allclose(out.collection.phi, leaf.collection.phi)
    assert np.array_equal(LeafShape.from_preset("wheat").phi, leaf.phi)


def test_bend_total_angle_and_composition() -> None:
    leaf = LeafShape.from_preset("grass")
    both = apply_ops(leaf, [bend(0.2, 0.4, 0.3), bend(0.6, 0.8, 0.2)])
    assert both.phi_at(1.0) == pytest.approx(leaf.phi_at(1.0) - 0.5)
    straight = apply_ops(leaf, [curvature(0.0, 1.0, 0.0)])
    assert np.allclose(straight.phi_at(S), leaf.phi_at(0.0))


def test_scale_width_on_interval() -> None:
    leaf = LeafShape.from_preset("maize")
    out = apply_ops(leaf, [scale_width(0.5, 0.7, 0.5)])
    s_in, s_out = np.array([0.55, 0.6, 0.65]), np.array([0.1, 0.3, 0.8, 0.9])
    assert np.allclose(out.width_at(s_in), 0.5 * leaf.width_at(s_in))
    assert np.allclose(out.width_at(s_out), leaf.width_at(s_out))
    assert out.area() < leaf.area()


def test_bad_operators() -> None:
    with pytest.raises(ParameterError, match="interval"):
        bend(0.6, 0.3, 1.0)
    with pytest.raises(ParameterError, match=">= 0"):
        scale_width(0.1, 0.2, -1.0)
