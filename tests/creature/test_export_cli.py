"""Exports (round trips / validators) and the CLI, including bad input → exit 2, no file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.creature.exporters import export
from biomorph.creature.generator import generate


@pytest.fixture(scope="module")
def creature():
    return generate(3, legs=4, wings=True)


def test_json_and_obj(creature, tmp_path):
    d = json.loads(export(creature, tmp_path / "c.json").read_text())
    assert d["n_joints"] == len(creature) and d["balance"]["stable"]
    assert np.isclose(sum(b["mass"] for b in d["bones"]), creature.total_mass)
    from biomorph.io.obj import read_mesh

    m = read_mesh(export(creature, tmp_path / "c.obj", bone_shape="box"))
    assert m.n_faces == 12 * int(np.sum(creature.bone_length > 0))


def test_glb_is_valid_and_skinned(creature, tmp_path):
    from biomorph.io.gltf import read_gltf_summary
    from tests.gltf_validator import assert_valid_glb

    p = export(creature, tmp_path / "c.glb")
    assert_valid_glb(p)
    s = read_gltf_summary(p)
    assert s["joints"] == len(creature) + 1  # + the ground-level root bone
    p2 = export(creature, tmp_path / "w.glb", walk=True, bone_shape="bone")
    assert_valid_glb(p2)


def test_bvh_round_trip_with_walk(creature, tmp_path):
    import biomorph.io as bio

    p = export(creature, tmp_path / "c.bvh", walk=True)
    mo = bio.read_bvh(p)
    assert mo.n_joints == len(creature) and mo.n_frames == 64
    rest = bio.read_bvh(export(creature, tmp_path / "r.bvh"))
    # frame 0 of the rest-pose BVH reproduces the generated pose
    pos = rest.world_positions()[0]
    order = [rest.skeleton.index(n) for n in creature.names]  # BVH is depth-first
    assert np.allclose(
        pos[order] - pos[order[0]],
        creature.joint_positions - creature.joint_positions[0],
        atol=1e-5,
    )


def test_osim_bodies_and_ranges(creature, tmp_path):
    from biomorph.io.osim import read_osim_summary

    s = read_osim_summary(export(creature, tmp_path / "c.osim"))
    assert len(s["bodies"]) == len(creature) and s["joints"] == len(creature)
    assert np.isclose(sum(b["mass"] for b in s["bodies"].values()), creature.total_mass, rtol=1e-6)
    ranges = np.array(list(s["coordinates"].values()))
    assert np.all(ranges[:, 0] <= 0) and np.all(ranges[:, 1] >= 0)
    assert np.all(np.abs(ranges) <= 2 * np.pi)  # radians


def test_mjcf_loads_and_settles(creature, tmp_path):
    import mujoco

    from biomorph.io.mjcf import settle

    p = export(creature, tmp_path / "c.xml")
    model = mujoco.MjModel.from_xml_path(str(p))
    assert model.nbody == len(creature) + 1
    assert np.isclose(model.body_mass.sum(), creature.total_mass, rtol=1e-6)
    r = settle(creature, seconds=1.0)
    assert r["upright"], r


def test_cli_generate_json(tmp_path, capsys):
    out = tmp_path / "h.json"
    assert (
        run(
            [
                "creature",
                "generate",
                "--seed",
                "7",
                "--legs",
                "4",
                "--no-wings",
                "-o",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert s["legs"] == 4 and out.exists() and s["stable"]


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--legs", "7"], "--legs"),
        (["--legs", "3"], "legs=3"),
        (["--weight", "-5"], "weight"),
        (["--class", "dragon"], "dragon"),
        (["--class", "fish", "--wings"], "wings"),
        (["-o", "x.fbx"], "fbx"),
        (["--class", "fish", "--legs", "2"], "fish"),
        (["--rigify", "--legs", "0"], "--rigify"),
        (["--weight", "2e6"], "--allow-extrapolation"),
        (["--weight", "0.00005"], "dataset's range"),
        (["--temperature", "-1"], "--temperature"),
        (["--k", "30"], "--k"),
        (["--seed", "-3"], "--seed"),
        (["--neck-length", "2"], "neck"),
    ],
)
def test_cli_bad_input_exit_2_nothing_written(tmp_path, capsys, args, needle):
    out = tmp_path / "c.glb"
    argv = ["creature", "generate", "-o", str(out)] + args
    if "-o" in args:
        argv = ["creature", "generate"] + [a if a != "x.fbx" else str(tmp_path / a) for a in args]
    assert run(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) <= 2
    assert list(tmp_path.iterdir()) == []


SVG = """<svg xmlns="http://www.w3.org/2000/svg"
 xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape" viewBox="0 0 1000 1000">
 <g transform="translate(10,0)">
 <path inkscape:label="neck" d="M 200,300 C 250,350 300,400 350,450"/>
 <path id="back" d="m 350,450 c 100,-20 200,-20 300,0"/>
 <path inkscape:label="tail" d="M 650,450 C 700,470 750,500 800,550"/>
 <path inkscape:label="upper_arm" d="M 360,460 L 360,600"/>
 <path inkscape:label="lower_arm" d="m 360,600 v 150"/>
 <path inkscape:label="hand" d="M 360,750 H 300"/>
 <path inkscape:label="upper_leg" d="M 640,460 l 0,160"/>
 <path inkscape:label="lower_leg" d="M 640,620 L 640,780"/>
 <path inkscape:label="foot" d="M 640,780 h -70"/>
 </g></svg>"""


def test_svg_annotations_absolute_relative_and_flip(tmp_path):
    from biomorph.io.svg_annotations import read_annotations

    p = tmp_path / "a.svg"
    p.write_text(SVG)
    a = read_annotations(p)
    pts = a["points"]
    assert np.allclose(pts[0], [210, 700]) and np.allclose(pts[3], [360, 550])
    assert np.allclose(pts[6], [660, 550])  # relative c: 350+300, 450+0
    assert np.allclose(pts[9], [810, 450])
    assert np.allclose(a["lengths"], [140, 150, 60, 160, 160, 70])


def test_cli_annotate_appends_and_rejects_malformed(tmp_path):
    p = tmp_path / "okapi.svg"
    p.write_text(SVG)
    ds = tmp_path / "species.csv"
    assert (
        run(
            [
                "creature",
                "annotate",
                str(p),
                "--class",
                "mammal",
                "--weight",
                "250",
                "--dataset",
                str(ds),
            ]
        )
        == 0
    )
    from biomorph.creature.dataset import load_species

    t = load_species(ds)
    assert len(t) == 45 and t.name[-1] == "okapi"
    # the extended dataset drives generation
    assert (
        run(
            [
                "creature",
                "generate",
                "--seed",
                "1",
                "--dataset",
                str(ds),
                "-o",
                str(tmp_path / "o.json"),
            ]
        )
        == 0
    )
    bad = tmp_path / "bad.svg"
    bad.write_text(SVG.replace('id="back"', 'id="spine"'))
    assert run(["creature", "annotate", str(bad), "--dataset", str(tmp_path / "n.csv")]) == 2
    assert not (tmp_path / "n.csv").exists()
    curvy = tmp_path / "curvy.svg"
    curvy.write_text(
        SVG.replace('d="M 200,300 C 250,350 300,400 350,450"', 'd="M 200,300 L 350,450"')
    )
    assert run(["creature", "annotate", str(curvy), "--dataset", str(tmp_path / "m.csv")]) == 2
    broken = tmp_path / "broken.svg"
    broken.write_text("<svg><path")
    assert run(["creature", "annotate", str(broken), "--dataset", str(tmp_path / "k.csv")]) == 2


def test_cli_dataset_json(capsys):
    assert run(["creature", "dataset", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert len(d["species"]) == 44 and d["seed_spectrum"]["first"] == 0.349


def test_cli_batch_serial_resumable(tmp_path, capsys):
    out = tmp_path / "b"
    assert (
        run(
            [
                "creature",
                "batch",
                "--count",
                "3",
                "--chunk",
                "2",
                "--out",
                str(out),
                "--workers",
                "0",
                "--format",
                "json",
                "--json",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert s["count"] == 3 and s["stable"] == 3
    assert sorted(p.name for p in out.glob("*.json") if p.name.startswith("creature_")) == [
        "creature_000000.json",
        "creature_000001.json",
        "creature_000002.json",
    ]
    assert run(["creature", "batch", "--count", "3", "--out", str(out), "--format", "fbx"]) == 2


def test_rigify_names(creature, tmp_path):
    from biomorph.creature.rigify import rigify_names

    names = rigify_names(creature)
    assert len(set(names)) == len(names)
    assert {"spine", "head", "thigh.L", "thigh.R", "upper_arm.L", "foot.R"} <= set(names)
    import biomorph.io as bio

    mo = bio.read_bvh(export(creature, tmp_path / "r.bvh", rigify=True, walk=True))
    assert set(mo.skeleton.names) == set(names)


def test_dataset_plot_with_an_unwritten_extension_is_refused(tmp_path, capsys):
    out = tmp_path / "p.foo"
    assert run(["creature", "dataset", "--plot", str(out)]) == 2
    assert "--plot" in capsys.readouterr().err
    assert not out.exists()
