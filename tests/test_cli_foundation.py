"""CLI: --version, `biomorph info` on every kind, `biomorph render`, errors -> exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph import __version__
from biomorph.cli import run
from biomorph.core.mesh import Mesh
from biomorph.foundation_demo import sample_surface, synthetic_tree
from biomorph.io import write_graph, write_mesh, write_points
from tests.conftest import shared_file

PNG = b"\x89PNG\r\n\x1a\n"


def info_json(capsys, path):
    capsys.readouterr()
    assert run(["info", str(path), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    g = synthetic_tree(seed=1, generations=3)
    c = sample_surface(g, 3000, seed=1)
    m = Mesh.from_any(
        (
            np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 1.0]]),
            np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
        )
    )
    return {
        "graph": g,
        "cloud": c,
        "mesh": m,
        "laz": write_points(d / "c.laz", c),
        "xyz": write_points(d / "c.xyz", c),
        "ply_points": write_points(d / "c.ply", c),
        "npy": write_points(d / "c.npy", c),
        "ply_graph": write_graph(d / "g.ply", g),
        "mtg": write_graph(d / "g.mtg", g),
        "obj": write_mesh(d / "m.obj", m),
        "ply_mesh": write_mesh(d / "m.ply", m),
    }


def test_version(capsys):
    assert run(["--version"]) == 0
    assert __version__ in capsys.readouterr().out


@pytest.mark.parametrize("key", ["laz", "xyz", "ply_points", "npy"])
def test_info_point_clouds(capsys, files, key):
    info = info_json(capsys, files[key])
    c = files["cloud"]
    assert info["kind"] == "points" and info["points"] == c.n_points
    assert np.allclose(info["bbox_min"], c.xyz.min(0), atol=1e-4)
    assert np.allclose(info["bbox_max"], c.xyz.max(0), atol=1e-4)
    assert "Deviation" in info["attributes"]
    from scipy.spatial import cKDTree

    d, _ = cKDTree(c.xyz).query(c.xyz, k=2)
    assert info["spacing_median"] == pytest.approx(np.median(d[:, 1]), rel=0.02)


@pytest.mark.parametrize("key", ["ply_graph", "mtg"])
def test_info_skeleton_graphs(capsys, files, key):
    info = info_json(capsys, files[key])
    g = files["graph"]
    assert info["kind"] == "graph"
    assert info["nodes"] == g.n_nodes and info["edges"] == g.n_nodes - 1
    assert info["trees"] == 1 and info["tips"] == g.leaves.size
    assert info["total_length"] == pytest.approx(g.total_length, rel=1e-6)


@pytest.mark.parametrize("key", ["obj", "ply_mesh"])
def test_info_meshes(capsys, files, key):
    info = info_json(capsys, files[key])
    assert info["kind"] == "mesh" and info["vertices"] == 4 and info["faces"] == 4
    assert info["area"] == pytest.approx(files["mesh"].area(), rel=1e-6)


def test_info_motion(capsys):
    path = shared_file("motion", "fairmotion_sinusoidal.bvh")
    info = info_json(capsys, path)
    text = path.read_text()
    frames = int(text.split("Frames:")[1].split()[0])
    ft = float(text.split("Frame Time:")[1].split()[0])
    assert info["kind"] == "motion" and info["frames"] == frames
    assert info["joints"] == text.count("JOINT") + text.count("ROOT")
    assert info["channels"] == sum(
        int(ln.split()[1]) for ln in text.splitlines() if ln.strip().startswith("CHANNELS")
    )
    assert info["fps"] == pytest.approx(1 / ft, rel=1e-6)
    assert info["duration"] == pytest.approx((frames - 1) * ft, rel=1e-6)


def test_info_plain_table(capsys, files):
    assert run(["info", str(files["mtg"])]) == 0
    out = capsys.readouterr().out
    assert "nodes" in out and "total_length" in out


@pytest.mark.parametrize("key", ["laz", "ply_graph", "mtg", "obj"])
def test_render_writes_png(tmp_path, files, key):
    out = tmp_path / f"{key}.png"
    assert run(["render", str(files[key]), "-o", str(out)]) == 0
    data = out.read_bytes()
    assert data.startswith(PNG) and len(data) > 10_000
    assert [p.name for p in tmp_path.iterdir()] == [out.name]  # no temp files left


def test_render_motion_and_up_option(tmp_path):
    path = shared_file("motion", "fairmotion_sinusoidal.bvh")
    out = tmp_path / "m.png"
    assert run(["render", str(path), "-o", str(out), "--up", "y"]) == 0
    assert out.read_bytes().startswith(PNG)


def test_render_api_objects(tmp_path, files):
    from biomorph.core.skeleton import JointSkeleton
    from biomorph.render import render_cloud, render_graph, render_mesh, render_skeleton

    sk = JointSkeleton(["a", "b", "c"], [-1, 0, 1], [[0, 1, 0], [0, 0.5, 0], [0.3, 0, 0]])
    outs = [
        render_skeleton(sk, tmp_path / "s.png"),
        render_cloud(files["cloud"], tmp_path / "c.png", color_by="Deviation", max_points=500),
        render_graph(files["graph"], tmp_path / "g.png", cloud=files["cloud"]),
        render_mesh(files["mesh"], tmp_path / "m.png", up="y"),
    ]
    for o in outs:
        assert o.read_bytes().startswith(PNG)


@pytest.mark.parametrize(
    "args,message",
    [
        (["info", "{tmp}/missing.las"], "does not exist"),
        (["info", "{tmp}/x.weird"], "extension"),
        (["info", "{tmp}/bad.xyz"], "bad.xyz:2"),
        (["info", "{tmp}/bad.mtg"], "MTG"),
        (["render", "{tmp}/bad.xyz", "-o", "{tmp}/out.png"], "bad.xyz:2"),
        (["render", "{tmp}/ok.xyz", "-o", "{tmp}/out.jpg"], ".png"),
        (["render", "{tmp}/ok.xyz", "-o", "{tmp}/out.png", "--up", "q"], "up="),
        (["render", "{tmp}/missing.ply", "-o", "{tmp}/out.png"], "does not exist"),
    ],
)
def test_errors_exit_2_one_line_nothing_written(tmp_path, capsys, args, message):
    (tmp_path / "x.weird").write_text("?")
    (tmp_path / "bad.xyz").write_text("1 2 3\n4 5\n")
    (tmp_path / "bad.mtg").write_text("not an mtg\n")
    (tmp_path / "ok.xyz").write_text("1 2 3\n4 5 6\n")
    argv = [a.format(tmp=tmp_path) for a in args]
    before = set(tmp_path.iterdir())
    assert run(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "Traceback" not in err
    assert len(err.splitlines()) == 1
    assert set(tmp_path.iterdir()) == before


def test_info_large_las_uses_header_and_agrees_with_full_read(monkeypatch, files):
    import biomorph.inspect as inspect

    full = inspect.describe(files["laz"])
    monkeypatch.setattr(inspect, "LARGE_LAS_POINTS", 100)
    quick = inspect.describe(files["laz"])
    assert quick["bbox_source"] == "header" and "bbox_source" not in full
    assert quick["points"] == full["points"]
    assert np.allclose(quick["bbox_min"], full["bbox_min"], atol=1e-4)
    assert np.allclose(quick["bbox_max"], full["bbox_max"], atol=1e-4)
    assert quick["attributes"] == full["attributes"]
    assert quick["spacing_median"] == pytest.approx(full["spacing_median"], rel=1e-6)


def test_render_up_axis_mapping_is_a_rotation():
    from biomorph.errors import ParameterError
    from biomorph.render import _VIEWS, _to_zup

    e = np.eye(3)
    m = _to_zup(e, "y")  # rows: images of x, y, z
    assert np.allclose(m[1], [0, 0, 1])  # Y-up data: y becomes the vertical axis
    assert np.isclose(np.linalg.det(m), 1.0)  # a rotation, no mirror image
    assert np.allclose(_to_zup(e, "z"), e)
    for rot in _VIEWS.values():
        assert np.isclose(np.linalg.det(rot), 1.0) and np.allclose(rot @ rot.T, e)
    assert np.allclose(_VIEWS["front"][1], [0, 0, 1]) and np.allclose(_VIEWS["side"][1], [0, 0, 1])
    with pytest.raises(ParameterError):
        _to_zup(e, "x")


def test_a_tall_object_gets_tall_side_views(tmp_path):
    # a 20 m stem 2 m wide: front and side as tall as the figure, each as wide as its view
    # (in a square panel it filled a tenth of the width); 13 m wide keeps the 2 x 2 grid
    from matplotlib.figure import Figure
    from PIL import Image

    from biomorph.core.graph import BranchGraph
    from biomorph.render import _layout, render_graph

    z = np.linspace(0, 20, 41)
    stem = np.c_[0.3 * np.sin(z), 0.2 * np.cos(z), z]
    tips = stem[5::5] + [1.0, 0.5, 0.3]
    pos = np.vstack([stem, tips])
    parent = np.r_[-1, np.arange(40), np.arange(5, 41, 5)]
    g = BranchGraph(pos, parent, radius=np.full(pos.shape[0], 0.1))
    slots, slot3, tall = _layout(Figure(), pos)
    assert tall and len(slots) == 3
    assert _layout(Figure(), pos * [10, 10, 1])[2] is False  # 13 m wide: a grid
    # the front and side panels are the figure's height, each as wide as its view
    fig = Figure(figsize=(10, 10), layout="constrained")
    slots, slot3, _ = _layout(fig, pos)
    axes = [fig.add_subplot(s) for s in slots]
    fig.canvas.draw()
    boxes = [a.get_position() for a in axes]
    assert boxes[0].height > 0.7 and boxes[1].height > 0.7  # a grid panel: under 0.45
    assert boxes[0].width < 0.35 and boxes[2].height < 0.5  # the top view beside them
    out = render_graph(g, tmp_path / "tall.png")
    img = Image.open(out)
    assert img.size[0] == img.size[1] and np.asarray(img.convert("L")).min() < 128
