"""Shared tree fixtures: the noisy synthetic conifer that the pruning rules' pipeline
tests (empty tips, side branches inside thicker wood) each compare with a rule off."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def noisy_conifer():
    """The conifer preset (seed 0) scanned at 30,000 points with 8 mm noise, occlusion,
    two scanners and 5 % leaf clutter, and its default graph-method skeleton:
    ``(truth, cloud, skeleton)``."""
    from biomorph.tree import skeletonize
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    truth = generate_tree("conifer", seed=0)
    cloud = simulate_scan(
        truth, n_points=30_000, seed=0, noise=0.008, occlusion=True, scanners=2, leaves=0.05
    )
    return truth, cloud, skeletonize(cloud, method="graph")
