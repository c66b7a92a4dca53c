"""JSON request bodies read strictly, before FastAPI reads them.

Python's `json.loads` takes `NaN`, `Infinity`, numbers out of a float's range (`1e400`,
read as infinity), lone surrogates (an escaped `ud800`) and duplicate keys (the last wins),
none of which is JSON a client means: a body with any of them gets 422 in FastAPI's own
shape, its `loc` naming the field. So does a body nested deeper than `MAX_DEPTH` (no body
of the API nests more than four levels): reading one a thousand levels deep would exhaust
Python's recursion limit, here or in FastAPI.
"""

from __future__ import annotations

import json
import math
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from server.api.asgi import send_error


class _Bad:
    """Where a value JSON does not allow stood, and why."""

    def __init__(self, why: str, value: str) -> None:
        self.why = why
        self.value = value


MAX_DEPTH = 32
"""How deeply a request body's arrays and objects may nest."""


def _constant(name: str) -> _Bad:
    return _Bad(f"{name} is not a JSON number: use a finite number", name)


def _float(text: str) -> float | _Bad:
    value = float(text)
    if math.isfinite(value):
        return value
    return _Bad(f"{text} is out of a number's range: use a finite number", text)


def _int(text: str) -> int | _Bad:
    try:
        return int(text)
    except ValueError:  # over Python's limit of digits
        return _Bad(f"an integer of {len(text):,} digits is out of range", text[:20] + "...")


def _pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        out[key] = _Bad(f"key {key!r} appears more than once", key) if key in out else value
    return out


def _lone_surrogate(text: str) -> bool:
    return any(0xD800 <= ord(c) <= 0xDFFF for c in text)


def problems(value: Any, loc: tuple[str | int, ...] = ("body",)) -> list[dict[str, Any]]:
    """Each value of a decoded body that JSON does not allow, as a 422 error entry.

    Walked without recursion, in document order; a value nested deeper than `MAX_DEPTH`
    is one error, and nothing under it is looked at.
    """
    found: list[dict[str, Any]] = []
    todo: list[tuple[Any, tuple[str | int, ...]]] = [(value, loc)]
    while todo:
        value, at = todo.pop()
        if isinstance(value, _Bad):
            found.append(
                {"type": "json_invalid", "loc": list(at), "msg": value.why, "input": value.value}
            )
        elif isinstance(value, str) and _lone_surrogate(value):
            found.append(
                {
                    "type": "string_unicode",
                    "loc": list(at),
                    "msg": "a lone surrogate is not text",
                    "input": None,
                }
            )
        elif isinstance(value, dict | list) and len(at) - len(loc) >= MAX_DEPTH:
            found.append(_too_deep(at))
            break
        elif isinstance(value, dict):
            inner: list[tuple[Any, tuple[str | int, ...]]] = []
            for k, v in value.items():
                if _lone_surrogate(k):
                    found.append(
                        {
                            "type": "string_unicode",
                            "loc": list(at),
                            "msg": "a key holds a lone surrogate",
                            "input": None,
                        }
                    )
                    continue
                inner.append((v, (*at, k)))
            todo.extend(reversed(inner))
        elif isinstance(value, list):
            todo.extend(reversed([(v, (*at, i)) for i, v in enumerate(value)]))
    return found


def _too_deep(at: tuple[str | int, ...]) -> dict[str, Any]:
    return {
        "type": "json_invalid",
        "loc": list(at),
        "msg": f"the body nests arrays and objects more than {MAX_DEPTH} levels deep",
        "input": None,
    }


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
            found: list[dict[str, Any]] = []
            try:
                decoded = json.loads(
                    body,
                    parse_constant=_constant,
                    parse_float=_float,
                    parse_int=_int,
                    object_pairs_hook=_pairs,
                )
            except (ValueError, UnicodeDecodeError):
                pass  # not JSON at all: FastAPI's own 422 says where
            except RecursionError:  # far deeper than MAX_DEPTH
                found = [_too_deep(("body",))]
            else:
                found = problems(decoded)
            if found:
                await send_error(send, 422, found)
                return
        replay = iter(messages)

        async def replayed() -> Message:
            message = next(replay, None)
            return message if message is not None else await receive()

        await self.app(scope, replayed, send)
