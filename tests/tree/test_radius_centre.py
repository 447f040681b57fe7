"""Thin unfitted nodes move to the centroid of their cross-section (tree.radius.
centre_thin_nodes, issue 13: twig axes and the twig residual)."""

from __future__ import annotations

import numpy as np

from biomorph.core.graph import BranchGraph
from biomorph.tree.radius import CENTROID_MAX_RADIUS, centre_thin_nodes


def _twig(offset: float, r: float = 0.006, spacing: float = 0.004):
    """A 0.5 m horizontal twig along x (axis at y = z = 0) sampled on its surface every
    ``spacing``, and a skeleton of 11 nodes ``offset`` m off the axis in y."""
    rng = np.random.default_rng(0)
    n = int(0.5 * 2 * np.pi * r / spacing**2)
    x = rng.uniform(0, 0.5, n)
    a = rng.uniform(0, 2 * np.pi, n)
    xyz = np.column_stack([x, r * np.cos(a), r * np.sin(a)])
    pos = np.column_stack([np.linspace(0, 0.5, 11), np.full(11, offset), np.zeros(11)])
    g = BranchGraph(pos, np.arange(-1, 10))
    return g, xyz, np.full(11, r), spacing


def test_an_off_axis_twig_moves_onto_its_axis():
    g, xyz, r, sp = _twig(0.005)
    out = centre_thin_nodes(g, xyz, r, np.zeros(11, bool), sp)
    inner = slice(1, 10)  # the end slabs hold points on one side only
    assert np.abs(out.position[inner, 1]).max() < 0.0015  # was 5 mm off
    assert np.abs(out.position[inner, 0] - g.position[inner, 0]).max() < 1e-12


def test_fitted_and_thick_nodes_keep_their_place():
    g, xyz, r, sp = _twig(0.005)
    fitted = np.ones(11, bool)
    assert np.array_equal(centre_thin_nodes(g, xyz, r, fitted, sp).position, g.position)
    thick = np.full(11, 1.01 * CENTROID_MAX_RADIUS * sp)
    assert np.array_equal(
        centre_thin_nodes(g, xyz, thick, np.zeros(11, bool), sp).position, g.position
    )
    # no points near the skeleton: nothing moves
    far = xyz + [0, 1.0, 0]
    assert np.array_equal(centre_thin_nodes(g, far, r, np.zeros(11, bool), sp).position, g.position)
