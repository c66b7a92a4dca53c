"""The 3D view gate's HTTP: a request head read and checked, and the gate's own answers.

What `server.viewer.gate` needs of HTTP/1.1 before it relays a connection to viser: the
run a view URL names, the head parsed (websockets' parser) and checked against the site
policy, the 101 of a handshake, refusals, the page shown past `max_viewers`, and the 303
that trades a ticket for a view cookie.
"""

from __future__ import annotations

import base64
import json
import re
from http import HTTPStatus
from urllib.parse import parse_qsl

from websockets.exceptions import SecurityError
from websockets.http11 import Request
from websockets.streams import StreamReader
from websockets.utils import accept_key

from server.api.guard import SitePolicy
from server.viewer.passes import SESSION_S

RUN_PATH = re.compile(r"/run/([0-9]{1,18})/?")
"""A view URL's path that names a run. At most 18 digits: run ids stay below 2**62 (the
API's bound), and a longer or non-digit id is no run but a plain path (viser's 404)."""
FULL_RETRY_AFTER_S = 5
"""The `Retry-After` of a refusal past `max_viewers` (the API's full streams say the same)."""


def run_path(head: bytes) -> tuple[bytes, int | None]:
    """The request head as viser must get it, and the run its path names, if any.

    `GET /run/7?x HTTP/1.1` becomes `GET /?x HTTP/1.1` and names run 7; any other head
    is returned unchanged, with None.
    """
    line, sep, rest = head.partition(b"\r\n")
    parts = line.split(b" ")
    if len(parts) != 3:
        return head, None
    method, target, version = parts
    path, query, params = target.partition(b"?")
    found = RUN_PATH.fullmatch(path.decode("latin-1"))
    if found is None:
        return head, None
    return b" ".join((method, b"/" + query + params, version)) + sep + rest, int(found[1])


Refusal = tuple[HTTPStatus, str]


def parse_head(head: bytes) -> tuple[dict[str, str], Refusal | None]:
    """A request head's headers (names lower-case, last one wins), or why viser cannot take it.

    viser's server (websockets) takes a GET in HTTP/1.1 with no body and headers within its
    parser's limits, and logs a traceback for anything else; its own parser says which. The
    method and the version get their own statuses (405, 505).
    """
    parts = head.split(b"\r\n", 1)[0].split(b" ")
    if len(parts) == 3 and parts[0] != b"GET":
        method = parts[0].decode("latin-1")
        return {}, (HTTPStatus.METHOD_NOT_ALLOWED, f"the 3D view takes GET only, not {method}")
    if len(parts) == 3 and parts[2] != b"HTTP/1.1":
        version = parts[2].decode("latin-1")
        return {}, (
            HTTPStatus.HTTP_VERSION_NOT_SUPPORTED,
            f"the 3D view takes HTTP/1.1, not {version}",
        )
    stream = StreamReader()
    stream.feed_data(head)
    stream.feed_eof()
    parser = Request.parse(stream.read_line)
    try:
        next(parser)
    except StopIteration as done:
        request: Request = done.value
        return {k.lower(): v for k, v in request.headers.raw_items()}, None
    except (EOFError, SecurityError, ValueError, NotImplementedError) as e:
        return {}, (HTTPStatus.BAD_REQUEST, f"not a request the 3D view takes: {e}")
    return {}, (HTTPStatus.BAD_REQUEST, "not a request the 3D view takes: it is incomplete")


def refusal(headers: dict[str, str], policy: SitePolicy) -> Refusal | None:
    """Why the gate refuses a request with these headers, or None to let it through."""
    problem = policy.host_problem(headers.get("host"))
    if problem is not None:
        return HTTPStatus.BAD_REQUEST, problem
    if wants_upgrade(headers):
        problem = policy.origin_problem(headers, "http")
        if problem is not None:
            return HTTPStatus.FORBIDDEN, problem
    return None


def wants_upgrade(headers: dict[str, str]) -> bool:
    """Whether a request head asks for a websocket."""
    return headers.get("upgrade", "").lower() == "websocket"


def handshake_answer(headers: dict[str, str]) -> bytes | None:
    """The 101 viser would answer this websocket handshake with, or None if it is not one.

    viser's server (1.1) negotiates no extension (`compression=None`) and picks the first
    subprotocol offered that starts with `viser-v` (its client's version, checked after the
    handshake); so the answer depends on the request's headers alone. A request without
    a well-formed key or version 13 gets None: the gate refuses it.
    """
    key = headers.get("sec-websocket-key", "")
    if headers.get("sec-websocket-version") != "13":
        return None
    try:
        if len(base64.b64decode(key, validate=True)) != 16:
            return None
    except ValueError:
        return None
    lines = [
        "HTTP/1.1 101 Switching Protocols",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Accept: {accept_key(key)}",
    ]
    offered = [p.strip() for p in headers.get("sec-websocket-protocol", "").split(",")]
    chosen = next((p for p in offered if p.startswith("viser-v")), None)
    if chosen is not None:
        lines.append(f"Sec-WebSocket-Protocol: {chosen}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


BAD_HANDSHAKE = (
    "a websocket handshake here needs Sec-WebSocket-Version: 13 and a Sec-WebSocket-Key "
    "of 16 bytes in base64"
)


def response(
    status: HTTPStatus,
    body: bytes,
    content_type: str = "application/json",
    headers: tuple[str, ...] = (),
    *,
    head_only: bool = False,
) -> bytes:
    """An HTTP/1.1 answer that closes its connection (no body for a HEAD request)."""
    lines = [
        f"HTTP/1.1 {status.value} {status.phrase}",
        f"Content-Type: {content_type}",
        f"Content-Length: {len(body)}",
        *headers,
        "Connection: close",
    ]
    return ("\r\n".join(lines) + "\r\n\r\n").encode() + (b"" if head_only else body)


def refused(status: HTTPStatus, detail: str, *, head_only: bool = False) -> bytes:
    """An answer with a JSON `detail`, as the API's errors have."""
    extra = ("Allow: GET",) if status is HTTPStatus.METHOD_NOT_ALLOWED else ()
    body = json.dumps({"detail": detail}).encode()
    return response(status, body, headers=extra, head_only=head_only)


def full_detail(limit: int) -> str:
    """Why a viewer is turned away when `limit` are open."""
    return (
        f"the 3D view has {limit} viewers open, as many as it takes (SRLAB_VISER_MAX_VIEWERS): "
        "close one, or try again in a moment"
    )


def full_page(limit: int) -> bytes:
    """The page a browser gets in place of the view when it is full.

    It says so, and reloads itself after `FULL_RETRY_AFTER_S`.
    """
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8>"
        f'<meta http-equiv="refresh" content="{FULL_RETRY_AFTER_S}">'
        "<title>srlab 3D view: full</title></head>"
        '<body style="font-family: sans-serif; margin: 2em">'
        f"<h1>The 3D view is full</h1><p id=full>{full_detail(limit)}.</p>"
        f"<p>This page tries again every {FULL_RETRY_AFTER_S} seconds.</p></body></html>"
    ).encode()


def target(head: bytes) -> tuple[str, list[tuple[str, str]]]:
    """A request head's path and its query's parameters ("" and none for no request line)."""
    parts = head.split(b"\r\n", 1)[0].split(b" ")
    if len(parts) != 3:
        return "", []
    path, _, query = parts[1].decode("latin-1").partition("?")
    return path, parse_qsl(query, keep_blank_values=True)


def cookie_values(headers: dict[str, str], name: str) -> list[str]:
    """Every value the request's `Cookie` header gives `name` (the most specific path first)."""
    pairs = (c.strip().partition("=") for c in headers.get("cookie", "").split(";"))
    return [value.strip() for key, _, value in pairs if key.strip() == name]


def exchanged(location: str, cookie: str) -> bytes:
    """The answer to a page opened with a good ticket: its cookie, and on to `location`."""
    return response(
        HTTPStatus.SEE_OTHER,
        b"",
        "text/plain",
        (
            f"Location: {location}",
            f"Set-Cookie: {cookie}; Max-Age={int(SESSION_S)}; HttpOnly; SameSite=Strict",
            "Cache-Control: no-store",
            "Referrer-Policy: no-referrer",
        ),
    )
