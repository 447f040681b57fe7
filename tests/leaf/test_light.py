"""Light interception: Beer–Lambert on turbid canopies, the exact shadow of one leaf, sun
position, sky, CLI end to end and bad input."""

from __future__ import annotations

import json
from datetime import datetime

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.core.mesh import Mesh
from biomorph.errors import InputError, ParameterError
from biomorph.leaf.light import LightOptions, intercept, sky_directions, sun_position
from biomorph.leaf.light import turbid_canopy as turbid
from tests.conftest import shared_file


@pytest.mark.parametrize("lai,horizontal", [(0.5, False), (2.0, True), (5.0, False)])
def test_gap_fraction_follows_beer_lambert(lai: float, horizontal: bool) -> None:
    m = turbid(lai, leaf=0.015, horizontal=horizontal, seed=int(lai * 10))
    r = intercept(m, LightOptions(sky=16, ground=(0, 0, 1, 1), ray_spacing=0.006))
    cz = r.directions[:, 2]
    # horizontal leaves: G/cos = 1 in every direction; spherical: G = 0.5
    expected = np.exp(-lai) * np.ones_like(cz) if horizontal else np.exp(-0.5 * lai / cz)
    assert np.abs(r.gap_by_direction - expected).max() < 0.02
    # energy is conserved: intercepted + ground = incident
    inc = r.incident.sum() * r.ground_area
    ground = np.dot(r.gap_by_direction, r.incident) * r.ground_area
    assert r.energy.sum() + ground == pytest.approx(inc, rel=1e-9)


def test_analytic_shadow_of_one_horizontal_leaf() -> None:
    a, h = 0.2, 0.5
    v = np.array([[0, 0, h], [a, 0, h], [a, a, h], [0, a, h]]) + [0.4, 0.4, 0]
    leaf = Mesh(
        v,
        np.array([[0, 1, 2], [0, 2, 3]]),
        face_ids={"plant": np.zeros(2, int), "leaf": np.ones(2, int)},
    )
    when = datetime(2026, 6, 21, 10, 0)
    opts = LightOptions(
        when=when,
        latitude=45.0,
        longitude=0.0,
        sky=0,
        diffuse_fraction=0.0,
        par=1000.0,
        ground=(0, 0, 1, 1),
        ray_spacing=0.0025,
        periodic=False,
    )
    r = intercept(leaf, opts)
    # a horizontal leaf intercepts the horizontal irradiance times its area, whatever the sun
    assert r.energy.sum() == pytest.approx(1000.0 * a * a, rel=3e-3)
    assert r.gap_fraction_sun == pytest.approx(1 - a * a, abs=3e-3)
    assert r.leaves["fraction"][0] == pytest.approx(a * a, rel=3e-3)
    assert r.leaves["absorbed"][0] == pytest.approx(0.85 * 1000.0 * a * a, rel=3e-3)
    # where the shadow falls: rays from ground points under the offset shadow hit the leaf
    el, az = r.sun
    from biomorph.leaf.light import direction_from

    d = direction_from(el, az)
    shift = -d[:2] / d[2] * h  # shadow offset on the ground
    assert 0 < np.linalg.norm(shift) < 0.5
    from biomorph.leaf.light import _cast, _Embree, _Trimesh

    inside = np.array([[0.5, 0.5, 0.0], [0.45, 0.55, 0.0]]) + [*shift, 0]
    outside = np.array([[0.5, 0.5, 0.0]]) - [*shift, 0]
    ground = np.concatenate([inside, outside])
    for engine in (_Embree, _Trimesh):  # both ray engines agree
        eng = engine(leaf.vertices[leaf.faces])
        hit = _cast(eng, ground, d, 1.0, (0, 0, 1, 1), False)
        assert min(hit[:2]) >= 0 and hit[2] == -1


def test_sun_position_known_values() -> None:
    # solstice, solar noon at 0° longitude, 45° N: elevation 90 - 45 + 23.44
    el, az = sun_position(datetime(2026, 6, 21, 12, 2), 45.0, 0.0)
    assert el == pytest.approx(68.44, abs=0.15) and az == pytest.approx(180, abs=2)
    # equinox at the equator, 06:00 UTC: the equation of time (-7.5 min) puts the sun
    # 1.9° below the eastern horizon
    el, az = sun_position(datetime(2026, 3, 20, 6, 0), 0.0, 0.0)
    assert el == pytest.approx(-1.9, abs=0.3) and az == pytest.approx(90, abs=1.0)


def test_sky_matches_caribu_turtle16() -> None:
    d, w = sky_directions(16)
    assert w.sum() == pytest.approx(1.0) and d.shape == (16, 3)
    rows = np.loadtxt(shared_file("leaves", "caribu", "Turtle16soc.light"))
    theirs = -rows[:, 1:] / np.linalg.norm(rows[:, 1:], axis=1, keepdims=True)  # travel dir.
    ang = np.degrees(np.arccos(np.clip(d @ theirs.T, -1, 1)))
    assert ang.min(axis=1).max() < 0.1  # every direction is one of theirs
    d46, w46 = sky_directions(46)
    assert d46.shape == (46, 3) and np.all(d46[:, 2] > 0) and w46.sum() == pytest.approx(1)


def test_bad_light_input(tmp_path) -> None:
    m = turbid(1.0, size=0.2)
    with pytest.raises(ParameterError, match="below the horizon"):
        intercept(m, LightOptions(when=datetime(2026, 6, 21, 23, 0), latitude=48.8))
    with pytest.raises(InputError, match="no triangles"):
        intercept(Mesh(np.zeros((0, 3)), np.zeros((0, 3), int)), LightOptions())
    with pytest.raises(ParameterError, match="sky"):
        intercept(m, LightOptions(sky=12))


def test_light_cli_end_to_end(tmp_path, capsys) -> None:
    from biomorph.io.gltf import read_gltf_summary

    field = tmp_path / "field.glb"
    assert run(["leaf", "canopy", "--plants", "8", "--rows", "2", "-o", str(field)]) == 0
    capsys.readouterr()
    png, lit, csv = tmp_path / "light.png", tmp_path / "lit.glb", tmp_path / "leaves.csv"
    assert (
        run(
            [
                "leaf",
                "light",
                str(field),
                "--sun",
                "2026-06-21T12:00",
                "--sky",
                "0",
                "--png",
                str(png),
                "-o",
                str(lit),
                "--table",
                str(csv),
                "--json",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert 0 < s["gap_fraction"] < 1 and s["engine"] == "zbuffer"
    assert s["intercepted_fraction"] == pytest.approx(1 - s["gap_fraction"], abs=1e-9)
    assert png.stat().st_size > 1000
    assert "_PAR_ABSORBED" in read_gltf_summary(lit)["attributes"]
    rows = csv.read_text().splitlines()
    assert rows[0].startswith("plant,leaf,area_m2") and len(rows) > 8


def test_light_takes_the_ground_tile_the_canopy_glb_stores(tmp_path, capsys) -> None:
    """`leaf canopy` stores its ground tile in the GLB's scene extras and `leaf light` uses
    it: the gap fraction is that of the field (LAI over its tile), not of the leaves'
    bounding box (which overhangs the tile and dilutes the LAI)."""
    from biomorph.leaf.files import read_canopy_scene

    field = tmp_path / "field.glb"
    assert run(["leaf", "canopy", "--plants", "24", "--rows", "3", "-o", str(field), "--json"]) == 0
    made = json.loads(capsys.readouterr().out)
    tile = read_canopy_scene(field)[1]
    assert tile is not None and ",".join(f"{v:.6g}" for v in tile) == made["ground"]
    args = ["leaf", "light", str(field), "--sky", "16", "--json"]
    assert run(args) == 0
    lit = json.loads(capsys.readouterr().out)
    assert lit["ground_from"] == "file"
    assert lit["ground_area_m2"] == pytest.approx(made["ground_area_m2"])
    bbox = tmp_path / "bbox.obj"
    assert run(["leaf", "canopy", "--plants", "24", "--rows", "3", "-o", str(bbox)]) == 0
    capsys.readouterr()
    assert read_canopy_scene(bbox)[1] is None
    assert run(["leaf", "light", str(bbox), "--sky", "16", "--json"]) == 0
    loose = json.loads(capsys.readouterr().out)
    assert loose["ground_from"] == "canopy extent"
    assert loose["ground_area_m2"] > lit["ground_area_m2"]
    assert lit["gap_fraction"] < loose["gap_fraction"]


@pytest.fixture(scope="module")
def small_field(tmp_path_factory):
    field = tmp_path_factory.mktemp("light") / "field.glb"
    assert run(["leaf", "canopy", "--plants", "4", "--rows", "2", "-o", str(field)]) == 0
    return field


@pytest.mark.parametrize(
    "args,match",
    [
        (["--sun", "2026-06-21T23:00"], "below the horizon"),
        (["--sun", "noon"], "ISO 8601"),
        (["--sky", "12"], "0, 16 or 46"),
        (["--engine", "optix"], "--engine"),
        (["--latitude", "95"], "--latitude"),
        (["--par", "-1"], "--par"),
        (["--ground", "1,1,0,0"], "--ground"),
        (["--png", "x.jpg"], ".png"),
    ],
)
def test_light_cli_bad_input(small_field, tmp_path, capsys, args, match) -> None:
    field = small_field
    out = tmp_path / "lit.glb"
    args = [a if not a.endswith(".jpg") else str(tmp_path / a) for a in args]
    assert run(["leaf", "light", str(field), *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert match in err.replace("\n", " ") and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_light_cli_empty_canopy(tmp_path, capsys) -> None:
    empty = tmp_path / "empty.obj"
    empty.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    assert run(["leaf", "light", str(empty), "--json"]) == 2
    assert "triangle" in capsys.readouterr().err


def test_fallback_engine_warns_and_agrees(monkeypatch) -> None:
    from biomorph.leaf import light

    m = turbid(1.0, size=0.3, leaf=0.03, seed=2)
    opts = LightOptions(
        when=datetime(2026, 6, 21, 12),
        sky=0,
        diffuse_fraction=0.0,
        ground=(0, 0, 0.3, 0.3),
        ray_spacing=0.005,
        engine="embree",
    )
    fast = intercept(m, opts)

    def missing(tri):
        raise ImportError("no embreex")

    monkeypatch.setattr(light, "_Embree", missing)
    with pytest.warns(RuntimeWarning, match="embreex is not installed"):
        slow = intercept(m, opts)
    assert slow.engine == "trimesh" and fast.engine == "embree"
    assert np.abs(slow.gap_by_direction - fast.gap_by_direction).max() < 0.005
    zbuf = intercept(m, LightOptions(**{**opts.__dict__, "engine": "zbuffer"}))
    assert np.abs(zbuf.gap_by_direction - fast.gap_by_direction).max() < 0.005


def test_light_reads_every_canopy_format(small_field, tmp_path, capsys) -> None:
    from biomorph.leaf.files import read_canopy, write_leaf_mesh

    m = read_canopy(small_field)
    gaps = []
    for ext in (".can", ".ply", ".obj"):
        path = write_leaf_mesh(tmp_path / f"f{ext}", m)
        back = read_canopy(path)
        assert back.n_faces == m.n_faces
        # same ids per face (the OBJ writer groups faces by id, so compare counts)
        assert np.array_equal(np.bincount(back.face_ids["leaf"]), np.bincount(m.face_ids["leaf"]))
        assert back.area() == pytest.approx(m.area(), rel=1e-5)
        assert (
            run(["leaf", "light", str(path), "--sun", "2026-06-21T12:00", "--sky", "0", "--json"])
            == 0
        )
        gaps.append(json.loads(capsys.readouterr().out)["gap_fraction"])
    assert max(gaps) - min(gaps) < 0.01
