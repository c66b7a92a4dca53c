"""The 3D view's lifecycle: viser's server, and per viewer a renderer thread and controller."""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import viser
from websockets.asyncio.server import ServerConnection
from websockets.frames import CloseCode

from core.brain.catalog import Catalog
from core.ports import RunQueries
from core.sim.world import WorldConfig
from core.sim.worlds import load_world
from server.api.guard import SitePolicy
from server.api.ratelimit import RateLimiter
from server.runtime import Runs as Engines
from server.viewer.control import Controller
from server.viewer.gate import MAX_VIEWERS, TICKET, Gate, Peer
from server.viewer.inbound import quiet_malformed
from server.viewer.passes import Pass, Passes
from server.viewer.render import Renderer
from server.viewer.scene import static_scene
from server.viewer.state import ClientsChanged, Inbox, SelectRun, SetMode
from server.viewer.upstream import guard, quietly
from server.viewer.wakeups import install as install_loop_safe_buffers

log = logging.getLogger("srlab.viewer")


CHOICE_TTL_S = 60.0
"""How long a run chosen for the next viewer (POST /api/runs/{id}/view) waits for it."""


@dataclass
class Session:
    """One viewer's own view: its state, its controller task and its renderer thread."""

    inbox: Inbox
    controller: Controller
    renderer: Renderer
    task: concurrent.futures.Future[None]


class Viewer:
    """viser on its own port, showing the service's runs; `start` it, then `await stop()`.

    Each browser that connects gets a `Session` of its own: its own scene and panel (viser's
    client-scoped API), its own run, live or replay, and tick, so two trainers never steer
    each other. viser serves on its own thread and event loop. Its callbacks only post
    commands to a session's controller, which runs on the service's event loop; a
    session's renderer thread is the only caller of that client's scene and panel API.
    Only a socket that came through the gate gets a session (its panel, its writes).
    """

    def __init__(
        self,
        server: viser.ViserServer,
        gate: Gate,
        loop: asyncio.AbstractEventLoop,
        make: Callable[[viser.ViserServer | viser.ClientHandle, Pass | None], Session],
    ) -> None:
        self.server = server
        self.gate = gate
        self.sessions: dict[int, Session] = {}
        """The connected viewers' sessions by viser client id."""
        self._loop = loop
        self._make = make
        self._lock = threading.Lock()
        self._choice: tuple[int, float] | None = None
        self._shared: Session | None = None

    @property
    def port(self) -> int:
        """The 3D view's port (its gate's: viser itself listens on loopback behind it)."""
        return self.gate.port

    @property
    def shared(self) -> Session:
        """A session on the server's own scene and panel, driven by no browser (tests).

        Every browser sees what it draws beneath its own session's: it is made only when
        asked for, never by the service.
        """
        if self._shared is None:
            self._shared = self._make(self.server, None)
        return self._shared

    @property
    def controller(self) -> Controller:
        """The shared session's controller (tests)."""
        return self.shared.controller

    @property
    def renderer(self) -> Renderer:
        """The shared session's renderer (tests)."""
        return self.shared.renderer

    @property
    def passes(self) -> Passes:
        """The view's tickets and cookies (its gate's)."""
        return self.gate.passes

    def ticket_path(self, run_id: int, *, organiser: bool) -> str:
        """The view's path on `run_id` with a one-time ticket (`server/viewer/passes.py`).

        The organiser's opens every run, its panel writable; a participant's that run
        alone, read-only.
        """
        ticket = self.passes.issue(Pass(None if organiser else run_id, organiser))
        return f"/run/{run_id}?{TICKET}={ticket}"

    def choose(self, run_id: int) -> None:
        """Show `run_id` to the next browser that connects (within `CHOICE_TTL_S`).

        The console's "3D view" button opens a new viewer: it starts on the console's run,
        and the viewers already open keep theirs.
        """
        with self._lock:
            self._choice = (run_id, time.monotonic())

    def _take_choice(self, named: int | None = None) -> int | None:
        """The run a new viewer starts on: the one its URL `named`, else the chosen one.

        A choice of the run the URL names is used up too: the console's link posts the
        choice and opens `/run/<id>`, and the next viewer on `/` must not inherit it.
        """
        with self._lock:
            choice = self._choice
            if named is None or (choice is not None and choice[0] == named):
                self._choice = None
        if named is not None:
            return named
        if choice is None or time.monotonic() - choice[1] > CHOICE_TTL_S:
            return None
        return choice[0]

    def open(
        self,
        target: viser.ViserServer | viser.ClientHandle,
        named: int | None = None,
        granted: Pass | None = None,
    ) -> Session:
        """A new watching session drawing on `target`, on the run chosen for it if any.

        `named` is the run its URL names (`/run/<id>`), which wins over `choose`'s; a
        `granted` view cookie for one run shows that run alone.
        Blocking (it builds the scene): call it from a thread, not the event loop.
        """
        session = self._make(target, granted)
        if granted is not None and granted.run is not None:
            run_id: int | None = granted.run  # the console's choice is not for it
        else:
            run_id = self._take_choice(named)
        if run_id is not None:
            session.controller.post(SetMode("live"))
            session.controller.post(SelectRun(run_id))
        session.controller.post(ClientsChanged(1))
        return session

    @staticmethod
    def close(session: Session) -> None:
        """End a session (blocking: its renderer thread is joined)."""
        session.task.cancel()
        session.renderer.stop(session.inbox)

    def connected(self, client: viser.ClientHandle) -> None:
        """A browser connected (viser's thread pool): build and start its session.

        Only for a socket viser sees come from one of the gate's relays (viser's server
        refuses any other already: this holds should that check ever let one by). Another
        gets no session, so no panel to write with, and is closed. The relay tells the run
        its URL names (`/run/<id>`): kept by socket, not in `choose`'s one slot, since
        pages reconnecting together after a restart (their retry timers started at the
        same moment) would otherwise take each other's runs.
        """
        peer = _peer(self.server, client.client_id)
        relay = None if peer is None else self.gate.relay(peer)
        if relay is None or not relay.socket:
            log.warning(
                "the 3D view gave viewer %d no session: its socket is none of the gate's "
                "(closed already, or not through the gate)",
                client.client_id,
            )
            _drop(self.server, client.client_id)
            return
        session = self.open(client, relay.run, relay.granted)
        with self._lock:
            self.sessions[client.client_id] = session

    def disconnected(self, client: viser.ClientHandle) -> None:
        """A browser left (viser's thread pool): end its session."""
        with self._lock:
            session = self.sessions.pop(client.client_id, None)
        if session is not None:
            self.close(session)

    @classmethod
    async def start(
        cls,
        *,
        host: str,
        port: int,
        manager: Engines,
        store: RunQueries,
        catalog: Catalog,
        limiter: RateLimiter,
        writable: bool,
        policy: SitePolicy | None = None,
        world: WorldConfig | None = None,
        max_viewers: int = MAX_VIEWERS,
        require_pass: bool = False,
    ) -> Viewer:
        """Listen on `host`:`port` and show the runs of `manager` and `store`.

        Each run is drawn in its own world preset; `world` replaces them all (tests).
        A busy port is an error here (viser itself would silently take the next one, and
        the editor's link would point at someone else's server). `policy` says which Host
        names and origins the view accepts (default: loopback names, no other origin);
        `max_viewers` how many may watch at once; `require_pass`, that a viewer needs a
        ticket's cookie (the service keeps reads to tokens).

        Raises:
            OSError: the port is taken.
            UnguardedViewError: viser's own port cannot be kept to the gate.
        """
        policy = policy or SitePolicy.of(["127.0.0.1", "localhost", "[::1]", host], [])
        loop = asyncio.get_running_loop()
        first = world or load_world().config  # until a run is shown
        scene = static_scene(first)

        def make(target: viser.ViserServer | viser.ClientHandle, granted: Pass | None) -> Session:
            inbox = Inbox()
            controller = Controller(
                inbox,
                manager,
                store,
                catalog,
                limiter,
                writable=writable if granted is None else granted.organiser,
                world=world,
                loop=loop,
                only=None if granted is None else granted.run,
            )
            renderer = Renderer(target, scene, first, controller.post, fixed=world)
            task = asyncio.run_coroutine_threadsafe(controller.run(), loop)
            renderer.start(inbox)
            return Session(inbox, controller, renderer, task)

        server = await asyncio.to_thread(_listen)
        try:
            quiet_malformed(server)
            server.scene.world_axes.visible = False  # for every client
            gate = Gate(
                host,
                port,
                server.get_port(),
                policy,
                max_viewers=max_viewers,
                require_pass=require_pass,
            )
            # Before the gate opens: from then on viser answers the gate's relays alone.
            await guard(server, gate.relay, policy)
            # Wired before the gate opens: a browser reconnecting after a restart may be
            # the very first connection, and its /run/<id> must find its viewer.
            viewer = cls(server, gate, loop, make)
            server.on_client_connect(viewer.connected)
            server.on_client_disconnect(viewer.disconnected)
            await asyncio.to_thread(_open, gate)
        except BaseException:
            await asyncio.to_thread(server.stop)
            raise
        log.info("the 3D view is on http://%s:%d/", host, viewer.port)
        return viewer

    async def stop(self) -> None:
        """Stop every session, then viser's server and the gate."""
        with self._lock:
            sessions = list(self.sessions.values())
            self.sessions.clear()
        if self._shared is not None:
            sessions.append(self._shared)
            self._shared = None
        for session in sessions:
            session.task.cancel()
        for session in sessions:
            with contextlib.suppress(asyncio.CancelledError, concurrent.futures.CancelledError):
                await asyncio.wrap_future(session.task)
            await asyncio.to_thread(session.renderer.stop, session.inbox)
        await asyncio.to_thread(self.gate.stop)
        await asyncio.to_thread(self.server.stop)


def _listen() -> viser.ViserServer:
    """The viser server, on an ephemeral loopback port reached only through the gate."""
    install_loop_safe_buffers()
    with quietly():  # its port is printed nowhere: the gate alone is to reach it
        return viser.ViserServer(host="127.0.0.1", port=0, label="srlab", verbose=False)


def _connection(server: viser.ViserServer, client_id: int) -> ServerConnection | None:
    """Client `client_id`'s websocket, if viser tells.

    viser (1.1) offers no public way to tell which connection a client is; its websocket
    server's table of live connections does. Should another viser lack it, no socket gets
    a session, and every test of a real viewer (tests/server/test_viewer_*.py) fails.
    """
    connections = getattr(getattr(server, "_websock_server", None), "_live_connections", None)
    connection = connections.get(client_id) if isinstance(connections, dict) else None
    return connection if isinstance(connection, ServerConnection) else None


def _peer(server: viser.ViserServer, client_id: int) -> Peer | None:
    """The address viser sees client `client_id`'s websocket come from, if it tells."""
    address = getattr(_connection(server, client_id), "remote_address", None)
    if not isinstance(address, tuple) or len(address) < 2:
        return None
    return str(address[0]), int(address[1])


def _drop(server: viser.ViserServer, client_id: int) -> None:
    """Close client `client_id`'s websocket (policy violation), if it is still open."""
    connection = _connection(server, client_id)
    if connection is not None:
        asyncio.run_coroutine_threadsafe(
            connection.close(CloseCode.POLICY_VIOLATION, "not through the 3D view's gate"),
            server.get_event_loop(),
        )


def _open(gate: Gate) -> None:
    try:
        gate.start()
    except OSError as e:
        raise OSError(
            f"the 3D view's port {gate.port} on {gate.host} is taken: set SRLAB_VISER_PORT "
            f"to a free one, or SRLAB_VISER=false to run without the 3D view ({e})"
        ) from None
