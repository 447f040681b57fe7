"""Clouds in centimetres or millimetres (plant scanners, photogrammetry, CloudCompare
exports): read as metres they are trees kilometres tall, so the pipeline stops with a
message naming the units they look like; ``--units`` converts them and every output is in
metres (tree.cloud.check_units / to_metres)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError
from biomorph.tree.cloud import MAX_TREE_HEIGHT, check_units, to_metres
from tests.tree.test_cli import _nothing_written, _write_xyz
from tests.tree.test_livny import make_cloud


def _column(height: float, n: int = 2000) -> PointCloud:
    rng = np.random.default_rng(0)
    return PointCloud(
        np.c_[rng.normal(0, 0.1, n), rng.normal(0, 0.1, n), np.linspace(0, height, n)]
    )


def test_a_cloud_taller_than_any_tree_is_not_in_metres():
    check_units(_column(150.0))  # a tall tree on a slope: metres
    with pytest.raises(InputError) as e:
        check_units(_column(3650.0))  # rTwig's 3.65 m coffee tree in millimetres
    msg = str(e.value)  # (the 0.1-99.9 percentile range: 3,643 m of the column's 3,650)
    assert "3,643 m tall read as metres" in msg and "\n" not in msg
    # both readings are trees: the message gives each height
    assert "cm (36.4 m tall) or mm (3.64 m tall)" in msg and "--units" in msg
    with pytest.raises(InputError, match=r"look like mm \(1\d\d m tall\): pass"):
        check_units(_column(120_000.0))  # a 120 m tree in mm; in cm it would be 1.2 km
    # a stray point far above does not make a cloud in metres look like millimetres
    c = _column(20.0)
    xyz = c.xyz.copy()
    xyz[0, 2] = 10_000.0
    check_units(PointCloud(xyz))
    # just under the bound is a (very tall) tree in metres, just over it is not
    check_units(_column(MAX_TREE_HEIGHT / 0.998 - 0.1))
    with pytest.raises(InputError):
        check_units(_column(MAX_TREE_HEIGHT / 0.998 + 0.5))


def test_to_metres_scales_coordinates_offset_and_the_las_grid():
    c = PointCloud(
        np.array([[1000.0, 2000.0, 3000.0]] * 12),
        offset=np.array([10.0, 20.0, 30.0]),
        meta={"scales": np.array([0.1, 0.1, 0.1]), "offsets": np.array([0.0, 0.0, 100.0])},
        source="x.laz",
    )
    m = to_metres(c, "mm")
    assert np.allclose(m.xyz[0], [1.0, 2.0, 3.0]) and np.allclose(m.offset, [0.01, 0.02, 0.03])
    assert np.allclose(m.meta["scales"], 1e-4) and np.allclose(m.meta["offsets"], [0, 0, 0.1])
    assert m.source == "x.laz" and to_metres(c, "m") is c
    assert np.allclose(to_metres(c, "ft").xyz[0, 0], 304.8)
    with pytest.raises(ParameterError, match="units 'km'"):
        to_metres(c, "km")


def test_the_pipeline_stops_or_converts():
    from biomorph.tree.options import PrepareOptions, SkeletonizeOptions
    from biomorph.tree.pipeline import skeletonize

    cloud = make_cloud(n=4000, seed=5)
    ref = skeletonize(cloud, ground=None)
    mm = cloud * 1000.0
    with pytest.raises(InputError, match="taller than any tree"):
        skeletonize(mm, ground=None)
    got = skeletonize(mm, ground=None, units="mm")
    assert got.params["units"] == "mm" and ref.params["units"] == "m"
    assert got.graph.n_nodes == ref.graph.n_nodes
    vol = [
        float(np.sum(np.pi * s.graph.radius[1:] ** 2 * s.graph.edge_length[1:])) for s in (ref, got)
    ]
    assert vol[1] == pytest.approx(vol[0], rel=1e-3)
    assert np.allclose(got.world_graph().position, ref.world_graph().position, atol=1e-4)
    # --units m runs it as it is (a kilometre-tall "tree"), as the message says
    assert skeletonize(mm, ground=None, units="m").params["units"] == "m"
    with pytest.raises(ParameterError, match="units 'inch'"):
        SkeletonizeOptions(prepare=PrepareOptions(units="inch"))


def test_the_cli_says_which_units_and_writes_metres(tmp_path, capsys):
    from biomorph.cli import run
    from biomorph.io import read_points, write_points

    cloud = make_cloud(n=4000, seed=6)
    src = _write_xyz(tmp_path / "plant_mm.xyz", cloud * 1000.0)
    out = tmp_path / "o"
    base = ["tree", "skeletonize", "--no-ground"]
    assert run([*base, str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "plant_mm.xyz" in err and "--units" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and _nothing_written(out)
    assert run([*base, str(src), "--units", "furlong", "--out", str(out)]) == 2
    assert "units 'furlong'" in capsys.readouterr().err and _nothing_written(out)
    # a LAS file in millimetres on a 0.1 mm grid: outputs in metres on a 0.1 mm grid
    las = write_points(tmp_path / "plant_mm.laz", PointCloud(cloud * 1000.0), scale=0.1)
    assert run([*base, str(las), "--units", "mm", "--json", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["params"]["units"] == "mm"
    pts = read_points(out / "points.laz")
    assert np.ptp(pts.xyz[:, 2]) < 5.0 and np.allclose(pts.meta["scales"], 1e-4)
    assert 1.0 < max(t["height"] for t in summary["metrics"]["trees"]) < 5.0
