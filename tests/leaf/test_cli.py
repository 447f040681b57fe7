"""`biomorph leaf ...` end to end: outputs, JSON, bad input → exit 2 and nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.cli import run


@pytest.mark.parametrize("ext", [".obj", ".ply", ".glb", ".can"])
def test_mesh_every_format(tmp_path, capsys, ext: str) -> None:
    out = tmp_path / f"leaf{ext}"
    code = run(
        [
            "leaf",
            "mesh",
            "--preset",
            "wheat",
            "--age",
            "0.7",
            "--triangles",
            "50",
            "--twist",
            "90",
            "-o",
            str(out),
            "--json",
        ]
    )
    assert code == 0 and out.stat().st_size > 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["triangles"] == 50


def test_mesh_obj_has_ids_and_area(tmp_path, capsys) -> None:
    from biomorph.io.obj import read_mesh

    out = tmp_path / "leaf.obj"
    assert (
        run(["leaf", "mesh", "--preset", "maize", "--length", "0.8", "-o", str(out), "--json"]) == 0
    )
    s = json.loads(capsys.readouterr().out)
    m = read_mesh(out)
    assert m.n_faces == s["triangles"]
    assert m.area() == pytest.approx(s["area_m2"], rel=1e-4)
    assert s["length_m"] == 0.8


@pytest.mark.parametrize(
    "args,match",
    [
        (["--age", "1.5"], "--age: got 1.5; expected [0, 1]"),
        (["--age", "-0.1"], "expected [0, 1]"),
        (["--triangles", "0"], "--triangles: got 0; expected >= 1"),
        (["--length", "-1"], "--length: got -1.0; expected > 0"),
        (["--length", "nan"], "--length"),
        (["--undulation", "-0.01"], ">= 0"),
        (["--n-s", "1"], "--n-s"),
        (["--preset", "oak"], "unknown leaf preset"),
        (["--preset", "wheat", "--class", "9"], "no shape class"),
    ],
)
def test_mesh_bad_input(tmp_path, capsys, args, match) -> None:
    out = tmp_path / "leaf.obj"
    assert run(["leaf", "mesh", *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert match in err.replace("\n", " ") and len(err.strip().splitlines()) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_bad_extension(tmp_path, capsys) -> None:
    assert run(["leaf", "mesh", "-o", str(tmp_path / "leaf.stl")]) == 2
    assert "not supported" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_grow_glb_and_folder(tmp_path, capsys) -> None:
    from biomorph.io.gltf import read_gltf_summary

    glb = tmp_path / "grow.glb"
    assert (
        run(["leaf", "grow", "--preset", "wheat", "--frames", "6", "-o", str(glb), "--json"]) == 0
    )
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
        assert (
            run(
                [
                    "leaf",
                    "canopy",
                    "--plants",
                    "8",
                    "--rows",
                    "2",
                    "--spacing",
                    "0.2",
                    "--seed",
                    "3",
                    "-o",
                    str(p),
                    "--json",
                ]
            )
            == 0
        )
    s = json.loads(capsys.readouterr().out.split("}\n{")[0] + "}")
    assert a.read_bytes() == b.read_bytes()
    assert s["lai"] > 0 and s["plants"] == 8
    assert (
        run(["leaf", "canopy", "--plants", "2", "--rows", "3", "-o", str(tmp_path / "c.glb")]) == 2
    )
    assert not (tmp_path / "c.glb").exists()


def test_reduce_curve(tmp_path, capsys) -> None:
    out = tmp_path / "curve.png"
    assert (
        run(
            [
                "leaf",
                "reduce-curve",
                "--preset",
                "grass",
                "--points",
                "60",
                "--leaves",
                "12",
                "-o",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert len(s["time_s"]) == len(s["budgets"]) and s["midrib_error"][-1] > 0


@pytest.mark.parametrize(
    "midrib,widths,match",
    [
        ("x,y\n0,0\n", None, "at least 2"),
        ("x,y\n0,0\n1,5\n1,5\n3,8\n", None, "duplicates"),
        ("x,y\n0,0\n1,5\n3,8\n", "s,r\n0,1\n0.5,-0.2\n1,0\n", "negative"),
        ("x,y\n0,0\n1,5\n3,8\n", "s,r\n0,1\n0.5,1\n0.5,0.8\n1,0\n", "increase strictly"),
        ("x,z\n0,0\n1,5\n", None, "expected columns x and y"),
    ],
)
def test_fit_from_digitised_files_bad_input(tmp_path, capsys, midrib, widths, match) -> None:
    m = tmp_path / "mid.csv"
    m.write_text(midrib)
    args = ["leaf", "mesh", "--midrib", str(m)]
    if widths:
        w = tmp_path / "w.csv"
        w.write_text(widths)
        args += ["--widths", str(w)]
    out = tmp_path / "leaf.obj"
    assert run([*args, "-o", str(out)]) == 2
    assert match in capsys.readouterr().err.replace("\n", " ")
    assert not out.exists()


def test_fit_from_digitised_file(tmp_path, capsys) -> None:
    m = tmp_path / "mid.csv"
    m.write_text("x,y\n0,0\n2,10\n6,18\n12,22\n18,21\n")
    w = tmp_path / "w.csv"
    w.write_text("s,r\n0,1.0\n10,1.6\n20,1.2\n32,0\n")
    out = tmp_path / "leaf.ply"
    assert (
        run(
            [
                "leaf",
                "mesh",
                "--midrib",
                str(m),
                "--widths",
                str(w),
                "--n-s",
                "300",
                "--undulation",
                "0",
                "--twist",
                "0",
                "-o",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert s["width_m"] == pytest.approx(0.016)
    assert s["area_m2"] == pytest.approx(s["analytic_area_m2"], rel=5e-3)


def test_glb_outputs_pass_khronos_validator(tmp_path) -> None:
    from tests.gltf_validator import validate_many, validator_missing

    reason = validator_missing()
    if reason:
        pytest.skip(reason)
    files = [tmp_path / n for n in ("leaf.glb", "grow.glb", "plant.glb", "field.glb")]
    assert run(["leaf", "mesh", "--preset", "maize", "-o", str(files[0])]) == 0
    assert run(["leaf", "grow", "--frames", "4", "-o", str(files[1])]) == 0
    assert (
        run(["leaf", "grow", "--plant", "--leaves", "3", "--frames", "3", "-o", str(files[2])]) == 0
    )
    assert run(["leaf", "canopy", "--plants", "6", "--rows", "2", "-o", str(files[3])]) == 0
    for f, rep in zip(files, validate_many(files), strict=True):
        assert rep["issues"]["numErrors"] == 0, (f, rep["issues"]["messages"][:5])


def test_ids_in_every_export(tmp_path) -> None:
    from biomorph.io.caribu import read_can
    from biomorph.io.gltf import read_gltf_summary
    from biomorph.io.ply import read_mesh

    base = ["leaf", "canopy", "--plants", "4", "--rows", "2", "--seed", "1", "-o"]
    for ext in (".ply", ".obj", ".can", ".glb"):
        assert run([*base, str(tmp_path / f"f{ext}")]) == 0
    ply = read_mesh(tmp_path / "f.ply")
    can = read_can(tmp_path / "f.can")
    assert set(ply.face_ids["plant"]) == set(can.face_ids["plant"]) == {0, 1, 2, 3}
    assert np.array_equal(ply.face_ids["leaf"], can.face_ids["leaf"])
    groups = [ln for ln in (tmp_path / "f.obj").read_text().splitlines() if ln.startswith("g ")]
    assert "g plant_3__leaf_1" in groups
    attrs = read_gltf_summary(tmp_path / "f.glb")["attributes"]
    assert any("PLANT" in a for a in attrs) and any("LEAF" in a for a in attrs)


def test_canopy_thermal_time_classes_and_warning(tmp_path, capsys) -> None:
    out = tmp_path / "f.ply"
    assert (
        run(
            [
                "leaf",
                "canopy",
                "--plants",
                "6",
                "--rows",
                "2",
                "--preset",
                "maize",
                "--leaves",
                "16",
                "--thermal-time",
                "400",
                "--json",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    cap = capsys.readouterr()
    s = json.loads(cap.out)
    assert s["missing_leaves_per_plant"] > 0 and "have not emerged" in cap.err
    assert s["below_ground_vertices"] == 0 and len(s["ground"].split(",")) == 4


@pytest.mark.parametrize(
    "args,match",
    [
        (["--thermal-time", "-5"], "--thermal-time"),
        (["--phyllochron", "0"], "--phyllochron"),
        (["--density", "inf"], "--density"),
        (["--leaves", "0"], "--leaves"),
    ],
)
def test_canopy_bad_numbers(tmp_path, capsys, args, match) -> None:
    out = tmp_path / "f.glb"
    assert run(["leaf", "canopy", *args, "-o", str(out)]) == 2
    assert match in capsys.readouterr().err
    assert not out.exists()
