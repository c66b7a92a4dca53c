"""What viser's page sends over the 3D view's websocket, for tests that speak as it does."""

from __future__ import annotations

import msgspec
from viser._messages import ViewerCameraMessage


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
