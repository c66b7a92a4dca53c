"""The 3D view's lifecycle: viser's server, the renderer thread and the controller task."""

from __future__ import annotations

import asyncio
import contextlib
import logging

import viser

from core.brain.catalog import Catalog
from core.sim.world import WorldConfig
from core.worlds import load_world
from server.engines import EngineManager
from server.guard import SitePolicy
from server.persistence import SqlAlchemyRunStore
from server.ratelimit import RateLimiter
from server.viewer.control import Controller
from server.viewer.gate import Gate
from server.viewer.render import Renderer
from server.viewer.scene import static_scene
from server.viewer.state import ClientsChanged, Inbox

log = logging.getLogger("srlab.viewer")


class Viewer:
    """viser on its own port, showing the service's runs; `start` it, then `await stop()`.

    viser serves on its own thread and event loop. Its callbacks only post commands to the
    controller, which runs on the service's event loop; the renderer thread is the only
    caller of viser's scene and panel API.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        renderer: Renderer,
        controller: Controller,
        inbox: Inbox,
        gate: Gate,
    ) -> None:
        self.server = server
        self.gate = gate
        self.renderer = renderer
        self.controller = controller
        self.inbox = inbox
        self._task: asyncio.Task[None] | None = None

    @property
    def port(self) -> int:
        """The 3D view's port (its gate's: viser itself listens on loopback behind it)."""
        return self.gate.port

    @classmethod
    async def start(
        cls,
        *,
        host: str,
        port: int,
        manager: EngineManager,
        store: SqlAlchemyRunStore,
        catalog: Catalog,
        limiter: RateLimiter,
        writable: bool,
        policy: SitePolicy | None = None,
        world: WorldConfig | None = None,
    ) -> Viewer:
        """Listen on `host`:`port` and show the runs of `manager` and `store`.

        Each run is drawn in its own world preset; `world` replaces them all (tests).
        A busy port is an error here (viser itself would silently take the next one, and
        the editor's link would point at someone else's server). `policy` says which Host
        names and origins the view accepts (default: loopback names, no other origin).
        """
        policy = policy or SitePolicy.of(["127.0.0.1", "localhost", "[::1]", host], [])
        inbox = Inbox()
        controller = Controller(
            inbox, manager, store, catalog, limiter, writable=writable, world=world
        )
        first = world or load_world().config  # until a run is shown
        server = await asyncio.to_thread(_listen)
        gate = Gate(host, port, server.get_port(), policy)
        try:
            await asyncio.to_thread(_open, gate)
            renderer = await asyncio.to_thread(
                Renderer, server, static_scene(first), first, controller.post, fixed=world
            )
        except BaseException:
            await asyncio.to_thread(gate.stop)
            await asyncio.to_thread(server.stop)
            raise
        viewer = cls(server, renderer, controller, inbox, gate)

        def clients_changed(_: viser.ClientHandle) -> None:
            controller.post(ClientsChanged(len(server.get_clients())))

        server.on_client_connect(clients_changed)
        server.on_client_disconnect(clients_changed)
        viewer._task = asyncio.create_task(controller.run(), name="viewer controller")
        renderer.start(inbox)
        log.info("the 3D view is on http://%s:%d/", host, viewer.port)
        return viewer

    async def stop(self) -> None:
        """Stop the controller, the renderer and viser's server."""
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        await asyncio.to_thread(self.renderer.stop, self.inbox)
        await asyncio.to_thread(self.gate.stop)
        await asyncio.to_thread(self.server.stop)


def _listen() -> viser.ViserServer:
    """The viser server, on an ephemeral loopback port reached only through the gate."""
    return viser.ViserServer(host="127.0.0.1", port=0, label="srlab", verbose=False)


def _open(gate: Gate) -> None:
    try:
        gate.start()
    except OSError as e:
        raise OSError(
            f"the 3D view's port {gate.port} on {gate.host} is taken: set SRLAB_VISER_PORT "
            f"to a free one, or SRLAB_VISER=false to run without the 3D view ({e})"
        ) from None
