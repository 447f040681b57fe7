"""Plants and fields: determinism, phyllotaxy, LAI, growth frames."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.leaf.canopy import (
    FieldSpec,
    PlantSpec,
    build_field,
    build_plant,
    field_mesh,
    leaf_area_index,
    plant_growth_frames,
)

SPEC = FieldSpec(plants=12, rows=3, row_spacing=0.2, plant=PlantSpec(preset="wheat", leaves=5))


def test_same_seed_same_canopy_and_other_seed_differs() -> None:
    a = field_mesh(build_field(SPEC, seed=4))
    b = field_mesh(build_field(SPEC, seed=4))
    c = field_mesh(build_field(SPEC, seed=5))
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert a.vertices.shape != c.vertices.shape or not np.allclose(a.vertices, c.vertices)


def test_distichous_phyllotaxy_and_ages() -> None:
    spec = PlantSpec(leaves=6, age=1.0, azimuth_jitter_deg=0.0)
    plant = build_plant(spec, seed=1)
    d = np.diff(plant.azimuth)
    assert np.allclose(np.cos(d), -1.0)  # successive leaves 180° apart
    assert np.all(np.diff(plant.origin[:, 2]) > 0)  # insertion heights increase up the stem
    assert np.all(np.diff(plant.age) <= 0)  # lower leaves are older
    young = build_plant(PlantSpec(leaves=6, age=0.25), seed=1)
    assert young.n_leaves < plant.n_leaves


def test_ids_and_lai() -> None:
    fld = build_field(SPEC, seed=0)
    m = field_mesh(fld, triangles_per_leaf=15)
    assert set(np.unique(m.face_ids["plant"])) == set(range(12))
    leaf_faces = m.face_ids["leaf"] > 0
    counts = np.bincount(m.face_ids["plant"][leaf_faces] * 10 + m.face_ids["leaf"][leaf_faces])
    assert set(counts[counts > 0]) == {15}  # every leaf got its LOD budget
    lai = leaf_area_index(fld, m)
    assert lai == pytest.approx(m.face_areas()[leaf_faces].sum() / (3 * 0.2 * 4 * 0.2 / 3))
    assert 0.05 < lai < 10


def test_growth_frames_share_topology_and_area_grows() -> None:
    frames = plant_growth_frames(PlantSpec(leaves=4), frames=6, seed=2)
    assert len({f.faces.tobytes() for f in frames}) == 1
    areas = [f.area() for f in frames]
    assert all(b >= a - 1e-12 for a, b in zip(areas, areas[1:], strict=False))


def test_bad_field() -> None:
    with pytest.raises(ParameterError):
        build_field(FieldSpec(plants=2, rows=5))
    with pytest.raises(ParameterError, match="outside"):
        build_field(FieldSpec(plant=PlantSpec(age=2.0)))


def test_density_sets_ground_area() -> None:
    fld = build_field(FieldSpec(plants=40, rows=4, row_spacing=0.2, density=250.0), seed=0)
    assert 40 / fld.ground_area == pytest.approx(250.0)
    with pytest.raises(ParameterError, match="density"):
        build_field(FieldSpec(density=-1.0))


def test_maize_canopy_stem_is_the_mature_plant_stem() -> None:
    """A maize field is as tall as a `leaf plant` maize plant (2–2.5 m), not 2.5 × a blade."""
    from biomorph.leaf.data import mature_maize_stem
    from biomorph.leaf.plant import mature_thermal_time

    spec = PlantSpec(preset="maize", leaves=16, thermal_time=mature_thermal_time("maize", 16, None))
    plant = build_plant(spec, seed=3)
    internodes = mature_maize_stem(blade_params={"n_ranks": 16})["L_internode"]
    assert plant.stem_height[0] == pytest.approx(internodes.sum())
    assert plant.origin[:, 2].min() < 0.05  # crown leaves emerge near the soil
    top = field_mesh(plant, triangles_per_leaf=12).vertices[:, 2].max()
    assert 2.0 <= top <= 2.6
    wheat = build_plant(PlantSpec(preset="wheat", leaves=5, stem_height=0.4), seed=3)
    assert wheat.stem_height[0] == pytest.approx(0.4)
