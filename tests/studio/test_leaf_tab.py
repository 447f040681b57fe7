"""Leaf tab in a real browser: sliders, LOD count/error, canopy, export OBJ/GLB, bad upload."""

from __future__ import annotations

import pytest

from tests.studio.conftest import wait_for

pytestmark = pytest.mark.browser


def test_leaf_tab(studio, tmp_path):
    app = studio.app
    assert "leaf" in app.tabs, f"leaf tab failed to build: {app.unavailable.get('leaf')}"
    tab = app.tabs["leaf"]
    studio.open_tab("Leaf")
    wait_for(lambda: tab.mesh is not None, what="the first leaf")
    before = studio.canvas_png()

    # LOD: the triangle count follows the slider exactly, and the error is shown
    v0 = tab.version
    studio.set_slider(tab.lod, 40)
    wait_for(lambda: tab.version > v0 and tab.triangles == 40, what="the LOD change")
    studio.expect_text("40 triangles")
    coarse_error = tab.error[0]
    studio.set_slider(tab.lod, 300)
    wait_for(lambda: tab.triangles == 300, what="the finer LOD")
    assert tab.error[0] <= coarse_error

    # shape and growth: a younger leaf is shorter (a blade is fully extended from the
    # normalised age of its data's full extension on, 2/14 for the wheat collection)
    full = float(tab.mesh.vertices[:, 2].max())
    studio.set_slider(tab.age, 0.08)
    wait_for(
        lambda: abs(tab.age.value - 0.08) < 1e-9 and float(tab.mesh.vertices[:, 2].max()) < full,
        what="the younger leaf",
    )
    studio.set_slider(tab.twist, 90)
    wait_for(lambda: abs(tab.shape.twist - 1.5707963) < 1e-3, what="the twist")
    studio.assert_scene_changed(before)

    # canopy
    studio.set_checkbox(tab.canopy, True)
    wait_for(
        lambda: "leaf" in tab.mesh.face_ids and tab.mesh.face_ids["plant"].max() == 8,
        what="the canopy",
    )
    studio.screenshot("leaf")
    # the latency log records an edit once its job returns, just after the redraw
    wait_for(
        lambda: {"leaf/lod", "leaf/age"} <= set(app.latency.summary()), what="the edits' timings"
    )

    # exports read back
    import trimesh

    studio.click("OBJ")
    obj = app.sandbox.root / "exports" / "leaf_maize.obj"
    wait_for(obj.is_file, what="the OBJ export")
    assert len(trimesh.load(obj, force="mesh").faces) == tab.mesh.n_faces
    studio.click("GLB")
    glb = app.sandbox.root / "exports" / "leaf_maize.glb"
    wait_for(glb.is_file, what="the GLB export")
    from biomorph.io.gltf import read_gltf_summary

    assert read_gltf_summary(glb)["meshes"] >= 1

    # uploads: a JSON without the shape keys is refused; a valid shape is used
    bad = tmp_path / "bad_leaf.json"
    bad.write_text('{"length": 0.3}')
    studio.upload(tab.shape_picker.upload, bad)
    wait_for(lambda: tab.last_error is not None, what="the bad-upload error")
    studio.expect_text("needs the keys")
    import json

    good = tmp_path / "my_leaf.json"
    good.write_text(
        json.dumps(
            {
                "s": [0, 0.5, 1],
                "phi": [1.2, 0.6, -0.3],
                "s_r": [0, 0.3, 1],
                "r": [0.5, 1, 0.1],
                "length": 0.4,
                "width": 0.03,
            }
        )
    )
    studio.upload(tab.shape_picker.upload, good)
    wait_for(lambda: tab.custom is not None and tab.last_error is None, what="the good shape")
    assert abs(tab.shape.length - 0.4) < 1e-9

    # a bad plastic operator value is shown as an error, the page stays usable
    studio.select(tab.op_kind, "curvature")
    studio.set_slider(tab.op_value, -1.0)
    wait_for(lambda: tab.last_error is not None, what="the operator error")
    studio.expect_text("must be >= 0")
    studio.set_slider(tab.op_value, 0.5)
    wait_for(lambda: tab.last_error is None, what="recovery")
