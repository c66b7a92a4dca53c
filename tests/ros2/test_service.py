"""A run on the fake AmigoBot from `srlab serve`: created, started, rewarded, read, stopped.

The service (a real `srlab serve` on loopback, in this loopback-only namespace) reaches the
robot through a robot file of its data folder; the fake robot runs in lockstep, so the run
ticks as at 20 Hz however busy the machine is.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import ros2_or_skip  # noqa: F401  # before rclpy: skips the module without it
from amigobot_process import GUARD_S, fake_amigobot

from bench.liveserver import LiveServer, live_server
from core.brain.catalog import data_dir
from core.sim.robotfile import robots_dir

ROBOT = "ros2:amigobot-lockstep"


def lockstep_robot_file(robots: Path) -> None:
    """The AmigoBot's robot file on the fake robot's clock (`amigobot_process.LOCKSTEP`)."""
    text = (robots_dir() / "amigobot.toml").read_text(encoding="utf-8")
    text = text.replace("lost_after_s = 0.1 ", "lost_after_s = 1.0 ")
    text = text.replace("stale_after_s = 0.2", "stale_after_s = 1.0")
    text = text.replace('node = "srlab_brain"', 'node = "srlab_brain"\nuse_sim_time = true')
    assert "lost_after_s = 1.0" in text and "use_sim_time" in text
    (robots / "amigobot-lockstep.toml").write_text(text, encoding="utf-8")


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("robot")
    data = folder / "data"
    shutil.copytree(data_dir(), data)
    lockstep_robot_file(data / "robots")
    with live_server(folder / "srlab.db", env={"SRLAB_DATA_DIR": str(data)}) as server:
        yield server


def _until(server: LiveServer, run_id: int, done: Callable[[dict[str, Any]], bool]) -> None:
    deadline = time.monotonic() + GUARD_S
    while True:
        run: dict[str, Any] = server.client.get(f"/api/runs/{run_id}").json()
        if done(run):
            return
        assert time.monotonic() < deadline, run
        time.sleep(0.05)


def _first_tick(server: LiveServer, run_id: int) -> dict[str, Any]:
    with server.client.stream("GET", f"/api/runs/{run_id}/events?tick_hz=20") as r:
        name = ""
        for line in r.iter_lines():
            if line.startswith("event: "):
                name = line[7:]
            elif line.startswith("data: ") and name == "tick":
                tick: dict[str, Any] = json.loads(line[6:])
                return tick
    raise AssertionError("the stream ended without a tick")


def test_a_robot_run_is_checked_when_created(service: LiveServer) -> None:
    body = {"condition": "kp", "world": ROBOT, "mode": "fast"}
    runs = service.client.get("/api/runs").json()["count"]
    r = service.client.post("/api/runs", json=body)
    assert r.status_code == 409, r.text
    assert r.json()["detail"].startswith("mode: a run on a robot ticks in realtime")
    r = service.client.post("/api/runs", json={**body, "mode": "realtime", "hz": 10})
    assert r.status_code == 409, r.text
    assert r.json()["detail"].startswith("hz: the robot 'amigobot-lockstep' ticks at 20 Hz")
    assert service.client.get("/api/runs").json()["count"] == runs  # nothing stored
    r = service.client.post("/api/runs", json={**body, "world": "ros2:nosuch"})
    assert r.status_code == 422, r.text
    assert "amigobot-lockstep" in r.text


def test_a_run_on_the_robot_ticks_takes_rewards_and_stops_it(service: LiveServer) -> None:
    with fake_amigobot("--world", "classic") as fake:
        created = service.client.post(
            "/api/runs", json={"condition": "kp", "world": ROBOT, "mode": "realtime"}
        )
        assert created.status_code == 201, created.text
        run = created.json()
        assert (run["world"], run["hz"]) == (ROBOT, 20.0)
        started = service.client.post(f"/api/runs/{run['id']}/start")
        assert started.status_code == 200, started.text
        _until(service, run["id"], lambda r: r["live"] is not None and r["live"]["tick"] >= 40)
        # A second run on the same robot is refused while this one drives it.
        other = service.client.post(
            "/api/runs", json={"condition": "kp", "world": ROBOT, "mode": "realtime"}
        ).json()
        refused = service.client.post(f"/api/runs/{other['id']}/start")
        assert refused.status_code == 409, refused.text
        assert f"driven by run {run['id']}" in refused.text
        # The console's and the 3D view's tick events: the robot where its odometry says.
        tick = _first_tick(service, run["id"])
        assert tick["progress_m"] > 0 and math.isfinite(tick["x"]) and math.isfinite(tick["y"])
        reward = service.client.post(f"/api/runs/{run['id']}/rewards", json={"value": 1.0})
        assert reward.status_code == 202, reward.text
        kp = service.client.get(f"/api/runs/{run['id']}/kp")
        assert kp.status_code == 200, kp.text
        world = service.client.get(f"/api/runs/{run['id']}/world")
        assert world.status_code == 200, world.text
        stopped = service.client.post(f"/api/runs/{run['id']}/stop")
        assert stopped.status_code == 200, stopped.text
        _until(service, run["id"], lambda r: r["status"] == "stopped")
        fake.stop()
    rewards = service.client.get(f"/api/runs/{run['id']}/rewards").json()
    assert [r["value"] for r in rewards["data"] if r["source"] == "trainer"] == [1.0]
    assert fake.stats["commands"] >= 40  # the robot drove on the run's commands


def test_a_robot_run_resumes_and_a_silent_robot_interrupts_it(service: LiveServer) -> None:
    created = service.client.post(
        "/api/runs", json={"condition": "kp", "world": ROBOT, "mode": "realtime"}
    ).json()
    run_id = created["id"]
    with fake_amigobot("--world", "classic"):
        assert service.client.post(f"/api/runs/{run_id}/start").status_code == 200
        _until(service, run_id, lambda r: r["live"] is not None and r["live"]["tick"] >= 20)
        assert service.client.post(f"/api/runs/{run_id}/stop").status_code == 200
        _until(service, run_id, lambda r: r["status"] == "stopped")
        # Started again, it runs on: the episode it stopped in starts over on the robot.
        assert service.client.post(f"/api/runs/{run_id}/start").status_code == 200
        _until(service, run_id, lambda r: r["live"] is not None and r["live"]["tick"] >= 20)
    # The fake robot is gone (its process ended): the run is interrupted, saying why.
    _until(service, run_id, lambda r: r["status"] == "interrupted")
    run = service.client.get(f"/api/runs/{run_id}").json()
    assert run["error"].startswith("the robot went silent for 1 s: it was stopped")
