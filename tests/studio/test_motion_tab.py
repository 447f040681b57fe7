"""Motion tab in a real browser: load, scrub, edit (equalizer), plot, export, bad upload."""

from __future__ import annotations

import pytest

from tests.studio.conftest import wait_for
from tests.studio.motiondata import write_walk_bvh

pytestmark = pytest.mark.browser


def test_motion_tab(studio, tmp_path):
    app = studio.app
    assert "motion" in app.tabs, f"motion tab failed to build: {app.unavailable.get('motion')}"
    tab = app.tabs["motion"]
    write_walk_bvh(app.sandbox.root / "walk.bvh", seconds=20, fps=60)
    studio.open_tab("Motion")
    before = studio.canvas_png()
    studio.click("Refresh")
    wait_for(lambda: "walk.bvh" in tab.picker.dropdown.options, what="walk.bvh listed")
    studio.select(tab.picker.dropdown, "walk.bvh")
    studio.click("Open")
    wait_for(lambda: tab.edited is not None or tab.last_error, timeout=30, what="the clip to load")
    assert tab.last_error is None, tab.last_error
    assert tab.source.n_frames == 1200
    studio.expect_text("1200 frames")

    # scrub: the server-side frame follows the slider typed in the page
    v0 = tab.version
    studio.set_slider(tab.frame, 1034)
    wait_for(lambda: tab.frame_index == 1034 and tab.version > v0, what="scrubbing")
    studio.assert_scene_changed(before)

    # play / pause: the player thread advances the frame, pause stops it
    studio.click("Play")
    f0 = tab.frame_index
    wait_for(lambda: tab.frame_index != f0, what="playback to advance")
    studio.click("Pause")
    wait_for(lambda: not tab._playing.is_set(), what="pause")

    # equalizer: a band gain changes the edited signal
    if tab.gains:
        v0 = tab.version
        studio.set_slider(tab.gains[0], 0)
        wait_for(lambda: tab.gains[0].value == 0.0 and tab.version > v0, what="the equalizer edit")
        wait_for(lambda: tab.edited is not tab.source, what="an edited clip")
        # the latency log records the edit once its job returns, after the redraw
        wait_for(lambda: "motion/equalizer" in app.latency.summary(), what="the equalizer timing")
    # speed, cycle and blend stages
    if tab.speed is not None:
        n0 = tab.edited.n_frames
        studio.open_folder("Speed")
        studio.set_slider(tab.speed, 2.0)
        wait_for(lambda: abs(tab.edited.n_frames - n0 / 2) < 3, what="the speed change")
        studio.set_slider(tab.speed, 1.0)
        wait_for(lambda: tab.edited.n_frames == n0, what="speed back to 1")
    if tab.cycle_on is not None:
        studio.open_folder("Cycle")
        studio.set_slider(tab.cycle_repeats, 3)
        studio.set_checkbox(tab.cycle_on, True)
        wait_for(lambda: len(tab.seams) == 2, what="the cycle seams")
        studio.expect_text("Seams")
        studio.set_checkbox(tab.cycle_on, False)
        wait_for(lambda: not tab.seams, what="cycle off")
    if tab.blend_on is not None:
        write_walk_bvh(app.sandbox.root / "walk_b.bvh", seconds=5, fps=60, seed=3)
        tab.picker_b.refresh()
        studio.open_folder("Blend")
        studio.select(tab.picker_b.dropdown, "walk_b.bvh")
        studio.page.get_by_role("button", name="Open", exact=True).nth(1).click()
        wait_for(lambda: tab.clip_b is not None, what="clip B")
        ref = tab.edited
        studio.set_checkbox(tab.blend_on, True)
        import numpy as np

        def blended() -> bool:
            return not np.allclose(tab.edited.rotation[150], ref.rotation[150])

        wait_for(lambda: blended() or tab.last_error, what="the blend")
        assert tab.last_error is None, tab.last_error
        studio.set_checkbox(tab.blend_on, False)
        wait_for(lambda: not blended(), what="blend off")
    studio.screenshot("motion")

    # export BVH and GLB: valid files that read back
    from biomorph import io

    studio.click("BVH")
    wait_for(
        lambda: (app.sandbox.root / "exports" / "walk_edited.bvh").is_file(), what="the BVH export"
    )
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
    assert tab.source.n_frames == 1200
