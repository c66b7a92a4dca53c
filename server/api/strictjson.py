"""JSON request bodies read strictly, before FastAPI reads them.

Python's `json.loads` takes `NaN`, `Infinity`, lone surrogates (an escaped `ud800`) and duplicate
keys (the last wins), none of which is JSON a client means: a body with any of them gets
422 in FastAPI's own shape, its `loc` naming the field.
"""

from __future__ import annotations

import json
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from server.asgi import send_error


class _Bad:
    """Where a value JSON does not allow stood, and why."""

    def __init__(self, why: str, value: str) -> None:
        self.why = why
        self.value = value


def _constant(name: str) -> _Bad:
    return _Bad(f"{name} is not a JSON number: use a finite number", name)


def _pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        out[key] = _Bad(f"key {key!r} appears more than once", key) if key in out else value
    return out


def _lone_surrogate(text: str) -> bool:
    return any(0xD800 <= ord(c) <= 0xDFFF for c in text)


def problems(value: Any, loc: tuple[str | int, ...] = ("body",)) -> list[dict[str, Any]]:
    """Each value of a decoded body that JSON does not allow, as a 422 error entry."""
    found: list[dict[str, Any]] = []
    if isinstance(value, _Bad):
        found.append(
            {"type": "json_invalid", "loc": list(loc), "msg": value.why, "input": value.value}
        )
    elif isinstance(value, str) and _lone_surrogate(value):
        found.append(
            {
                "type": "string_unicode",
                "loc": list(loc),
                "msg": "a lone surrogate is not text",
                "input": None,
            }
        )
    elif isinstance(value, dict):
        for k, v in value.items():
            if _lone_surrogate(k):
                found.append(
                    {
                        "type": "string_unicode",
                        "loc": [*loc],
                        "msg": "a key holds a lone surrogate",
                        "input": None,
                    }
                )
                continue
            found += problems(v, (*loc, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            found += problems(v, (*loc, i))
    return found


class StrictJson:
    """Reads a JSON body once, refuses it with 422 if it is not strict JSON, replays it."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check the body of a JSON request to the API."""
        if scope["type"] != "http" or not scope["path"].startswith("/api/"):
            await self.app(scope, receive, send)
            return
        content_type = dict(scope["headers"]).get(b"content-type", b"")
        if not content_type.split(b";")[0].strip().lower().endswith(b"json"):
            await self.app(scope, receive, send)
            return
        chunks: list[bytes] = []
        messages: list[Message] = []
        while True:
            message = await receive()
            messages.append(message)
            if message["type"] != "http.request":
                break
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        if body.strip():
            try:
                decoded = json.loads(body, parse_constant=_constant, object_pairs_hook=_pairs)
            except (ValueError, UnicodeDecodeError):
                decoded = None  # not JSON at all: FastAPI's own 422 says where
            found = problems(decoded)
            if found:
                await send_error(send, 422, found)
                return
        replay = iter(messages)

        async def replayed() -> Message:
            message = next(replay, None)
            return message if message is not None else await receive()

        await self.app(scope, replayed, send)
