"""ASGI helpers of the middleware: JSON errors in the API's model, a body read cut off."""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send


async def send_error(
    send: Send,
    status: int,
    detail: str | list[dict[str, Any]],
    headers: list[tuple[bytes, bytes]] | None = None,
) -> None:
    """Answer `{"detail": detail}` with `status` (and `headers`).

    `detail` is a sentence, or for 422 FastAPI's list of field errors.
    """
    body = json.dumps({"detail": detail}).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", b"application/json"),
                (b"content-length", str(len(body)).encode()),
                *(headers or []),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


async def cut_off(
    app: ASGIApp,
    scope: Scope,
    receive: Receive,
    send: Send,
    cut: type[Exception],
    reject: Callable[[Send], Awaitable[None]],
) -> None:
    """Run `app`; when `receive` raises `cut`, the client gets `reject`'s answer instead.

    The app may make an answer of its own out of the cut-off read (FastAPI's is 400 "error
    parsing the body"): that one is replaced, unless it had started before the cut.
    """
    started = False
    over = False

    async def watched() -> Message:
        nonlocal over
        try:
            return await receive()
        except cut:
            over = True
            raise

    async def tracking(message: Message) -> None:
        nonlocal started
        if over:
            if message["type"] == "http.response.start" and not started:
                started = True
                await reject(send)
            return
        started = started or message["type"] == "http.response.start"
        await send(message)

    try:
        await app(scope, watched, tracking)
    except cut:
        if not started:
            await reject(send)
