"""A network made in the S-R editor runs the same from the service and from the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from liveharness import wait_status

from bench.liveserver import live_server
from server.cli import main


@pytest.mark.slow
def test_the_editors_network_runs_the_same_through_the_api_and_srlab_simulate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "editor.db"
    with live_server(db) as server:
        api = server.client
        made = api.post(
            "/api/networks",
            json={
                "name": "edited",
                "base": "kp",
                "associations": [
                    {"stimulus": "Obstacle_M_M", "behaviour": "leftturn30", "strength": 0.6}
                ],
            },
        )
        assert made.status_code == 201, made.text
        r = api.post(
            "/api/runs",
            json={"condition": "sonar", "network": "edited", "seed": 4, "episodes": 6,
                  "mode": "fast"},
        )  # fmt: skip
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        assert api.post(f"/api/runs/{run_id}/start").status_code == 200
        served = wait_status(api, run_id, "finished")
        episodes = api.get(f"/api/runs/{run_id}/episodes").json()["data"]

    capsys.readouterr()
    argv = ["simulate", "--condition", "sonar", "--network", "edited", "--seed", "4"]
    argv += ["--episodes", "6", "--url", f"sqlite:///{db}", "--quiet", "--json"]
    assert main(argv) == 0
    cli = json.loads(capsys.readouterr().out)
    assert cli["network"] == "edited"
    assert (cli["successes"], cli["ticks"]) == (served["successes"], served["ticks"])
    causes = [e["cause"] for e in episodes if e["cause"] is not None]
    assert cli["failures"] == {c: causes.count(c) for c in cli["failures"]}
    assert sum(cli["failures"].values()) == len(causes) > 0  # the edit is not a perfect one


def test_an_editor_network_is_not_looked_for_in_a_database_that_is_not_there(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from clihelpers import exits_2

    url = f"sqlite:///{tmp_path / 'none.db'}"
    argv = ["simulate", "--condition", "kp", "--network", "edited", "--url", url]
    assert "no such network" in exits_2(argv, capsys)
    assert not (tmp_path / "none.db").exists()
