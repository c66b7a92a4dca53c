"""The 3D view's gate in the service: a run's URL across restarts, the viewer cap, viser's own port.

viser's own port answers the gate's relays alone, and a socket that got past that still
gets no session; a page's socket on `/run/<id>` shows that run again after a restart.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest
import viser
from apphelpers import client_for, settings_for
from gatehelpers import (
    WAIT_S,
    becomes_viewer,
    page_socket,
    shows,
    start_run,
    until,
    viewer_of,
    watching,
)
from viserpage import camera_message
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.typing import Origin, Subprotocol

from bench.liveserver import free_port
from server.viewer import upstream
from server.viewer.upstream import Checked, UnguardedViewError, websocket_servers

pytestmark = pytest.mark.anyio


@pytest.mark.slow
async def test_a_socket_on_a_runs_url_shows_that_run_again_after_a_restart(
    tmp_path: Path,
) -> None:
    port = free_port()
    settings = settings_for(tmp_path, viser=True, viser_port=port)
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        chosen = await start_run(client, condition="kp", mode="realtime", hz=20, seed=1)
        newest = await start_run(client, condition="delayed", mode="realtime", hz=20)
        # On /, a viewer follows the newest running run.
        async with watching(viewer, "/") as session:
            await until(lambda: shows(session, newest), f"run {newest}, the newest")
        # On /run/<chosen>, and again on the next socket (a reconnect), the chosen run, live.
        for _ in range(2):
            async with watching(viewer, f"/run/{chosen}/") as session:
                await until(lambda: shows(session, chosen), f"run {chosen}, the URL's")
                assert session.controller.state.mode == "live"
                # The view looks for runs every second: it stays put (a bound, not a speed).
                await asyncio.sleep(2.5)
                assert shows(session, chosen)
        later = await start_run(client, start=False, condition="delayed")  # the newest stored
    # A restart: the page's socket reconnects on its own URL, to a new service where
    # another run is live and newer; it is given its run back, not the newest.
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        assert (await client.post(f"/api/runs/{later}/start")).status_code == 200
        async with watching(viewer, f"/run/{chosen}") as session:
            await until(lambda: shows(session, chosen), f"run {chosen} after the restart")
            await asyncio.sleep(2.5)
            assert shows(session, chosen)
            live = session.controller.state.live
            assert live is not None and live.status == "interrupted"
        await client.post(f"/api/runs/{later}/stop")


async def test_pages_reconnecting_together_each_get_their_own_run(tmp_path: Path) -> None:
    port = free_port()
    settings = settings_for(tmp_path, viser=True, viser_port=port)
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        one, two, newest = [
            await start_run(client, start=False, condition="delayed") for _ in range(3)
        ]
        # Both sockets are open before either becomes a viewer (viser waits for a page's
        # first camera message), as when pages reconnect at the same moment after a
        # restart; the second to connect becomes a viewer first.
        async with (
            page_socket(viewer, f"/run/{one}") as first,
            page_socket(viewer, f"/run/{two}") as second,
            page_socket(viewer, "/") as plain,
        ):
            two_session = await becomes_viewer(viewer, second)
            one_session = await becomes_viewer(viewer, first)
            plain_session = await becomes_viewer(viewer, plain)
            await until(lambda: shows(two_session, two), f"run {two} on its page")
            await until(lambda: shows(one_session, one), f"run {one} on its page")
            # A page on / takes no page's run: it shows the newest run.
            await until(lambda: shows(plain_session, newest), f"run {newest} on /")
        await until(lambda: not viewer.sessions, "the sessions to end")
        # The console's way still works: POST /view, then a page on /.
        assert (await client.post(f"/api/runs/{one}/view")).status_code == 200
        async with watching(viewer, "/") as session:
            await until(lambda: shows(session, one), f"run {one}, chosen by POST /view")
        # The console posts and opens /run/<id>: that choice is used up by this page.
        assert (await client.post(f"/api/runs/{two}/view")).status_code == 200
        async with watching(viewer, f"/run/{two}") as session:
            await until(lambda: shows(session, two), f"run {two}, chosen and named")
        async with watching(viewer, "/") as session:
            await until(lambda: shows(session, newest), f"run {newest}: nothing left chosen")


async def test_past_max_viewers_a_new_socket_is_refused_before_viser_builds_anything(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port(), viser_max_viewers=1)
    async with client_for(settings) as (_, app):
        viewer = viewer_of(app)
        async with watching(viewer, "/") as first:
            with pytest.raises(InvalidStatus) as refused:
                async with page_socket(viewer, "/"):
                    pass
            assert refused.value.response.status_code == 503
            assert list(viewer.sessions.values()) == [first]
        await until(lambda: viewer.gate.viewers == 0, "the first viewer to leave")
        async with watching(viewer, "/"):
            assert viewer.gate.turned_away == 1


# --- viser's own port: only the gate's relays --------------------------------------------


async def raw_status(port: int, *lines: str) -> bytes:
    """The status line a GET / with these header lines gets on `port`."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(("\r\n".join(["GET / HTTP/1.1", *lines]) + "\r\n\r\n").encode())
        await writer.drain()
        async with asyncio.timeout(WAIT_S):
            return await reader.readline()
    finally:
        writer.close()


async def test_visers_own_port_refuses_what_did_not_come_through_the_gate(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        run_id = await start_run(client, condition="delayed", mode="realtime", hz=20)
        (server,) = await asyncio.to_thread(websocket_servers, viewer.server)
        assert isinstance(server.process_request, Checked)
        # viser's own page and socket, asked for with viser's own Host and Origin (as a
        # page that found the port by scanning would): 403, and no viewer.
        own = f"127.0.0.1:{viewer.gate.upstream_port}"
        assert b" 403 " in await raw_status(viewer.gate.upstream_port, f"Host: {own}")
        protocol = Subprotocol(f"viser-v{viser.__version__}")
        with pytest.raises(InvalidStatus) as refused:
            await connect(f"ws://{own}/", subprotocols=[protocol], origin=Origin(f"http://{own}"))
        assert refused.value.response.status_code == 403
        assert "gate" in json.loads(refused.value.response.body)["detail"]
        # Through the gate, the same socket is a viewer, on the run its URL names.
        async with watching(viewer, f"/run/{run_id}") as session:
            await until(lambda: shows(session, run_id), f"run {run_id}")
        assert server.process_request.refused == 2


async def test_a_socket_that_got_past_visers_check_gets_no_session(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (_, app):
        viewer = viewer_of(app)
        (server,) = await asyncio.to_thread(websocket_servers, viewer.server)
        check = server.process_request
        assert isinstance(check, Checked)
        server.process_request = check.original  # as if viser's own check had let it by
        try:
            url = f"ws://127.0.0.1:{viewer.gate.upstream_port}/"
            protocol = Subprotocol(f"viser-v{viser.__version__}")
            async with connect(url, subprotocols=[protocol]) as socket:
                await socket.send(camera_message())  # what makes viser call it a viewer
                async with asyncio.timeout(WAIT_S):
                    with pytest.raises(ConnectionClosed) as closed:
                        while True:
                            await socket.recv()
            assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
            assert not viewer.sessions  # so no panel, and nothing to write with
        finally:
            server.process_request = check


async def test_a_viser_whose_server_cannot_be_guarded_is_not_served(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    class Elsewhere:
        """What srlab looks for, where another viser keeps nothing of the kind."""

    monkeypatch.setattr(upstream, "Server", Elsewhere)
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    with pytest.raises(UnguardedViewError, match="SRLAB_VISER=false"):
        async with client_for(settings):
            pass
