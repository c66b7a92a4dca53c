"""Live event streams capped per run and in total (past a cap, 503 with Retry-After), and
open to this service's own pages, not to another site's."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest
from apphelpers import client_for, create, settings_for

from server.runtime import Runs

pytestmark = pytest.mark.anyio


async def test_event_streams_past_the_caps_are_503_with_retry_after(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, max_streams=3, max_streams_per_run=2)
    async with client_for(settings) as (client, app):
        engines = app.state.srlab.engines
        a = await create(client, condition="expert", episodes=1, seed=1)
        b = await create(client, condition="expert", episodes=1, seed=2)
        subs = [engines.subscribe(a["id"], 8, 0.0) for _ in range(2)]
        per_run = await client.get(f"/api/runs/{a['id']}/events")
        assert per_run.status_code == 503 and per_run.headers["retry-after"] == "5"
        assert "SRLAB_MAX_STREAMS_PER_RUN" in per_run.json()["detail"]
        subs.append(engines.subscribe(b["id"], 8, 0.0))
        total = await client.get(f"/api/runs/{b['id']}/events")
        assert total.status_code == 503 and "SRLAB_MAX_STREAMS" in total.json()["detail"]
        assert engines.streams() == 3  # the refused ones took nothing
        unknown = await client.get("/api/runs/99/events")
        assert unknown.status_code == 503  # the cap is checked before any database read
        engines.unsubscribe(b["id"], subs.pop())
        assert (await client.get("/api/runs/99/events")).status_code == 404
        assert engines.streams() == 2  # the 404 gave its slot back
        # A slot freed is taken again: this stream follows b from its start to its end.
        lines = await _follow(client, engines, b["id"])
        assert '"finished"' in lines[-1]
        assert engines.streams() == 2  # the stream's end gave its slot back
        for sub in subs:
            engines.unsubscribe(a["id"], sub)
        assert engines.streams() == 0


async def test_another_sites_page_gets_403_and_holds_no_stream_slot(tmp_path: Path) -> None:
    # An allowed foreign origin makes the service reachable from elsewhere: a token, then.
    settings = settings_for(
        tmp_path, max_streams_per_run=16, cors_origins=["http://lab:3000"], token="s3cret"
    )
    async with client_for(settings, {"Authorization": "Bearer s3cret"}) as (client, app):
        engines = app.state.srlab.engines
        run = await create(client, condition="expert", episodes=1, seed=1)
        events = f"/api/runs/{run['id']}/events?tick_hz=0"
        foreign = [
            {"Origin": "http://127.0.0.1:9999"},  # another loopback origin: another site
            {"Origin": "null"},
            {"Sec-Fetch-Site": "cross-site"},
        ]
        for headers in foreign * 6:  # more than the run's slots
            r = await client.get(events, headers=headers)
            assert r.status_code == 403, (headers, r.text)
            assert "another site" in r.json()["detail"]
            assert engines.streams() == 0  # it held nothing
        # The service's own pages, an allowed origin and clients that are not browsers
        # (no Origin) follow a run as before, from its start to its end (the in-process
        # transport hands a stream over only once the app has sent all of it).
        for headers in (
            {"Origin": "http://127.0.0.1", "Sec-Fetch-Site": "same-origin"},
            {"Sec-Fetch-Site": "same-origin"},
            {"Origin": "http://lab:3000"},
            {},
        ):
            run = await create(client, condition="expert", episodes=1, seed=2)
            lines = await _follow(client, engines, run["id"], headers)
            assert '"status": "created"' in lines[0], headers
            assert '"finished"' in lines[-1], headers
            assert engines.streams() == 0


async def _follow(
    client: httpx.AsyncClient,
    engines: Runs,
    run_id: int,
    headers: dict[str, str] | None = None,
) -> list[str]:
    """The data lines of a stream, sent with `headers`, that follows run `run_id` from
    before its start to its end (the run is started once the stream holds its slot)."""
    lines: list[str] = []
    before = engines.streams()

    async def follow() -> None:
        events = f"/api/runs/{run_id}/events?tick_hz=0"
        async with client.stream("GET", events, headers=headers) as r:
            assert r.status_code == 200, headers
            lines.extend([x async for x in r.aiter_lines() if x.startswith("data: ")])

    async with asyncio.timeout(60):  # a hang guard, not a timing
        follower = asyncio.create_task(follow())
        while engines.streams() == before:
            await asyncio.sleep(0.01)
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
        await follower
    return lines
