"""Growing leaves: arc length, monotone area, age interpolation, timeline."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.leaf.growth import GrowthRates, LeafTimeline, state_at_age, visible_area
from biomorph.leaf.mesh import LeafBatch, mesh_batch
from biomorph.leaf.shape import LeafShape, MidribCollection
from tests.conftest import shared_file


def _midrib_length(mesh, n_s: int, n_u: int) -> float:
    mid = np.asarray(mesh.vertices).reshape(n_s, n_u, 3)[:, n_u // 2]
    return float(np.linalg.norm(np.diff(mid, axis=0), axis=1).sum())


@pytest.mark.parametrize("age", np.linspace(0, 1, 11))
def test_visible_midrib_length_equals_l(age: float) -> None:
    leaf = LeafShape.from_preset("wheat")
    st = state_at_age(leaf, age)
    m = mesh_batch(LeafBatch.from_shapes([leaf], states=[st], s=np.linspace(0, 1, 25)), 3)
    assert _midrib_length(m, 25, 3) == pytest.approx(st.visible, rel=1e-12)
    tl = LeafTimeline(leaf, GrowthRates(age_rate=1.0), 1.0, hidden=0.01)
    st2 = tl.state(age)
    m2 = tl.mesh(age, n_s=25)
    assert _midrib_length(m2, 25, 3) == pytest.approx(st2.visible, rel=1e-12, abs=1e-15)


def test_area_non_decreasing_with_positive_rates() -> None:
    leaf = LeafShape.from_preset("maize")
    rates = GrowthRates(age_rate=0.5, length_rate=0.3, width_rate=0.2, bend_rate=0.4)
    tl = LeafTimeline(leaf, rates, 2.0, hidden=0.05)
    times = np.linspace(0, 2, 25)
    areas = np.array([tl.mesh(t, n_s=30).area() for t in times])
    assert np.all(np.diff(areas) >= -1e-12)
    assert areas[-1] > 10 * max(areas[0], 1e-9)
    exact = np.array([tl.visible_area(t) for t in times])
    big = exact > 1e-4
    assert np.allclose(areas[big], exact[big], rtol=0.01)


def test_collection_interpolates_between_ages() -> None:
    s = np.linspace(0, 1, 5)
    coll = MidribCollection(np.array([0.0, 10.0]), s, np.array([np.full(5, 1.0), np.full(5, 0.0)]))
    assert np.allclose(coll.phi_at(0.25), 0.75)
    pts = coll.curve_at(0.5, form="curve")
    assert np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() == pytest.approx(1.0)
    with pytest.raises(ParameterError, match="outside"):
        coll.phi_at(1.5)


def test_held_out_age_of_real_trajectories() -> None:
    from biomorph.leaf.data import read_trajectories

    path = shared_file("leaves", "adel", "echap_leaf_data", "median_leaf_trajectories_Tremie12.csv")
    coll = read_trajectories(path)[1]
    # drop every other stored age and predict the held-out ones by interpolation
    keep = np.arange(0, coll.ages.size, 2)
    thin = MidribCollection(coll.ages[keep], coll.s, coll.phi[keep])
    errs = []
    for j in range(1, coll.ages.size - 1, 2):
        a = (coll.ages[j] - thin.ages[0]) / (thin.ages[-1] - thin.ages[0])
        pred = thin.curve_at(a)
        truth = coll.curve_at((coll.ages[j] - coll.ages[0]) / (coll.ages[-1] - coll.ages[0]))
        errs.append(np.abs(pred - truth).max())
        nearest = thin.curve_at(round(a * (keep.size - 1)) / (keep.size - 1))
        assert np.abs(pred - truth).max() <= np.abs(nearest - truth).max() + 1e-12
    assert max(errs) < 0.02  # unit-length curves: < 2 % of leaf length


def test_timeline_bad_input() -> None:
    leaf = LeafShape.from_preset("wheat")
    with pytest.raises(ParameterError):
        LeafTimeline(leaf, duration=0.0)
    tl = LeafTimeline(leaf, duration=1.0)
    with pytest.raises(ParameterError, match="outside"):
        tl.state(2.0)
    assert visible_area(leaf, tl.state(1.0)) == pytest.approx(leaf.area(), rel=1e-4)


def test_collections_by_leaf_class() -> None:
    from biomorph.leaf.data import read_trajectories

    path = shared_file(
        "leaves",
        "adel",
        "echap_leaf_data",
        "median_leaf_trajectories_Tremie_Boigneville2012_2013_byleafclass.csv",
    )
    colls = read_trajectories(path)
    assert sorted(colls) == [1, 2]
    for c in colls.values():
        assert c.ages.size == 25 and c.s.size == 51
        pts = c.curve_at(0.37)
        assert np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() == pytest.approx(1.0)
    leaf = LeafShape.from_preset("wheat").with_(collection=colls[2])
    st = state_at_age(leaf, 0.9)
    assert leaf.mesh(age=0.9).area() == pytest.approx(visible_area(leaf, st), rel=5e-3)
