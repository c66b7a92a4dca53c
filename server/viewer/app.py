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

from core.brain.catalog import Catalog
from core.ports import RunQueries
from core.sim.world import WorldConfig
from core.worlds import load_world
from server.engines import Engines
from server.guard import SitePolicy
from server.ratelimit import RateLimiter
from server.viewer import upstream
from server.viewer.control import Controller
from server.viewer.gate import Gate, Peer
from server.viewer.inbound import quiet_malformed
from server.viewer.render import Renderer
from server.viewer.scene import static_scene
from server.viewer.state import ClientsChanged, Inbox, SelectRun, SetMode
from server.viewer.wakeups import install as install_loop_safe_buffers

log = logging.getLogger("srlab.viewer")


CHOICE_TTL_S = 60.0
"""How long a run chosen for the next viewer (POST /api/runs/{id}/view), or named by a
socket that has not become a viewer yet (`/run/<id>`), waits for it."""


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
    """

    def __init__(
        self,
        server: viser.ViserServer,
        gate: Gate,
        loop: asyncio.AbstractEventLoop,
        make: Callable[[viser.ViserServer | viser.ClientHandle], Session],
    ) -> None:
        self.server = server
        self.gate = gate
        self.sessions: dict[int, Session] = {}
        """The connected viewers' sessions by viser client id."""
        self._loop = loop
        self._make = make
        self._lock = threading.Lock()
        self._choice: tuple[int, float] | None = None
        self._named: dict[Peer, tuple[int, float]] = {}
        """Runs named by the URL of a socket not yet a viewer, by the socket's address."""
        self._shared: Session | None = None
        # A view URL that names its run (/run/<id>) chooses it for the socket it opens.
        gate.on_run = self.name

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
            self._shared = self._make(self.server)
        return self._shared

    @property
    def controller(self) -> Controller:
        """The shared session's controller (tests)."""
        return self.shared.controller

    @property
    def renderer(self) -> Renderer:
        """The shared session's renderer (tests)."""
        return self.shared.renderer

    def choose(self, run_id: int) -> None:
        """Show `run_id` to the next browser that connects (within `CHOICE_TTL_S`).

        The console's "3D view" button opens a new viewer: it starts on the console's run,
        and the viewers already open keep theirs.
        """
        with self._lock:
            self._choice = (run_id, time.monotonic())

    def name(self, run_id: int, peer: Peer) -> None:
        """Show `run_id` to the viewer whose websocket viser sees come from `peer`.

        The gate calls it for a websocket on `/run/<id>`, just before viser gets the
        handshake, so a page opened on such a URL gets its run back each time it
        reconnects, after a restart of the service included. It is kept by socket, not in
        `choose`'s one slot: viser makes a socket a viewer only at its first camera
        message, and pages reconnecting together after a restart (their retry timers
        started at the same moment) would otherwise take each other's runs. A socket
        closed before it became a viewer leaves its entry, dropped after `CHOICE_TTL_S`.
        """
        now = time.monotonic()
        with self._lock:
            self._named = {p: c for p, c in self._named.items() if now - c[1] <= CHOICE_TTL_S}
            self._named[peer] = (run_id, now)

    def _named_run(self, client: viser.ClientHandle) -> int | None:
        peer = _peer(self.server, client.client_id)
        if peer is None:
            return None
        with self._lock:
            named = self._named.pop(peer, None)
        return None if named is None else named[0]

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
        self, target: viser.ViserServer | viser.ClientHandle, named: int | None = None
    ) -> Session:
        """A new watching session drawing on `target`, on the run chosen for it if any.

        `named` is the run its URL names (`/run/<id>`), which wins over `choose`'s.
        Blocking (it builds the scene): call it from a thread, not the event loop.
        """
        session = self._make(target)
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

        Only a socket the gate relays gets one (viser's server answers nobody else; this
        holds if that ever fails): a session is what carries a viewer's panel and its writes.
        """
        peer = _peer(self.server, client.client_id)
        if peer is None or not self.gate.relays(peer):
            log.warning("the 3D view refused a viewer that did not come through its gate")
            upstream.drop(self.server, client.client_id)
            return
        session = self.open(client, self._named_run(client))
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
        max_viewers: int | None = None,
    ) -> Viewer:
        """Listen on `host`:`port` and show the runs of `manager` and `store`.

        Each run is drawn in its own world preset; `world` replaces them all (tests).
        A busy port is an error here (viser itself would silently take the next one, and
        the editor's link would point at someone else's server). `policy` says which Host
        names and origins the view accepts (default: loopback names, no other origin).
        `max_viewers` bounds the viewers open at once (None: no bound).

        Raises:
            OSError: the port is taken.
            UnguardedViewerError: viser's own server could not be limited to the gate.
        """
        policy = policy or SitePolicy.of(["127.0.0.1", "localhost", "[::1]", host], [])
        loop = asyncio.get_running_loop()
        first = world or load_world().config  # until a run is shown
        scene = static_scene(first)

        def make(target: viser.ViserServer | viser.ClientHandle) -> Session:
            inbox = Inbox()
            controller = Controller(
                inbox, manager, store, catalog, limiter, writable=writable, world=world, loop=loop
            )
            renderer = Renderer(target, scene, first, controller.post, fixed=world)
            task = asyncio.run_coroutine_threadsafe(controller.run(), loop)
            renderer.start(inbox)
            return Session(inbox, controller, renderer, task)

        server = await asyncio.to_thread(_listen)
        quiet_malformed(server)
        server.scene.world_axes.visible = False  # for every client
        gate = Gate(host, port, server.get_port(), policy, max_sockets=max_viewers)
        # Wired before the gate opens: a browser reconnecting after a restart may be the
        # very first connection, and its /run/<id> must find the viewer to choose with.
        viewer = cls(server, gate, loop, make)
        server.on_client_connect(viewer.connected)
        server.on_client_disconnect(viewer.disconnected)
        try:
            # viser answers only the gate's relays, from before the gate opens.
            await asyncio.to_thread(upstream.guard, server, gate.relays, policy)
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
    """The viser server, on an ephemeral loopback port reached only through the gate.

    Its port is not printed: only the gate's is anybody's business.
    """
    install_loop_safe_buffers()
    with upstream.quiet_start():
        return viser.ViserServer(host="127.0.0.1", port=0, label="srlab", verbose=False)


def _peer(server: viser.ViserServer, client_id: int) -> Peer | None:
    """The address viser sees client `client_id`'s websocket come from, if it tells.

    viser (1.1) offers no public way to tell which connection a client is; its websocket
    server's table of live connections does. Should another viser lack it, a URL's run is
    lost (the viewer starts as on `/`) and tests/server/test_viewer_gate.py says so.
    """
    connections = getattr(getattr(server, "_websock_server", None), "_live_connections", None)
    connection = connections.get(client_id) if isinstance(connections, dict) else None
    address = getattr(connection, "remote_address", None)
    if not isinstance(address, tuple) or len(address) < 2:
        return None
    return str(address[0]), int(address[1])


def _open(gate: Gate) -> None:
    try:
        gate.start()
    except OSError as e:
        raise OSError(
            f"the 3D view's port {gate.port} on {gate.host} is taken: set SRLAB_VISER_PORT "
            f"to a free one, or SRLAB_VISER=false to run without the 3D view ({e})"
        ) from None
