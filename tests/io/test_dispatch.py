"""biomorph.io dispatch by extension across all foundation formats."""

from __future__ import annotations

import numpy as np
import pytest

import biomorph.io as bio
from biomorph.core.graph import BranchGraph
from biomorph.core.mesh import Mesh
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import FormatError, UnsupportedFormatError


@pytest.mark.parametrize("ext", sorted(bio.POINT_FORMATS))
def test_every_point_format_round_trips(tmp_path, ext):
    rng = np.random.default_rng(0)
    c = PointCloud(
        rng.uniform(0, 10, (50, 3)), {"intensity": rng.integers(0, 999, 50).astype(np.uint16)}
    )
    back = bio.read_points(bio.write_points(tmp_path / f"c{ext}", c))
    tol = 1e-4 if ext in (".las", ".laz") else 0.0
    assert np.abs(back.xyz - c.xyz).max() <= tol
    assert np.array_equal(
        back.attributes["intensity"].astype(np.int64), c.attributes["intensity"].astype(np.int64)
    )


@pytest.mark.parametrize("ext", sorted(bio.GRAPH_FORMATS))
def test_graph_formats(tmp_path, ext):
    g = BranchGraph([[0, 0, 0], [0, 0, 1], [0, 1, 2]], [-1, 0, 1], radius=[0.3, 0.2, 0.1])
    back = bio.read_graph(bio.write_graph(tmp_path / f"g{ext}", g))
    assert back.parent.tolist() == [-1, 0, 1] and np.allclose(back.radius, g.radius)


@pytest.mark.parametrize("ext", [".obj", ".ply"])
def test_mesh_formats(tmp_path, ext):
    m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    out = bio.write_mesh(tmp_path / f"m{ext}", m)
    assert out.exists()
    from biomorph.inspect import load_mesh

    assert np.isclose(load_mesh(out).area(), 0.5)
    assert np.isclose(bio.read_mesh(out).area(), 0.5)
    with pytest.raises(UnsupportedFormatError, match="meshes"):
        bio.read_mesh(tmp_path / "m.xyz")


def test_unknown_extension_and_missing_files(tmp_path):
    with pytest.raises(UnsupportedFormatError, match=r"\.foo"):
        bio.read_points(tmp_path / "x.foo")
    with pytest.raises(UnsupportedFormatError, match="expected one of"):
        bio.write_points(tmp_path / "x", PointCloud(np.zeros((1, 3))))
    with pytest.raises(UnsupportedFormatError):
        bio.read_graph(tmp_path / "x.las")
    with pytest.raises(FormatError, match="does not exist"):
        bio.read_points(tmp_path / "nope.las")
    (tmp_path / "d.xyz").mkdir()
    with pytest.raises(FormatError, match="directory"):
        bio.read_points(tmp_path / "d.xyz")
    assert not (tmp_path / "x").exists()
