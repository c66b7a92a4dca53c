"""Requests that only read memory run on the event loop: no hand-off to a worker thread.

FastAPI runs a plain-function dependency or handler on a worker thread (and validates a
plain handler's answer on one too): a hand-off there and back that cost a cheap request
about half its CPU (docs/benchmarks.md). The routes' dependencies and the handlers that
read only memory are coroutines; this counts the hand-offs of real requests on the app.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio.to_thread
import pytest
from apphelpers import client_for, settings_for

pytestmark = pytest.mark.anyio


@pytest.fixture
def handoffs(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The names of the functions run on worker threads (starlette's threadpool)."""
    calls: list[str] = []
    real = anyio.to_thread.run_sync

    async def counted(func: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        calls.append(getattr(func, "__qualname__", repr(func)))
        return await real(func, *args, **kwargs)

    monkeypatch.setattr(anyio.to_thread, "run_sync", counted)
    return calls


async def test_reads_of_memory_hand_nothing_to_a_thread(
    tmp_path: Path, handoffs: list[str]
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        body = {"condition": "kp", "mode": "realtime", "hz": 5}
        run = (await client.post("/api/runs", json=body)).json()["id"]
        assert (await client.post(f"/api/runs/{run}/start")).status_code == 200
        handoffs.clear()
        for path in ("/api/stimuli", "/api/behaviours", "/api/sensors", "/api/conditions"):
            assert (await client.get(path)).status_code == 200, path
        assert handoffs == []
        # A running run is read from its engine.
        r = await client.get(f"/api/runs/{run}")
        assert r.status_code == 200 and r.json()["live"] is not None
        assert handoffs == []
        assert (await client.post(f"/api/runs/{run}/stop")).status_code == 200


async def test_a_write_hands_only_its_storage_call_to_a_thread(
    tmp_path: Path, handoffs: list[str]
) -> None:
    # The write guard and the network service are coroutines: what is left on a thread
    # is the blocking call into storage.
    async with client_for(settings_for(tmp_path)) as (client, _):
        assert (await client.post("/api/networks", json={"name": "mine"})).status_code == 201
        handoffs.clear()
        r = await client.put(
            "/api/networks/mine/associations/Corner/leftturn90", json={"strength": 0.5}
        )
        assert r.status_code == 200, r.text
    assert len(handoffs) == 1, handoffs
