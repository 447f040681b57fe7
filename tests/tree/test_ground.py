"""Ground removal: grid minimum + robust TIN, cloth simulation filter."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError
from biomorph.tree.cloud import has_ground
from biomorph.tree.ground import DEFAULT_METHOD, METHODS, remove_ground
from biomorph.tree.synthetic import generate_tree, simulate_scan
from tests.conftest import shared_file


@pytest.fixture(scope="module")
def scan():
    return simulate_scan(generate_tree("conifer", seed=3), n_points=8000, seed=3)


def _tilt(c, deg):
    a = np.radians(deg)
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return c.with_(xyz=c.xyz @ rot.T)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("tilt", [0, 10])
def test_ground_labels_recovered(scan, method, tilt):
    c = _tilt(scan, tilt)
    lab = c.attributes["is_ground"]
    if method == "classified":  # a file whose processing chain classified its ground
        c = c.with_(attributes={**c.attributes, "classification": np.where(lab, 2, 1)})
    veg, mask = remove_ground(c, method=method)
    assert mask.shape == (c.n_points,) and mask.dtype == bool
    recall = (mask & lab).sum() / lab.sum()
    wood_lost = (mask & ~lab).sum() / (~lab).sum()
    assert recall > 0.97 and wood_lost < 0.04, (recall, wood_lost)
    assert veg.n_points == (~mask).sum()
    assert veg.attributes["is_ground"].mean() < 0.01
    assert veg.xyz[:, 2].max() == pytest.approx(c.xyz[:, 2].max())  # the tree is kept


def test_default_is_a_known_method():
    assert DEFAULT_METHOD in METHODS


@pytest.mark.parametrize("method", METHODS)
def test_no_tree_above_ground(method):
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (3000, 2))
    flat = PointCloud(
        np.c_[xy, 0.02 * rng.normal(size=3000)],
        {"classification": np.full(3000, 2, np.uint8)},
        source="lawn.laz",
    )
    with pytest.raises(InputError, match="no tree above the ground") as e:
        remove_ground(flat, method=method)
    assert "lawn.laz" in str(e.value)


def test_bad_method(scan):
    with pytest.raises(ParameterError, match="method"):
        remove_ground(scan, method="magic")
    with pytest.raises(ParameterError, match="cell"):
        remove_ground(scan, method="grid", cell=0)


def test_pine_plot_ground():
    laspy = pytest.importorskip("laspy")
    las = laspy.read(shared_file("trees", "treels_pine_plot.laz"))
    xyz = np.column_stack([las.x, las.y, las.z]).astype(float)
    c = PointCloud(xyz - xyz.min(axis=0), source="treels_pine_plot.laz")
    assert has_ground(c)
    veg, mask = remove_ground(c)
    # a 10 x 10 m plot: ground everywhere, a thin layer; trees ~15-20 m tall kept
    assert 0.1 < mask.mean() < 0.35
    gz = c.xyz[mask, 2]
    ij = np.floor(c.xyz[mask, :2]).astype(int)
    cells = np.unique(ij, axis=0)
    assert len(cells) >= 95  # ground found in (almost) every 1 m cell
    assert np.ptp(gz) < 3.0
    assert veg.xyz[:, 2].max() - gz.max() > 10
