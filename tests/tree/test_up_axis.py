"""Y-up clouds (glTF-style PLY / OBJ exports, photogrammetry tools): read as Z-up a tree
lies on its side and is modelled so without a word (rTwig with y and z swapped: one
"measured stem" 1.5 m tall, 9.1 L for 22.2 L), so ``--up y`` turns them Z-up and every
output is in that frame (tree.cloud.to_z_up)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import ParameterError
from biomorph.tree.cloud import Y_UP_TO_Z_UP, to_z_up
from tests.tree.test_cli import _nothing_written, _write_xyz
from tests.tree.test_livny import make_cloud


def _y_up(xyz: np.ndarray) -> np.ndarray:
    """Z-up points as a Y-up tool writes them: (x, y, z) -> (x, z, -y)."""
    return xyz @ Y_UP_TO_Z_UP


def test_to_z_up_turns_coordinates_offset_and_the_las_grid():
    c = PointCloud(
        np.array([[1.0, 2.0, 3.0]] * 12),
        offset=np.array([10.0, 20.0, 30.0]),
        meta={"scales": np.array([0.1, 0.2, 0.3]), "offsets": np.array([1.0, 2.0, 3.0])},
        source="x.ply",
    )
    t = to_z_up(c, "y")
    # y was up: it becomes z; z (towards the viewer in a Y-up frame) becomes -y
    assert np.allclose(t.xyz[0], [1.0, -3.0, 2.0]) and np.allclose(t.offset, [10, -30, 20])
    assert np.allclose(t.meta["scales"], [0.1, 0.3, 0.2])
    assert np.allclose(t.meta["offsets"], [1.0, -3.0, 2.0])
    assert np.isclose(np.linalg.det(Y_UP_TO_Z_UP), 1.0)  # a rotation: nothing mirrored
    assert to_z_up(c, "z") is c and t.source == "x.ply"
    with pytest.raises(ParameterError, match="up axis 'x'"):
        to_z_up(c, "x")


def test_a_y_up_cloud_gives_the_z_up_model():
    from biomorph.tree.options import PrepareOptions, SkeletonizeOptions
    from biomorph.tree.pipeline import skeletonize

    cloud = make_cloud(n=4000, seed=5)
    ref = skeletonize(cloud, ground=None)
    lying = _y_up(cloud)
    assert np.ptp(lying[:, 2]) < 0.5 * np.ptp(cloud[:, 2])  # on its side
    got = skeletonize(lying, ground=None, up="y")
    assert got.params["up"] == "y" and ref.params["up"] == "z"
    assert got.graph.n_nodes == ref.graph.n_nodes
    assert np.allclose(got.world_graph().position, ref.world_graph().position, atol=1e-6)
    assert np.allclose(got.graph.radius, ref.graph.radius)
    with pytest.raises(ParameterError, match="up axis 'x'"):
        SkeletonizeOptions(prepare=PrepareOptions(up="x"))


def test_the_cli_turns_a_y_up_cloud_and_refuses_an_unknown_axis(tmp_path, capsys):
    from biomorph.cli import run

    cloud = make_cloud(n=4000, seed=6)
    src = _write_xyz(tmp_path / "photogrammetry.xyz", _y_up(cloud))
    out = tmp_path / "o"
    base = ["tree", "skeletonize", "--no-ground", str(src)]
    assert run([*base, "--up", "x", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "up axis 'x'" in err and "Traceback" not in err and _nothing_written(out)
    assert run([*base, "--up", "y", "--json", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["params"]["up"] == "y"
    height = max(t["height"] for t in summary["metrics"]["trees"])
    assert height == pytest.approx(np.ptp(cloud[:, 2]), rel=0.05)
