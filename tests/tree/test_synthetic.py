"""Synthetic trees and the LiDAR simulator."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.tree.metrics import point_to_skeleton_distance
from biomorph.tree.synthetic import PRESETS, generate_tree, simulate_scan

# thesis B4-B6 (Blender Sapling presets): tips and total length (m)
THESIS = {"maple": (286, 460.4), "birch": (291, 599.07), "aspen": (30, 116.83)}


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_presets_are_valid_trees(preset):
    g = generate_tree(preset, seed=0)
    assert len(g.roots) == 1 and g.radius is not None and g.depth is not None
    assert g.position[:, 2].min() == pytest.approx(0)
    assert (g.radius > 0).all()
    el = g.edge_length[g.parent >= 0]
    assert 0.01 < np.median(el) < 0.2  # node spacing a few cm to a dm
    # radius never grows from parent to child by more than rounding
    ch = np.flatnonzero(g.parent >= 0)
    assert (g.radius[ch] <= g.radius[g.parent[ch]] + 1e-12).all()
    assert g.depth[g.roots[0]] == 0 and g.depth.max() >= 1
    if preset in THESIS:
        nob, tbl = THESIS[preset]
        assert 0.75 * nob <= len(g.leaves) <= 1.25 * nob
        assert 0.75 * tbl <= g.total_length <= 1.25 * tbl


def test_generate_deterministic_and_overrides():
    a = generate_tree("maple", seed=4)
    b = generate_tree("maple", seed=4)
    c = generate_tree("maple", seed=5)
    assert np.array_equal(a.position, b.position)
    assert a.n_nodes != c.n_nodes or not np.array_equal(a.position, c.position)
    tall = generate_tree("aspen", height=25.0)
    assert tall.position[:, 2].max() > 22
    with pytest.raises(ParameterError, match="preset"):
        generate_tree("baobab")
    with pytest.raises(ParameterError, match="unknown tree parameter"):
        generate_tree("maple", heigth=3)


def test_scan_attributes_and_accuracy():
    truth = generate_tree("aspen", seed=2)
    scan = simulate_scan(truth, n_points=8000, noise=0.0, seed=2, leaves=0.1)
    a = scan.attributes
    assert scan.n_points == pytest.approx(8000, abs=5)
    assert a["is_ground"].dtype == bool and a["is_leaf"].dtype == bool
    assert 0.15 < a["is_ground"].mean() < 0.25 and 0.05 < a["is_leaf"].mean() < 0.15
    wood = ~a["is_ground"] & ~a["is_leaf"]
    assert (a["node"][wood] >= 0).all() and (a["node"][a["is_ground"]] == -1).all()
    # noise-free wood points lie on the tube surfaces: distance to axis ~= radius
    d = point_to_skeleton_distance(truth, scan.xyz[wood])
    r = truth.radius[a["node"][wood]]
    assert np.median(np.abs(d - r)) < 0.01


def test_scan_noise_occlusion_and_density():
    truth = generate_tree("conifer", seed=0)
    kw = dict(n_points=6000, ground=False, seed=1, scanners=1)
    clean = simulate_scan(truth, noise=0.0, occlusion=False, **kw)
    noisy = simulate_scan(truth, noise=0.02, occlusion=False, **kw)
    occl = simulate_scan(truth, noise=0.0, occlusion=True, **kw)
    d_clean = point_to_skeleton_distance(truth, clean.xyz) - truth.radius[clean.attributes["node"]]
    d_noisy = point_to_skeleton_distance(truth, noisy.xyz) - truth.radius[noisy.attributes["node"]]
    mad = [np.median(np.abs(d - np.median(d))) for d in (d_clean, d_noisy)]
    # MAD of N(0, 0.02) is 0.0135; the noise runs along the scanner ray, so the radial part
    # is cos(incidence) of it: 0.0077 on this scan
    assert mad[1] > 3 * mad[0] and 0.006 < mad[1] < 0.02
    # occlusion: with one scanner, the far side of the stem behind other wood gets fewer
    # points; the set of sampled truth nodes shrinks
    assert np.unique(occl.attributes["node"]).size < np.unique(clean.attributes["node"]).size
    a = simulate_scan(truth, **kw)
    b = simulate_scan(truth, **kw)
    assert np.array_equal(a.xyz, b.xyz)


def test_no_scanner_sees_inside_the_wood():
    """A branch starts at its parent's axis: the part of its tube inside the parent is not
    scanned (a conifer's whorl branches inside the stem gave circle fits of 3.5 cm at the
    stem's centre, a DBH of 7 cm for 35 cm)."""
    from scipy.spatial import cKDTree

    truth = generate_tree("conifer", seed=1)
    for occlusion in (False, True):
        cloud = simulate_scan(truth, n_points=20000, seed=1, ground=False, occlusion=occlusion)
        stem = np.flatnonzero(truth.radius > 0.1)
        d, j = cKDTree(truth.position[stem]).query(cloud.xyz)
        assert (d < 0.7 * truth.radius[stem][j]).sum() == 0


def test_scan_bad_parameters():
    truth = generate_tree("aspen")
    with pytest.raises(ParameterError, match="scanners"):
        simulate_scan(truth, scanners=0)
    with pytest.raises(ParameterError, match="noise"):
        simulate_scan(truth, noise=-1)
