"""Shape classes fitted to the digitised leaves, one age axis, soil, leaf-count warning."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.leaf.canopy import FieldSpec, LeafCountWarning, PlantSpec, build_field, field_mesh
from biomorph.leaf.fit import curves_of, max_distances, unit_curve
from biomorph.leaf.mesh import LeafBatch, mesh_batch, rest_on_soil
from biomorph.leaf.shape import LeafShape, class_of_rank, preset_classes, shape_classes
from biomorph.leaf.thermal import ThermalTime
from tests.conftest import shared_file


def test_every_class_within_its_spread() -> None:
    for preset in ("wheat", "maize"):
        classes = shape_classes(preset)
        assert len(classes) >= (6 if preset == "wheat" else 5)
        for key, c in classes.items():
            # shape (one insertion angle fitted per leaf) and as digitised
            assert c["median_maxdist"] < c["spread"], (preset, key)
            assert c["median_maxdist_raw"] < c["spread_raw"], (preset, key)
            assert c["members_maxdist"] <= 0.1 + 1e-9 or c["n_members"] >= 12


def test_one_shape_per_class_once_insertion_is_fitted() -> None:
    # the spread of the digitised classes is mostly insertion angle: with one insertion
    # angle fitted per leaf, one shape is within 0.1 L of the median leaf in every maize
    # group and in the lower wheat classes 4-6; wheat 1-3 mix two shape families
    maize, wheat = shape_classes("maize"), shape_classes("wheat")
    assert max(c["median_maxdist"] for c in maize.values()) <= 0.1
    assert max(wheat[k]["median_maxdist"] for k in "456") <= 0.1
    assert min(wheat[k]["median_maxdist"] for k in "123") > 0.1


def test_aligned_distance_fits_a_turned_leaf() -> None:
    from biomorph.leaf.fit import aligned_distances

    leaf = LeafShape.from_preset("wheat", rank_class="5")
    ref = unit_curve(leaf.phi_at)
    turned = np.array([unit_curve(lambda q, a=a: leaf.phi_at(q) + a) for a in (-0.6, 0.0, 0.3)])
    d, a = aligned_distances(turned, ref)
    assert np.all(d < 2e-3) and np.allclose(a, [-0.6, 0.0, 0.3], atol=1e-3)
    raw = max_distances(turned, ref)
    assert raw[0] > 0.5 and raw[1] < 1e-12


def test_wheat_classes_recomputed_from_so99() -> None:
    from biomorph.leaf.data import wheat_leaves
    from biomorph.leaf.fit import aligned_distances

    root = shared_file("leaves", "README.md").parent
    leaves = wheat_leaves(root)
    for key in ("1", "5"):
        mine = [lf for lf in leaves if lf.name.split()[1] == f"r{key}"]
        ref = unit_curve(LeafShape.from_preset("wheat", rank_class=key).phi_at)
        cur = curves_of(mine)
        c = shape_classes("wheat")[key]
        assert float(np.median(aligned_distances(cur, ref)[0])) == pytest.approx(
            c["median_maxdist"], abs=2e-3
        )
        raw = float(np.median(max_distances(cur, ref)))
        assert raw == pytest.approx(c["median_maxdist_raw"], abs=2e-3)
    # the So99 class is chosen by rank from the top (ADEL): class 1 = flag leaf; the
    # lower classes (4-6) hold erect leaves, the upper ones arch over further
    chords = [shape_classes("wheat")[k]["chord_deg"] for k in "123456"]
    assert max(chords[:3]) < 55 < 60 < min(chords[3:])


def test_rank_to_class() -> None:
    # ADEL (geoLeaf Lindex = nf - n + 1): So99 class 1 is the flag leaf; lower leaves than
    # the sixth from the top share class 6
    assert [class_of_rank("wheat", r, 12) for r in (1, 6, 7, 11, 12)] == ["6", "6", "6", "2", "1"]
    assert [class_of_rank("wheat", r, 3) for r in (1, 2, 3)] == ["3", "2", "1"]
    # maize: one class per rank of the 16-rank mature table, read on the normalised rank
    assert class_of_rank("maize", 9, 16) == "9"
    assert class_of_rank("maize", 20, 20) == "16"
    assert [class_of_rank("maize", r, 8) for r in (1, 8)] == ["1", "16"]
    # shapes matched by time since ligulation: rank 11 (ear leaf) is 5 phyllochrons past it,
    # like the digitised rank 5; the top three take the youngest fully extended group
    assert preset_classes("maize")["11"]["shape_class"] == "g5"
    assert preset_classes("maize")["16"]["shape_class"] == "g8-10"
    assert class_of_rank("grass", 1, 3) is None
    with pytest.raises(ParameterError, match="class"):
        LeafShape.from_preset("wheat", rank_class="9")


def test_fully_grown_leaf_equals_mature_preset() -> None:
    wheat = LeafShape.from_preset("wheat")
    assert wheat.extension_end == pytest.approx(2 / 14)
    assert ThermalTime.for_preset("wheat").full_extension() == pytest.approx(2 / 14)
    a = wheat.extension_end
    assert np.abs(wheat.midrib(51, age=a) - wheat.midrib(51)).max() < 1e-12
    grown = wheat.mesh(age=a, n_s=40)
    mature = wheat.mesh(n_s=40)
    assert np.abs(grown.vertices - mature.vertices).max() < 1e-9
    young, old = wheat.midrib(51, age=0.0), wheat.midrib(51, age=1.0)
    assert old[-1, 2] < wheat.midrib(51)[-1, 2] < young[-1, 2]  # droops with age
    # presets without a collection reach full length where the thermal axis says so
    for preset in ("maize", "grass"):
        tt = ThermalTime.for_preset(preset)
        assert LeafShape.from_preset(preset).extension_end == pytest.approx(tt.full_extension())


def test_thermal_time_axis() -> None:
    tt = ThermalTime(phyllochron=100.0, base_temperature=0.0)
    assert tt.degree_days([5.0, -3.0, 12.0]).tolist() == [5.0, 5.0, 17.0]
    # leaf 3 is fully extended at Haun stage 3
    assert tt.leaf_age(300.0, 3) == pytest.approx(tt.full_extension())
    assert tt.thermal_time_of(3, tt.full_extension()) == pytest.approx(300.0)
    assert not tt.emerged(50.0, 3) and tt.emerged(150.0, 3)
    with pytest.raises(ParameterError, match="phyllochron"):
        ThermalTime(phyllochron=0.0)
    spec = FieldSpec(
        plants=4, rows=2, plant=PlantSpec(preset="wheat", leaves=8, thermal_time=500.0)
    )
    with pytest.warns(LeafCountWarning, match="thermal time 500"):
        fld = build_field(spec, seed=0)
    assert fld.n_leaves == 4 * 7  # ranks with HS - rank >= -2: 1..7


def test_leaf_count_warning_instead_of_silence() -> None:
    spec = FieldSpec(plants=3, rows=1, plant=PlantSpec(preset="wheat", leaves=12, age=0.8))
    with pytest.warns(LeafCountWarning, match="3 of the 12 requested leaves"):
        fld = build_field(spec, seed=0)
    assert fld.missing_leaves() == 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        build_field(FieldSpec(plants=3, rows=1, plant=PlantSpec(leaves=6, age=0.8)), seed=0)


def test_no_vertex_below_ground_and_leaf_bends_at_soil() -> None:
    spec = FieldSpec(
        plants=30, rows=3, plant=PlantSpec(preset="wheat", leaves=9, age=1.0, stem_height=0.05)
    )
    fld = build_field(spec, seed=3)
    m = field_mesh(fld, triangles_per_leaf=21)
    assert m.vertices[:, 2].min() >= 0.0
    free = field_mesh(
        build_field(
            FieldSpec(
                **{**spec.__dict__, "plant": PlantSpec(**{**spec.plant.__dict__, "soil": False})}
            ),
            seed=3,
        ),
        triangles_per_leaf=21,
    )
    assert (free.vertices[:, 2] < -1e-3).sum() > 0  # the same leaves went underground
    # length is kept when a leaf is bent at the soil
    shape = LeafShape.parametric(0.3, 0.02, insertion_deg=-30.0, bending_deg=40.0)
    b = LeafBatch.from_shapes([shape], s=np.linspace(0, 1, 31), origin=[(0, 0, 0.05)])
    rested = rest_on_soil(b, 0.0)
    assert rested.seg.sum() == pytest.approx(0.3)
    mesh = mesh_batch(rested, n_u=3)
    assert mesh.vertices[:, 2].min() >= 0.0
    assert np.isclose(mesh.vertices[:, 2], 0.0).sum() > 10  # the tip part lies on the soil
