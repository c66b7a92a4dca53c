"""The `trainer` condition: a person's rewards and the task's, no reinforcement program."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest
from apphelpers import client_for, create, settings_for, until

from core.run.conditions import CONDITIONS, get_condition

pytestmark = pytest.mark.anyio


async def reward_log(client: httpx.AsyncClient, run_id: int) -> list[dict[str, Any]]:
    r = await client.get(f"/api/runs/{run_id}/rewards", params={"limit": 1000})
    assert r.status_code == 200
    data: list[dict[str, Any]] = r.json()["data"]
    return data


def test_the_trainer_condition_is_rp_without_its_program() -> None:
    trainer, rp = get_condition("trainer"), get_condition("rp")
    assert trainer.trainer is None and trainer.interactive
    assert (trainer.network, trainer.learning, trainer.epsilon, trainer.success_reward) == (
        rp.network, rp.learning, rp.epsilon, rp.success_reward,
    )  # fmt: skip
    assert [n for n, c in CONDITIONS.items() if c.interactive] == ["trainer"]


async def test_a_trainer_run_logs_no_program_reward_where_rp_logs_many(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        sources: dict[str, set[str]] = {}
        for condition in ("trainer", "rp"):
            run = await create(client, condition=condition, seed=4, episodes=5)
            assert (await client.post(f"/api/runs/{run['id']}/start")).status_code == 200
            done = await until(client, run["id"], "finished", timeout=120)
            assert done["ticks"] > 0
            sources[condition] = {r["source"] for r in await reward_log(client, run["id"])}
    assert sources["trainer"] <= {"task"}
    assert "program" in sources["rp"]


async def test_list_conditions_says_which_run_a_reward_program(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.get("/api/conditions")
    assert r.status_code == 200
    by_name = {c["name"]: c for c in r.json()}
    assert by_name["trainer"]["trainer"] == "" and by_name["trainer"]["learning"]
    assert by_name["rp"]["trainer"] == "rp"
    assert "qlambda" not in by_name  # the runs API runs the brain's conditions only


async def test_an_undo_is_a_new_opposite_reward_and_the_undone_one_stays(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="trainer", mode="realtime", hz=200)
        run_id = run["id"]
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
        first = await client.post(
            f"/api/runs/{run_id}/rewards", json={"value": 0.5, "note": "took the corner"}
        )
        assert first.status_code == 202
        given = first.json()
        # What the console's "undo my last reward" sends: the opposite value, naming it.
        undo = await client.post(
            f"/api/runs/{run_id}/rewards",
            json={"value": -given["value"], "note": f"undo of #{given['id']}"},
        )
        assert undo.status_code == 202
        undone = undo.json()
        assert undone["id"] > given["id"] and undone["value"] == -0.5
        graded = await client.post(f"/api/runs/{run_id}/rewards", json={"value": -0.25})
        assert graded.status_code == 202
        assert (await client.post(f"/api/runs/{run_id}/stop")).status_code == 200
        log = [r for r in await reward_log(client, run_id) if r["source"] == "trainer"]
    assert [(r["id"], r["value"], r["note"]) for r in log] == [
        (given["id"], 0.5, "took the corner"),
        (undone["id"], -0.5, f"undo of #{given['id']}"),
        (graded.json()["id"], -0.25, ""),
    ]
    assert all(r["applied"] for r in log)
