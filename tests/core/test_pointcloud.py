"""PointCloud container: validation, selection, offsets."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError


def test_select_bounds_world_xyz():
    xyz = np.arange(30, dtype=float).reshape(10, 3)
    c = PointCloud(xyz, {"i": np.arange(10)}, offset=[100, 200, 0])
    assert c.n_points == len(c) == 10
    lo, hi = c.bounds()
    assert np.allclose(lo, xyz.min(0)) and np.allclose(hi, xyz.max(0))
    assert np.allclose(c.world_xyz, xyz + [100, 200, 0])
    s = c.select(c.attributes["i"] % 2 == 0)
    assert s.n_points == 5 and s.attributes["i"].tolist() == [0, 2, 4, 6, 8]
    assert np.allclose(s.offset, c.offset)
    t = c.select(np.array([9, 0]))
    assert t.xyz[0].tolist() == [27, 28, 29]
    assert c.with_(source="x").source == "x"


def test_validation():
    with pytest.raises(InputError, match=r"expected \(n, 3\)"):
        PointCloud(np.zeros((4, 2)))
    with pytest.raises(InputError, match="attribute 'a' has 3 values"):
        PointCloud(np.zeros((4, 3)), {"a": np.zeros(3)})
    with pytest.raises(InputError, match="empty"):
        PointCloud(np.zeros((0, 3))).bounds()
    assert PointCloud(np.zeros((2, 3), dtype=np.float32)).xyz.dtype == np.float64
