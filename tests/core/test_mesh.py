"""Mesh contract: areas, normals, merge, conversions, validation."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from biomorph.core.mesh import Mesh
from biomorph.errors import InputError


def square():
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 3, 0], [0, 3, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return Mesh(v, f, face_ids={"leaf": [1, 2]})


def test_area_and_face_areas():
    m = square()
    assert m.area() == pytest.approx(6.0)
    assert np.allclose(m.face_areas(), [3.0, 3.0])
    sphere = trimesh.creation.icosphere(3)
    assert Mesh.from_any(sphere).area() == pytest.approx(sphere.area)


def test_normals_area_weighted_and_outward():
    m = square().compute_normals()
    assert np.allclose(m.normals, [0, 0, 1])
    sphere = Mesh.from_any(trimesh.creation.icosphere(2)).compute_normals()
    assert np.allclose(np.linalg.norm(sphere.normals, axis=1), 1.0)
    assert np.all(np.sum(sphere.normals * sphere.vertices, axis=1) > 0.99)
    # area weighting: a vertex shared by a big +z face and a tiny +x face leans to +z
    v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 0.1], [0, 0.1, 0]], float)
    f = np.array([[0, 1, 2], [0, 4, 3]])
    n = Mesh(v, f).compute_normals().normals[0]
    assert n[2] > 0.99


def test_merge_offsets_and_face_ids():
    a = square()
    b = Mesh(a.vertices + 10, a.faces, face_ids={"plant": [5, 5]})
    m = Mesh.merge([a, b, (a.vertices, a.faces)])
    assert m.n_vertices == 12 and m.n_faces == 6
    assert m.faces[2:4].tolist() == (a.faces + 4).tolist()
    assert m.face_ids["leaf"].tolist() == [1, 2, -1, -1, -1, -1]
    assert m.face_ids["plant"].tolist() == [-1, -1, 5, 5, -1, -1]
    assert m.area() == pytest.approx(18.0)
    assert Mesh.merge([]).n_faces == 0


def test_from_any_variants_and_trimesh_round_trip():
    a = square().with_(uv=np.zeros((4, 2)))
    assert Mesh.from_any(a) is a
    assert Mesh.from_any({"vertices": a.vertices, "faces": a.faces}).n_faces == 2
    assert Mesh.from_any([a.vertices, a.faces]).n_vertices == 4
    tm = a.to_trimesh()
    assert isinstance(tm, trimesh.Trimesh)
    assert np.allclose(tm.vertices, a.vertices) and np.array_equal(tm.faces, a.faces)
    back = Mesh.from_any(tm)
    assert back.face_ids["leaf"].tolist() == [1, 2]
    assert back.uv is not None and back.uv.shape == (4, 2)

    class Holder:
        mesh = a

    assert Mesh.from_any(Holder()).n_faces == 2
    with pytest.raises(InputError, match="cannot make a mesh"):
        Mesh.from_any(42)
    with pytest.raises(InputError, match="keys"):
        Mesh.from_any({"vertices": a.vertices})


def test_validation_and_immutability():
    v = np.zeros((3, 3))
    with pytest.raises(InputError, match="out of range"):
        Mesh(v, [[0, 1, 3]])
    with pytest.raises(InputError, match="triangles"):
        Mesh(v, [[0, 1, 2, 0]])
    with pytest.raises(InputError, match="NaN"):
        Mesh([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(InputError, match="face_ids"):
        Mesh(v, [[0, 1, 2]], face_ids={"a": [1, 2]})
    with pytest.raises(InputError, match="normals"):
        Mesh(v, [[0, 1, 2]], normals=np.zeros((2, 3)))
    with pytest.raises(InputError, match="non-integer"):
        Mesh(v, [[0, 1.5, 2]])
    m = Mesh(v, [[0, 1, 2]], vertex_colors=[[255, 0, 0]] * 3)
    assert m.vertex_colors.shape == (3, 4) and m.vertex_colors[0, 3] == 255
    with pytest.raises(ValueError):
        m.vertices[0, 0] = 1.0
    src = np.zeros((3, 3))
    m2 = Mesh(src, [[0, 1, 2]])
    src[0, 0] = 9.0
    assert m2.vertices[0, 0] == 0.0  # inputs are copied, never aliased
