"""Helpers for API tests: the real app on a migrated SQLite file, driven through httpx."""

from __future__ import annotations

import asyncio
import atexit
import functools
import shutil
import tempfile
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import httpx
from asgi_lifespan import LifespanManager
from fastapi import FastAPI

from server.config import Settings
from server.main import create_app
from server.persistence import upgrade
from server.persistence.storage import StorageFactory, open_storage


@functools.cache
def migrated_template() -> Path:
    """A SQLite file migrated to head and seeded, once per test process, for tests to copy.

    Migrating costs about 0.2 s of CPU; a copy, well under a millisecond.
    """
    folder = Path(tempfile.mkdtemp(prefix="srlab-template-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    path = folder / "srlab.db"
    upgrade(f"sqlite:///{path}")
    # Every connection is closed, so the file holds everything (no write-ahead log left).
    assert not path.with_name(path.name + "-wal").exists()
    return path


def migrated_copy(path: Path) -> str:
    """A fresh copy of the migrated, seeded template at `path`; its URL."""
    shutil.copyfile(migrated_template(), path)
    return f"sqlite:///{path}"


def settings_for(tmp_path: Path, **overrides: Any) -> Settings:
    """Settings on the migrated and seeded SQLite file under `tmp_path` (fresh the first time).

    A second call for the same `tmp_path` keeps what the first service stored (a restart).
    The 3D view is off unless a test asks for it (`viser=True`): it needs a port.
    """
    path = tmp_path / "api.db"
    if path.exists():
        url = f"sqlite:///{path}"
        upgrade(url)
    else:
        url = migrated_copy(path)
    overrides.setdefault("viser", False)
    return Settings(database_url=url, **overrides)


@asynccontextmanager
async def client_for(
    settings: Settings,
    headers: dict[str, str] | None = None,
    storage: StorageFactory = open_storage,
) -> AsyncIterator[tuple[httpx.AsyncClient, FastAPI]]:
    """An httpx client on the app with its lifespan running (ASGITransport skips it)."""
    app = create_app(settings, storage)
    # Hang guards, not timings: a cold start on a busy machine takes more than 5 s.
    async with LifespanManager(app, startup_timeout=60, shutdown_timeout=60) as manager:
        transport = httpx.ASGITransport(app=manager.app)
        async with httpx.AsyncClient(
            transport=transport, base_url="http://127.0.0.1", headers=headers or {}
        ) as client:
            yield client, app


async def create(client: httpx.AsyncClient, **body: Any) -> dict[str, Any]:
    """POST /api/runs with `body`, which must create the run (201); returns it."""
    r = await client.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    out: dict[str, Any] = r.json()
    return out


async def started_realtime(client: httpx.AsyncClient) -> int:
    """A 50 Hz realtime `rp` run, created and started (200); its id."""
    run_id = int((await create(client, condition="rp", mode="realtime", hz=50))["id"])
    r = await client.post(f"/api/runs/{run_id}/start")
    assert r.status_code == 200, r.text
    return run_id


async def until(
    client: httpx.AsyncClient, run_id: int, status: str, timeout: float = 30
) -> dict[str, Any]:
    """Poll a run until it has `status` (within `timeout` seconds); returns it."""
    async with asyncio.timeout(timeout):
        while True:
            run: dict[str, Any] = (await client.get(f"/api/runs/{run_id}")).json()
            if run["status"] == status:
                return run
            await asyncio.sleep(0.02)
