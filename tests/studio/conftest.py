"""Browser-test harness: the studio in-process on a free port, Debian's chromium headless.

Playwright never downloads a browser here: it drives ``/usr/bin/chromium`` (installed by
``scripts/ensure_chromium.sh``). Tests needing it are marked ``browser`` and skip with a
reason when it is absent. Set ``BIOMORPH_STUDIO_SCREENSHOTS=docs/img`` to keep one
screenshot per tab (``studio_<tab>.png``) for the README.
"""

from __future__ import annotations

import contextlib
import io
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = Path(os.environ.get("BIOMORPH_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    # a stand-in for a rebinding DNS: evil.test resolves to this machine
    "--host-resolver-rules=MAP evil.test 127.0.0.1",
]
VIEWPORT = {"width": 880, "height": 600}


def wait_for(cond: Callable[[], object], timeout: float = 20.0, what: str = "condition") -> object:
    """Poll ``cond`` until truthy; fail the test naming ``what`` after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while True:
        value = cond()
        if value:
            return value
        if time.monotonic() > end:
            pytest.fail(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(0.05)


def png_stats(png: bytes) -> tuple[float, int]:
    """(pixel variance, number of distinct colours) of a PNG screenshot."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)
    colours = np.unique(img.reshape(-1, 3).astype(np.uint8), axis=0)
    return float(img.var()), int(len(colours))


@pytest.fixture(scope="session")
def browser() -> Iterator[object]:
    """A headless Debian chromium driven by Playwright (session-wide)."""
    if not CHROMIUM.exists():
        pytest.skip(
            f"{CHROMIUM} is absent: run `bash scripts/ensure_chromium.sh` "
            "(apt install chromium) to enable the studio browser tests"
        )
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="the playwright package is not installed"
    )
    os.environ.setdefault("PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD", "1")
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


class Studio:
    """A running :class:`StudioApp` plus helpers to drive its page."""

    def __init__(self, app, page) -> None:
        self.app = app
        self.page = page

    # -------------------------------------------------------------- driving the page
    @property
    def session(self):
        """The page's own session (the one that connected last)."""
        return self.app.latest_session()

    def open_tab(self, label: str) -> None:
        """Click the tab's button in the tab bar (it also switches the 3-D view)."""
        self.page.get_by_role("button", name=label, exact=True).first.click(no_wait_after=True)
        self.page.wait_for_timeout(150)

    def open_folder(self, label: str) -> None:
        """Expand a collapsed GUI folder by clicking its title."""
        for el in self.page.get_by_text(label, exact=True).all():
            if el.is_visible():
                el.click()
                self.page.wait_for_timeout(200)
                return
        pytest.fail(f"no visible folder titled {label!r}")

    def click(self, label: str) -> None:
        self.page.get_by_role("button", name=label, exact=True).click()

    def set_slider(self, handle, value: float) -> None:
        """Type ``value`` into the number box beside a slider and commit it."""
        from biomorph.studio.base import element_id

        box = self.page.locator(f'[id="{element_id(handle)}"] ~ div input')
        box.fill(str(value))
        box.press("Enter")
        box.blur()

    def set_number(self, handle, value: float) -> None:
        from biomorph.studio.base import element_id

        box = self.page.locator(f'input[id="{element_id(handle)}"]')
        box.fill(str(value))
        box.press("Enter")
        box.blur()

    def set_checkbox(self, handle, value: bool) -> None:
        from biomorph.studio.base import element_id

        box = self.page.locator(f'input[id="{element_id(handle)}"]')
        if box.is_checked() != value:
            box.click()

    def select(self, handle, option: str) -> None:
        """Choose ``option`` in a dropdown."""
        from biomorph.studio.base import element_id

        self.page.locator(f'[id="{element_id(handle)}"]').click()
        self.page.get_by_role("option", name=option, exact=True).click()

    def upload(self, handle, path: Path) -> None:
        from biomorph.studio.base import element_id

        self.page.set_input_files(f'[id="file_upload_{element_id(handle)}"]', str(path))

    def expect_text(self, text: str, timeout: float = 10.0) -> None:
        """Wait until ``text`` is visible somewhere in the page."""
        loc = self.page.get_by_text(text, exact=False)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if any(el.is_visible() for el in loc.all()):
                return
            self.page.wait_for_timeout(100)
        found = [(el.is_visible(), el.inner_text()[:80]) for el in loc.all()]
        pytest.fail(
            f"{text!r} not visible in the page after {timeout:.0f} s; "
            f"matches (visible, text): {found}"
        )

    # -------------------------------------------------------------- checks
    def canvas_png(self) -> bytes:
        """Screenshot of the 3-D view alone (the GUI panel excluded)."""
        self.page.wait_for_timeout(250)  # let three.js draw the latest messages
        box = self.page.locator("canvas").first.bounding_box()
        assert box is not None, "no WebGL canvas in the page"
        clip = {
            "x": box["x"] + 20,
            "y": box["y"] + 170,
            "width": max(box["width"] * 0.7 - 40, 10),
            "height": box["height"] - 260,
        }
        return self.page.screenshot(clip=clip)

    def assert_scene_not_blank(self, png: bytes | None = None) -> None:
        var, colours = png_stats(self.canvas_png() if png is None else png)
        assert var > 20.0 and colours > 8, (
            f"3-D view looks blank (variance {var:.1f}, {colours} colours)"
        )

    def assert_scene_changed(self, before: bytes, min_pixels: int = 300) -> bytes:
        """The 3-D view is not blank and differs from ``before`` in at least ``min_pixels``
        pixels; returns the new screenshot."""
        from PIL import Image

        a = np.asarray(Image.open(io.BytesIO(before)).convert("L"), dtype=np.int16)
        after = self.canvas_png()
        b = np.asarray(Image.open(io.BytesIO(after)).convert("L"), dtype=np.int16)
        assert a.shape == b.shape
        changed = int((np.abs(a - b) > 12).sum())
        assert changed >= min_pixels, f"3-D view barely changed ({changed} pixels)"
        rgb = np.asarray(Image.open(io.BytesIO(after)).convert("RGB"), dtype=np.int16)
        coloured = int((rgb.max(axis=2) - rgb.min(axis=2) > 40).sum())
        assert coloured >= min_pixels, (
            f"3-D view shows no coloured content, only "
            f"{coloured} coloured pixels (grey grid alone?)"
        )
        self.assert_scene_not_blank(after)
        return after

    def close_notifications(self) -> None:
        for btn in self.page.locator(".mantine-Notification-closeButton").all():
            with contextlib.suppress(Exception):  # already gone
                btn.click(timeout=1000)

    def screenshot(self, tab: str) -> Path | None:
        """Full-page screenshot into $BIOMORPH_STUDIO_SCREENSHOTS (for the README) if set."""
        keep = os.environ.get("BIOMORPH_STUDIO_SCREENSHOTS")
        if not keep:
            return None
        self.close_notifications()
        self.page.wait_for_timeout(600)
        Path(keep).mkdir(parents=True, exist_ok=True)
        out = Path(keep) / f"studio_{tab}.png"
        self.page.screenshot(path=str(out))
        var, _ = png_stats(out.read_bytes())
        assert var > 20.0, f"screenshot of the {tab} tab is blank"
        return out


@pytest.fixture(scope="session")
def studio_app(tmp_path_factory):
    """A studio on a free loopback port over a fresh data folder (1 MB upload limit)."""
    from biomorph.studio import StudioApp

    data = tmp_path_factory.mktemp("studio_data")
    app = StudioApp(data, host="127.0.0.1", port=0, max_upload_bytes=1_000_000)
    app.start()
    try:
        yield app
    finally:
        app.stop()


def open_page(app, browser, url: str | None = None):
    """A new browser context and page on the studio, waiting until the page's session is
    built; returns ``(context, page, session)``."""
    before = set(app.sessions.values())
    ctx = browser.new_context(viewport=VIEWPORT, accept_downloads=True)
    page = ctx.new_page()
    page.set_default_timeout(90_000)  # software WebGL on 2 shared cores is slow under load
    page.goto(url or app.url)
    page.bring_to_front()  # viser's page connects only while it has the focus
    page.get_by_role("button", name="Files", exact=True).first.wait_for(timeout=120000)

    def built():
        fresh = [s for s in app.sessions.values() if s not in before or s.shared]
        return next((s for s in fresh if s.ready.is_set() and (s.client or s.shared)), None)

    session = wait_for(built, timeout=120, what="the page's session")
    return ctx, page, session


@pytest.fixture
def studio(studio_app, browser) -> Iterator[Studio]:
    """A fresh page connected to the module's studio (its own session)."""
    ctx, page, _ = open_page(studio_app, browser)
    try:
        yield Studio(studio_app, page)
    finally:
        ctx.close()
