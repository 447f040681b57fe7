"""NPY point arrays: plain and structured round trips, malformed input."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import FormatError
from biomorph.io import npy


def test_plain_and_structured_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(100, 3))
    plain = npy.read_points(npy.write_points(tmp_path / "a.npy", PointCloud(xyz)))
    assert np.array_equal(plain.xyz, xyz) and plain.attributes == {}
    assert np.load(tmp_path / "a.npy").shape == (100, 3)
    c = PointCloud(
        xyz,
        {
            "i": rng.integers(0, 9, 100).astype(np.uint8),
            "d": rng.normal(size=100).astype(np.float32),
        },
    )
    back = npy.read_points(npy.write_points(tmp_path / "b.npy", c))
    assert np.array_equal(back.xyz, xyz)
    for k, v in c.attributes.items():
        assert back.attributes[k].dtype == v.dtype and np.array_equal(back.attributes[k], v)


def test_wide_plain_array_extra_columns(tmp_path):
    arr = np.arange(20.0).reshape(4, 5)
    np.save(tmp_path / "w.npy", arr)
    c = npy.read_points(tmp_path / "w.npy")
    assert np.array_equal(c.xyz, arr[:, :3])
    assert np.array_equal(c.attributes["column_3"], arr[:, 3])
    assert np.array_equal(c.attributes["column_4"], arr[:, 4])


@pytest.mark.parametrize(
    "arr,match",
    [
        (np.zeros(5), "shape"),
        (np.zeros((5, 2)), "shape"),
        (np.zeros((0, 3)), "no points"),
        (np.array([[0, 0, np.nan]]), "row 0"),
        (np.array([[0, 0, 1], [0, np.inf, 0]]), "row 1"),
        (np.array([["a", "b", "c"]]), "not numeric"),
        (np.zeros(3, dtype=[("x", float), ("y", float)]), "fields x, y, z"),
    ],
)
def test_malformed_arrays(tmp_path, arr, match):
    p = tmp_path / "bad.npy"
    np.save(p, arr)
    with pytest.raises(FormatError, match=match):
        npy.read_points(p)


def test_pickles_refused_and_garbage(tmp_path):
    p = tmp_path / "obj.npy"
    np.save(p, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(FormatError, match="not a readable"):
        npy.read_points(p)
    q = tmp_path / "g.npy"
    q.write_bytes(b"\x93NUMPY garbage")
    with pytest.raises(FormatError):
        npy.read_points(q)
    e = tmp_path / "e.npy"
    e.write_bytes(b"")
    with pytest.raises(FormatError, match="empty"):
        npy.read_points(e)
    good = npy.write_points(tmp_path / "t.npy", PointCloud(np.zeros((100, 3))))
    t = tmp_path / "trunc.npy"
    t.write_bytes(good.read_bytes()[:300])
    with pytest.raises(FormatError):
        npy.read_points(t)
