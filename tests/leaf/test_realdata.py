"""The whole pipeline on the real digitised leaves (skipped when ../shared is absent)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.leaf.data import maize_leaves, read_xy, wheat_leaves
from biomorph.leaf.mesh import LeafBatch, leaf_areas, mesh_batch
from biomorph.leaf.reduction import reduced_mesh
from tests.conftest import shared_file


def _root():
    return shared_file("leaves", "README.md").parent


@pytest.mark.parametrize("db", ["leaves_db", "simple"])
def test_all_maize_leaves_mesh_to_their_analytic_area(db: str) -> None:
    leaves = maize_leaves(_root(), db=db)
    assert len(leaves) == {"leaves_db": 158, "simple": 13}[db]
    m = mesh_batch(LeafBatch.from_shapes(leaves, s=np.linspace(0, 1, 400)), n_u=3)
    areas = leaf_areas(m)
    exact = np.array([lf.area() for lf in leaves])
    assert np.allclose(areas, exact, rtol=5e-3)
    for leaf in leaves[::20]:
        assert reduced_mesh(leaf, 21).area() == pytest.approx(leaf.area(), rel=1e-9)


def test_wheat_fit_follows_the_digitised_midribs() -> None:
    root = _root()
    leaves = wheat_leaves(root)
    raw = read_xy(root / "adel" / "So99.csv")
    devs = []
    for leaf, (x, y) in zip(leaves, raw.values(), strict=True):
        pts = leaf.midrib(400)[:, [0, 2]] / 0.01  # back to cm
        d = np.hypot(pts[:, None, 0] - x[None], pts[:, None, 1] - y[None]).min(axis=0)
        devs.append(d.max() / (leaf.length / 0.01))
    # every digitised point lies close to the fitted (corner-rounded) midrib
    assert np.median(devs) < 0.01 and np.max(devs) < 0.05
    lengths = np.array([lf.length for lf in leaves])
    assert 0.03 < lengths.min() and lengths.max() < 0.5  # metres, not cm
