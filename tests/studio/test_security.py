"""The studio against the attacks of issue 17, each in the real browser where a browser
carries it (cross-site websocket, DNS rebinding, stored XSS, page isolation) and with a raw
websocket client speaking viser's protocol where a hostile page would bypass the GUI
(out-of-range values, NaN, an upload streaming more than it declared)."""

from __future__ import annotations

import http.server
import threading
import time
import urllib.error
import urllib.request
import uuid

import pytest

from tests.studio.conftest import CHROMIUM_ARGS, open_page, wait_for

XSS = '<img src=x onerror="window.__xss=1">'


# ---------------------------------------------------------------------- helpers
def raw_client(app, origin: str | None = "own", path: str = "/"):
    """A websocket client of the studio speaking viser's protocol (msgpack dicts)."""
    import viser
    from websockets.sync.client import connect

    headers = {}
    if origin == "own":
        origin = f"http://127.0.0.1:{app.port}"
    if origin is not None:
        headers["Origin"] = origin
    return connect(
        f"ws://127.0.0.1:{app.port}{path}",
        additional_headers=headers,
        subprotocols=[f"viser-v{viser.__version__}"],
        max_size=None,
        open_timeout=10,
    )


def send(ws, type_: str, **fields) -> None:
    import msgspec

    ws.send(msgspec.msgpack.encode({"type": type_, **fields}))


def settle(seconds: float = 0.6) -> None:
    time.sleep(seconds)


@pytest.fixture(scope="module")
def shared_app(tmp_path_factory):
    """A ``--shared`` studio: its controls are server-level, so a raw client can address
    them exactly as the page's own (devtools-modified) client would."""
    from biomorph.studio import StudioApp

    app = StudioApp(
        tmp_path_factory.mktemp("shared"),
        port=0,
        max_upload_bytes=1_000_000,
        tabs=["files", "tree", "creature"],
        shared=True,
    )
    app.start()
    yield app
    app.stop()


class _Evil(http.server.BaseHTTPRequestHandler):
    page = b""

    def do_GET(self):
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.end_headers()
        self.wfile.write(self.page)

    def log_message(self, *args):
        pass


@pytest.fixture
def evil_site():
    """Another local origin (a different port) serving an attacker's page."""
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Evil)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    yield srv
    srv.shutdown()


# ---------------------------------------------------------------------- cross-site websocket
def test_a_page_of_another_origin_cannot_open_the_websocket(studio_app, browser, evil_site):
    import viser

    _Evil.page = f"""<html><body><script>
      window.result = {{opened: false, bytes: 0, closed: false}};
      const ws = new WebSocket("ws://127.0.0.1:{studio_app.port}/", ["viser-v{viser.__version__}"]);
      ws.binaryType = "arraybuffer";
      ws.onopen = () => {{ window.result.opened = true; }};
      ws.onmessage = (e) => {{ window.result.bytes += e.data.byteLength || e.data.length; }};
      ws.onclose = () => {{ window.result.closed = true; }};
      ws.onerror = () => {{ window.result.closed = true; }};
    </script></body></html>""".encode()
    sessions = len(studio_app.sessions)
    ctx = browser.new_context()
    try:
        page = ctx.new_page()
        page.goto(f"http://127.0.0.1:{evil_site.server_address[1]}/")
        page.wait_for_function("window.result && window.result.closed", timeout=15000)
        page.wait_for_timeout(500)
        result = page.evaluate("window.result")
    finally:
        ctx.close()
    assert result["bytes"] == 0, f"the other origin received {result['bytes']} bytes of state"
    assert not result["opened"]
    assert len(studio_app.sessions) == sessions


def test_a_client_without_origin_is_refused(studio_app):
    from websockets.exceptions import InvalidStatus

    with pytest.raises(InvalidStatus) as err:
        raw_client(studio_app, origin=None)
    assert err.value.response.status_code == 403


# ---------------------------------------------------------------------- DNS rebinding
def test_a_rebound_host_name_is_refused_in_the_browser(studio_app, browser):
    """Chromium resolves evil.test to 127.0.0.1 (as a rebinding DNS would, see
    ``CHROMIUM_ARGS``): the studio answers a request whose Host is not its own with 403,
    and serves no page."""
    assert any("evil.test" in a for a in CHROMIUM_ARGS)
    ctx = browser.new_context()
    try:
        page = ctx.new_page()
        resp = page.goto(f"http://evil.test:{studio_app.port}/")
        assert resp is not None and resp.status == 403
        assert "Forbidden" in page.content()
    finally:
        ctx.close()
    req = urllib.request.Request(studio_app.url, headers={"Host": f"evil.test:{studio_app.port}"})
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(req, timeout=10)
    assert err.value.code == 403


# ---------------------------------------------------------------------- token
def test_token_is_required_and_carried_by_the_printed_url(browser, tmp_path):
    from biomorph.studio import StudioApp

    app = StudioApp(tmp_path, port=0, tabs=["files"], token="s3cret-token-1")
    app.start()
    try:
        bare = app.url.split("/?")[0] + "/"
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(bare, timeout=10)
        assert err.value.code == 403
        assert "token=s3cret-token-1" in app.url
        ctx, page, session = open_page(app, browser, app.url)
        try:
            assert "/s/" in page.url and "token" not in page.url  # the cookie carries it
            assert session.tabs["files"] is not None
        finally:
            ctx.close()
        from websockets.exceptions import InvalidStatus

        with pytest.raises(InvalidStatus):
            raw_client(app)  # right Origin, no token
    finally:
        app.stop()


# ---------------------------------------------------------------------- stored XSS
def test_file_names_and_typed_text_are_shown_as_text(studio, browser):
    """A data-folder file named like an HTML tag fails to open; its name in the error
    line stays text, in this page and in a new one."""
    root = studio.app.sandbox.root
    (root / f"{XSS}.xyz").write_text("not numbers\n")
    tab = studio.session.tabs["files"]
    tab.run("refresh", tab.refresh)
    tab.run("open", lambda: tab.open(f"{XSS}.xyz"))
    assert tab.last_error is not None
    studio.expect_text("onerror")  # the name is shown, as characters
    studio.page.wait_for_timeout(500)
    assert studio.page.evaluate("window.__xss") is None
    assert studio.page.locator("img[src='x']").count() == 0
    status = tab.status.content
    assert "<img" not in status and "&lt;img" in status


def test_escaping_helper():
    from biomorph.studio.base import plain

    assert (
        plain("<b>*x*</b> [a](javascript:1)")
        == "&lt;b&gt;\\*x\\*&lt;/b&gt; \\[a\\]\\(javascript:1\\)"
    )


# ---------------------------------------------------------------------- values out of range
def _connected(app):
    ws = raw_client(app)
    send(
        ws,
        "ViewerCameraMessage",
        wxyz=(1.0, 0.0, 0.0, 0.0),
        position=(3.0, 3.0, 3.0),
        fov=1.0,
        near=0.01,
        far=100.0,
        image_height=100,
        image_width=100,
        look_at=(0.0, 0.0, 0.0),
        up_direction=(0.0, 0.0, 1.0),
    )
    return ws


@pytest.mark.parametrize(
    "field,value",
    [
        ("n_points", 300_000),
        ("n_points", float("nan")),
        ("seed", float("nan")),
        ("seed", -5),
        ("seed", 1.5),
        ("n_points", "many"),
    ],
)
def test_values_outside_the_ui_ranges_are_refused(shared_app, field, value):
    tab = shared_app.tabs["tree"]
    handle = getattr(tab, field)
    before = handle.value
    with _connected(shared_app) as ws:
        send(ws, "GuiUpdateMessage", uuid=handle._impl.uuid, updates={"value": value})
        settle()
    assert handle.value == before
    assert tab.last_error is not None and handle.label.split(" ")[0] in tab.last_error


def test_a_page_cannot_change_an_inputs_range(shared_app):
    tab = shared_app.tabs["tree"]
    with _connected(shared_app) as ws:
        send(ws, "GuiUpdateMessage", uuid=tab.n_points._impl.uuid, updates={"max": 10**9})
        settle()
    assert tab.n_points.max == 100_000


def test_accepted_changes_still_work_and_undo(shared_app):
    tab = shared_app.tabs["creature"]
    seed = int(tab.seed.value)
    with _connected(shared_app) as ws:
        send(ws, "GuiUpdateMessage", uuid=tab.seed._impl.uuid, updates={"value": seed + 1})
        wait_for(
            lambda: tab.generator is not None and tab.generator.options.seed == seed + 1,
            what="the new seed to be generated",
        )
    tab.run("undo", tab.undo_parameter)
    wait_for(lambda: tab.generator.options.seed == seed, what="undo to regenerate")
    assert int(tab.seed.value) == seed


# ---------------------------------------------------------------------- uploads
def _buffered(app) -> int:
    states = app.server.gui._current_file_upload_states
    return sum(len(p) for s in list(states.values()) for p in s["parts"].values())


def test_an_upload_streaming_more_than_it_declared_is_cut_off(shared_app):
    """Declare 1 kB, then stream megabytes: the server keeps nothing beyond the limit and
    closes the connection (stops reading)."""
    from websockets.exceptions import ConnectionClosed

    button = shared_app.tabs["tree"].picker.upload
    tid = str(uuid.uuid4())
    chunk = b"0" * 500_000
    closed = False
    with _connected(shared_app) as ws:
        send(
            ws,
            "FileTransferStartUpload",
            source_component_uuid=button._impl.uuid,
            transfer_uuid=tid,
            filename="big.xyz",
            mime_type="text/plain",
            part_count=1,
            size_bytes=1000,
        )
        try:
            for i in range(8):
                send(
                    ws,
                    "FileTransferPart",
                    source_component_uuid=button._impl.uuid,
                    transfer_uuid=tid,
                    part_index=i % 1,
                    content=chunk,
                )
                time.sleep(0.05)
            settle()
            ws.recv(timeout=2)
            while True:
                ws.recv(timeout=2)
        except (ConnectionClosed, TimeoutError):
            closed = True
    assert _buffered(shared_app) == 0
    assert tid not in shared_app.server.gui._current_file_upload_states
    assert closed


def test_an_upload_declaring_too_many_parts_is_refused_at_its_start(shared_app):
    button = shared_app.tabs["tree"].picker.upload
    tid = str(uuid.uuid4())
    with _connected(shared_app) as ws:
        send(
            ws,
            "FileTransferStartUpload",
            source_component_uuid=button._impl.uuid,
            transfer_uuid=tid,
            filename="big.xyz",
            mime_type="text/plain",
            part_count=100_000,
            size_bytes=1000,
        )
        for i in range(6):
            send(
                ws,
                "FileTransferPart",
                source_component_uuid=button._impl.uuid,
                transfer_uuid=tid,
                part_index=i,
                content=b"1" * 400_000,
            )
        settle(1.5)
        held = _buffered(shared_app)  # while the client is still connected
    assert held == 0
    assert tid not in shared_app.server.gui._current_file_upload_states


def test_a_websocket_message_over_the_cap_closes_the_connection(shared_app):
    from websockets.exceptions import ConnectionClosed

    with _connected(shared_app) as ws, pytest.raises(ConnectionClosed):
        send(ws, "GuiUpdateMessage", uuid="x", updates={"value": "a" * 3_000_000})
        for _ in range(20):
            ws.recv(timeout=2)


# ---------------------------------------------------------------------- jobs
def test_a_page_runs_at_most_max_jobs_heavy_jobs(shared_app):
    from biomorph.errors import InputError
    from biomorph.studio.session import MAX_JOBS

    session = shared_app.latest_session()
    slots = [session.job_slot() for _ in range(MAX_JOBS)]
    with pytest.raises(InputError, match="already running"):
        session.job_slot()
    for release in slots:
        release()
    session.job_slot()()


# ---------------------------------------------------------------------- one session per page
def test_two_pages_are_isolated_and_a_reload_restores(studio_app, browser):
    ctx_a, page_a, a = open_page(studio_app, browser)
    ctx_b, page_b, b = open_page(studio_app, browser)
    try:
        assert a is not b and a.sid != b.sid
        ca, cb = a.tabs["creature"], b.tabs["creature"]
        seed_b = int(cb.seed.value)
        downloads_b: list = []
        page_b.on("download", lambda d: downloads_b.append(d))
        ca.run("seed", lambda: setattr(ca.seed, "value", seed_b + 5))
        wait_for(lambda: ca.generator.options.seed == seed_b + 5, what="page A's creature")
        ca.run("boom", lambda: 1 / 0)
        ca.exports.export("BVH")
        page_a.wait_for_timeout(800)
        assert int(cb.seed.value) == seed_b and cb.generator.options.seed == seed_b
        assert cb.last_error is None and downloads_b == []
        assert a.tabs["files"] is not b.tabs["files"]
        # reload page A (its address again in the same browser): same session, same values
        old = ca.generator
        page_a.reload(wait_until="commit", timeout=90_000)
        page_a.bring_to_front()  # viser's page connects only while it has the focus
        page_a.get_by_role("button", name="Files", exact=True).first.wait_for(timeout=30000)
        wait_for(lambda: a.ready.is_set() and a.client is not None, what="A to re-attach")
        assert studio_app.sessions.get(a.sid) is a
        assert a.tabs["creature"].generator is old
        assert int(a.tabs["creature"].seed.value) == seed_b + 5
    finally:
        ctx_a.close()
        ctx_b.close()


# ---------------------------------------------------------------------- pictures
def test_creature_bone_models_are_drawn_shaded(shared_app):
    tab = shared_app.tabs["creature"]
    v = tab.version
    tab.bone_models.value = True  # its callback redraws
    wait_for(lambda: tab.version > v, what="the redraw with bone models")
    names = [n for n in tab.scene._handle_from_node_name if n.startswith("/creature/models/")]
    assert names, "no bone model meshes in the scene"
    tab.bone_models.value = False
    assert not [n for n in tab.scene._handle_from_node_name if n.startswith("/creature/models/")]


def test_tree_tubes_are_coloured_by_radius_with_a_legend(shared_app):
    import numpy as np

    tab = shared_app.tabs["tree"]
    tab.run("synthesise", tab.synthesise)
    tab.run("run", tab.start)
    wait_for(lambda: tab.result is not None, timeout=300, what="the skeleton")
    wait_for(lambda: "Tube radius" in tab.legend_md.content, what="the tubes and legend")
    colours = {c for _, _, c in tab._tubes}
    assert len(colours) >= 3, colours  # thin twigs to the trunk span several classes
    assert "Tube radius" in tab.legend_md.content and "cm" in tab.legend_md.content
    assert "Branch order" in tab.legend_md.content
    lo, hi = tab._tube_range
    assert 0 < lo < hi <= float(np.max(tab.result.graph.radius))
    assert tab.ticks[0] == "prepared" and tab.ticks[-1] == "metrics"


def test_creature_steps_and_limb_edits_before_girdles_are_user_errors(shared_app):
    """Found by the monkey: a stepwise rebuild drew the spine from a dict (the pillar's
    step states are typed now) and 'Change limb type' before the girdles step crashed."""
    tab = shared_app.tabs["creature"]
    tab.run("all steps", tab.all_steps)
    tab.run("next step", tab.next_step)  # starts a stepwise rebuild: the spine only
    assert tab.last_error is None, tab.last_error
    assert "/creature/spine" in tab.scene._handle_from_node_name
    tab.run("change limb type", tab.change_limb)
    assert tab.last_error is not None and "girdles" in tab.last_error
    tab.run("all steps", tab.all_steps)
    assert tab.last_error is None and tab.creature is not None
