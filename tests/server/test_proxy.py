"""Behind a reverse proxy: who a trainer is comes from X-Forwarded-For, if the proxy is trusted.

A live `srlab serve` on loopback; the test plays the proxy, whose address is 127.0.0.1.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from bench.liveserver import live_server, wait_status

LIMIT = {"SRLAB_REWARD_RATE_PER_S": "0.05", "SRLAB_REWARD_BURST": "2"}


def realtime_run(api: httpx.Client) -> int:
    run = api.post("/api/runs", json={"condition": "delayed", "mode": "realtime", "hz": 20})
    run_id: int = run.json()["id"]
    api.post(f"/api/runs/{run_id}/start").raise_for_status()
    wait_status(api, run_id, "running")
    return run_id


def reward(api: httpx.Client, run_id: int, client: str) -> httpx.Response:
    return api.post(
        f"/api/runs/{run_id}/rewards", json={"value": 1.0}, headers={"X-Forwarded-For": client}
    )


@pytest.fixture
def behind_proxy(tmp_path: Path) -> Iterator[httpx.Client]:
    env = {**LIMIT, "SRLAB_FORWARDED_ALLOW_IPS": "127.0.0.1"}
    with live_server(tmp_path / "srlab.db", env=env) as server:
        yield server.client


def test_each_trainer_behind_a_trusted_proxy_has_a_rate_limit_of_their_own(
    behind_proxy: httpx.Client,
) -> None:
    run_id = realtime_run(behind_proxy)
    codes = [reward(behind_proxy, run_id, "203.0.113.7").status_code for _ in range(3)]
    assert codes == [202, 202, 429]
    refused = reward(behind_proxy, run_id, "203.0.113.7")
    assert "203.0.113.7" in refused.json()["detail"]
    assert reward(behind_proxy, run_id, "203.0.113.8").status_code == 202
    behind_proxy.post(f"/api/runs/{run_id}/stop").raise_for_status()
    log = behind_proxy.get(f"/api/runs/{run_id}/rewards").json()["data"]
    assert len([r for r in log if r["source"] == "trainer"]) == 3  # the refused ones are not


def test_without_a_trusted_proxy_the_header_cannot_buy_a_new_limit(tmp_path: Path) -> None:
    with live_server(tmp_path / "srlab.db", env=LIMIT) as server:
        api = server.client
        run_id = realtime_run(api)
        codes = [reward(api, run_id, f"203.0.113.{n}").status_code for n in range(3)]
        assert codes == [202, 202, 429]
        refused = reward(api, run_id, "198.51.100.1")
        assert refused.status_code == 429
        assert "127.0.0.1" in refused.json()["detail"]
        api.post(f"/api/runs/{run_id}/stop").raise_for_status()
