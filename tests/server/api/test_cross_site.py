"""The cross-site guard on the real app and on the 3D view's gate; the reward limiter's keys.

The attack as it was found (a page of another loopback origin in Chromium) is
tests/web/test_cross_site.py; these check each rule of the guard at its edge.
"""

from __future__ import annotations

import asyncio
import base64
import os
from pathlib import Path

import pytest
import viser
from apphelpers import client_for, create, settings_for, until
from reliability_report import record

from bench.liveserver import free_port
from server.api.guard import SitePolicy, host_name
from server.api.ratelimit import RateLimiter, client_key

pytestmark = pytest.mark.anyio
FOREIGN = "http://127.0.0.1:9999"


async def test_a_cross_site_write_is_refused_and_changes_nothing(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="delayed", mode="realtime", hz=20)
        run_id = run["id"]
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
        for headers in (
            {"Origin": FOREIGN},
            {"Origin": "http://localhost"},  # same host name, another origin
            {"Origin": "null"},  # a sandboxed frame, a file: page
            {"Sec-Fetch-Site": "cross-site"},
        ):
            for path in ("stop", "pause", "rewards"):
                r = await client.post(f"/api/runs/{run_id}/{path}", headers=headers)
                assert r.status_code == 403, (headers, path, r.text)
                assert "may not change anything" in r.json()["detail"]
            created = await client.post("/api/runs", json={"condition": "delayed"}, headers=headers)
            assert created.status_code == 403
        assert (await client.get(f"/api/runs/{run_id}")).json()["status"] == "running"
        assert (await client.get("/api/runs")).json()["count"] == 1
        assert (await client.get(f"/api/runs/{run_id}/rewards")).json()["count"] == 0
        # Reads stay open to any page (CORS decides what it may see), and the service's own
        # pages and clients that send no Origin (curl, scripts) write as before.
        assert (await client.get("/api/runs", headers={"Origin": FOREIGN})).status_code == 200
        own = {"Origin": "http://127.0.0.1", "Sec-Fetch-Site": "same-origin"}
        r = await client.post(f"/api/runs/{run_id}/stop", headers=own)
        assert r.status_code == 200, r.text
        await until(client, run_id, "stopped")


async def test_an_origin_in_srlab_cors_origins_may_write(tmp_path: Path) -> None:
    # An origin on another host makes the token required (`Settings.reachable_through`).
    settings = settings_for(tmp_path, cors_origins=["http://lab.example:3000"], token="s3cret")
    async with client_for(settings) as (client, _):
        r = await client.post(
            "/api/runs",
            json={"condition": "delayed"},
            headers={"Origin": "http://lab.example:3000", "Authorization": "Bearer s3cret"},
        )
        assert r.status_code == 201, r.text


async def test_the_token_does_not_replace_the_origin_check(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, token="s3cret")
    auth = {"Authorization": "Bearer s3cret"}
    async with client_for(settings, headers=auth) as (client, _):
        refused = await client.post(
            "/api/runs", json={"condition": "delayed"}, headers={"Origin": FOREIGN}
        )
        assert refused.status_code == 403
        assert (await client.post("/api/runs", json={"condition": "delayed"})).status_code == 201


def test_host_names_and_origins_are_compared_without_case_or_default_ports() -> None:
    assert host_name("LocalHost:8000") == "localhost"
    assert host_name("[::1]:8080") == "[::1]"
    policy = SitePolicy.of(["127.0.0.1", "[::1]"], ["HTTP://Lab.Example"])
    assert policy.host_problem("127.0.0.1:8000") is None
    assert policy.host_problem("[::1]:8000") is None
    assert "evil.example" in (policy.host_problem("evil.example:8080") or "")
    assert policy.host_problem(None) is not None
    same = {"host": "127.0.0.1:8000", "origin": "http://127.0.0.1:8000"}
    assert policy.origin_problem(same, "http") is None
    assert policy.origin_problem({"host": "x", "origin": "http://lab.example:80"}, "http") is None
    other_port = {"host": "127.0.0.1:8000", "origin": "http://127.0.0.1:8001"}
    assert policy.origin_problem(other_port, "http") is not None


async def _handshake(port: int, host: str, origin: str | None) -> bytes:
    """The first line of the answer to a websocket handshake on the 3D view's port."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        "GET / HTTP/1.1",
        f"Host: {host}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
        f"Sec-WebSocket-Protocol: viser-v{viser.__version__}",
    ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    writer.write(("\r\n".join(lines) + "\r\n\r\n").encode())
    await writer.drain()
    status = await reader.readline()
    writer.close()
    return status


async def _get(port: int, host: str) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(f"GET / HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())
    await writer.drain()
    status = await reader.readline()
    writer.close()
    return status


async def test_the_3d_views_socket_refuses_other_sites_and_foreign_host_names(
    tmp_path: Path,
) -> None:
    port = free_port()
    settings = settings_for(tmp_path, viser=True, viser_port=port)
    async with client_for(settings) as (_, app):
        own = f"127.0.0.1:{port}"
        # DNS rebinding: evil.example resolving to 127.0.0.1 is refused, page and socket.
        assert b" 400 " in await _get(port, f"evil.example:{port}")
        assert b" 400 " in await _handshake(
            port, f"evil.example:{port}", f"http://evil.example:{port}"
        )
        # Another origin on this very machine is another site.
        assert b" 403 " in await _handshake(port, own, "http://127.0.0.1:9999")
        assert b" 403 " in await _handshake(port, own, "null")
        refused = app.state.srlab.viewer.gate.refused
        record(
            "the 3D view's gate",
            "Host: evil.example on its page and socket (DNS rebinding); websocket handshakes "
            "from http://127.0.0.1:9999 and Origin: null",
            f"{refused} of 4 refused (400, 400, 403, 403); its own page and the editor's "
            "origin still open it (101)",
        )
        assert refused == 4
        # The view's own page, and the editor that links to it, may open it.
        assert b" 200 " in await _get(port, own)
        assert b" 101 " in await _handshake(port, own, f"http://{own}")
        editor = f"http://127.0.0.1:{settings.port}"
        assert b" 101 " in await _handshake(port, f"localhost:{port}", editor)


def test_rewards_are_limited_per_trainer_not_per_address() -> None:
    assert client_key("127.0.0.1") == client_key("127.0.0.42") == client_key("::1")
    assert client_key("::ffff:203.0.113.7") == client_key("203.0.113.7") == "203.0.113.7"
    a, b = client_key("2001:db8:1:2::1"), client_key("2001:db8:1:2:ffff::9")
    assert a == b == "2001:db8:1:2::/64"
    assert client_key("2001:db8:1:3::1") != a
    assert client_key("203.0.113.7", token="t") == client_key("198.51.100.1", token="t")


def test_each_run_has_a_bucket_of_its_own_beside_each_trainers() -> None:
    now = [0.0]
    limiter = RateLimiter(1.0, 2, clock=lambda: now[0], run_rate=1.0, run_burst=3)
    # Three trainers, two rewards each allowed by their own buckets: the run takes three.
    answers = [limiter.allow(trainer, run=1) for trainer in ("a", "b", "c") for _ in range(2)]
    assert [w == 0 for w in answers] == [True, True, True, False, False, False]
    assert limiter.limited_by_run(1)
    assert limiter.allow("c", run=2) == 0  # another run: its own bucket
    now[0] = 1.0
    assert limiter.allow("c", run=1) == 0  # refused rewards took nothing from "c"
