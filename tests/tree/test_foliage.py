"""Leaf/wood separation by neighbourhood thickness (tree/foliage.py)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.tree.foliage import neighbourhood_thickness, separate_foliage
from biomorph.tree.synthetic import generate_tree, simulate_scan


def test_thickness_of_a_plane_is_its_noise_and_of_a_ball_is_large():
    rng = np.random.default_rng(0)
    plane = np.column_stack(
        [rng.uniform(0, 1, 4000), rng.uniform(0, 1, 4000), rng.normal(0, 0.002, 4000)]
    )
    th = neighbourhood_thickness(plane, k=12)
    assert np.median(th) < 0.002  # RMS off-plane distance of 12 neighbours < the noise σ
    ball = rng.normal(0, 0.1, (4000, 3))
    assert np.median(neighbourhood_thickness(ball, k=12)) > 4 * np.median(th)
    # rotation invariant
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    assert np.allclose(neighbourhood_thickness(plane @ q.T, k=12), th, atol=1e-12)


def test_thickness_in_blocks_equals_one_block(monkeypatch):
    import biomorph.tree.foliage as fol

    xyz = np.random.default_rng(1).normal(size=(2500, 3))
    whole = fol.neighbourhood_thickness(xyz)
    monkeypatch.setattr(fol, "_CHUNK", 700)
    assert np.allclose(fol.neighbourhood_thickness(xyz), whole, rtol=0, atol=1e-14)


@pytest.mark.parametrize("preset", ["maple", "conifer"])
def test_synthetic_foliage_is_removed_and_wood_kept(preset):
    truth = generate_tree(preset, seed=0)
    cloud = simulate_scan(
        truth,
        n_points=30000,
        seed=0,
        ground=False,
        noise=0.008,
        occlusion=True,
        scanners=2,
        leaves=0.05,
    )
    leaf = cloud.attributes["is_leaf"]
    split = separate_foliage(cloud.xyz)
    assert (~split.wood[leaf]).mean() > 0.75  # most foliage goes
    assert split.wood[~leaf].mean() > 0.95  # nearly all wood stays
    assert 0.04 < split.foliage_fraction < 0.12
    assert len(split.threshold) == 2 and split.threshold[0] > 0


def test_a_leafless_scan_loses_little():
    truth = generate_tree("aspen", seed=1)
    cloud = simulate_scan(truth, n_points=20000, seed=1, ground=False, noise=0.008)
    assert separate_foliage(cloud.xyz).wood.mean() > 0.98


def test_bad_parameters_are_refused():
    xyz = np.random.default_rng(0).normal(size=(100, 3))
    with pytest.raises(ParameterError, match="factor"):
        separate_foliage(xyz, factor=1.0)
    with pytest.raises(ParameterError, match="passes"):
        separate_foliage(xyz, passes=0)
    with pytest.raises(ParameterError, match="k must be"):
        neighbourhood_thickness(xyz, k=2)
    # tiny clouds are kept whole
    assert separate_foliage(xyz[:20]).wood.all()


def test_detection_keeps_leafless_scans_whole_and_splits_leafy_ones():
    truth = generate_tree("maple", seed=0)
    bare = simulate_scan(
        truth, n_points=30000, seed=0, ground=False, noise=0.002, occlusion=False, scanners=4
    )
    split = separate_foliage(bare.xyz, detect=True)
    assert not split.detected and split.wood.all() and split.threshold == ()
    assert split.foliage_share < 0.003
    # the same scan without detection loses its most curved twig points
    assert not separate_foliage(bare.xyz).wood.all()
    leafy = simulate_scan(
        truth,
        n_points=30000,
        seed=0,
        ground=False,
        noise=0.008,
        occlusion=True,
        scanners=2,
        leaves=0.05,
    )
    split = separate_foliage(leafy.xyz, detect=True)
    assert split.detected and split.foliage_share > 0.01
    assert (~split.wood[leafy.attributes["is_leaf"]]).mean() > 0.75
