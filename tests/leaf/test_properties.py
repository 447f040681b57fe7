"""Property-based checks on random digitised leaves (hypothesis)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from biomorph.leaf.reduction import reduced_mesh
from biomorph.leaf.shape import LeafShape


@st.composite
def leaves(draw):
    n = draw(st.integers(2, 15))
    steps = draw(st.lists(st.floats(0.2, 5.0), min_size=n - 1, max_size=n - 1))
    turns = draw(st.lists(st.floats(-0.6, 0.6), min_size=n - 1, max_size=n - 1))
    ang = np.radians(80) + np.cumsum(turns)
    x = np.concatenate([[0.0], np.cumsum(np.array(steps) * np.cos(ang))])
    y = np.concatenate([[0.0], np.cumsum(np.array(steps) * np.sin(ang))])
    m = draw(st.integers(3, 12))
    r = np.array(draw(st.lists(st.floats(0.05, 2.0), min_size=m, max_size=m)))
    if draw(st.booleans()):
        r[-1] = 0.0
    twist = draw(st.floats(0.0, np.pi / 2))
    return LeafShape.from_points(x, y, np.linspace(0, 1, m), r, twist=twist)


@settings(max_examples=25, deadline=None)
@given(leaves())
def test_random_leaf_invariants(leaf: LeafShape) -> None:
    pts = leaf.midrib(57)
    assert np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() == pytest.approx(leaf.length)
    flat = leaf.with_(twist=0.0)
    # untwisted, the width direction is normal to the bending plane: area is L·∫r exactly,
    # however sharply the midrib bends
    assert flat.mesh(n_s=500, n_u=3).area() == pytest.approx(flat.area(), rel=5e-3)
    # twisted, the blade stays close to L·∫r only while it is thin against the length and
    # against the bending radius (a twisted blade around a kink folds: a ruled surface
    # identity, not a model error)
    curvature = np.max(np.abs(np.diff(leaf.phi) / np.diff(leaf.s))) / leaf.length  # 1/m
    if leaf.width < 0.2 * leaf.length and curvature * leaf.width / 2 < 0.1:
        assert leaf.mesh(n_s=500, n_u=3).area() == pytest.approx(leaf.area(), rel=5e-3)
    for budget in (3, 8, 21):
        m = reduced_mesh(flat, budget)
        assert m.n_faces == budget
        assert m.area() == pytest.approx(flat.area(), rel=1e-9)
