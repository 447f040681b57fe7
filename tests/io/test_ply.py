"""PLY: point clouds with any properties, skeleton graphs (vertex + edge), meshes."""

from __future__ import annotations

import numpy as np
import plyfile
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.core.mesh import Mesh
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import FormatError
from biomorph.io import ply
from tests.core.test_treeops import random_forest


def forest(n=40, roots=2, seed=0):
    rng = np.random.default_rng(seed)
    parent = random_forest(n, roots, seed)
    return BranchGraph(
        rng.normal(size=(n, 3)),
        parent,
        radius=rng.uniform(0.01, 0.1, n),
        weight=rng.uniform(0, 5, n),
        depth=rng.integers(0, 4, n),
    )


@pytest.mark.parametrize("text", [False, True])
def test_points_round_trip_any_properties(tmp_path, text):
    rng = np.random.default_rng(0)
    c = PointCloud(
        rng.normal(size=(200, 3)),
        {
            "intensity": rng.integers(0, 60000, 200).astype(np.uint16),
            "nx": rng.normal(size=200).astype(np.float32),
            "label": rng.integers(-9, 9, 200).astype(np.int8),
            "big": rng.integers(0, 10**6, 200),
        },
    )
    back = ply.read_points(ply.write_points(tmp_path / "c.ply", c, text=text))
    assert np.array_equal(back.xyz, c.xyz)
    for k in ("intensity", "nx", "label"):
        assert back.attributes[k].dtype == c.attributes[k].dtype
        assert np.array_equal(back.attributes[k], c.attributes[k])
    assert np.array_equal(back.attributes["big"], c.attributes["big"])
    raw = plyfile.PlyData.read(str(tmp_path / "c.ply"))
    assert raw["vertex"].count == 200 and raw.text == text


@pytest.mark.parametrize("text", [False, True])
def test_graph_round_trip(tmp_path, text):
    g = forest()
    back = ply.read_graph(ply.write_graph(tmp_path / "g.ply", g, text=text))
    assert np.array_equal(back.position, g.position)
    assert np.array_equal(back.parent, g.parent)
    assert np.allclose(back.radius, g.radius) and np.allclose(back.weight, g.weight)
    assert np.array_equal(back.depth, g.depth)
    assert np.array_equal(back.trees, g.trees)
    assert ply.ply_kind(tmp_path / "g.ply") == "graph"
    names = plyfile.PlyData.read(str(tmp_path / "g.ply"))["vertex"].data.dtype.names
    assert names == ("x", "y", "z", "radius", "depth", "tree_id", "weight")


def test_graph_with_reversed_or_unordered_edges_is_oriented_from_lowest_node(tmp_path):
    # chain 0-1-2-3 going up in z; edges with mixed directions (node 1 has two "parents")
    pos = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2], [0, 0, 3], [5, 0, 1], [5, 0, 0]], float)
    vert = np.array([tuple(p) for p in pos], dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    dt = [("vertex1", "i4"), ("vertex2", "i4")]
    p = tmp_path / "rev.ply"
    edge = np.array([(0, 1), (2, 1), (2, 3), (4, 5)], dtype=dt)
    plyfile.PlyData(
        [plyfile.PlyElement.describe(vert, "vertex"), plyfile.PlyElement.describe(edge, "edge")]
    ).write(str(p))
    assert ply.read_graph(p).parent.tolist() == [-1, 0, 1, 2, 5, -1]
    # a consistent parent->child forest is taken as written, even if it hangs downwards
    edge = np.array([(1, 0), (2, 1), (3, 2), (4, 5)], dtype=dt)
    plyfile.PlyData(
        [plyfile.PlyElement.describe(vert, "vertex"), plyfile.PlyElement.describe(edge, "edge")]
    ).write(str(p))
    assert ply.read_graph(p).parent.tolist() == [1, 2, 3, -1, -1, 4]


def test_graph_cycle_and_bad_edges(tmp_path):
    vert = np.zeros(3, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    for edges, match in (
        [[(0, 1), (1, 2), (2, 0)], "cycle"],
        [[(0, 7)], "edge 0 joins"],
        [[(1, 1)], "edge 0 joins"],
    ):
        e = np.array(edges, dtype=[("vertex1", "i4"), ("vertex2", "i4")])
        p = tmp_path / "c.ply"
        plyfile.PlyData(
            [plyfile.PlyElement.describe(vert, "vertex"), plyfile.PlyElement.describe(e, "edge")]
        ).write(str(p))
        with pytest.raises(FormatError, match=match):
            ply.read_graph(p)


def test_graph_without_edges_is_all_roots(tmp_path):
    c = PointCloud(np.eye(3))
    g = ply.read_graph(ply.write_points(tmp_path / "p.ply", c))
    assert g.parent.tolist() == [-1, -1, -1] and ply.ply_kind(tmp_path / "p.ply") == "points"


def test_mesh_round_trip_with_face_ids(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    m = Mesh(
        v,
        [[0, 1, 2], [0, 2, 3]],
        uv=v[:, :2],
        vertex_colors=[[255, 0, 0, 255]] * 4,
        face_ids={"plant": [0, 0], "leaf": [3, 4]},
    ).compute_normals()
    back = ply.read_mesh(ply.write_mesh(tmp_path / "m.ply", m))
    assert np.allclose(back.vertices, m.vertices) and np.array_equal(back.faces, m.faces)
    assert back.face_ids["leaf"].tolist() == [3, 4] and back.face_ids["plant"].tolist() == [0, 0]
    assert np.allclose(back.normals, m.normals) and np.allclose(back.uv, m.uv)
    assert np.array_equal(back.vertex_colors, m.vertex_colors)
    assert ply.ply_kind(tmp_path / "m.ply") == "mesh"
    import trimesh

    tm = trimesh.load(tmp_path / "m.ply", process=False)
    assert np.isclose(tm.area, m.area())


def test_mesh_quads_are_triangulated(tmp_path):
    p = tmp_path / "q.ply"
    p.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"
    )
    m = ply.read_mesh(p)
    assert m.n_faces == 2 and np.isclose(m.area(), 1.0)


HEADER = (
    "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
    "property float z\nend_header\n"
)


@pytest.mark.parametrize(
    "content,match",
    [
        (b"", "empty"),
        (b"not a ply file\n", "malformed"),
        ((HEADER + "0 0 0\n1 1 nan\n").encode(), "vertex 1 has a NaN"),
        ((HEADER + "0 0 0\n1 1\n").encode(), "row 1 has 2 values; expected 3"),
        ((HEADER + "0 0 0\n1 x 1\n").encode(), "'x' is not a number"),
        ((HEADER + "0 0 0\n").encode(), "truncated"),
        ((HEADER.replace("vertex 2", "vertex 0")).encode(), "empty"),
        (
            b"ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n",
            "no 'vertex' element",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n",
            "lacks properties y, z",
        ),
    ],
)
def test_malformed(tmp_path, content, match):
    p = tmp_path / "bad.ply"
    p.write_bytes(content)
    with pytest.raises(FormatError) as err:
        ply.read_points(p)
    assert str(p) in str(err.value)
    assert match in err.value.detail  # the message itself, not the (test-named) path
    if "row 1" in match or "not a number" in match:
        assert err.value.line == 9


def test_ascii_fast_path_matches_plyfile(tmp_path):
    rng = np.random.default_rng(5)
    c = PointCloud(
        rng.normal(size=(500, 3)) * 1e3,
        {
            "i8": rng.integers(-100, 100, 500).astype(np.int8),
            "u16": rng.integers(0, 60000, 500).astype(np.uint16),
            "f32": rng.normal(size=500).astype(np.float32),
        },
    )
    p = ply.write_points(tmp_path / "a.ply", c, text=True)
    ours = ply.read_points(p)
    ref = plyfile.PlyData.read(str(p))["vertex"].data  # the library on our own text
    for name in ("x", "y", "z", "i8", "u16", "f32"):
        col = ours.xyz[:, "xyz".index(name)] if name in "xyz" else ours.attributes[name]
        assert np.array_equal(col, ref[name]), name
    assert np.array_equal(ours.xyz, c.xyz)
    assert np.array_equal(ours.attributes["f32"], c.attributes["f32"])
    g = forest(300)
    back = ply.read_graph(ply.write_graph(tmp_path / "g.ply", g, text=True))
    assert np.array_equal(back.parent, g.parent) and np.array_equal(back.radius, g.radius)
    bad = tmp_path / "range.ply"
    bad.write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
        "property float y\nproperty float z\nproperty uchar c\nend_header\n"
        "0 0 0 300\n"
    )
    with pytest.raises(FormatError, match="expected an integer in range") as err:
        ply.read_points(bad)
    assert err.value.line == 9


def test_truncated_binary(tmp_path):
    good = ply.write_graph(tmp_path / "g.ply", forest(200))
    data = good.read_bytes()
    for cut in (10, len(data) // 2, len(data) - 3):
        p = tmp_path / "t.ply"
        p.write_bytes(data[:cut])
        with pytest.raises(FormatError):
            ply.read_graph(p)
