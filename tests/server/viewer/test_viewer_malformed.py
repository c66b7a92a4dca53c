"""Malformed panel values over the 3D view's real websocket, as a hostile or buggy page sends.

A real `srlab serve` runs a realtime run. A socket opens on the view's port as viser's page
opens it (its subprotocol, the page's own Origin, a first camera message), reads every
element id from the panel viser sends, and sends each writable input what viser's page
never sends: wrong types, NaN, infinities, huge and negative numbers, options no dropdown
has, other properties than the value; then ids of no element, message types a client does
not send, and frames viser cannot read. The service must stay up, tell that page each value
it refused, change neither the run's rate nor its rewards, still take a well-formed value,
and log no traceback: unchecked, such values leave "Task exception was never retrieved" in
the log, and some do more (server/viewer/inbound.py says what).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import httpx
import msgspec
import pytest
import viser
import zstandard
from reliability_report import record
from viserpage import camera_message
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Origin, Subprotocol

from bench.liveserver import LiveServer, server_log, start_server, stop_server
from core.engine import HZ_MAX, HZ_MIN
from server.viewer.inbound import shown
from server.viewer.render import REWARD_NOTE

WAIT_S = 90.0
"""A bound for a hung service or page, not a speed test."""
HZ = 2.0
"""The run's rate as created: slow, so the view's work for each tick is small. At 20 Hz a
service stepped back (nice 10) behind busy processes once showed no notice in 90 s."""
PANEL_HZ = 3
"""The rate the first test sets from the panel."""
INPUTS = {
    "GuiSliderMessage": "slider",
    "GuiDropdownMessage": "dropdown",
    "GuiButtonGroupMessage": "dropdown",
    "GuiButtonMessage": "button",
}
WRITABLE = {
    "Run": "dropdown",
    "View": "dropdown",
    "Tick rate (Hz)": "slider",
    "+ reward": "button",
    "- reward": "button",
    "Episode": "dropdown",
    "Play": "button",
    "Tick": "slider",
    "Speed": "dropdown",
}
"""Every input of the panel, by label, and what viser's page sends it: a number within its
range, one of its options, or `true` for a click."""
ANY_WRONG: tuple[object, ...] = (None, [1, 2], {"a": 1}, math.nan, math.inf, -math.inf)
MALFORMED: dict[str, tuple[object, ...]] = {
    "slider": (
        *ANY_WRONG,
        "abc",
        "50",
        True,
        False,
        1e308,
        -5.0,
        0,
        1e-300,
        100.5,
        500,
        2**64 - 1,
        -(2**63),
    ),
    "dropdown": (
        *ANY_WRONG,
        "abc",
        "",
        "#999 kp realtime",
        "18446744073709551615 success, 9 ticks",
        "1000x",
        "nanx",
        5,
        True,
    ),
    "button": (*ANY_WRONG, False, "abc", "true", 1, 1.0, 0, [True], {"value": True}),
}
"""Values viser's page never sends each kind of input (`true` is a button's click)."""
NOT_A_VALUE: tuple[object, ...] = (
    {},
    {"nosuch": 1},
    {"disabled": False},
    {"value": None, "label": "x"},
    {"options": ["#1 x"]},
    "not a map",
    [1, 2],
)
"""`updates` of a GuiUpdateMessage that viser's page never sends (it sends only a value)."""


def update(element: object, updates: object) -> bytes:
    """A GuiUpdateMessage as viser's page sends it (msgpack, a `type` field)."""
    return msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": element, "updates": updates})


def decode(frame: bytes) -> list[dict[str, Any]]:
    """The messages in one of viser's frames: sizes, zstd-compressed msgpack, binary tail."""
    size = int.from_bytes(frame[:8], "little")
    compressed = int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16 : 16 + compressed], size)
    messages: list[dict[str, Any]] = msgspec.msgpack.decode(inner)["messages"]
    return messages


def until(check: Callable[[], object], what: str, timeout: float = WAIT_S) -> None:
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


@dataclass(frozen=True)
class Input:
    id: str
    kind: str


class Page:
    """viser's page as a bare socket: it reads all viser sends and knows the panel from it."""

    def __init__(self, port: int) -> None:
        self.socket: ClientConnection = connect(
            f"ws://127.0.0.1:{port}/",
            subprotocols=[Subprotocol(f"viser-v{viser.__version__}")],
            origin=Origin(f"http://127.0.0.1:{port}"),
            max_size=None,
            open_timeout=WAIT_S,
        )
        self.messages: list[dict[str, Any]] = []
        self.closed = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.socket.send(camera_message())

    def _read(self) -> None:
        try:
            for frame in self.socket:
                assert isinstance(frame, bytes)
                self.messages.extend(decode(frame))
        except ConnectionClosed:
            pass
        finally:
            self.closed.set()

    def close(self) -> None:
        self.socket.close()
        self._reader.join(timeout=WAIT_S)

    def inputs(self) -> dict[str, Input]:
        """The panel's inputs by label, from the messages that added them."""
        return {
            m["props"]["label"]: Input(m["uuid"], INPUTS[m["type"]])
            for m in list(self.messages)
            if m["type"] in INPUTS
        }

    def prop(self, element: str, name: str) -> object:
        """An element's property as the page last heard it (added, then updated)."""
        value: object = None
        for m in list(self.messages):
            if m.get("uuid") != element:
                continue
            if m["type"] == "GuiUpdateMessage":
                value = m["updates"].get(name, value)
            elif "props" in m:
                value = m.get(name, m["props"].get(name, value))
        return value

    def texts(self) -> list[str]:
        """Every markdown text the panel has shown, oldest first."""
        out = []
        for m in list(self.messages):
            if m["type"] == "GuiMarkdownMessage":
                out.append(m["props"]["_markdown"])
            elif m["type"] == "GuiUpdateMessage" and "_markdown" in m["updates"]:
                out.append(m["updates"]["_markdown"])
        return out

    def shows(self, fragment: str) -> bool:
        return any(fragment in t for t in self.texts())

    def shows_notice(self, start: str, end: str) -> bool:
        return any(t.startswith(start) and t.endswith(end) for t in self.texts())

    def live_panel(self) -> dict[str, Input]:
        """The panel once its writable inputs are live (its run is running, realtime)."""
        until(lambda: set(self.inputs()) >= set(WRITABLE), "the panel's inputs")
        inputs = self.inputs()
        assert {label: inputs[label].kind for label in WRITABLE} == WRITABLE
        until(lambda: self.prop(inputs["+ reward"].id, "disabled") is False, "a live run")
        until(lambda: self.prop(inputs["Tick rate (Hz)"].id, "disabled") is False, "its rate")
        return inputs


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[LiveServer, int, int]]:
    """A served realtime run: the service, the run's id and the 3D view's port."""
    folder = tmp_path_factory.mktemp("malformed")
    server = start_server(folder / "view.db", log=folder / "serve.log")
    try:
        api = server.client
        run = api.post("/api/runs", json={"condition": "kp", "mode": "realtime", "hz": HZ})
        assert run.status_code == 201, run.text
        run_id = int(run.json()["id"])
        assert api.post(f"/api/runs/{run_id}/start").status_code == 200
        port = int(api.get("/api/health").json()["viser_port"])
        yield server, run_id, port
    finally:
        stop_server(server)  # and no traceback in its whole log, shutdown included


def rewards(api: httpx.Client, run_id: int) -> list[dict[str, Any]]:
    """The run's trainers' rewards, newest first (the task's come as episodes succeed)."""
    data: list[dict[str, Any]] = api.get(f"/api/runs/{run_id}/rewards").json()["data"]
    return [r for r in data if r["source"] == "trainer"]


def reward_ids(api: httpx.Client, run_id: int) -> list[int]:
    """Which trainers' rewards the run has: a reward's other fields change as it is applied
    at its tick boundary, a period after it was stored."""
    return [r["id"] for r in rewards(api, run_id)]


def hz(api: httpx.Client, run_id: int) -> float:
    return float(api.get(f"/api/runs/{run_id}").json()["live"]["hz"])


def refused(page: Page, label: str, what: object) -> None:
    """Wait for the notice on `page` that the input `label` refused `what`."""
    notice(page, f"**Refused:** {label} takes ", f", not {shown(what)}")


def notice(page: Page, start: str, end: str) -> None:
    until(lambda: page.shows_notice(start, end), f"a notice '{start}...{end}'")


def assert_quiet_log(server: LiveServer) -> None:
    text = server_log(server)
    assert "Task exception was never retrieved" not in text, text[-3000:]
    assert "Traceback" not in text, text[-3000:]


def test_malformed_panel_values_are_refused_and_well_formed_ones_still_work(
    live: tuple[LiveServer, int, int],
) -> None:
    server, run_id, port = live
    api = server.client
    before, rate_before = reward_ids(api, run_id), hz(api, run_id)
    page = Page(port)
    try:
        inputs = page.live_panel()
        sent = 0
        for label, kind in WRITABLE.items():
            element = inputs[label].id
            for value in MALFORMED[kind]:
                page.socket.send(update(element, {"value": value}))
                sent += 1
                refused(page, label, value)  # on this page's panel, before the next is sent
            for updates in NOT_A_VALUE:
                page.socket.send(update(element, updates))
                sent += 1
                refused(page, label, updates)
        # No element, and messages a page does not send: nothing happens, and nothing fails.
        page.socket.send(update("no-such-element", {"value": 5.0}))
        for nothing in (None, [1]):  # a list is unhashable: viser's lookups fail on it
            page.socket.send(update(nothing, {"value": 5.0}))
            notice(page, "**Refused:** a panel value for no element", f"({shown(nothing)})")
        rate = inputs["Tick rate (Hz)"].id
        for other in (
            {"type": "GuiRemoveMessage", "uuid": rate},  # a server's message, from a client
            {"type": "ResetGuiMessage"},
            {"type": "GuiButtonHoldMessage", "uuid": [1], "frequency": 10.0},
            {"type": "GuiFormSubmitMessage", "uuid": {"a": 1}},
        ):
            page.socket.send(msgspec.msgpack.encode(other))
        assert not page.closed.is_set()

        assert api.get("/api/health").status_code == 200
        assert hz(api, run_id) == rate_before
        assert HZ_MIN <= rate_before <= HZ_MAX
        assert reward_ids(api, run_id) == before
        assert_quiet_log(server)

        # The same page still sets the rate and rewards, with the values its page sends.
        page.socket.send(update(rate, {"value": PANEL_HZ}))
        until(lambda: hz(api, run_id) == PANEL_HZ, "the rate set from the panel")
        until(lambda: page.shows(f"Tick rate set to {PANEL_HZ} Hz"), "the rate's notice")
        page.socket.send(update(inputs["+ reward"].id, {"value": True}))
        until(lambda: len(rewards(api, run_id)) == len(before) + 1, "the panel's reward")
        reward = rewards(api, run_id)[0]
        assert (reward["value"], reward["source"], reward["note"]) == (1.0, "trainer", REWARD_NOTE)
        until(lambda: page.shows(f"stored as #{reward['id']}"), "the reward's notice")
        assert_quiet_log(server)
        record(
            "malformed values on the 3D view's socket",
            f"{sent} GuiUpdateMessages viser's page never sends (wrong types, NaN, infinities, "
            "huge and negative numbers, options no dropdown has, other properties) to each of "
            f"the panel's {len(WRITABLE)} inputs over a live run's websocket; ids of no "
            "element; 4 messages a page does not send",
            f"{sent} refused, each with a notice on that page; rate {rate_before:g} Hz and rewards "
            f"unchanged; then a rate of {PANEL_HZ} Hz and a +1 reward from the panel taken; "
            "no traceback",
        )
    finally:
        page.close()


UNREADABLE: tuple[bytes | str, ...] = (
    b"\xc1garbage",  # no msgpack
    b"",
    msgspec.msgpack.encode([1, 2, 3]),
    msgspec.msgpack.encode({"no": "type"}),
    msgspec.msgpack.encode({"type": "NoSuchMessage"}),
    msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": "x"}),  # no updates
    msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": "x", "updates": {}, "y": 1}),
    msgspec.msgpack.encode({"type": "GuiButtonHoldMessage", "uuid": "x", "frequency": "x"}),
    msgspec.msgpack.encode({**msgspec.msgpack.decode(camera_message()), "fov": "wide"}),
    "a text frame",
)
"""Frames viser cannot read: it closes the socket that sent one."""


def test_frames_viser_cannot_read_close_that_socket_only(
    live: tuple[LiveServer, int, int],
) -> None:
    server, run_id, port = live
    api = server.client
    before = reward_ids(api, run_id)
    bystander = Page(port)
    try:
        inputs = bystander.live_panel()
        for frame in UNREADABLE:
            page = Page(port)
            try:
                page.live_panel()
                page.socket.send(frame)
                until(page.closed.is_set, f"viser to close the socket that sent {frame!r}")
            finally:
                page.close()
        assert not bystander.closed.is_set()
        assert api.get("/api/health").status_code == 200
        assert reward_ids(api, run_id) == before
        assert_quiet_log(server)
        # Another page's panel still works.
        rate = 4.0 if hz(api, run_id) != 4.0 else 5.0
        bystander.socket.send(update(inputs["Tick rate (Hz)"].id, {"value": rate}))
        until(lambda: hz(api, run_id) == rate, "the rate set from the other page")
        assert_quiet_log(server)
        record(
            "unreadable frames on the 3D view's socket",
            f"{len(UNREADABLE)} frames viser cannot read (no msgpack, empty, not a map, no or "
            "an unknown type, fields missing, extra or of the wrong type, a text frame), each "
            "from a page of its own beside another open page",
            "each sender's socket closed, the other page open and its rate change taken; "
            "rewards unchanged; one log line each, no traceback",
        )
    finally:
        bystander.close()
