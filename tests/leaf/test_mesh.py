"""Vectorised meshing of many leaves."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.leaf.mesh import LeafBatch, leaf_areas, mesh_batch
from biomorph.leaf.shape import LeafShape


def test_batch_equals_single_leaves_and_keeps_ids() -> None:
    shapes = [LeafShape.from_preset(n) for n in ("wheat", "maize", "grass")]
    origin = np.array([[0, 0, 0], [1, 0, 0.2], [0, 2, 0.5]], float)
    az = np.array([0.0, 1.0, 2.5])
    batch = LeafBatch.from_shapes(
        shapes,
        ages=[None, 0.4, 0.9],
        s=np.linspace(0, 1, 12),
        origin=origin,
        azimuth=az,
        plant=[3, 3, 4],
        leaf=[1, 2, 1],
    )
    m = mesh_batch(batch, n_u=3)
    assert set(np.unique(m.face_ids["plant"])) == {3, 4}
    for i in range(3):
        single = mesh_batch(
            LeafBatch.from_shapes(
                [shapes[i]],
                ages=[[None, 0.4, 0.9][i]],
                s=np.linspace(0, 1, 12),
                origin=origin[i],
                azimuth=az[i],
            ),
            n_u=3,
        )
        sel = (m.face_ids["plant"] == [3, 3, 4][i]) & (m.face_ids["leaf"] == [1, 2, 1][i])
        assert m.face_areas()[sel].sum() == pytest.approx(single.area(), rel=1e-12)
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0)
    assert m.uv.min() >= 0 and m.uv.max() <= 1


def test_rotation_keeps_area_and_normals_face_up() -> None:
    shape = LeafShape.from_preset("maize", twist=0.0, undulation=0.0)
    a = mesh_batch(LeafBatch.from_shapes([shape]))
    b = mesh_batch(LeafBatch.from_shapes([shape], azimuth=[1.3], origin=[[1, 2, 3]]))
    assert a.area() == pytest.approx(b.area())
    # upper side: face normals agree with vertex normals
    fn = a.face_normals()
    vn = a.normals[a.faces].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", fn, vn) > 0)


def test_leaf_areas_and_closed_tip() -> None:
    shape = LeafShape.from_preset("wheat")
    assert shape.r[-1] == 0.0
    m = mesh_batch(LeafBatch.from_shapes([shape, shape], s=np.linspace(0, 1, 6)), n_u=2)
    assert m.n_faces == 2 * (2 * 5 - 1)  # closed tip strip: one triangle
    areas = leaf_areas(m)
    assert areas.shape == (2,) and areas[0] == pytest.approx(areas[1])
