"""Creature tab in a real browser: parameters (incl. a PCA score slider), steps
(next/undo/re-roll/limb type), centre of mass and support polygon, exports GLB/BVH/OSIM,
errors shown in the page."""

from __future__ import annotations

import pytest

from tests.studio.conftest import wait_for

pytestmark = pytest.mark.browser


def test_creature_tab(studio, tmp_path):
    app = studio.app
    assert "creature" in app.tabs, f"tab failed to build: {app.unavailable.get('creature')}"
    tab = app.tabs["creature"]
    studio.open_tab("Creature")
    wait_for(lambda: tab.creature is not None, what="the first creature")
    before = studio.canvas_png()

    # a parameter edit regenerates (timed server-side)
    first = tab.creature
    v0 = tab.version
    studio.set_number(tab.seed, 11)
    wait_for(lambda: tab.version > v0 and tab.creature is not first, what="a new creature")
    assert tab.generator.options.seed == 11 and tab.generator.options.legs == 4
    # the latency log records an edit once its job returns, just after the redraw
    wait_for(lambda: "creature/parameters" in app.latency.summary(), what="the edit's timing")
    studio.expect_text("Balance:")

    # a PCA component slider fixes that score and regenerates (issue 7)
    seeded = tab.creature
    v1 = tab.version
    studio.set_slider(tab.pcs[0], 2.5)
    wait_for(lambda: tab.version > v1 and tab.creature is not seeded, what="the PC1 creature")
    assert tab.generator.options.scores == {0: 2.5} and tab.generator.options.seed == 11
    import numpy as np

    from biomorph.creature.generator import _model

    pca = _model(None)["pca"]
    z = pca.project(np.asarray(tab.creature.params["features"])[None])[0]
    assert abs(z[0] / np.sqrt(pca.eigenvalues[0]) - 2.5) < 1e-6
    assert not np.allclose(tab.creature.params["features"], seeded.params["features"])

    # steps: a stepwise rebuild, undo, all steps
    studio.click("Next step")
    wait_for(lambda: tab.generator.done == ("spine",), what="the spine step")
    studio.click("Next step")
    wait_for(lambda: tab.generator.done == ("spine", "girdles"), what="the girdles step")
    studio.click("Undo")
    wait_for(lambda: tab.generator.done == ("spine",), what="undo")
    studio.click("All steps")
    wait_for(lambda: tab.creature is not None, what="the finished creature")

    # change a limb type: the shoulder legs become arms is impossible for a quadruped
    # standing on them? the pillar decides; either a new creature or an error in the page
    before_kinds = tab.creature.kind
    studio.select(tab.limb_kind, "wing")
    studio.click("Add limb pair")
    wait_for(
        lambda: tab.creature is not None and (tab.creature.kind != before_kinds or tab.last_error),
        what="the limb edit",
    )
    if tab.last_error is None:
        assert "wing" in " ".join(tab.creature.kind)
    studio.click("Re-roll this part")
    wait_for(
        lambda: "creature/re-roll" in app.latency.summary() or tab.last_error, what="the re-roll"
    )
    studio.assert_scene_changed(before)
    studio.screenshot("creature")

    # exports
    out = app.sandbox.root / "exports"
    for fmt in ("GLB", "BVH", "OSIM"):
        studio.click(fmt)
    stem = f"creature_{int(tab.seed.value)}"
    wait_for(
        lambda: all((out / f"{stem}.{e}").is_file() for e in ("glb", "bvh", "osim")),
        what="the three exports",
    )
    from biomorph import io

    assert (out / f"{stem}.glb").read_bytes()[:4] == b"glTF"
    assert io.read_bvh(out / f"{stem}.bvh").n_joints == len(tab.creature)
    assert "<OpenSimDocument" in (out / f"{stem}.osim").read_text()

    # an impossible request is shown in the page and the last creature stays
    kept = tab.creature
    studio.select(tab.cls, "fish")
    wait_for(lambda: tab.last_error is not None, what="the fish-with-legs error")
    studio.expect_text("fish")
    assert tab.creature is kept
