"""ADEL-like plants: tables (schema, bad input), tubes, tillers, senescence, MTG, CLI."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.errors import FormatError
from biomorph.io.plant_tables import (
    DIM_COLUMNS,
    PHEN_COLUMNS,
    read_dimensions,
    read_phenology,
    write_table,
)
from biomorph.leaf.canopy import LeafCountWarning
from biomorph.leaf.plant import (
    ORGAN_BLADE,
    ORGAN_INTERNODE,
    ORGAN_SHEATH,
    SENESCENT,
    PlantOptions,
    build_plant_architecture,
    default_tables,
    write_plant_mtg,
)


def test_default_tables_follow_the_wheat_profiles(tmp_path) -> None:
    d, p = default_tables("wheat", 11)
    assert d["rank"].tolist() == list(range(1, 12))
    # the longest blade of Wheat_dimension_profiles.csv (21.2 cm at xn = 0) is F-1
    assert np.argmax(d["L_blade"]) + 1 == 10 and d["L_blade"].max() == pytest.approx(
        0.2116, abs=1e-3
    )
    assert np.all(d["L_internode"] >= 0) and np.all(np.diff(p["col"]) == 1)
    write_table(tmp_path / "d.csv", d, DIM_COLUMNS)
    write_table(tmp_path / "p.csv", p, PHEN_COLUMNS)
    back = read_dimensions(tmp_path / "d.csv")
    assert np.allclose(back["L_blade"], d["L_blade"], rtol=1e-5)
    assert np.array_equal(read_phenology(tmp_path / "p.csv")["tip"], p["tip"])


@pytest.mark.parametrize(
    "kind,text,match",
    [
        (
            "dims",
            "rank,L_blade,W_blade,L_sheath,W_sheath,L_internode,W_internode\n"
            "1,0.1,0.01,0.03,0.004,0,0.004\n3,0.1,0.01,0.03,0.004,0,0.004\n",
            "missing rank(s) 2",
        ),
        (
            "dims",
            "rank,L_blade,W_blade,L_sheath,W_sheath,L_internode,W_internode\n"
            "1,0.1,0.01,-0.03,0.004,0,0.004\n",
            "L_sheath = -0.03",
        ),
        ("dims", "rank,L_blade,W_blade\n1,0.1,0.01\n", "missing column(s) L_sheath"),
        ("phen", "rank,tip,col,ssi,disp\n1,-1,1,5,13\n2,3,2,6,14\n", "out of order"),
        ("phen", "rank,tip,col,ssi,disp\n1,-1,x,5,13\n", "not a number"),
    ],
)
def test_bad_tables_one_line_exit_2_no_file(tmp_path, capsys, kind, text, match) -> None:
    f = tmp_path / f"{kind}.csv"
    f.write_text(text)
    reader = read_dimensions if kind == "dims" else read_phenology
    with pytest.raises(FormatError, match=match.replace("(", r"\(").replace(")", r"\)")):
        reader(f)
    out = tmp_path / "plant.glb"
    assert run(["leaf", "plant", f"--{kind}", str(f), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_plant_organs_tillers_senescence_and_soil() -> None:
    plant = build_plant_architecture(
        PlantOptions(preset="wheat", thermal_time=1100.0, tillers=2), seed=3
    )
    m = plant.mesh
    organs = set(np.unique(m.face_ids["organ"]).tolist())
    assert organs == {ORGAN_BLADE, ORGAN_SHEATH, ORGAN_INTERNODE}
    assert set(np.unique(m.face_ids["axis"]).tolist()) == {0, 1, 2}
    assert m.vertices[:, 2].min() >= 0.0
    s = plant.summary()
    assert 0 < s["senescent_area_m2"] < s["leaf_area_m2"]
    lv = plant.leaves
    old = lv["rank"] == 1
    assert np.all(lv["green_length"][old] < lv["length"][old])  # lowest leaf senescing
    assert (m.vertex_colors == SENESCENT).all(axis=1).any()
    # insertion: collars climb the stem; successive main-stem leaves are 180° apart (±jitter)
    main = [o for o in plant.organs if o["axis"] == 0 and o["organ"] == "sheath"]
    tops = np.array([o["top"][2] for o in main])
    # collars climb where internodes have elongated (the profiles' lowest sheaths shrink
    # slightly, so the lowest collars are not strictly ordered, as in the data)
    assert tops[-1] > 3 * tops[0] and np.all(np.diff(tops[-5:]) > 0)
    # insertion from the vertical: the digitised So99 bases of the upper classes lean up
    # to ~20° past the vertical (over the stem) before the blade arches out
    assert np.all((lv["insertion_deg"] > -45) & (lv["insertion_deg"] < 180))


def test_young_plant_warns_and_grows() -> None:
    with pytest.warns(LeafCountWarning, match="have not emerged"):
        young = build_plant_architecture(PlantOptions(thermal_time=300.0), seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        older = build_plant_architecture(PlantOptions(thermal_time=700.0), seed=0)
    assert young.summary()["height_m"] < older.summary()["height_m"]
    assert young.leaves["rank"].size < older.leaves["rank"].size


def test_plant_mtg_scales(tmp_path) -> None:
    from biomorph.io.mtg import read_graph

    plant = build_plant_architecture(PlantOptions(thermal_time=900.0, tillers=1), seed=1)
    path = write_plant_mtg(tmp_path / "p.mtg", plant)
    text = path.read_text()
    for sym, scale in (("P", 1), ("A", 2), ("M", 3), ("I", 4), ("S", 4), ("L", 4)):
        assert f"\n{sym}\t{scale}\t" in text
    assert "+A2" in text  # the tiller branches off a metamer
    g = read_graph(path)
    assert g.n_nodes == len(plant.organs)  # every organ row carries XX YY ZZ


def test_plant_cli(tmp_path, capsys) -> None:
    d, p = tmp_path / "d.csv", tmp_path / "p.csv"
    assert (
        run(
            [
                "leaf",
                "tables",
                "--preset",
                "maize",
                "--leaves",
                "16",
                "--dims",
                str(d),
                "--phen",
                str(p),
            ]
        )
        == 0
    )
    out, mtg = tmp_path / "maize.glb", tmp_path / "maize.mtg"
    capsys.readouterr()
    assert (
        run(
            [
                "leaf",
                "plant",
                "--preset",
                "maize",
                "--dims",
                str(d),
                "--phen",
                str(p),
                "--thermal-time",
                "800",
                "--mtg",
                str(mtg),
                "-o",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert s["leaves"] == len(s["per_leaf"]) > 5 and s["below_ground_vertices"] == 0
    assert 0.3 < s["height_m"] < 3.5 and mtg.stat().st_size > 0


def test_plant_stand_to_light(tmp_path, capsys) -> None:
    out, mtg = tmp_path / "stand.glb", tmp_path / "stand.mtg"
    assert (
        run(
            [
                "leaf",
                "plant",
                "--thermal-time",
                "900",
                "--plants",
                "6",
                "--rows",
                "2",
                "--density",
                "200",
                "--mtg",
                str(mtg),
                "-o",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert s["plants"] == 6 and s["lai"] > 0 and len({p["plant"] for p in s["per_leaf"]}) == 6
    assert mtg.read_text().count("\n/P") == 6
    assert (
        run(
            [
                "leaf",
                "light",
                str(out),
                "--sun",
                "2026-06-21T12:00",
                "--sky",
                "0",
                "--ground",
                s["ground"],
                "--json",
            ]
        )
        == 0
    )
    lit = json.loads(capsys.readouterr().out)
    assert 0 < lit["intercepted_fraction"] < 1 and lit["leaves"] == s["leaves"]


def test_mature_maize_default_table_gives_field_lai() -> None:
    from biomorph.leaf.shape import LeafShape, class_of_rank

    d, p = default_tables("maize", 16)
    ranks = d["rank"].astype(int)
    ff = np.array(
        [
            LeafShape.from_preset("maize", rank_class=class_of_rank("maize", r, 16)).form_factor()
            for r in ranks
        ]
    )
    area = float(np.sum(d["L_blade"] * d["W_blade"] * ff))
    assert 0.5 - 1e-3 <= area <= 0.7  # m² per mature plant
    for density in (7.0, 8.5, 10.0):
        assert 3.0 <= density * area <= 5.0 + 1e-3
    # bell-shaped: the largest blade is the ear leaf, five ranks below the top
    k = int(np.argmax(d["L_blade"]))
    assert ranks[k] == 11 and np.all(np.diff(d["L_blade"][: k + 1]) > 0)
    assert np.all(np.diff(d["L_blade"][k:]) < 0)
    assert 0.85 <= d["L_blade"][k] <= 1.0 and 0.085 <= d["W_blade"][k] <= 0.1
    # defaults: 16 leaves, thermal time of the last leaf's ligulation
    opts = PlantOptions(preset="maize")
    assert opts.leaves == 16 and opts.thermal_time == pytest.approx(16 * 50.0)
    assert PlantOptions().thermal_time == pytest.approx(1100.0)  # wheat: 11 leaves


@pytest.mark.parametrize("density", [7.0, 10.0, None])
def test_mature_maize_field_lai(tmp_path, capsys, density) -> None:
    out = tmp_path / "maize.glb"
    field = ["--spacing", "0.75", "--density", str(density)] if density else []
    code = run(
        ["leaf", "canopy", "--preset", "maize", "--plants", "60", "--rows", "6", *field,
         "-o", str(out), "--json"]
    )  # fmt: skip
    assert code == 0
    density = density or 8.0  # the maize default: 0.75 m rows, 8 plants/m²
    s = json.loads(capsys.readouterr().out)
    assert s["missing_leaves_per_plant"] == 0 and s["leaves"] == 60 * 16
    # the meshed field: the table's 0.5 m² per plant within the LOD and length jitter
    assert 3.0 <= s["lai"] <= 5.1
    assert s["lai"] == pytest.approx(0.5 * density, rel=0.03)


def test_insertion_jitter_comes_from_the_class_spread() -> None:
    from biomorph.leaf.shape import class_of_rank, preset_classes

    def ins(seed, jitter=None):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opts = PlantOptions(preset="maize", insertion_jitter_deg=jitter)
            return build_plant_architecture(opts, seed=seed).leaves["insertion_deg"]

    assert np.allclose(ins(1, 0.0), ins(2, 0.0))  # no jitter: the class shapes' own angle
    dev = np.array([ins(s) - ins(0, 0.0) for s in range(1, 13)])  # (seeds, leaves)
    ranks = build_plant_architecture(PlantOptions(preset="maize"), seed=0).leaves["rank"]
    sd = [preset_classes("maize")[class_of_rank("maize", int(r), 16)]["insertion_sd_deg"]
          for r in ranks]  # fmt: skip
    ratio = dev.std(axis=0) / np.array(sd)
    assert 0.5 < np.median(ratio) < 1.6
