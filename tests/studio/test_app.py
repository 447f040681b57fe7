"""The app without a browser: hostile file names from a page, latency log, tab isolation."""

from __future__ import annotations

import pytest

from biomorph.studio import StudioApp


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    root = tmp_path_factory.mktemp("app")
    (root / "secret.txt").write_text("not for the page")
    data = root / "data"
    data.mkdir()
    a = StudioApp(data, port=0, tabs=["files"], shared=True)
    a.start()
    yield a
    a.stop()


@pytest.mark.parametrize("name", ["../secret.txt", "/etc/passwd", "uploads/../../secret.txt"])
def test_a_page_cannot_open_files_outside_the_data_folder(app, name):
    tab = app.tabs["files"]
    tab.run("open", lambda: tab.open(name))
    assert tab.last_error is not None
    assert "data folder" in tab.last_error
    assert "Error" in tab.status.content
    assert tab.loaded is None


def test_export_names_cannot_escape(app):
    tab = app.tabs["files"]
    path = app.export(tab, "../../evil.txt", lambda p: p.write_text("x"))
    assert path.parent == app.sandbox.root / "exports"


def test_failures_do_not_count_as_latency_and_the_tab_recovers(app):
    tab = app.tabs["files"]
    tab.run("boom", lambda: 1 / 0)
    assert "ZeroDivisionError" in tab.last_error
    assert "files/boom" not in app.latency.summary()
    tab.run("fine", lambda: None)
    assert tab.last_error is None
    assert app.latency.summary()["files/fine"]["n"] == 1


def test_url_is_loopback(app):
    assert app.url.startswith("http://127.0.0.1:")


def test_stop_waits_at_most_its_timeout_for_the_web_server(tmp_path):
    """After Ctrl-C the studio stops within the interrupt guard's grace: a web server
    whose teardown hangs (viser joins its loop for up to 6 s) is left to finish alone."""
    import threading
    import time

    class SlowServer:
        def __init__(self):
            self.done = threading.Event()

        def stop(self):
            time.sleep(1.0)
            self.done.set()

    a = StudioApp(tmp_path, port=0, tabs=["files"])
    slow = a.server = SlowServer()
    t0 = time.monotonic()
    a.stop(timeout=0.1)
    assert time.monotonic() - t0 < 0.6 and a.server is None and not slow.done.is_set()
    assert slow.done.wait(5.0)  # the teardown still ran, in the background
    slow = a.server = SlowServer()
    a.stop()  # no timeout: waits for it
    assert slow.done.is_set()
