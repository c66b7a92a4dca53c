"""The Ray backend on a real local Ray instance (one for the module): same results as local."""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

try:
    import ray
except ImportError:
    if os.environ.get("CI", "").lower() == "true":
        raise  # CI must test the Ray backend: `make test` installs the ray extra
    pytest.skip(
        "ray is not installed: `uv sync --frozen --extra ray` (make test does)",
        allow_module_level=True,
    )

from core.lab.experiment import Task, TaskResult, run_task, run_tasks
from server.backends.ray import RayBackend
from server.cli import main

SWEEP = [
    "sweep",
    "--param",
    "epsilon=0,1",
    "--param",
    "eta=0.1,0.5",
    "--conditions",
    "kp,qlambda",
    "--seeds",
    "2",
    "--episodes",
    "3",
    "--quiet",
]
EXPERIMENT = [
    "experiment",
    "--conditions",
    "innate,rp,qlambda,sonar,qlambda-hybrid",
    "--seeds",
    "2",
    "--episodes",
    "3",
    "--eval-episodes",
    "2",
    "--quiet",
]


RAY_STARTS = 3
"""Ray waits a fixed 30 s for its new node to register (ray/_private/node.py); on a loaded
2-core machine (pytest-xdist's workers beside other work) that can run out, so a start that
timed out is tried again: a bound for a hung start, not a speed test."""


def start_ray() -> RayBackend:
    for attempt in range(1, RAY_STARTS + 1):
        try:
            return RayBackend(None, jobs=2, ship_code=True).__enter__()
        except Exception as e:
            if "timed out during startup" not in str(e) or attempt == RAY_STARTS:
                raise
            ray.shutdown()
    raise AssertionError("unreachable")


@pytest.fixture(scope="module")
def cluster() -> Iterator[RayBackend]:
    """A private Ray instance with 2 CPUs, shipping this checkout's core to its workers.

    The CLI finds the driver connected and uses it as it is, so the module starts Ray once.
    """
    assert not ray.is_initialized()
    with pytest.MonkeyPatch.context() as env:
        # Ray gives a new local instance a token; given none, it writes one to
        # ~/.ray/auth_token, which a test has no business leaving in the user's home.
        env.setenv("RAY_AUTH_TOKEN", secrets.token_hex(32))
        with start_ray() as backend:
            yield backend
    assert not ray.is_initialized()


def run_both(argv: list[str], tmp: Path) -> tuple[Path, Path]:
    local, on_ray = tmp / "local", tmp / "ray"
    assert main([*argv, "--jobs", "1", "--out", str(local)]) == 0
    assert main([*argv, "--backend", "ray", "--jobs", "2", "--out", str(on_ray)]) == 0
    return local, on_ray


def without_timing(doc: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in doc.items() if k != "params"}


def test_the_job_ships_this_checkouts_core_to_the_requested_cpus(cluster: RayBackend) -> None:
    runtime_env = ray.get_runtime_context().runtime_env
    assert len(runtime_env["py_modules"]) == 1
    assert cluster.cpus() == 2
    assert cluster.where == "a local Ray instance with 2 CPUs"

    @ray.remote
    def catalogue_size() -> int:
        from core.brain.catalog import load_catalog

        return len(load_catalog().behaviours)

    assert ray.get(catalogue_size.remote()) == 21


def test_a_sweep_on_ray_gives_the_local_results(
    cluster: RayBackend, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    local, on_ray = run_both(SWEEP, tmp_path)
    assert (on_ray / "runs.jsonl").read_text() == (local / "runs.jsonl").read_text()
    a = json.loads((local / "summary.json").read_text())
    b = json.loads((on_ray / "summary.json").read_text())
    assert without_timing(b) == without_timing(a)
    assert (b["params"]["backend"], a["params"]["backend"]) == ("ray", "local")
    assert b["params"]["ticks"] == a["params"]["ticks"] > 0
    out = " ".join(capsys.readouterr().out.split())  # the console wraps long lines
    assert "on the Ray this process was connected to (2 CPUs)" in out
    assert ray.is_initialized(), "a connected driver is left as it was"


def test_an_experiment_on_ray_gives_the_local_results(cluster: RayBackend, tmp_path: Path) -> None:
    local, on_ray = run_both(EXPERIMENT, tmp_path)
    assert (on_ray / "runs.jsonl").read_text() == (local / "runs.jsonl").read_text()
    a = json.loads((local / "summary.json").read_text())
    b = json.loads((on_ray / "summary.json").read_text())
    assert without_timing(b) == without_timing(a)


def test_a_task_that_fails_on_ray_is_kept_and_the_others_survive(cluster: RayBackend) -> None:
    def flaky(task: Task) -> TaskResult:
        if task.seed == 1:
            raise RuntimeError("sonar unplugged")
        return run_task(task)

    tasks = [Task("innate", s, 2) for s in range(3)]
    results = run_tasks(tasks, cluster, fn=flaky)
    assert [r.task for r in results] == tasks
    assert [r.ok for r in results] == [True, False, True]
    assert "sonar unplugged" in (results[1].error or "")
    assert results[0] == run_task(tasks[0])
