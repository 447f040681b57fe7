"""Exports: skeleton PLY/MTG round trips, tube mesh, QSM cylinder CSV, summary, preview."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.io import read_graph
from biomorph.tree.export import (
    CYLINDER_COLUMNS,
    cylinder_table,
    export_skeleton,
    tube_mesh,
    write_cylinders,
)
from biomorph.tree.order import with_order
from biomorph.tree.pipeline import skeletonize
from biomorph.tree.reference import read_qsm_csv
from tests.tree.test_livny import make_cloud


def _y_graph():
    pos = np.array([[0, 0, 0], [0, 0, 1.0], [0, 0, 2], [0.5, 0, 1.5], [1.0, 0, 2.0]])
    parent = np.array([-1, 0, 1, 1, 3])
    r = np.array([0.1, 0.09, 0.08, 0.04, 0.03])
    return with_order(BranchGraph(pos, parent, radius=r, tree_id=np.zeros(5, int)))


@pytest.fixture(scope="module")
def skel():
    return skeletonize(make_cloud(n=4000, seed=11) + [1000.0, 2000.0, 50.0], ground=None)


def test_tube_mesh_volume_and_labels():
    g = BranchGraph(
        np.array([[0, 0, 0], [0, 0, 2.0]]),
        np.array([-1, 0]),
        radius=np.array([0.1, 0.1]),
        depth=np.zeros(2, int),
    )
    m = tube_mesh(g, sides=32)
    tm = m.to_trimesh()
    assert tm.is_watertight
    # a closed 32-gon prism of radius 0.1 and length 2 (+ a small tip cone)
    assert abs(tm.volume) == pytest.approx(np.pi * 0.01 * 2, rel=0.05)
    m2 = tube_mesh(_y_graph(), sides=6)
    assert m2.n_faces > 0 and set(m2.face_ids) == {"tree", "order"}
    assert m2.face_ids["order"].max() == 1


def test_cylinder_table_follows_treeqsm_conventions(tmp_path):
    g = _y_graph()
    tab = cylinder_table(g)
    assert tab["ID"].tolist() == [1, 2, 3, 4]
    assert tab["parent"][0] == 0  # base cylinder
    # every parent id points at a cylinder that ends where this one starts
    ends = (
        np.column_stack([tab["start_x"], tab["start_y"], tab["start_z"]])
        + np.column_stack([tab["axis_x"], tab["axis_y"], tab["axis_z"]]) * tab["length"][:, None]
    )
    for i, p in enumerate(tab["parent"]):
        if p:
            assert np.allclose(
                ends[p - 1], [tab["start_x"][i], tab["start_y"][i], tab["start_z"][i]]
            )
    assert sorted(np.unique(tab["BranchOrder"]).tolist()) == [0, 1]
    assert tab["length"].sum() == pytest.approx(g.total_length)
    path = write_cylinders(tmp_path / "c.csv", g)
    header = path.read_text().splitlines()[0].split(",")
    assert tuple(header) == CYLINDER_COLUMNS
    back = read_qsm_csv(path)  # our own reader reads it
    assert back.total_length == pytest.approx(g.total_length, rel=1e-5)
    assert back.leaves.size == g.leaves.size


def test_export_all_in_world_coordinates(skel, tmp_path):
    files = export_skeleton(skel, tmp_path / "out", world=True)
    assert set(files) == {
        "ply",
        "mtg",
        "glb",
        "obj",
        "mesh_ply",
        "csv",
        "branches",
        "treedata",
        "las",
        "json",
        "png",
    }
    g = read_graph(files["ply"])
    assert g.n_nodes == skel.graph.n_nodes
    assert np.allclose(g.position, skel.graph.position + skel.offset, atol=1e-6)
    assert np.allclose(g.radius, skel.graph.radius)
    assert (g.depth == skel.graph.depth).all()
    m = read_graph(files["mtg"])
    assert m.n_nodes == skel.graph.n_nodes
    assert m.total_length == pytest.approx(skel.graph.total_length, rel=1e-4)
    summary = json.loads(files["json"].read_text())
    assert summary["world_coordinates"] is True and summary["method"] == "graph"
    assert summary["offset"][0] == pytest.approx(skel.offset[0])
    assert files["png"].stat().st_size > 10_000
    obj_first_v = next(
        line for line in files["obj"].read_text().splitlines() if line.startswith("v ")
    )
    assert float(obj_first_v.split()[1]) > 900  # world x ~ 1000 m
    leftovers = [p for p in (tmp_path / "out").iterdir() if p.name.startswith(".")]
    assert leftovers == []  # atomic writes


def test_export_local_frame_and_subset(skel, tmp_path):
    files = export_skeleton(skel, tmp_path / "local", world=False, formats=("ply", "csv"))
    assert set(files) == {"ply", "csv", "branches", "treedata"}
    g = read_graph(files["ply"])
    assert np.allclose(g.position, skel.graph.position, atol=1e-9)
    with pytest.raises(Exception, match="unknown export format"):
        export_skeleton(skel, tmp_path / "x", formats=("stl",))


def test_tube_mesh_branches_are_closed_tubes_with_outward_normals():
    g = _y_graph()
    m = tube_mesh(g, sides=12)
    parts = m.to_trimesh().split(only_watertight=False)
    assert len(parts) == 2 and all(p.is_watertight for p in parts)  # stem and branch
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0)
    # ring vertices of the vertical stem: normals point away from the axis
    ring = m.vertices[:12]
    radial = ring - [0.0, 0.0, 0.0]
    radial[:, 2] = 0
    assert (np.einsum("ij,ij->i", m.normals[:12, :2], radial[:, :2]) > 0).all()


def test_glb_frame_is_stated_in_its_metadata(tmp_path):
    import pygltflib

    from biomorph.tree.export import write_tube_glb

    m = tube_mesh(_y_graph(), sides=6)
    path, lacking = write_tube_glb(tmp_path / "near.glb", m, np.array([10.0, 20.0, 5.0]))
    extras = pygltflib.GLTF2().load(str(path)).scenes[0].extras
    assert extras["frame"] == "world" and extras["offset"] == [0.0, 0.0, 0.0]
    assert not lacking.any()
    geo = np.array([512_000.0, 5_400_000.0, 300.0])  # UTM-like
    path, lacking = write_tube_glb(tmp_path / "geo.glb", m, geo)
    extras = pygltflib.GLTF2().load(str(path)).scenes[0].extras
    assert extras["frame"] == "centred" and extras["offset"] == geo.tolist()
    assert np.array_equal(lacking, geo)
