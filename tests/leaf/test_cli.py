"""`biomorph leaf ...` end to end: outputs, JSON, bad input → exit 2 and nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.cli import run


@pytest.mark.parametrize("ext", [".obj", ".ply", ".glb", ".can"])
def test_mesh_every_format(tmp_path, capsys, ext: str) -> None:
    out = tmp_path / f"leaf{ext}"
    code = run(["leaf", "mesh", "--preset", "wheat", "--age", "0.7", "--triangles", "50",
                "--twist", "90", "-o", str(out), "--json"])
    assert code == 0 and out.stat().st_size > 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["triangles"] == 50


def test_mesh_obj_has_ids_and_area(tmp_path, capsys) -> None:
    from biomorph.io.obj import read_mesh

    out = tmp_path / "leaf.obj"
    assert run(["leaf", "mesh", "--preset", "maize", "--length", "0.8", "-o", str(out),
                "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    m = read_mesh(out)
    assert m.n_faces == s["triangles"]
    assert m.area() == pytest.approx(s["area_m2"], rel=1e-4)
    assert s["length_m"] == 0.8


@pytest.mark.parametrize("args,match", [
    (["--age", "1.5"], "outside [0, 1]"),
    (["--age", "-0.1"], "outside [0, 1]"),
    (["--triangles", "0"], "below the minimum"),
    (["--length", "-1"], "positive"),
    (["--undulation", "-0.01"], ">= 0"),
    (["--preset", "oak"], "unknown leaf preset"),
])
def test_mesh_bad_input(tmp_path, capsys, args, match) -> None:
    out = tmp_path / "leaf.obj"
    assert run(["leaf", "mesh", *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert match in err.replace("\n", " ")
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_bad_extension(tmp_path, capsys) -> None:
    assert run(["leaf", "mesh", "-o", str(tmp_path / "leaf.stl")]) == 2
    assert "not supported" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_grow_glb_and_folder(tmp_path, capsys) -> None:
    from biomorph.io.gltf import read_gltf_summary

    glb = tmp_path / "grow.glb"
    assert run(["leaf", "grow", "--preset", "wheat", "--frames", "6", "-o", str(glb),
                "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert np.all(np.diff(s["area_m2"]) >= -1e-15)
    assert read_gltf_summary(glb)["animations"] == 1
    folder = tmp_path / "frames"
    assert run(["leaf", "grow", "--frames", "3", "-o", str(folder)]) == 0
    assert len(list(folder.glob("frame_*.obj"))) == 3
    assert run(["leaf", "grow", "--frames", "0", "-o", str(tmp_path / "x.glb")]) == 2
    assert run(["leaf", "grow", "--age-start", "2", "-o", str(tmp_path / "y.glb")]) == 2
    assert not (tmp_path / "x.glb").exists() and not (tmp_path / "y.glb").exists()


def test_canopy_deterministic(tmp_path, capsys) -> None:
    a, b = tmp_path / "a.can", tmp_path / "b.can"
    for p in (a, b):
        assert run(["leaf", "canopy", "--plants", "8", "--rows", "2", "--spacing", "0.2",
                    "--seed", "3", "-o", str(p), "--json"]) == 0
    s = json.loads(capsys.readouterr().out.split("}\n{")[0] + "}")
    assert a.read_bytes() == b.read_bytes()
    assert s["lai"] > 0 and s["plants"] == 8
    assert run(["leaf", "canopy", "--plants", "2", "--rows", "3", "-o",
                str(tmp_path / "c.glb")]) == 2
    assert not (tmp_path / "c.glb").exists()


def test_reduce_curve(tmp_path, capsys) -> None:
    out = tmp_path / "curve.png"
    assert run(["leaf", "reduce-curve", "--preset", "grass", "--points", "60",
                "--leaves", "12", "-o", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert len(s["time_s"]) == len(s["budgets"]) and s["midrib_error"][-1] > 0
