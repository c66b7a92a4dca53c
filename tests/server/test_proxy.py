"""Behind a reverse proxy: who a trainer is comes from X-Forwarded-For, if the proxy is trusted.

A live `srlab serve` on loopback; the test plays the proxy, whose address is 127.0.0.1.
Trusting a proxy means clients from elsewhere reach the service, so it needs the token.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from liveharness import wait_status

from bench.liveserver import ROOT, free_port, live_server

LIMIT = {"SRLAB_REWARD_RATE_PER_S": "0.05", "SRLAB_REWARD_BURST": "2"}
TOKEN = "proxy-test-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
OUTSIDE = "203.0.113.7"
"""A client on the internet, as the proxy names it."""


def realtime_run(api: httpx.Client, headers: dict[str, str] | None = None) -> int:
    run = api.post(
        "/api/runs",
        json={"condition": "delayed", "mode": "realtime", "hz": 20},
        headers=headers,
    )
    assert run.status_code == 201, run.text
    run_id: int = run.json()["id"]
    api.post(f"/api/runs/{run_id}/start", headers=headers).raise_for_status()
    wait_status(api, run_id, "running")
    return run_id


def reward(api: httpx.Client, run_id: int, client: str, token: bool = True) -> httpx.Response:
    return api.post(
        f"/api/runs/{run_id}/rewards",
        json={"value": 1.0},
        headers={"X-Forwarded-For": client, **(AUTH if token else {})},
    )


PROXIED = {"SRLAB_FORWARDED_ALLOW_IPS": "127.0.0.1", "SRLAB_ALLOWED_HOSTS": "srlab.example"}
"""A proxy on this machine that serves the service to the internet as srlab.example."""


@pytest.fixture
def behind_proxy(tmp_path: Path) -> Iterator[httpx.Client]:
    env = {**LIMIT, **PROXIED, "SRLAB_TOKEN": TOKEN}
    with live_server(tmp_path / "srlab.db", env=env) as server:
        yield server.client


def test_behind_a_proxy_the_service_needs_the_token_and_every_write_then_does(
    tmp_path: Path,
) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SRLAB_")}
    env |= {**PROXIED, "SRLAB_DATABASE_URL": f"sqlite:///{tmp_path / 'srlab.db'}"}
    port = str(free_port())
    serve = [sys.executable, "-m", "server.cli", "serve", "--port", port]
    child = subprocess.Popen(serve, cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True)
    try:
        _, err = child.communicate(timeout=120)  # a hang guard: it must refuse at once
    except subprocess.TimeoutExpired:
        child.terminate()
        child.communicate(timeout=60)
        pytest.fail("srlab serve started behind a proxy without SRLAB_TOKEN")
    assert child.returncode == 2
    [line] = err.splitlines()
    assert line.startswith("srlab: error: srlab is reachable from beyond this machine (")
    for variable in ("SRLAB_FORWARDED_ALLOW_IPS", "SRLAB_ALLOWED_HOSTS", "set SRLAB_TOKEN"):
        assert variable in line

    # Given the token, it serves; a client from the internet, as the proxy forwards it,
    # writes nothing without the token and everything with it.
    outside = {"X-Forwarded-For": OUTSIDE, "Host": "srlab.example"}
    with live_server(tmp_path / "srlab.db", env={**PROXIED, "SRLAB_TOKEN": TOKEN}) as server:
        api = server.client
        created = api.post("/api/runs", json={"condition": "delayed"}, headers=outside)
        assert created.status_code == 401, created.text
        assert "SRLAB_TOKEN" in created.json()["detail"]
        run_id = realtime_run(api, {**outside, **AUTH})
        for path in ("pause", "resume", "stop"):
            refused = api.post(f"/api/runs/{run_id}/{path}", headers=outside)
            assert refused.status_code == 401, (path, refused.text)
        assert reward(api, run_id, OUTSIDE, token=False).status_code == 401
        assert api.get(f"/api/runs/{run_id}").json()["status"] == "running"
        assert api.get(f"/api/runs/{run_id}/rewards").json()["count"] == 0
        assert reward(api, run_id, OUTSIDE).status_code == 202
        stopped = api.post(f"/api/runs/{run_id}/stop", headers={**outside, **AUTH})
        assert stopped.status_code == 200, stopped.text
        assert stopped.json()["status"] == "stopped"
        assert api.get(f"/api/runs/{run_id}/rewards").json()["count"] == 1


def test_each_trainer_behind_a_trusted_proxy_has_a_rate_limit_of_their_own(
    behind_proxy: httpx.Client,
) -> None:
    # Every trainer holds the same SRLAB_TOKEN: the address the proxy names tells them apart.
    run_id = realtime_run(behind_proxy, AUTH)
    codes = [reward(behind_proxy, run_id, OUTSIDE).status_code for _ in range(3)]
    assert codes == [202, 202, 429]
    refused = reward(behind_proxy, run_id, OUTSIDE)
    assert OUTSIDE in refused.json()["detail"]
    assert reward(behind_proxy, run_id, "203.0.113.8").status_code == 202
    behind_proxy.post(f"/api/runs/{run_id}/stop", headers=AUTH).raise_for_status()
    log = behind_proxy.get(f"/api/runs/{run_id}/rewards").json()["data"]
    assert len([r for r in log if r["source"] == "trainer"]) == 3  # the refused ones are not


def test_without_a_trusted_proxy_the_header_cannot_buy_a_new_limit(tmp_path: Path) -> None:
    with live_server(tmp_path / "srlab.db", env=LIMIT) as server:
        api = server.client
        run_id = realtime_run(api)
        codes = [reward(api, run_id, f"203.0.113.{n}", token=False).status_code for n in range(3)]
        assert codes == [202, 202, 429]
        refused = reward(api, run_id, "198.51.100.1", token=False)
        assert refused.status_code == 429
        assert "127.0.0.1" in refused.json()["detail"]
        api.post(f"/api/runs/{run_id}/stop").raise_for_status()
