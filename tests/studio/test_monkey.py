"""A randomised UI session (fixed seed) in the real browser: 0 uncaught handler exceptions.

Clicks tab buttons and buttons, types numbers (inside and outside the ranges, NaN, 1e12)
and text (including markup) into the inputs, toggles checkboxes, picks dropdown options,
presses Space and Ctrl-Z. Every exception that reaches a traceback print (viser's
callback error reporters, the tabs' internal-error path) or the asyncio / websockets
loggers counts as a failure. Errors the tabs *report* to the user (bad input, refused
values) are the intended behaviour and do not count.

``BIOMORPH_MONKEY_SECONDS`` sets the length (default 20 s here; the issue's 10-minute run:
``BIOMORPH_MONKEY_SECONDS=600 pytest -o addopts="" tests/studio/test_monkey.py``).
"""

from __future__ import annotations

import logging
import os
import time
import traceback

import numpy as np
import pytest

from tests.studio.conftest import open_page

SECONDS = float(os.environ.get("BIOMORPH_MONKEY_SECONDS", "20"))
SKIP_BUTTONS = ("Save Canvas", "Dev Settings", "Reset View", "Orbit Origin Tool")
TEXTS = ("0:1, 2:2.5", "0:1, 1:", "<b>x</b>", "0:0, 1:1", "", "nan:1", "1e9:1", "abc")
T = 1500  # ms an element may take to become clickable
NUMBERS = ("0", "1", "7", "-3", "1e12", "NaN", "0.5", "250000", "-0.1", "3")


class _Count(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.records: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record.getMessage()[:200])


@pytest.fixture
def uncaught(monkeypatch):
    """Every exception printed as a traceback or logged as an error, while the test runs."""
    seen: list[str] = []
    original = traceback.print_exception

    def record(*args, **kw):
        exc = args[0] if args else kw.get("exc")
        seen.append(
            f"{type(exc).__name__ if isinstance(exc, BaseException) else exc}: "
            f"{args[1] if len(args) > 1 else exc}"[:300]
        )
        return original(*args, **kw)

    monkeypatch.setattr(traceback, "print_exception", record)
    handler = _Count()
    loggers = [logging.getLogger(n) for n in ("asyncio", "websockets", "websockets.server")]
    for lg in loggers:
        lg.addHandler(handler)
    try:
        yield seen, handler.records
    finally:
        for lg in loggers:
            lg.removeHandler(handler)


def _pick(page, selector: str, rng):
    """A random element matching ``selector`` (or ``None``)."""
    loc = page.locator(selector)
    n = loc.count()
    return loc.nth(int(rng.integers(n))) if n else None


def _act(page, rng) -> str:
    """One random user action; returns what it did."""
    kind = str(
        rng.choice(
            ["tab", "button", "number", "text", "check", "select", "key"],
            p=[0.15, 0.3, 0.2, 0.08, 0.1, 0.1, 0.07],
        )
    )
    if kind == "tab":
        label = str(rng.choice(["Files", "Creature", "Motion", "Tree", "Leaf"]))
        page.get_by_role("button", name=label, exact=True).first.click(timeout=T)
        return f"tab {label}"
    if kind == "key":
        key = str(rng.choice(["Space", "Control+z"]))
        page.keyboard.press(key)
        return f"key {key}"
    if kind == "button":
        b = _pick(page, "button:visible", rng)
        text = (b.inner_text(timeout=T) if b is not None else "").strip()
        if not text or "Upload" in text or any(x in text for x in SKIP_BUTTONS):
            return "no button"
        b.click(timeout=T)
        return f"button {text[:30]}"
    if kind == "check":
        box = _pick(page, "input[type=checkbox]:visible", rng)
        if box is not None:
            box.click(timeout=T)
        return "checkbox"
    if kind == "select":
        sel = _pick(page, ".mantine-Select-input:visible", rng)
        if sel is None:
            return "no select"
        sel.click(timeout=T)
        opt = _pick(page, "[role=option]:visible", rng)
        if opt is not None:
            opt.click(timeout=T)
        else:
            page.keyboard.press("Escape")
        return "select"
    selector = (
        "input[inputmode=decimal]:visible, input[inputmode=numeric]:visible"
        if kind == "number"
        else "input[type=text]:visible:not([readonly])"
    )
    box = _pick(page, selector, rng)
    if box is None:
        return f"no {kind} input"
    value = str(rng.choice(NUMBERS if kind == "number" else TEXTS))
    box.fill(value, timeout=T)
    box.press("Enter", timeout=T)
    return f"{kind} {value!r}"


def test_randomised_session_has_no_uncaught_exceptions(studio_app, browser, uncaught):
    seen, logged = uncaught
    ctx, page, session = open_page(studio_app, browser)
    rng = np.random.default_rng(2024)
    done: list[str] = []
    try:
        end = time.monotonic() + SECONDS
        while time.monotonic() < end:
            try:
                done.append(_act(page, rng))
            except Exception as exc:  # noqa: BLE001 - a vanished element; the page moved on
                done.append(f"skipped ({type(exc).__name__})")
                page.keyboard.press("Escape")
            page.wait_for_timeout(int(rng.integers(20, 250)))
        page.wait_for_timeout(1500)  # let the last callbacks finish
    finally:
        ctx.close()
    for key, tab in session.tabs.items():
        tab.close()
        session.tabs[key]  # still there
    acted = [d for d in done if not d.startswith(("no ", "skipped"))]
    print(
        f"\nmonkey: {SECONDS:.0f} s, {len(acted)} actions ({len(done)} tries), "
        f"{len(seen)} uncaught exceptions, {len(logged)} logged errors"
    )
    assert len(acted) >= 3, done  # a loaded 2-core machine manages a few per 10 s
    assert not seen, f"uncaught exceptions after {len(done)} actions: {seen[:5]}"
    assert not logged, f"errors logged after {len(done)} actions: {logged[:5]}"
