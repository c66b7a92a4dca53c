"""What viser's page sends over the 3D view's websocket, for tests that speak as it does."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import msgspec
import viser
from fastapi import FastAPI
from viser._messages import ViewerCameraMessage
from websockets.asyncio.client import ClientConnection, connect
from websockets.typing import Subprotocol

from server.viewer import Viewer

PROTOCOL = Subprotocol(f"viser-v{viser.__version__}")
"""The subprotocol viser's page offers (viser refuses other versions)."""


def camera_message() -> bytes:
    """The page's first message (its camera), which makes viser call the socket a viewer."""
    message = ViewerCameraMessage(
        wxyz=(1.0, 0.0, 0.0, 0.0),
        position=(0.0, 0.0, 5.0),
        fov=1.0,
        near=0.01,
        far=100.0,
        image_height=600,
        image_width=800,
        look_at=(0.0, 0.0, 0.0),
        up_direction=(0.0, 0.0, 1.0),
    )
    return msgspec.msgpack.encode(message.as_serializable_dict())


def viewer_of(app: FastAPI) -> Viewer:
    """The 3D view of an app started with `viser=True`."""
    viewer = app.state.srlab.viewer
    assert isinstance(viewer, Viewer)
    return viewer


@asynccontextmanager
async def page_socket(port: int, path: str = "/") -> AsyncIterator[ClientConnection]:
    """A websocket on `path` of the view at `port`, opened and read as viser's page does."""
    async with connect(f"ws://127.0.0.1:{port}{path}", subprotocols=[PROTOCOL]) as socket:
        drain = asyncio.create_task(_drain(socket))
        try:
            yield socket
        finally:
            drain.cancel()


async def _drain(socket: ClientConnection) -> None:
    """Read what viser sends, as the page does (an unread socket would push back)."""
    async for _ in socket:
        pass
