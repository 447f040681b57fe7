"""The skeleton stage stops with a clear message before it would run out of memory
(tree.memory): a machine's available memory is simulated below the estimate."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import InputError
from biomorph.tree import memory
from biomorph.tree.memory import MEMORY_BASE, MEMORY_PER_POINT, check_memory, graph_memory
from tests.tree.test_livny import make_cloud


def test_the_estimate_is_the_measured_line():
    # bench/tree.py --one: 848 MB at 10^6 points, 1,443 MB at 2 x 10^6 (session 29)
    assert graph_memory(1_000_000) == pytest.approx(848e6, rel=0.02)
    assert graph_memory(2_000_000) == pytest.approx(1443e6, rel=0.02)


def test_a_cloud_too_big_for_the_memory_gets_a_voxel_edge_that_fits():
    rng = np.random.default_rng(0)
    # a 1 m x 1 m surface sampled every ~5 mm: 40,000 points
    xyz = np.c_[rng.uniform(0, 1, 40_000), rng.uniform(0, 1, 40_000), np.zeros(40_000)]
    room = MEMORY_BASE + MEMORY_PER_POINT * 10_000  # room for a quarter of them
    with pytest.raises(InputError) as e:
        check_memory(xyz, "big.laz", available=room)
    msg = str(e.value)
    assert msg.startswith("big.laz: 40,000 points need about")
    assert "--downsample-voxel" in msg and "--no-memory-check" in msg and "\n" not in msg
    v = float(msg.split("--downsample-voxel ")[1].split()[0])
    said = int(msg.split("(keeps ")[1].split()[0].replace(",", ""))
    # the suggested voxel keeps no more points than fit, and not far fewer: thinned as
    # the pipeline thins, that is what it keeps
    from biomorph.core.pointcloud import PointCloud
    from biomorph.tree.cloud import downsample

    kept = downsample(PointCloud(xyz), method="voxel", voxel_size=v).n_points
    assert kept == said and 8_000 <= kept <= 10_000, (v, kept)
    check_memory(xyz, "big.laz", available=graph_memory(40_000))  # fits: no error


def test_the_pipeline_and_the_cli_stop_before_the_skeleton_stage(monkeypatch, tmp_path, capsys):
    from biomorph.cli import run
    from biomorph.tree.pipeline import skeletonize
    from tests.tree.test_cli import _write_xyz

    cloud = make_cloud(n=4000, seed=21)
    monkeypatch.setattr(memory, "available_memory", lambda: MEMORY_BASE + 100 * MEMORY_PER_POINT)
    with pytest.raises(InputError, match="points need about"):
        skeletonize(cloud, method="graph")
    # thinned by a ratio: the points left are what counts
    half = round(len(cloud) * 0.5)
    with pytest.raises(InputError, match=f"{half:,} points need"):
        skeletonize(cloud, method="graph", downsample=0.5)
    # the voxel method by the same line; --no-memory-check runs it anyway
    with pytest.raises(InputError, match="points need about"):
        skeletonize(cloud, method="voxel")
    assert skeletonize(cloud, method="graph", memory_check=False).graph.n_nodes > 0
    src = _write_xyz(tmp_path / "y.xyz", cloud)
    out = tmp_path / "o"
    assert run(["tree", "skeletonize", str(src), "--no-ground", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "y.xyz" in err and "points need about" in err and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())  # nothing half-written
    args = ["tree", "skeletonize", str(src), "--no-ground", "--no-memory-check", "--json"]
    assert run([*args, "--out", str(out)]) == 0
