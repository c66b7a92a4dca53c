"""What viewers' sockets send, as the 3D view takes it: panel values are checked first.

viser applies a client's `GuiUpdateMessage` by casting each value to the type its input
holds (`float(v)` for a slider, `bool(v)` for a button, `str(v)` for a dropdown) in a task
nobody awaits. A value it cannot cast left "Task exception was never retrieved" and a
traceback in the log; a value it can cast became another value: `true` set a run to 1 Hz,
any value clicked a reward button, any text was taken for a run or an episode. viser's own
page sends a number within a slider's range, one of a dropdown's options and `true` for a
click, and nothing else, so `guard_panel` checks each message against that before viser's
handler sees it; a refused one gets a notice on that viewer's panel and one log line.

A frame viser cannot decode (not msgpack, an unknown type, a field missing) fails its
socket's reader: viser closes the socket (1011) and websockets logs a traceback, as for a
broken server. A message viser decodes but cannot handle fails the task it is handled in.
`quiet_malformed` logs both in one line; a failure that passes through srlab's own code
keeps its traceback, since that is srlab's bug and not the client's.
"""

from __future__ import annotations

import asyncio
import logging
import math
import reprlib
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import viser
from viser._messages import GuiUpdateMessage

log = logging.getLogger("srlab.viewer")

SRLAB = (Path(__file__).resolve().parents[1], Path(__file__).resolve().parents[2] / "core")
"""srlab's packages: a failure whose traceback passes through them is srlab's."""
HANDLER = "WebsockMessageHandler._handle_incoming_message"
"""viser's coroutine that hands one decoded client message to its handlers."""
READER = "_message_consumer"
"""viser's function that reads and decodes a client's frames."""

_short = reprlib.Repr()
_short.maxstring = _short.maxother = 40
_short.maxlist = _short.maxdict = 4


def shown(value: object) -> str:
    """A client's value as a notice or the log quotes it: short, whatever was sent."""
    return _short.repr(value)


def refusal(control: object, updates: object) -> str | None:
    """Why the panel input `control` refuses a client's `updates`, or None to apply them."""
    label = getattr(control, "label", "?")
    if not isinstance(updates, dict) or list(updates) != ["value"]:
        return f"{label} takes a value only, not {shown(updates)}"
    value = updates["value"]
    if isinstance(control, viser.GuiButtonHandle):
        return None if value is True else f"{label} takes a click (true), not {shown(value)}"
    if isinstance(control, viser.GuiSliderHandle):
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not number or (isinstance(value, float) and not math.isfinite(value)):
            return f"{label} takes a finite number, not {shown(value)}"
        if not control.min <= value <= control.max:
            return f"{label} takes {control.min:g} to {control.max:g}, not {shown(value)}"
        return None
    if isinstance(control, viser.GuiDropdownHandle | viser.GuiButtonGroupHandle):
        if isinstance(value, str) and value in control.options:
            return None
        return f"{label} takes one of its options, not {shown(value)}"
    return f"{label} takes no value from a viewer"


def guard_panel(gui: viser.GuiApi, refuse: Callable[[str], None]) -> bool:
    """Check each client's value for an input of `gui` before viser applies it.

    A refused message goes no further: `refuse` gets why (for that viewer's panel), and the
    log a line. Messages for ids that are no input here go on to viser, which ignores them.
    Install it before adding the inputs: it reads them at each message. viser (1.1) has no
    hook on a client's messages, so this swaps its GUI API's own handler for one that checks
    first; should another viser lack that handler it returns False and the panel takes what
    viser takes (tests/server/viewer/test_viewer_malformed.py says so).
    """
    interface = getattr(gui, "_websock_interface", None)
    apply = getattr(gui, "_handle_gui_updates", None)
    inputs = getattr(gui, "_gui_input_handle_from_uuid", None)
    if interface is None or apply is None or not isinstance(inputs, Mapping):
        log.warning("this viser has no handler of panel values to guard: values go unchecked")
        return False

    async def checked(client_id: int, message: GuiUpdateMessage) -> None:
        uuid: object = message.uuid
        if not isinstance(uuid, str):
            problem: str | None = f"a panel value for no element ({shown(uuid)})"
        else:
            control = inputs.get(uuid)
            problem = None if control is None else refusal(control, message.updates)
        if problem is None:
            await apply(client_id, message)
            return
        log.warning("the 3D view refused a panel value from viewer %s: %s", client_id, problem)
        refuse(problem)

    try:
        interface.unregister_handler(GuiUpdateMessage, apply)
    except (AssertionError, ValueError):
        log.warning("this viser's handler of panel values is not its own: values go unchecked")
        return False
    interface.register_handler(GuiUpdateMessage, checked)
    return True


def _frames(tb: TracebackType | None) -> list[Path]:
    files = []
    while tb is not None:
        files.append(Path(tb.tb_frame.f_code.co_filename))
        tb = tb.tb_next
    return files


def _srlabs(tb: TracebackType | None) -> bool:
    return any(f.is_relative_to(p) for f in _frames(tb) for p in SRLAB)


def _raised_in(tb: TracebackType | None, function: str) -> bool:
    while tb is not None:
        if tb.tb_frame.f_code.co_name == function:
            return True
        tb = tb.tb_next
    return False


def _where(tb: TracebackType | None) -> str:
    last = None
    while tb is not None:
        last = tb
        tb = tb.tb_next
    if last is None:
        return "?"
    return f"{Path(last.tb_frame.f_code.co_filename).name}:{last.tb_lineno}"


def _one_line(e: BaseException) -> str:
    text = str(e)
    said = "" if not text else f": {text}" if len(text) <= 80 else f": {text[:77]}..."
    return f"{type(e).__name__}{said} (at {_where(e.__traceback__)})"


def handler_failed(loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
    """The exception handler of viser's event loop: a client's message it could not handle."""
    e = context.get("exception")
    task = context.get("future")
    if (
        isinstance(e, Exception)
        and isinstance(task, asyncio.Task)
        and getattr(task.get_coro(), "__qualname__", "") == HANDLER
        and not _srlabs(e.__traceback__)
    ):
        log.warning("the 3D view ignored a message viser could not handle: %s", _one_line(e))
        return
    loop.default_exception_handler(context)


class MalformedFrames(logging.Filter):
    """On websockets' server logger: a socket whose frame viser could not read, in one line."""

    def filter(self, record: logging.LogRecord) -> bool:
        """False (dropped, and said in one line) for a reader's failure, else True."""
        e = record.exc_info[1] if record.exc_info else None
        if (
            record.msg != "connection handler failed"
            or not isinstance(e, Exception)
            or not _raised_in(e.__traceback__, READER)
            or _srlabs(e.__traceback__)
        ):
            return True
        log.warning(
            "the 3D view closed a socket that sent what viser cannot read: %s", _one_line(e)
        )
        return False


def quiet_malformed(server: viser.ViserServer) -> None:
    """Log what `server`'s clients send that viser cannot read or handle in one line each."""
    loop = server.get_event_loop()
    loop.call_soon_threadsafe(loop.set_exception_handler, handler_failed)
    websockets_log = logging.getLogger("websockets.server")
    if not any(isinstance(f, MalformedFrames) for f in websockets_log.filters):
        websockets_log.addFilter(MalformedFrames())


__all__ = [
    "MalformedFrames",
    "guard_panel",
    "handler_failed",
    "quiet_malformed",
    "refusal",
    "shown",
]
