"""Taper model of tree.radius: reliable fits kept, the rest from the model (issue 13)."""

from __future__ import annotations

import numpy as np

from biomorph.core.graph import BranchGraph
from biomorph.tree.radius import MIN_RADIUS, PIPE_EXPONENT, RadiusFit, taper_radii


def _tree():
    """A 5 m stem (51 nodes, 0.1 m apart) with a 1 m side branch (10 nodes) at 2 m."""
    z = np.arange(51) * 0.1
    stem = np.column_stack([np.zeros(51), np.zeros(51), z])
    br = np.column_stack([0.1 * np.arange(1, 11), np.zeros(10), np.full(10, 2.0)])
    pos = np.vstack([stem, br])
    parent = np.concatenate([[-1], np.arange(50), [20], 51 + np.arange(9)])
    return BranchGraph(pos, parent)


def _fit(g, radius, ok, coverage=0.8, mad=0.001):
    n = g.n_nodes
    return RadiusFit(
        centre=g.position.copy(),
        radius=np.asarray(radius, dtype=float),
        inliers=np.full(n, 50),
        coverage=np.full(n, coverage),
        ok=np.asarray(ok),
        search_radius=np.full(n, 1.0),
        mad=np.full(n, mad),
    )


def test_a_thick_branch_fit_does_not_survive_the_model():
    g = _tree()
    carried = g.subtree_length() + g.edge_length
    truth = 0.02 * carried ** (1 / PIPE_EXPONENT)  # the pipe-model taper
    fitted = truth.copy()
    fitted[51:] = 0.12  # needle-clump circles on the branch
    ok = np.ones(g.n_nodes, dtype=bool)
    r, fit = taper_radii(g, _fit(g, fitted, ok))
    assert fit.reliable[:20].all() and not fit.reliable[51:].any()
    assert np.allclose(r[:40], truth[:40], rtol=0.05)  # the stem follows its fits
    assert np.allclose(r[53:], truth[53:], rtol=0.25)  # the branch follows the model
    assert r[51] <= r[20] + 1e-12  # never thicker than its parent
    assert fit.model[0]["anchor"] == "stem" and fit.model[0]["b"] == 0.5


def test_poorly_covered_fits_are_not_reliable_and_radii_have_a_floor():
    g = _tree()
    fitted = np.full(g.n_nodes, 0.05)
    ok = np.ones(g.n_nodes, dtype=bool)
    _, fit = taper_radii(g, _fit(g, fitted, ok, coverage=0.25))
    assert not fit.reliable.any()
    _, fit = taper_radii(g, _fit(g, fitted, ok, mad=0.01))  # scatter 20 % of r
    assert not fit.reliable.any()
    r, _ = taper_radii(g, _fit(g, np.full(g.n_nodes, 1e-5), ok), min_radius=MIN_RADIUS)
    assert r.min() >= MIN_RADIUS


def test_a_measured_limb_passes_its_ratio_to_the_model_down_to_its_twigs():
    """The branch's first three cross-sections are measured 30 % thinner than the stem's
    pipe model says; its outer nodes, without fits, keep that ratio instead of reverting to
    the model (the pipe model flows from the base to the tips)."""
    g = _tree()
    carried = g.subtree_length() + g.edge_length
    model = 0.02 * carried**0.5
    rng = np.random.default_rng(0)
    fitted = model * np.exp(rng.normal(0.0, 0.2, g.n_nodes))  # fit scatter as on real stems
    fitted[51:54] = 0.7 * model[51:54]
    ok = np.zeros(g.n_nodes, dtype=bool)
    ok[:40] = True
    ok[51:54] = True
    r, fit = taper_radii(g, _fit(g, fitted, ok))
    assert fit.reliable[51:54].all()
    assert np.allclose(r[56:] / model[56:], 0.7, rtol=0.1)  # not back to 1.0
    assert np.allclose(r[:20], fitted[:20], rtol=0.3)  # the stem follows its fits


def test_the_slope_follows_the_exponent():
    g = _tree()
    carried = g.subtree_length() + g.edge_length
    truth = 0.02 * carried ** (1 / 2.5)
    ok = np.ones(g.n_nodes, dtype=bool)
    _, fit = taper_radii(g, _fit(g, truth, ok), exponent=2.5)
    assert fit.model[0]["b"] == 0.4
    assert fit.model[0]["b_free"] is not None and abs(fit.model[0]["b_free"] - 0.4) < 0.02
