"""The z-buffer light engine (leaf/raster.py) against Embree ray casting on the same rays,
periodic wrapping of shadows, and reproducible jitter."""

from __future__ import annotations

from datetime import datetime

import numpy as np
import pytest

from biomorph.core.mesh import Mesh
from biomorph.errors import ParameterError
from biomorph.leaf.light import LightOptions, intercept, turbid_canopy
from biomorph.leaf.raster import first_hits, jitter


@pytest.mark.parametrize("periodic", [True, False])
def test_zbuffer_sees_what_embree_sees(periodic: bool) -> None:
    pytest.importorskip("embreex")
    m = turbid_canopy(2.0, 0.5, 0.02, seed=4, horizontal=False)
    opts = dict(sky=16, ground=(0, 0, 0.5, 0.5), ray_spacing=0.005, periodic=periodic)
    z = intercept(m, LightOptions(engine="zbuffer", **opts))
    e = intercept(m, LightOptions(engine="embree", **opts))
    assert z.engine == "zbuffer" and e.engine == "embree"
    # same rays, same first hits (up to float32 ties in Embree on shared edges)
    assert np.abs(z.gap_by_direction - e.gap_by_direction).max() < 2e-3
    same = np.isclose(z.energy, e.energy, rtol=1e-9, atol=0).mean()
    assert same > 0.99
    assert z.energy.sum() == pytest.approx(e.energy.sum(), rel=2e-3)


def test_shadow_wraps_around_a_periodic_tile() -> None:
    a, h = 0.2, 0.6
    sun = datetime(2026, 12, 21, 9, 0)  # low winter sun: the shadow leaves the tile
    for x0 in (0.05, 0.75):  # inside, and straddling the tile's east edge
        v = np.array([[0, 0, h], [a, 0, h], [a, a, h], [0, a, h]]) + [x0, 0.4, 0]
        leaf = Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]))
        base = dict(when=sun, latitude=45.0, longitude=0.0, sky=0, par=1000.0)
        opts = LightOptions(ground=(0, 0, 1, 1), ray_spacing=0.004, **base)
        r = intercept(leaf, opts)
        # a horizontal leaf intercepts E_h · a² wherever its shadow falls on the tile
        assert r.energy.sum() == pytest.approx(1000.0 * a * a, rel=5e-3)
    flat = intercept(
        leaf, LightOptions(ground=(0, 0, 1, 1), ray_spacing=0.004, periodic=False, **base)
    )
    assert flat.energy.sum() < 0.9 * 1000.0 * a * a  # without wrapping, part of it is lost


def test_triangles_below_the_ground_are_not_hit() -> None:
    tri = np.array([[[0.1, 0.1, -0.1], [0.9, 0.1, -0.1], [0.5, 0.9, -0.1]]])
    hits = first_hits(tri, np.array([[0.0, 0.0, 1.0]]), (0, 0, 1, 1), (20, 20))
    assert (hits == -1).all()
    up = tri + [0, 0, 0.2]
    hits = first_hits(up, np.array([[0.0, 0.0, 1.0]]), (0, 0, 1, 1), (20, 20))
    assert 0.25 < (hits == 0).mean() < 0.45  # the triangle's area is 0.32 of the tile


def test_nearest_triangle_from_the_sky_wins() -> None:
    low = [[0.0, 0.0, 0.2], [1.0, 0.0, 0.2], [0.0, 1.0, 0.2]]
    high = [[0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [0.0, 1.0, 0.5]]
    tri = np.array([low, high])
    hits = first_hits(tri, np.array([[0.0, 0.0, 1.0]]), (0, 0, 1, 1), (30, 30))
    assert set(np.unique(hits).tolist()) == {-1, 1}  # the low one is hidden from above
    # oblique: the answer does not depend on the order of the triangles
    d = np.array([[0.3, 0.1, 1.0]]) / np.linalg.norm([0.3, 0.1, 1.0])
    a = first_hits(tri, d, (0, 0, 1, 1), (30, 30))
    b = first_hits(tri[::-1], d, (0, 0, 1, 1), (30, 30))
    assert np.array_equal(a, np.where(b >= 0, 1 - b, -1)) and (a == 0).any()


def test_jitter_is_reproducible_and_stratified() -> None:
    a, b = jitter(3, 5, 40, 30), jitter(3, 5, 40, 30)
    assert np.array_equal(a, b) and a.shape == (1200, 2)
    assert (a >= -0.5).all() and (a < 0.5).all()
    assert not np.array_equal(a, jitter(4, 5, 40, 30))
    assert abs(a.mean()) < 0.03 and a.std() == pytest.approx(np.sqrt(1 / 12), rel=0.05)
    m = turbid_canopy(1.0, 0.3, 0.02, seed=1)
    r1 = intercept(m, LightOptions(sky=16, seed=7))
    r2 = intercept(m, LightOptions(sky=16, seed=7))
    assert np.array_equal(r1.energy, r2.energy)


def test_unknown_engine_is_refused() -> None:
    with pytest.raises(ParameterError, match="light engine"):
        intercept(turbid_canopy(1.0, 0.2), LightOptions(engine="optix"))
