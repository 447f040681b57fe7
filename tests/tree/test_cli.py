"""``biomorph tree …`` commands, including every bad input of the issue (exit 2, one line,
nothing written)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.cli import run
from tests.tree.test_livny import make_cloud


def _write_xyz(path, pts):
    np.savetxt(path, pts, fmt="%.6f")
    return path


def _nothing_written(out):
    return not out.exists() or not any(out.iterdir())


@pytest.fixture(scope="module")
def good_xyz(tmp_path_factory):
    return _write_xyz(tmp_path_factory.mktemp("cli") / "tree.xyz", make_cloud(n=4000, seed=21))


def _bad_inputs(tmp):
    rng = np.random.default_rng(0)
    cases = {}
    (tmp / "empty.xyz").write_text("")
    cases["empty"] = tmp / "empty.xyz"
    cases["single"] = _write_xyz(tmp / "single.xyz", np.array([[1.0, 2.0, 3.0]]))
    nan = make_cloud(n=500)
    nan[17, 1] = np.nan
    cases["nan"] = _write_xyz(tmp / "nan.xyz", nan)
    inf = make_cloud(n=500)
    inf[3, 2] = np.inf
    cases["inf"] = _write_xyz(tmp / "inf.xyz", inf)
    flat = rng.uniform(-1, 1, (500, 3))
    flat[:, 2] = 0.5
    cases["coplanar"] = _write_xyz(tmp / "coplanar.xyz", flat)
    line = np.outer(np.linspace(0, 1, 500), [1.0, 2.0, 3.0])
    cases["collinear"] = _write_xyz(tmp / "collinear.xyz", line)
    ground = np.column_stack([rng.uniform(-5, 5, (20000, 2)), rng.normal(0, 0.01, 20000)])
    cases["no_tree"] = _write_xyz(tmp / "ground_only.xyz", ground)
    (tmp / "corrupt.laz").write_bytes(b"LASF" + bytes(rng.integers(0, 255, 600, dtype=np.uint8)))
    cases["corrupt_laz"] = tmp / "corrupt.laz"
    (tmp / "text.xyz").write_text("1 2 3\n4 five 6\n")
    cases["non_numeric"] = tmp / "text.xyz"
    return cases


@pytest.mark.parametrize(
    "case",
    [
        "empty",
        "single",
        "nan",
        "inf",
        "coplanar",
        "collinear",
        "no_tree",
        "corrupt_laz",
        "non_numeric",
    ],
)
def test_bad_input_exits_2_with_one_line_and_writes_nothing(case, tmp_path, capsys):
    path = _bad_inputs(tmp_path)[case]
    out = tmp_path / f"out_{case}"
    code = run(["tree", "skeletonize", str(path), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.startswith("error:") and len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    assert _nothing_written(out)


def test_missing_file_and_bad_parameters(tmp_path, good_xyz, capsys):
    assert (
        run(["tree", "skeletonize", str(tmp_path / "nope.laz"), "--out", str(tmp_path / "o")]) == 2
    )
    assert (
        run(
            [
                "tree",
                "skeletonize",
                str(good_xyz),
                "--method",
                "magic",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert (
        run(
            [
                "tree",
                "skeletonize",
                str(good_xyz),
                "--order-angle",
                "0",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert (
        run(
            [
                "tree",
                "skeletonize",
                str(good_xyz),
                "--filter",
                "Deviation",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert (
        run(
            ["tree", "skeletonize", str(good_xyz), "--foliage", "0.5", "--out", str(tmp_path / "o")]
        )
        == 2
    )
    assert "--foliage must be 0 (off) or a factor > 1" in capsys.readouterr().err
    assert (
        run(
            [
                "tree",
                "skeletonize",
                str(good_xyz),
                "--edge-weights",
                "heavy",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert "edge_weights 'heavy'" in capsys.readouterr().err
    assert (
        run(
            [
                "tree",
                "skeletonize",
                str(good_xyz),
                "--tip-support",
                "1.5",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert "--tip-support: got 1.5; expected (0, 1)" in capsys.readouterr().err
    capsys.readouterr()
    assert _nothing_written(tmp_path / "o")


def test_the_same_points_in_another_order_and_frame_give_the_same_summary(tmp_path, capsys):
    """Two exports of one scan -- the points listed in another order, moved by a
    georeferencing offset, six decimals -- give the same model from the CLI."""
    pts = np.round(make_cloud(n=4000, seed=21), 6)  # the scan's own lattice: 1 µm
    a = _write_xyz(tmp_path / "a.xyz", pts)
    moved = pts[np.random.default_rng(2).permutation(len(pts))] + (512345.678, 5401234.567, 300)
    b = _write_xyz(tmp_path / "b.xyz", moved)
    got = []
    for f in (a, b):
        assert run(["tree", "skeletonize", str(f), "--out", str(tmp_path / f.stem), "--json"]) == 0
        got.append(json.loads(capsys.readouterr().out))
    assert got[0]["metrics"]["tbl"] == got[1]["metrics"]["tbl"]
    vol = [g["metrics"]["trees"][0]["total_volume"] for g in got]
    assert vol[0] == vol[1]
    shift = np.subtract(got[1]["offset"], got[0]["offset"])
    np.testing.assert_allclose(shift, (512345.678, 5401234.567, 300), atol=1e-5)


def test_skeletonize_json_and_outputs(good_xyz, tmp_path, capsys):
    out = tmp_path / "out"
    code = run(["tree", "skeletonize", str(good_xyz), "--out", str(out), "--json", "--no-ground"])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["method"] == "graph" and data["metrics"]["nob"] == 3
    assert data["params"]["foliage"] == 3.0 and data["params"]["edge_weights"] == "livny"
    # foliage separation off, the paper's alternative weights: still the same Y
    out2 = tmp_path / "out2"
    assert (
        run(
            [
                "tree",
                "skeletonize",
                str(good_xyz),
                "--out",
                str(out2),
                "--json",
                "--no-ground",
                "--foliage",
                "0",
                "--edge-weights",
                "branch",
                "--tip-support",
                "0.3",
                "--no-crown-partition",
            ]
        )
        == 0
    )
    data2 = json.loads(capsys.readouterr().out)
    assert data["params"]["crown_partition"] is True
    assert data2["params"]["crown_partition"] is False
    assert data2["params"]["foliage"] is None and data2["params"]["edge_weights"] == "branch"
    assert data2["params"]["tip_support"] == 0.3
    assert data["params"]["min_cylinder_radius"] == 0.01 and "tip_support" not in data["params"]
    # with --tip-support 0.3 (fewer spurs pruned) a spur of one node survives on half the
    # point orders of this Y (shuffled: 3, 4 or 5 branches; the default keeps 3 on 7 of 8)
    assert data2["metrics"]["nob"] in (3, 4)
    for name in (
        "skeleton.ply",
        "skeleton.mtg",
        "tube.glb",
        "tube.obj",
        "cylinders.csv",
        "branches.csv",
        "treedata.csv",
        "points.laz",
        "summary.json",
        "preview.png",
    ):
        assert (out / name).is_file(), name


def test_georeferenced_cloud_is_written_back_in_world_coordinates(tmp_path, capsys):
    off = np.array([650000.0, 5800000.0, 120.0])
    path = _write_xyz(tmp_path / "geo.xyz", make_cloud(n=4000, seed=22) + off)
    out = tmp_path / "geo"
    assert run(["tree", "skeletonize", str(path), "--out", str(out), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["offset"][0] == pytest.approx(off[0], abs=2)
    from biomorph.io import read_graph

    g = read_graph(out / "skeleton.ply")
    assert np.allclose(g.position[g.roots[0], :2], off[:2], atol=0.05)


def test_synth_then_evaluate(tmp_path, capsys):
    syn = tmp_path / "syn"
    assert (
        run(
            ["tree", "synth", "--preset", "aspen", "--points", "20000", "--out", str(syn), "--json"]
        )
        == 0
    )
    info = json.loads(capsys.readouterr().out)
    assert info["nob"] > 5 and (syn / "truth.ply").is_file() and (syn / "cloud.ply").is_file()
    out = tmp_path / "sk"
    assert run(["tree", "skeletonize", str(syn / "cloud.ply"), "--out", str(out)]) == 0
    capsys.readouterr()
    assert (
        run(
            [
                "tree",
                "evaluate",
                str(out / "skeleton.ply"),
                "--truth",
                str(syn / "truth.ply"),
                "--cloud",
                str(syn / "cloud.ply"),
                "--json",
            ]
        )
        == 0
    )
    ev = json.loads(capsys.readouterr().out)
    assert ev["comparison"]["f1"] > 0.6
    assert ev["mse"] is not None and ev["nob"] > 0
    assert run(["tree", "evaluate", str(tmp_path / "missing.ply")]) == 2


def test_batch_reports_failures_and_resumes(tmp_path, good_xyz, capsys):
    bad = tmp_path / "bad.xyz"
    bad.write_text("1 2 3\n")
    out = tmp_path / "batch"
    code = run(
        ["tree", "batch", str(good_xyz), str(bad), "--out", str(out), "--workers", "0", "--json"]
    )
    assert code == 1
    rep = json.loads(capsys.readouterr().out)
    assert rep["n_ok"] == 1 and rep["n_failed"] == 1
    assert (out / "tree" / "summary.json").is_file()
    # the inventory: every tree of the finished input (none of the failed one), its
    # treedata row and location
    inv = (out / "inventory.csv").read_text().splitlines()
    tree_rows = (out / "tree" / "treedata.csv").read_text().splitlines()
    assert inv[0] == "input," + tree_rows[0] and "location_x" in inv[0]
    assert inv[1:] == [f"{good_xyz.name},{r}" for r in tree_rows[1:]]
    code = run(["tree", "batch", str(good_xyz), "--out", str(out), "--workers", "0", "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert code == 0 and rep["n_skipped"] == 1
    # a resumed (skipped) input stays in the inventory
    assert (out / "inventory.csv").read_text().splitlines() == inv


@pytest.mark.parametrize(
    ("flag", "value", "name"),
    [("--trunk-angle", "0", "--trunk-angle"), ("--taper-exponent", "5", "--taper-exponent")],
)
def test_trunk_angle_and_taper_exponent_are_checked(flag, value, name, good_xyz, tmp_path, capsys):
    out = tmp_path / "o"
    code = run(["tree", "skeletonize", str(good_xyz), flag, value, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and name in err and "Traceback" not in err, err
    assert _nothing_written(out)


def test_trunk_angle_and_taper_exponent_reach_the_summary(good_xyz, tmp_path, capsys):
    out = tmp_path / "o"
    args = ["tree", "skeletonize", str(good_xyz), "--no-ground", "--json", "--out", str(out)]
    code = run([*args, "--trunk-angle", "50", "--taper-exponent", "2.5"])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["params"]["trunk_angle_deg"] == pytest.approx(50.0)
    assert all(m["b"] == pytest.approx(0.4) for m in data["info"]["taper_model"].values())


def test_no_twig_scale_reaches_the_summary(good_xyz, tmp_path, capsys):
    args = ["tree", "skeletonize", str(good_xyz), "--no-ground", "--json"]
    assert run([*args, "--out", str(tmp_path / "on")]) == 0
    on = json.loads(capsys.readouterr().out)
    assert run([*args, "--no-twig-scale", "--out", str(tmp_path / "off")]) == 0
    off = json.loads(capsys.readouterr().out)
    assert on["params"]["twig_scale"] is True and off["params"]["twig_scale"] is False
    assert "twig_offset" not in off["info"]


def test_the_summary_table_gives_the_wood_volume_height_and_dbh(good_xyz, tmp_path, capsys):
    """What a forester reads first, without --json: the volume in all and per diameter
    class, and for one tree its height, trunk length and DBH, matching summary.json."""
    from biomorph.tree.metrics import summary_rows

    out = tmp_path / "out"
    args = ["tree", "skeletonize", str(good_xyz), "--out", str(out), "--no-ground"]
    assert run(args) == 0
    text = capsys.readouterr().out
    data = json.loads((out / "summary.json").read_text())
    rows = dict(summary_rows(data["metrics"]))
    tree = data["metrics"]["trees"][0]
    assert rows["wood volume (L)"] == f"{1e3 * tree['total_volume']:,.1f}"
    assert rows["height / trunk (m)"] == f"{tree['height']:.2f} / {tree['trunk_length']:.2f}"
    assert "<2.5cm" in rows["volume by diameter (L)"]
    for label in ("wood volume (L)", "volume by diameter (L)", "height / trunk (m)"):
        assert label in text
    # a plot: the total and the classes, no single height
    two = dict(data["metrics"], trees=[tree, tree])
    rows2 = dict(summary_rows(two))
    assert rows2["wood volume (L)"] == f"{2e3 * tree['total_volume']:,.1f}"
    assert "height / trunk (m)" not in rows2 and "DBH (cm)" not in rows2
    # what the run read from the scan: spacings and the residual threshold it chose
    ns = data["params"]["node_spacing"]
    assert f"/ {1e3 * ns:.1f}" in text
    f = data["params"]["residual_factor"]
    assert f"{f:.2f} (auto, twigs:" in text
    assert run([*args, "--residual-threshold", "0.8"]) == 0
    assert "0.80 (set)" in capsys.readouterr().out


def test_evaluate_reports_agreement_with_reference_models(good_xyz, tmp_path, capsys):
    """``tree evaluate --reference``: the agreement a forester reads against a QSM (here
    the model against itself and against a thinner copy); a missing reference is one
    line and exit 2."""
    from biomorph.io import read_graph, write_graph

    out = tmp_path / "out"
    assert run(["tree", "skeletonize", str(good_xyz), "--out", str(out), "--no-ground"]) == 0
    capsys.readouterr()
    skel = out / "skeleton.ply"
    g = read_graph(skel)
    thin = write_graph(tmp_path / "thin.ply", g.with_(radius=g.radius * 0.5))
    argv = ["tree", "evaluate", str(skel), "--reference", str(skel), "--reference", str(thin)]
    assert run([*argv, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)["references"]
    same, half = data[str(skel)], data[str(thin)]
    assert same["f1"] == pytest.approx(1.0) and same["volume_ratio"] == pytest.approx(1.0)
    assert same["trunk_length_ratio"] == pytest.approx(1.0)
    assert half["volume_ratio"] == pytest.approx(4.0)  # ours against a model half as thick
    assert run(argv) == 0
    text = capsys.readouterr().out
    assert "volume ours / ref." in text and "(4.00×)" in text and "F1 @ 5 cm" in text
    assert run(["tree", "evaluate", str(skel), "--reference", str(tmp_path / "no.mat")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no.mat" in err[0]
