"""Files tab in a real browser: open a file from the data folder, upload, bad upload."""

from __future__ import annotations

import numpy as np
import pytest

from tests.studio.conftest import wait_for

pytestmark = pytest.mark.browser


def _box_obj(path):
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0, 1)])
    f = [
        [1, 2, 4],
        [2, 4, 3],
        [5, 6, 8],
        [6, 8, 7],
        [1, 2, 6],
        [1, 6, 5],
        [3, 4, 8],
        [3, 8, 7],
        [1, 3, 7],
        [1, 7, 5],
        [2, 4, 8],
        [2, 8, 6],
    ]
    path.write_text(
        "".join(f"v {a} {b} {c}\n" for a, b, c in v) + "".join(f"f {a} {b} {c}\n" for a, b, c in f)
    )
    return path


def test_files_tab_opens_uploads_and_reports_errors(studio, tmp_path):
    app, tab = studio.app, studio.app.tabs["files"]
    _box_obj(app.sandbox.root / "box.obj")
    studio.click("Refresh list")
    wait_for(lambda: "box.obj" in tab.file.options, what="the listing to show box.obj")
    v0 = tab.version
    before = studio.canvas_png()
    studio.select(tab.file, "box.obj")
    studio.click("Open")
    wait_for(lambda: tab.version > v0 and tab.loaded_kind == "mesh", what="the mesh to open")
    studio.expect_text("12 triangles")
    studio.assert_scene_changed(before)
    studio.screenshot("files")

    # a point cloud through biomorph.io.read_points
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(3000, 3)) * [0.3, 0.3, 1.0] + [0, 0, 1.5]
    np.savetxt(app.sandbox.root / "cloud.xyz", pts, fmt="%.5f")
    studio.click("Refresh list")
    wait_for(lambda: "cloud.xyz" in tab.file.options, what="cloud.xyz in the listing")
    v0 = tab.version
    studio.select(tab.file, "cloud.xyz")
    studio.click("Open")
    wait_for(lambda: tab.version > v0 and tab.loaded_kind == "points", what="the cloud")
    assert tab.loaded.n_points == 3000
    studio.expect_text("3,000 points")

    # a broken upload: the error is shown in the page and the page stays usable
    bad = tmp_path / "broken.obj"
    bad.write_text("this is not a mesh\n")
    studio.upload(tab.upload, bad)
    wait_for(lambda: tab.last_error is not None, what="the upload error")
    studio.expect_text("Error")
    # too large for the 1 MB limit of the test studio: refused before it is stored
    big = tmp_path / "big.obj"
    big.write_bytes(b"#" * 1_500_000)
    studio.upload(tab.upload, big)
    wait_for(
        lambda: tab.last_error and "upload limit" in tab.last_error, what="the size-limit error"
    )
    studio.expect_text("upload limit")
    assert not (app.sandbox.root / "uploads" / "big.obj").exists()
    # the refused upload ends in the page: no spinner left, the button works again
    button = studio.page.get_by_role("button", name="Upload and open", exact=True)
    wait_for(lambda: button.is_enabled(), what="the upload button to be enabled again")
    wait_for(
        lambda: studio.page.locator(".mantine-Notification-loader").count() == 0,
        what="the upload spinner to stop",
    )
    # still usable: a good upload opens
    v1 = tab.version
    studio.upload(tab.upload, _box_obj(tmp_path / "good.obj"))
    wait_for(lambda: tab.version > v1 and tab.last_error is None, what="the good upload")
    assert (app.sandbox.root / "uploads" / "good.obj").is_file()
