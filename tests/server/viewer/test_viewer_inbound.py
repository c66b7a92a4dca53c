"""What the 3D view takes from a socket (server/viewer/inbound.py), on a bare viser server.

The same over a live service's real websocket is tests/server/viewer/test_viewer_malformed.py.
These reach into the viser internals the guard relies on (its GUI handler, its message
handling task, its socket reader), so a viser that changes them fails here first.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Iterator
from typing import Any, NoReturn

import pytest
import viser
from viser._messages import GuiUpdateMessage
from viser.infra import ClientId, Message, WebsockMessageHandler
from viser.infra._infra import _message_consumer

from server.viewer.inbound import MalformedFrames, guard_panel, handler_failed, refusal
from server.viewer.render import run_of_label

CLIENT = ClientId(0)


@pytest.fixture(scope="module")
def viser_server() -> Iterator[viser.ViserServer]:
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


@pytest.fixture(scope="module")
def panel(viser_server: viser.ViserServer) -> dict[str, Any]:
    gui = viser_server.gui
    return {
        "slider": gui.add_slider("Rate", 1.0, 100.0, 1.0, 10.0),
        "dropdown": gui.add_dropdown("Run", ("#1 kp realtime", "#2 rp fast")),
        "group": gui.add_button_group("View", ("Live", "Replay")),
        "button": gui.add_button("+ reward"),
    }


@pytest.mark.parametrize(
    ("kind", "value"),
    [
        ("slider", 10),
        ("slider", 1.0),
        ("slider", 100.0),
        ("dropdown", "#2 rp fast"),
        ("group", "Replay"),
        ("button", True),
    ],
)
def test_what_visers_page_sends_is_taken(panel: dict[str, Any], kind: str, value: object) -> None:
    assert refusal(panel[kind], {"value": value}) is None


@pytest.mark.parametrize(
    ("kind", "value", "why"),
    [
        ("slider", "50", "takes a finite number, not '50'"),
        ("slider", True, "takes a finite number, not True"),
        ("slider", None, "takes a finite number, not None"),
        ("slider", [1], "takes a finite number, not [1]"),
        ("slider", math.nan, "takes a finite number, not nan"),
        ("slider", -math.inf, "takes a finite number, not -inf"),
        ("slider", 0.5, "takes 1 to 100, not 0.5"),
        ("slider", 500, "takes 1 to 100, not 500"),
        ("slider", 2**64 - 1, "takes 1 to 100, not 18446744073709551615"),
        ("dropdown", "#3 kp fast", "takes one of its options, not '#3 kp fast'"),
        ("dropdown", 1, "takes one of its options, not 1"),
        ("group", "live", "takes one of its options, not 'live'"),
        ("group", ["Live"], "takes one of its options, not ['Live']"),
        ("button", False, "takes a click (true), not False"),
        ("button", 1, "takes a click (true), not 1"),
        ("button", "x" * 100, "takes a click (true), not 'xxxxxxxxxxxxxxxxx...xxxxxxxxxxxxxxxxxx'"),
    ],
)
def test_anything_else_is_refused_saying_what_the_input_takes(
    panel: dict[str, Any], kind: str, value: object, why: str
) -> None:
    assert refusal(panel[kind], {"value": value}) == f"{panel[kind].label} {why}"


@pytest.mark.parametrize("updates", [{}, {"disabled": False}, {"value": 5, "x": 1}, [5], "5"])
def test_a_page_sends_an_inputs_value_only(panel: dict[str, Any], updates: object) -> None:
    assert refusal(panel["slider"], updates) == f"Rate takes a value only, not {updates!r}"


def test_the_guard_refuses_before_viser_applies_and_passes_the_rest_on(
    viser_server: viser.ViserServer, panel: dict[str, Any]
) -> None:
    refused: list[str] = []
    assert guard_panel(viser_server.gui, refused.append)
    slider = panel["slider"]
    element = slider._impl.uuid

    def send(uuid: Any, updates: Any) -> None:
        # viser's own entry for a decoded client message, on viser's own loop.
        handling = viser_server._websock_server._handle_incoming_message(
            CLIENT, GuiUpdateMessage(uuid, updates)
        )
        asyncio.run_coroutine_threadsafe(handling, viser_server.get_event_loop()).result(timeout=30)

    send(element, {"value": "abc"})
    send(element, {"value": True})
    send([element], {"value": 20.0})
    assert slider.value == 10.0
    assert refused == [
        "Rate takes a finite number, not 'abc'",
        "Rate takes a finite number, not True",
        f"a panel value for no element ([{element!r}])",
    ]
    send("no such element", {"value": 20.0})  # viser's to ignore
    send(element, {"value": 20})
    assert slider.value == 20.0
    assert len(refused) == 3


class Handlers(WebsockMessageHandler):
    def get_message_buffer(self) -> NoReturn:
        raise NotImplementedError


def failed_task(handler: Any) -> asyncio.Task[None]:
    """viser's task handling one message with `handler`, finished with its exception."""
    handlers = Handlers()
    handlers.register_handler(GuiUpdateMessage, handler)

    async def run() -> asyncio.Task[None]:
        message = GuiUpdateMessage([1], {})  # type: ignore[arg-type]
        task = asyncio.create_task(handlers._handle_incoming_message(CLIENT, message))
        await asyncio.gather(task, return_exceptions=True)
        return task

    return asyncio.run(run())


def test_a_message_viser_cannot_handle_is_one_line_and_srlabs_failure_keeps_its_traceback(
    caplog: pytest.LogCaptureFixture,
) -> None:
    def visers(client: ClientId, message: GuiUpdateMessage) -> None:
        raise TypeError("unhashable type: 'list'")

    def srlabs(client: ClientId, message: GuiUpdateMessage) -> None:
        run_of_label(message.uuid)  # a list: it fails in srlab's own code

    loop = asyncio.new_event_loop()
    try:
        for handler in (visers, srlabs):
            task = failed_task(handler)
            context = {"message": "Task exception", "exception": task.exception(), "future": task}
            handler_failed(loop, context)
    finally:
        loop.close()
    one, full = caplog.records
    assert (one.name, one.levelno, one.exc_info) == ("srlab.viewer", logging.WARNING, None)
    assert one.getMessage().startswith(
        "the 3D view ignored a message viser could not handle: TypeError: unhashable type"
    )
    assert (full.name, full.levelno) == ("asyncio", logging.ERROR)
    assert full.exc_info is not None and isinstance(full.exc_info[1], AttributeError)


class Socket:
    def __init__(self, frame: bytes | str) -> None:
        self.frame = frame

    async def recv(self) -> bytes | str:
        return self.frame


def unreadable(frame: bytes | str) -> Exception:
    """What viser's reader of a socket raises on `frame`."""

    async def read() -> Exception:
        try:
            await _message_consumer(Socket(frame), lambda m: None, Message)  # type: ignore[arg-type, type-abstract]
        except Exception as e:
            return e
        raise AssertionError(f"viser read {frame!r}")

    return asyncio.run(read())


@pytest.mark.parametrize(
    ("frame", "said"),
    [
        (b"\xc1", "DecodeError: MessagePack data is malformed"),
        ("text", "AssertionError (at "),
    ],
)
def test_a_frame_viser_cannot_read_is_one_line(
    caplog: pytest.LogCaptureFixture, frame: bytes | str, said: str
) -> None:
    e = unreadable(frame)
    record = logging.LogRecord(
        "websockets.server",
        logging.ERROR,
        __file__,
        1,
        "connection handler failed",
        None,
        (type(e), e, e.__traceback__),
    )
    assert not MalformedFrames().filter(record)
    (line,) = caplog.records
    assert line.levelno == logging.WARNING and line.exc_info is None
    assert f"closed a socket that sent what viser cannot read: {said}" in line.getMessage()


def test_other_failures_of_a_socket_keep_their_traceback() -> None:
    try:
        raise RuntimeError("a producer failed")
    except RuntimeError as e:
        exc_info = (type(e), e, e.__traceback__)
    record = logging.LogRecord(
        "websockets.server", logging.ERROR, __file__, 1, "connection handler failed", None, exc_info
    )
    assert MalformedFrames().filter(record)
