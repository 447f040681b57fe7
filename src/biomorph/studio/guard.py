"""Who may talk to the studio, and what a page may send it.

Binding to loopback is not enough: any web page the user opens can reach
``ws://127.0.0.1:PORT`` (cross-site websocket hijacking) and a DNS-rebinding page can
reach it under a name of its own. So every request passes :class:`AccessPolicy`:

* **Host** of every HTTP request and websocket upgrade must name the bound address (for
  loopback also ``localhost`` / ``127.0.0.1`` / ``[::1]``) and the bound port — a rebinding
  page sends its own name and is refused (403);
* **Origin** of a websocket upgrade must be the studio's own origin (same host rule);
  a page of another origin, or a client sending none, is refused (403);
* **token** (optional ``--token``): the printed address carries ``?token=…``; the first
  request sets it as an ``HttpOnly; SameSite=Strict`` cookie, which every later request
  and the websocket must carry.

What a connected page sends is checked by :func:`harden_gui`:

* only the ``value`` of an input may change (viser applies any property a client names),
  and the value must fit the element: a number finite and within the ``min``/``max`` the
  page shows (whole for integer steps), a dropdown value among its options, a text at
  most :data:`MAX_TEXT` characters; anything else is dropped, the page's element is set
  back and the tab shows why;
* uploads are counted while they stream: a transfer declaring more than the limit is
  refused at its start, and one whose parts add up to more than it declared (or than the
  limit) is dropped — its buffer freed — and the connection closed so nothing more is
  read; single websocket messages are capped at :data:`MAX_MESSAGE` bytes.
"""

from __future__ import annotations

import gc
import hmac
import http
import math
import re
import secrets
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qs, urlsplit

#: Names a loopback-bound studio answers to.
LOOPBACK = ("127.0.0.1", "localhost", "::1")
#: Longest text a text field accepts (the longest key list anyone types is far shorter).
MAX_TEXT = 2000
#: Largest single websocket message a page may send (viser uploads in 512 KiB parts).
MAX_MESSAGE = 2 * 1024 * 1024
COOKIE = "biomorph_studio_token"
#: Page address of a session: ``/s/<id>/`` (id from :func:`new_session_id`).
SESSION_PATH = re.compile(r"^/s/([A-Za-z0-9_-]{8,40})/?$")


def new_session_id() -> str:
    """A fresh, unguessable session id (URL-safe)."""
    return secrets.token_urlsafe(12)


def session_of(path: str) -> str | None:
    """The session id named by a request path (``/s/<id>/``), or ``None``."""
    m = SESSION_PATH.match(urlsplit(path).path)
    return m.group(1) if m else None


def _split_host(value: str) -> tuple[str, int | None]:
    """``"name:port"`` / ``"[v6]:port"`` -> (lower-case name, port or None)."""
    value = value.strip().lower()
    if value.startswith("["):
        name, _, rest = value[1:].partition("]")
        port = rest[1:] if rest.startswith(":") else ""
    else:
        name, _, port = value.partition(":")
    if port and not port.isdigit():
        return name, -1
    return name, int(port) if port else None


@dataclass
class AccessPolicy:
    """The Host / Origin / token rules of one studio (see the module docstring)."""

    host: str
    port: int
    token: str | None = None
    names: set[str] = field(default_factory=set)

    def __post_init__(self) -> None:
        host = self.host.lower()
        names = {host}
        if host in LOOPBACK:
            names |= set(LOOPBACK)
        elif host in ("0.0.0.0", "::", ""):  # every interface: this machine's own names
            names |= set(LOOPBACK) | {socket.gethostname().lower(), socket.getfqdn().lower()}
            try:
                names |= {a[4][0] for a in socket.getaddrinfo(socket.gethostname(), None)}
            except OSError:
                pass
        self.names |= names

    def host_ok(self, value: str | None) -> bool:
        if not value:
            return False
        name, port = _split_host(value)
        return name in self.names and (port or 80) == self.port

    def origin_ok(self, value: str | None) -> bool:
        if not value:
            return False
        parts = urlsplit(value)
        if parts.scheme not in ("http", "https") or parts.hostname is None:
            return False
        try:
            port = parts.port or (443 if parts.scheme == "https" else 80)
        except ValueError:
            return False
        return parts.hostname.lower() in self.names and port == self.port

    def token_of(self, headers: Any, path: str) -> str | None:
        """The token a request carries (query ``token=`` or the cookie)."""
        query = parse_qs(urlsplit(path).query).get("token")
        if query:
            return query[0]
        for raw in headers.get_all("Cookie") if hasattr(headers, "get_all") else []:
            for part in raw.split(";"):
                k, _, v = part.strip().partition("=")
                if k == COOKIE:
                    return v
        return None

    def token_ok(self, headers: Any, path: str) -> bool:
        if self.token is None:
            return True
        got = self.token_of(headers, path)
        return got is not None and hmac.compare_digest(got.encode(), self.token.encode())

    def refusal(self, headers: Any, path: str, websocket: bool) -> str | None:
        """Why this request is refused, or ``None`` when it may pass."""
        if not self.host_ok(headers.get("Host")):
            return f"Host {headers.get('Host')!r} is not this studio's address"
        if websocket and not self.origin_ok(headers.get("Origin")):
            return f"Origin {headers.get('Origin')!r} is not this studio's page"
        if not self.token_ok(headers, path):
            return "missing or wrong token"
        return None


def install_http_guard(viser_server: Any, policy: AccessPolicy, shared: bool) -> None:
    """Wrap the studio's websocket server's ``process_request`` with ``policy``.

    Plain HTTP requests are routed too: ``/`` goes to a new session page ``/s/<id>/``
    (unless ``shared``), a session page serves viser's single-file client.
    """
    from websockets.datastructures import Headers
    from websockets.http11 import Request, Response

    server = _websockets_server(viser_server)
    inner = server.process_request

    def refuse(why: str) -> Response:
        body = f"403 Forbidden: {why}\n".encode()
        return Response(
            http.HTTPStatus.FORBIDDEN,
            "Forbidden",
            Headers(
                {"Content-Type": "text/plain; charset=utf-8", "Content-Length": str(len(body))}
            ),
            body,
        )

    def redirect(location: str, set_token: bool) -> Response:
        headers = Headers(
            {"Location": location, "Content-Length": "0", "Cache-Control": "no-store"}
        )
        if set_token and policy.token is not None:
            headers["Set-Cookie"] = f"{COOKIE}={policy.token}; HttpOnly; SameSite=Strict; Path=/"
        return Response(http.HTTPStatus.FOUND, "Found", headers, b"")

    def process_request(connection: Any, request: Any) -> Any:
        websocket = request.headers.get("Upgrade", "").lower() == "websocket"
        why = policy.refusal(request.headers, request.path, websocket)
        if why is not None:
            return refuse(why)
        if websocket:
            return None
        url = urlsplit(request.path)
        with_query_token = "token" in parse_qs(url.query)
        if url.path == "/" and (not shared or with_query_token):
            return redirect("/" if shared else f"/s/{new_session_id()}/", with_query_token)
        if session_of(url.path) is not None:
            if shared:
                return redirect("/", with_query_token)
            if with_query_token:
                return redirect(url.path, True)
            request = Request("/", request.headers)
        response = inner(connection, request)
        if response is not None:
            for k, v in (
                ("X-Frame-Options", "DENY"),
                ("Referrer-Policy", "no-referrer"),
                ("X-Content-Type-Options", "nosniff"),
                ("Cache-Control", "no-store"),
            ):
                response.headers[k] = v
        return response

    server.process_request = process_request


def _websockets_server(viser_server: Any) -> Any:
    """The ``websockets`` server object viser listens with (it keeps no reference to it)."""
    from websockets.asyncio.server import Server

    port = int(viser_server.get_port())
    for obj in gc.get_objects():
        if isinstance(obj, Server):
            try:
                socks = obj.sockets
            except Exception:  # noqa: BLE001, S112 - not serving
                continue
            if any(s.getsockname()[1] == port for s in socks):
                return obj
    raise RuntimeError(f"cannot find the websocket server on port {port} to guard it")


# ---------------------------------------------------------------------- page input checks
def check_value(handle: Any, value: Any) -> tuple[bool, Any]:
    """``(True, value)`` when ``value`` fits GUI input ``handle``, else ``(False, why)``."""
    impl = handle._impl
    if impl.is_button:
        return True, value
    cur = impl.value
    label = getattr(handle, "label", "") or "value"
    if isinstance(cur, bool):
        return (
            (True, value)
            if isinstance(value, bool)
            else (False, f"{label}: expected true or false")
        )
    if isinstance(cur, int | float):
        return _check_number(handle, label, value, isinstance(cur, int))
    if isinstance(cur, tuple):
        if not isinstance(value, list | tuple) or len(value) != len(cur):
            return False, f"{label}: expected {len(cur)} numbers"
        out = []
        for v in value:
            ok, got = _check_number(handle, label, v, bool(cur) and isinstance(cur[0], int))
            if not ok:
                return ok, got
            out.append(got)
        if out != sorted(out):
            return False, f"{label}: the range must be in increasing order"
        return True, tuple(out)
    if isinstance(cur, str):
        if not isinstance(value, str):
            return False, f"{label}: expected text"
        options = getattr(handle, "options", None)
        if options is not None and not hasattr(handle, "multiline"):
            if value not in tuple(options):
                return False, f"{label}: {value[:60]!r} is not one of the choices"
            return True, value
        if len(value) > MAX_TEXT or "\x00" in value:
            return False, f"{label}: at most {MAX_TEXT} characters of text"
        return True, value
    return False, f"{label}: this element takes no value from the page"


def _check_number(handle: Any, label: str, value: Any, integer: bool) -> tuple[bool, Any]:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False, f"{label}: expected a number, got {str(value)[:40]!r}"
    if not math.isfinite(value):
        return False, f"{label}: {value} is not a finite number"
    lo, hi = getattr(handle, "min", None), getattr(handle, "max", None)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        return False, (f"{label}: {value:g} is outside {_g(lo)}..{_g(hi)}")
    if integer and float(value) != round(float(value)):
        return False, f"{label}: {value:g} is not a whole number"
    return True, int(round(value)) if integer else float(value)


def _g(v: Any) -> str:
    return "" if v is None else f"{v:g}"


@dataclass
class InputGuard:
    """Server-side checks of one viser ``GuiApi`` (see the module docstring).

    ``report(uuid, message)`` shows a refused input or upload in the page (``uuid`` is
    the element's, ``None`` for a transfer whose element is unknown); ``close(client_id)``
    drops a connection that sent more than it declared; ``changed(uuid, handle, old)``
    hears of every accepted change (for undo).
    """

    gui: Any
    max_upload: Callable[[], int]
    report: Callable[[str | None, str], None]
    close: Callable[[int], None]
    changed: Callable[[str, Any, Any], None] | None = None
    refused: int = 0

    def install(self) -> None:
        from viser import _messages

        iface = self.gui._websock_interface
        for cls, mine, theirs in (
            (_messages.GuiUpdateMessage, self.on_update, self.gui._handle_gui_updates),
            (
                _messages.FileTransferStartUpload,
                self.on_start,
                self.gui._handle_file_transfer_start,
            ),
            (_messages.FileTransferPart, self.on_part, self.gui._handle_file_transfer_part),
        ):
            iface.unregister_handler(cls, theirs)
            iface.register_handler(cls, mine(theirs))

    def _revert(self, handle: Any) -> None:
        from viser._messages import GuiUpdateMessage

        self.gui._websock_interface.queue_message(
            GuiUpdateMessage(handle._impl.uuid, {"value": handle._impl.value})
        )

    def _release(self, component: str | None, transfer: str) -> None:
        """Tell the page's upload button the transfer is over (viser's client otherwise
        spins forever and keeps the button disabled after a refusal)."""
        from viser._messages import FileTransferPartAck

        self.gui._websock_interface.queue_message(
            FileTransferPartAck(
                source_component_uuid=component,
                transfer_uuid=transfer,
                transferred_bytes=0,
                total_bytes=0,
            )
        )

    def on_update(self, inner: Callable) -> Callable:
        async def handler(client_id: int, message: Any) -> None:
            handle = self.gui._gui_input_handle_from_uuid.get(message.uuid)
            if handle is None:
                return
            updates = message.updates if isinstance(message.updates, dict) else {}
            if set(updates) - {"value"}:
                self.refused += 1
                self.report(message.uuid, "the page may change only an element's value")
                updates = {k: v for k, v in updates.items() if k == "value"}
                if not updates:
                    return
            if "value" in updates:
                ok, got = check_value(handle, updates["value"])
                if not ok:
                    self.refused += 1
                    self._revert(handle)
                    self.report(message.uuid, got)
                    return
                updates = {"value": got}
            old = handle._impl.value
            message.updates = updates
            await inner(client_id, message)
            if (
                self.changed is not None
                and "value" in updates
                and not handle._impl.is_button
                and handle._impl.value != old
            ):
                self.changed(message.uuid, handle, old)

        return handler

    def on_start(self, inner: Callable) -> Callable:
        def handler(client_id: int, message: Any) -> None:
            limit = self.max_upload()
            size, parts = message.size_bytes, message.part_count
            if (
                not isinstance(size, int)
                or size < 0
                or size > limit
                or not isinstance(parts, int)
                or parts < 0
                or parts > size // 1024 + 1
            ):
                self.refused += 1
                self.report(
                    message.source_component_uuid,
                    f"{message.filename}: {size / 1e6:.1f} MB exceeds the upload "
                    f"limit of {limit / 1e6:.1f} MB"
                    if isinstance(size, int) and size > limit
                    else f"{message.filename}: malformed upload",
                )
                self._release(message.source_component_uuid, message.transfer_uuid)
                return  # nothing is buffered: later parts find no transfer and are dropped
            inner(client_id, message)

        return handler

    def on_part(self, inner: Callable) -> Callable:
        def handler(client_id: int, message: Any) -> None:
            states = self.gui._current_file_upload_states
            state = states.get(message.transfer_uuid)
            if state is None:
                return
            got = state["transferred_bytes"] + len(message.content)
            if got > min(state["total_bytes"], self.max_upload()):
                states.pop(message.transfer_uuid, None)
                self.refused += 1
                self.report(
                    message.source_component_uuid,
                    f"{state['filename']}: the upload sent more than the "
                    f"{state['total_bytes']:,} bytes it declared; dropped",
                )
                self._release(message.source_component_uuid, message.transfer_uuid)
                self.close(client_id)
                return
            inner(client_id, message)

        return handler
