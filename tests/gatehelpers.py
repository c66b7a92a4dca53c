"""What the 3D view's tests share: the service's viewer, runs to show, a page's socket."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import httpx
import viser
from fastapi import FastAPI
from viserpage import camera_message
from websockets.asyncio.client import ClientConnection, connect
from websockets.typing import Subprotocol

from server.viewer import Viewer
from server.viewer.app import Session

WAIT_S = 60.0
"""A bound for a hung view, not a speed test."""


async def until(check: Callable[[], object], what: str) -> None:
    deadline = asyncio.get_running_loop().time() + WAIT_S
    while not check():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.02)


def viewer_of(app: FastAPI) -> Viewer:
    viewer = app.state.srlab.viewer
    assert isinstance(viewer, Viewer)
    return viewer


async def start_run(client: httpx.AsyncClient, start: bool = True, **body: object) -> int:
    r = await client.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run_id = int(r.json()["id"])
    if start:
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
    return run_id


@asynccontextmanager
async def page_socket(
    viewer: Viewer, path: str, cookie: str | None = None
) -> AsyncIterator[ClientConnection]:
    """A websocket on the view's `path`, as viser's page opens it (no viewer yet).

    `cookie`: the `Cookie` header the browser would send with it (a view cookie).
    """
    url = f"ws://127.0.0.1:{viewer.port}{path}"
    protocol = Subprotocol(f"viser-v{viser.__version__}")  # viser refuses other versions
    headers = {} if cookie is None else {"Cookie": cookie}
    async with connect(url, subprotocols=[protocol], additional_headers=headers) as socket:
        drain = asyncio.create_task(_drain(socket))
        try:
            yield socket
        finally:
            drain.cancel()


async def _drain(socket: ClientConnection) -> None:
    """Read what viser sends, as the page does (an unread socket would push back)."""
    async for _ in socket:
        pass


async def becomes_viewer(viewer: Viewer, socket: ClientConnection) -> Session:
    """Send the page's first camera message, which makes viser call the socket a viewer."""
    before = set(viewer.sessions)
    await socket.send(camera_message())
    await until(lambda: set(viewer.sessions) - before, "the socket's viewer session")
    (client_id,) = set(viewer.sessions) - before
    return viewer.sessions[client_id]


@asynccontextmanager
async def watching(viewer: Viewer, path: str) -> AsyncIterator[Session]:
    """A page's viewer on the view's `path`; its session ends on the way out."""
    async with page_socket(viewer, path) as socket:
        yield await becomes_viewer(viewer, socket)
    await until(lambda: not viewer.sessions, "the viewer's session to end")


def shows(session: Session, run_id: int) -> bool:
    return session.controller.state.run_id == run_id
