"""OBJ mesh writer: groups per face-id combination, normals/uv, exact coordinates."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from biomorph.core.mesh import Mesh
from biomorph.errors import InputError
from biomorph.io import obj


def two_leaves():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) + 0.1
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    a = Mesh(v, quad, face_ids={"plant": [0, 0], "leaf": [0, 1]})
    b = Mesh(v + [0, 0, 1], quad, face_ids={"plant": [1, 1], "leaf": [0, 0]})
    return Mesh.merge([a, b])


def parse_obj(path):
    groups, faces, v, vn, vt = {}, [], [], [], []
    current = None
    for line in path.read_text().splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "v":
            v.append([float(t) for t in tok[1:4]])
        elif tok[0] == "vn":
            vn.append([float(t) for t in tok[1:]])
        elif tok[0] == "vt":
            vt.append([float(t) for t in tok[1:]])
        elif tok[0] == "g":
            current = tok[1]
            groups[current] = []
        elif tok[0] == "f":
            f = [int(t.split("/")[0]) - 1 for t in tok[1:]]
            faces.append(f)
            groups[current].append(f)
    return np.array(v), np.array(faces), groups, vn, vt


def test_groups_per_face_id_combination(tmp_path):
    m = two_leaves()
    p = obj.write_mesh(tmp_path / "m.obj", m)
    v, faces, groups, vn, vt = parse_obj(p)
    assert np.array_equal(v, m.vertices)  # shortest repr: exact
    assert set(groups) == {"plant_0__leaf_0", "plant_0__leaf_1", "plant_1__leaf_0"}
    assert len(groups["plant_1__leaf_0"]) == 2 and len(groups["plant_0__leaf_1"]) == 1
    # same set of triangles as the mesh
    assert sorted(map(tuple, faces.tolist())) == sorted(map(tuple, m.faces.tolist()))
    assert vn == [] and vt == []
    tm = trimesh.load(p, process=False, force="mesh")
    assert np.isclose(tm.area, m.area())


def test_normals_and_uv_written(tmp_path):
    m = two_leaves().compute_normals()
    m = m.with_(uv=m.vertices[:, :2])
    p = obj.write_mesh(tmp_path / "n.obj", m, object_name="leaves")
    text = p.read_text()
    assert "o leaves" in text and "\nf 1/1/1 2/2/2 3/3/3\n" in text
    _, _, _, vn, vt = parse_obj(p)
    assert np.allclose(vn, m.normals) and np.allclose(vt, m.uv)
    back = obj.read_mesh(p)
    assert back.n_faces == m.n_faces and np.isclose(back.area(), m.area())


def test_accepts_tuple_dict_trimesh_and_vertex_colors(tmp_path):
    box = trimesh.creation.box()
    for i, src in enumerate(
        [(box.vertices, box.faces), {"vertices": box.vertices, "faces": box.faces}, box]
    ):
        p = obj.write_mesh(tmp_path / f"b{i}.obj", src)
        assert np.isclose(obj.read_mesh(p).area(), box.area)
    colored = Mesh(box.vertices, box.faces, vertex_colors=np.tile([255, 0, 0, 255], (8, 1)))
    line = obj.write_mesh(tmp_path / "c.obj", colored).read_text().splitlines()[1]
    assert line.split()[4:] == ["1", "0", "0"]


def test_bad_mesh_writes_nothing(tmp_path):
    with pytest.raises(InputError):
        obj.write_mesh(tmp_path / "bad.obj", (np.zeros((3, 3)), [[0, 1, 5]]))
    assert not (tmp_path / "bad.obj").exists()


def faces_with_ids(m, keys):
    return sorted(
        zip(map(tuple, m.faces.tolist()), *[m.face_ids[k].tolist() for k in keys], strict=True)
    )


def test_read_back_restores_face_ids_uv_normals(tmp_path):
    m = two_leaves().compute_normals()
    m = m.with_(uv=m.vertices[:, :2] * 0.5)
    back = obj.read_mesh(obj.write_mesh(tmp_path / "r.obj", m))
    assert np.array_equal(back.vertices, m.vertices)
    assert faces_with_ids(back, ["plant", "leaf"]) == faces_with_ids(m, ["plant", "leaf"])
    assert np.array_equal(back.uv, m.uv) and np.array_equal(back.normals, m.normals)
    plain = obj.read_mesh(obj.write_mesh(tmp_path / "p.obj", (m.vertices, m.faces)))
    assert plain.face_ids == {} and plain.uv is None


def test_foreign_obj_groups_polygons_and_relative_indices(tmp_path):
    p = tmp_path / "f.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\ng left\nf 1 2 3\ng right side\nf 1 3 4\n")
    m = obj.read_mesh(p)
    assert m.face_ids["group"].tolist() == [0, 1] and np.isclose(m.area(), 1.0)
    quad = tmp_path / "q.obj"
    quad.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    assert obj.read_mesh(quad).n_faces == 2  # general reader (trimesh) triangulates
    rel = tmp_path / "r.obj"
    rel.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf -3 -2 -1\n")
    assert np.isclose(obj.read_mesh(rel).area(), 0.5)
