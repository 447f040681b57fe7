"""Motion tab in a real browser: load, scrub, edit (equalizer), plot, export, bad upload."""

from __future__ import annotations

import pytest

from tests.studio.conftest import wait_for
from tests.studio.motiondata import write_walk_bvh

pytestmark = pytest.mark.browser


def test_motion_tab(studio, tmp_path):
    app = studio.app
    if "motion" not in app.tabs:
        pytest.skip(f"motion tab unavailable: {app.unavailable.get('motion')}")
    tab = app.tabs["motion"]
    write_walk_bvh(app.sandbox.root / "walk.bvh", seconds=60, fps=60)
    studio.open_tab("Motion")
    before = studio.canvas_png()
    studio.click("Refresh")
    wait_for(lambda: "walk.bvh" in tab.picker.dropdown.options, what="walk.bvh listed")
    studio.select(tab.picker.dropdown, "walk.bvh")
    studio.click("Open")
    wait_for(lambda: tab.edited is not None or tab.last_error, timeout=30,
             what="the clip to load")
    assert tab.last_error is None, tab.last_error
    assert tab.source.n_frames == 3600
    studio.expect_text("3600 frames")

    # scrub: the server-side frame follows the slider typed in the page
    v0 = tab.version
    studio.set_slider(tab.frame, 1234)
    wait_for(lambda: tab.frame_index == 1234 and tab.version > v0, what="scrubbing")
    studio.assert_scene_changed(before)

    # equalizer: a band gain changes the edited signal
    if tab.gains:
        v0 = tab.version
        studio.set_slider(tab.gains[0], 0.0)
        wait_for(lambda: tab.gains[0].value == 0.0 and tab.version > v0,
                 what="the equalizer edit")
        wait_for(lambda: tab.edited is not tab.source, what="an edited clip")
        stats = app.latency.summary()
        assert "motion/equalizer" in stats
    studio.screenshot("motion")

    # export BVH and GLB: valid files that read back
    from biomorph import io

    studio.click("BVH")
    wait_for(lambda: (app.sandbox.root / "exports" / "walk_edited.bvh").is_file(),
             what="the BVH export")
    back = io.read_motion(app.sandbox.root / "exports" / "walk_edited.bvh")
    assert back.n_frames == tab.edited.n_frames and back.n_joints == 17
    studio.click("GLB")
    glb = app.sandbox.root / "exports" / "walk_edited.glb"
    wait_for(glb.is_file, what="the GLB export")
    assert glb.read_bytes()[:4] == b"glTF"

    # a malformed BVH: error shown, the loaded clip stays
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0\n")
    studio.upload(tab.picker.upload, bad)
    wait_for(lambda: tab.last_error is not None, what="the BVH error")
    studio.expect_text("Error")
    assert tab.source.n_frames == 3600
