"""Mature maize plant: stem profile (height, ear position, crown internodes) and the
senescence timing from silking (issue 16)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.io.plant_tables import PHEN_COLUMNS, check_phenology, read_phenology, write_table
from biomorph.leaf.data import (
    MAIZE_SENESCENCE,
    MAIZE_STEM,
    maize_senescence_stages,
    mature_maize_stem,
)
from biomorph.leaf.plant import PlantOptions, build_plant_architecture, default_tables


@pytest.fixture(scope="module")
def mature():
    return build_plant_architecture(PlantOptions(preset="maize"), seed=0)


def test_default_maize_plant_is_field_height_with_the_ear_near_mid_height(mature) -> None:
    s = mature.summary()
    assert 2.0 <= s["height_m"] <= 2.5
    ear = next(o for o in mature.organs if o["organ"] == "blade" and o["rank"] == 11)
    assert 0.35 <= ear["top"][2] / s["height_m"] <= 0.6  # ear leaf (largest blade) collar
    d, _ = default_tables("maize", 16)
    assert int(np.argmax(d["L_blade"])) + 1 == 11
    # crown: the five lowest internodes stay short; the longest ones are around the ear
    assert np.all(d["L_internode"][:5] <= 0.02)
    assert d["L_internode"][10] == pytest.approx(d["L_internode"].max())
    assert 0.15 <= d["L_internode"].max() <= 0.2 and d["L_internode"][-1] < d["L_internode"][10]
    assert d["L_sheath"][10] == pytest.approx(d["L_sheath"].max())
    assert np.all(np.diff(d["W_internode"]) < 0)  # tapering stem
    assert np.all(d["W_sheath"] > d["W_internode"])


def test_mature_maize_keeps_the_ear_leaf_and_above_green(mature) -> None:
    s, lv = mature.summary(), mature.leaves
    green = lv["green_length"] == lv["length"]
    assert set(range(8, 17)) <= set(lv["rank"][green].astype(int).tolist())
    # only the small juvenile leaves have died (bottom-up), under 15 % of the plant's area
    gone = sorted(set(range(1, 17)) - set(lv["rank"].astype(int).tolist()))
    assert gone == list(range(1, len(gone) + 1)) and len(gone) <= 7
    total = 0.5  # the table's blade area per plant
    assert s["green_area_m2"] >= 0.8 * total and s["leaf_area_m2"] <= total * 1.02


def _senesced(areas, ssi, disp, hs):
    return float(np.sum(areas * np.clip((hs - ssi) / (disp - ssi), 0, 1)))


def test_maize_senescence_follows_the_bilinear_course() -> None:
    from biomorph.leaf.shape import preset_classes

    ph, p = 50.0, MAIZE_SENESCENCE
    areas = np.array([preset_classes("maize")[str(r)]["area"] for r in range(1, 17)])
    ssi, disp = maize_senescence_stages(areas, ph)
    assert np.all(np.diff(ssi) > 0) and np.all(disp > ssi) and np.all(ssi >= np.arange(1, 17))
    silk = 16 * ph + p["silking_after_last_ligule_cd"]
    onset = silk - p["onset_before_silking_cd"]
    assert ssi[0] == pytest.approx(onset / ph)  # the lowest leaf starts at the onset
    # slow phase (Borrás et al. 2003: 1.4 cm² per plant per °Cd) up to silking ...
    got = _senesced(areas, ssi, disp, silk / ph)
    assert got == pytest.approx(p["rate1_m2_per_cd"] * p["onset_before_silking_cd"], rel=1e-6)
    # ... then 5.5 cm²/°Cd in the second half of grain filling
    fill = p["grain_filling_cd"]
    ends = disp[disp * ph > silk + p["fast_phase_after_silking"] * fill] * ph
    t1, t2 = ends[0], ends[-1]  # leaf deaths after the break (one leaf at a time)
    rate = (_senesced(areas, ssi, disp, t2 / ph) - _senesced(areas, ssi, disp, t1 / ph)) / (t2 - t1)
    assert rate == pytest.approx(p["rate2_m2_per_cd"], rel=1e-6)
    _, phen = default_tables("maize", 16)
    check_phenology(phen)  # tip < col <= ssi < disp
    assert np.allclose(phen["ssi"], ssi) and np.allclose(phen["disp"], disp)
    # a plant twice as large senesces twice as much area in the same time
    s2, d2 = maize_senescence_stages(2 * areas, ph)
    assert np.allclose(s2, ssi) and np.allclose(d2, disp)
    # the thermal times, not the stages, are what the phyllochron keeps
    s3, _ = maize_senescence_stages(areas, 2 * ph)
    assert np.allclose(s3 * 2 * ph - 16 * 2 * ph, ssi * ph - 16 * ph)


def test_maize_plant_senesces_bottom_up_through_grain_filling() -> None:
    fill = MAIZE_SENESCENCE["grain_filling_cd"]
    silk = 16 * 50.0 + MAIZE_SENESCENCE["silking_after_last_ligule_cd"]
    areas = []
    for tt in (silk, silk + 0.5 * fill, silk + fill):
        pl = build_plant_architecture(PlantOptions(preset="maize", thermal_time=tt), seed=0)
        s, lv = pl.summary(), pl.leaves
        sen = lv["green_length"] < lv["length"]
        assert np.all(lv["rank"][sen] <= lv["rank"][~sen].min() + 1e-9) if sen.any() else True
        areas.append(s["green_area_m2"])
    assert areas[0] > areas[1] > areas[2] > 0  # some leaves still green at maturity


@pytest.mark.parametrize("n", [12, 20])
def test_maize_stem_profile_for_other_leaf_counts(tmp_path, n) -> None:
    stem = mature_maize_stem(blade_params={"n_ranks": n})
    ear = n - 5
    li = stem["L_internode"]
    assert li.size == n and li[ear - 1] == pytest.approx(MAIZE_STEM["max_internode_m"])
    k = MAIZE_STEM["unelongated_internodes"]
    assert np.all(li[:k] == MAIZE_STEM["unelongated_internode_m"])
    d, p = default_tables("maize", n)
    assert d["rank"].size == n and np.all(d["L_internode"] >= 0)
    write_table(tmp_path / "p.csv", p, PHEN_COLUMNS)
    assert np.allclose(read_phenology(tmp_path / "p.csv")["disp"], p["disp"], rtol=1e-5)


def test_maize_plant_cli_reports_height_and_green_area(tmp_path, capsys) -> None:
    out = tmp_path / "maize.glb"
    assert run(["leaf", "plant", "--preset", "maize", "-o", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert 2.0 <= s["height_m"] <= 2.5 and s["leaves"] >= 9
    assert s["green_area_m2"] >= 0.4 and 0 <= s["senescent_area_m2"] < 0.05


def test_user_maize_table_times_senescence_on_its_own_blades() -> None:
    d0, p0 = default_tables("maize", 16)
    flat = {**d0, "L_blade": np.full(16, 0.8), "W_blade": np.full(16, 0.08)}  # no bell
    _, phen = PlantOptions(preset="maize", dimensions=flat).tables()
    check_phenology(phen)
    assert phen["ssi"][0] == pytest.approx(p0["ssi"][0])  # same onset ...
    assert phen["disp"][0] > p0["disp"][0] + 1  # ... but a large lowest leaf lasts longer
    given = PlantOptions(preset="maize", dimensions=flat, phenology=p0).tables()[1]
    assert np.allclose(given["disp"], p0["disp"])  # a given phenology is kept as is
