"""`srlab serve`'s start: what a first request would do on the runs' event loop is done first.

The server is uvicorn's, as `srlab serve` runs it (`server.serve._Server`), on loopback.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import os
import socket
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn
from fastapi import FastAPI

from bench.liveserver import ROOT, free_port
from server.config import Settings
from server.main import create_app
from server.persistence import upgrade
from server.serve import _Server

pytestmark = pytest.mark.anyio


@pytest.fixture
def unfrozen() -> Iterator[None]:
    """The test process's heap as it was: what the server froze goes back to the collector."""
    yield
    gc.unfreeze()


async def test_the_server_builds_the_api_document_before_the_lifespan_which_freezes_the_heap(
    tmp_path: Path, unfrozen: None
) -> None:
    url = f"sqlite:///{tmp_path / 'serve.db'}"
    upgrade(url)
    app = create_app(Settings(database_url=url, viser=False))
    document_built_at_lifespan: list[bool] = []
    lifespan = app.router.lifespan_context

    @contextlib.asynccontextmanager
    async def watched(a: FastAPI) -> AsyncIterator[Any]:
        document_built_at_lifespan.append(app.openapi_schema is not None)
        async with lifespan(a) as state:
            yield state

    app.router.lifespan_context = watched
    assert app.openapi_schema is None
    frozen_before = gc.get_freeze_count()
    server = _Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"), app)
    serving = asyncio.create_task(server.serve())
    try:
        while not server.started:
            assert not serving.done(), "the server stopped before it started"
            await asyncio.sleep(0.01)
        # Built before the lifespan started any run: its first GET is served from memory.
        assert document_built_at_lifespan == [True]
        # What the start built is out of every later collection (the lifespan's warm-up).
        assert gc.get_freeze_count() > frozen_before
        port = server.servers[0].sockets[0].getsockname()[1]
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}") as client:
            served = await client.get("/openapi.json")
        assert served.status_code == 200
        assert served.json() == app.openapi()
    finally:
        server.should_exit = True
        await serving


@pytest.mark.slow
@pytest.mark.parametrize("taken", ["SRLAB_PORT", "SRLAB_VISER_PORT"])
def test_a_taken_port_is_one_line_naming_its_setting(tmp_path: Path, taken: str) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SRLAB_")}
    env |= {
        "SRLAB_DATABASE_URL": f"sqlite:///{tmp_path / 'srlab.db'}",
        "SRLAB_PORT": str(free_port()),
        "SRLAB_VISER_PORT": str(free_port()),
    }
    with socket.socket() as other:  # another program on the port
        other.bind(("127.0.0.1", int(env[taken])))
        other.listen()
        done = subprocess.run(
            [sys.executable, "-m", "server.cli", "serve"],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=240,  # a hang guard
        )
    assert done.returncode != 0
    assert "Traceback" not in done.stderr
    [line] = done.stderr.splitlines()
    assert line.startswith("srlab: error: ")
    assert f"port {env[taken]} on 127.0.0.1 is taken" in line
    assert f"set {taken}" in line
