"""Trainer studies over HTTP: the organiser's routes, a participant's, and the study flow."""

from __future__ import annotations

import asyncio
import sqlite3
from pathlib import Path
from typing import Any

import httpx
import pytest
from apphelpers import client_for, settings_for

from core.studies import token_digest
from server.services import studies as studies_service

pytestmark = pytest.mark.anyio

STUDY: dict[str, Any] = {
    "name": "pilot",
    "conditions": ["trainer", "kp"],
    "budget": {"seconds": 1},
    "consent_text": "You will train a simulated robot.",
    "consent_version": "v2",
    "questionnaire": ["How hard was it?"],
    "completion_code": "C0DE42",
}


def as_participant(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


async def invited(client: httpx.AsyncClient, body: dict[str, Any]) -> list[dict[str, Any]]:
    r = await client.post("/api/studies/pilot/participants", json=body)
    assert r.status_code == 201, r.text
    data: list[dict[str, Any]] = r.json()["data"]
    return data


async def consented(client: httpx.AsyncClient, token: str) -> dict[str, Any]:
    r = await client.post(
        "/api/participant/consent", json={"consent_version": "v2"}, headers=as_participant(token)
    )
    assert r.status_code == 200, r.text
    out: dict[str, Any] = r.json()
    return out


async def test_create_study_and_read_it_with_progress(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/studies", json=STUDY)
        assert r.status_code == 201, r.text
        made = r.json()
        assert (made["name"], made["budget_s"], made["budget_episodes"]) == ("pilot", 1.0, None)
        assert made["progress"] == {"invited": 0, "consented": 0, "training": 0, "done": 0}
        assert "secret" not in made
        assert (await client.get("/api/studies/pilot")).json() == made
        assert (await client.get("/api/studies")).json() == {"data": [made], "count": 1}
        again = await client.post("/api/studies", json=STUDY)
        assert again.status_code == 409 and "pilot" in again.json()["detail"]
        assert (await client.get("/api/studies/nope")).status_code == 404


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"conditions": ["telepathy"]}, "conditions"),
        ({"conditions": []}, "conditions"),
        ({"conditions": ["kp", "kp"]}, "conditions"),
        ({"budget": {"episodes": 3, "seconds": 5}}, "budget"),
        ({"budget": {}}, "budget"),
        ({"budget": None}, "budget"),
        ({"budget": {"episodes": 0}}, "budget"),
        ({"assignment": "random"}, "assignment"),
        ({"consent_text": ""}, "consent_text"),
        ({"name": "no spaces please"}, "name"),
        ({"redirect_url": "javascript:alert(1)"}, "redirect_url"),
    ],
)
async def test_create_study_with_bad_input_names_the_field(
    tmp_path: Path, change: dict[str, Any], field: str
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/studies", json={**STUDY, **change})

        assert r.status_code == 422
        assert {e["loc"][1] for e in r.json()["detail"]} == {field}
        assert (await client.get("/api/studies")).json()["count"] == 0


async def test_add_participants_answers_each_token_once_and_stores_its_digest(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path)
    async with client_for(settings) as (client, _):
        await client.post("/api/studies", json=STUDY)
        named = await invited(client, {"external_ids": ["prolific-1", "prolific-2"]})
        anonymous = await invited(client, {"count": 2})
        twice = await client.post(
            "/api/studies/pilot/participants", json={"external_ids": ["prolific-1"]}
        )
        bad = await client.post("/api/studies/pilot/participants", json={"count": 0})
        nowhere = await client.post("/api/studies/nope/participants", json={"count": 1})
        listed = (await client.get("/api/studies/pilot/participants")).json()

    everyone = named + anonymous
    assert all(p["link"].endswith(f"/#/study/{p['token']}") for p in everyone)
    assert all(p["token"].startswith("srp_") and p["status"] == "invited" for p in everyone)
    assert len({p["token"] for p in everyone}) == 4
    assert twice.status_code == 409 and "prolific-1" in twice.json()["detail"]
    assert bad.status_code == 422 and nowhere.status_code == 404
    assert listed["count"] == 4 and all("token" not in p for p in listed["data"])
    with sqlite3.connect(tmp_path / "api.db") as db:
        stored = {h for (h,) in db.execute("SELECT token_hash FROM participants")}
        external = {i for (i,) in db.execute("SELECT external_id FROM participant_identities")}
    assert stored == {token_digest(p["token"]) for p in everyone}
    assert external == {"prolific-1", "prolific-2"}


async def test_study_routes_need_the_organisers_token(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, token="organiser-secret")
    organiser = {"Authorization": "Bearer organiser-secret"}
    async with client_for(settings) as (client, _):
        refused = await client.post("/api/studies", json=STUDY)
        listing = await client.get("/api/studies")
        made = await client.post("/api/studies", json=STUDY, headers=organiser)
        [p] = (
            await client.post(
                "/api/studies/pilot/participants", json={"count": 1}, headers=organiser
            )
        ).json()["data"]
        own = await client.get("/api/studies", headers=as_participant(p["token"]))

    assert (refused.status_code, listing.status_code, made.status_code) == (401, 401, 201)
    assert own.status_code == 403


async def test_study_flow_consent_assignment_rewards_and_completion(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/studies", json=STUDY)
        people = await invited(client, {"external_ids": ["a", "b", "c", "d"]})
        tokens = [p["token"] for p in people]
        first = as_participant(tokens[0])

        before = (await client.get("/api/participant", headers=first)).json()
        assert (before["status"], before["run_id"], before["completion_code"]) == (
            "invited",
            None,
            None,
        )
        assert before["consent_text"] == STUDY["consent_text"]
        assert before["questionnaire"] == ["How hard was it?"]
        no_run = await client.post("/api/runs/1/rewards", json={"value": 1}, headers=first)
        assert no_run.status_code == 403 and "consent first" in no_run.json()["detail"]
        stale = await client.post(
            "/api/participant/consent", json={"consent_version": "v1"}, headers=first
        )
        assert stale.status_code == 409 and "'v2'" in stale.json()["detail"]
        assert (await client.get("/api/participant", headers=first)).json()["status"] == "invited"

        views = [await consented(client, t) for t in tokens]
        assert [v["condition"] for v in views] == ["trainer", "kp", "trainer", "kp"]
        assert all(v["status"] == "training" for v in views)
        runs = [v["run_id"] for v in views]
        assert len(set(runs)) == 4
        assert (await consented(client, tokens[0]))["run_id"] == runs[0]  # a reload

        own = await client.post(f"/api/runs/{runs[0]}/rewards", json={"value": 1}, headers=first)
        assert own.status_code == 202, own.text
        foreign = await client.post(
            f"/api/runs/{runs[1]}/rewards", json={"value": 1}, headers=first
        )
        assert foreign.status_code == 403 and f"run {runs[1]}" in foreign.json()["detail"]
        assert (await client.get(f"/api/runs/{runs[1]}/rewards")).json()["count"] == 0
        mine = (await client.get("/api/runs", headers=first)).json()
        assert (mine["count"], [r["id"] for r in mine["data"]]) == (1, [runs[0]])
        assert (await client.get("/api/runs")).json()["count"] == 4  # the organiser's

        unknown = await client.get("/api/participant", headers=as_participant("srp_nobody"))
        assert unknown.status_code == 401
        organiser = await client.get("/api/participant")
        assert organiser.status_code == 401

        async with asyncio.timeout(30):  # the budget: one second of the run's clock
            while (view := (await client.get("/api/participant", headers=first)).json())[
                "status"
            ] != "done":
                await asyncio.sleep(0.05)
        # The questionnaire first, then the code.
        assert (view["completion_code"], view["answered"], view["run_id"]) == (None, False, runs[0])
        answered = await client.post(
            "/api/participant/answers", json={"answers": ["Easy."]}, headers=first
        )
        assert answered.status_code == 201, answered.text
        assert (answered.json()["completion_code"], answered.json()["answered"]) == ("C0DE42", True)
        spent = await client.post(f"/api/runs/{runs[0]}/rewards", json={"value": 1}, headers=first)
        assert spent.status_code == 403 and "budget" in spent.json()["detail"]
        progress = (await client.get("/api/studies/pilot")).json()["progress"]
        assert progress["done"] >= 1 and sum(progress.values()) == 4

        deleted = await client.delete("/api/studies/pilot/identities")
        assert deleted.json() == {"deleted": 4}
        assert (await client.get("/api/studies/pilot/participants")).json()["count"] == 4


async def test_each_participant_has_a_reward_limit_of_their_own(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, reward_rate_per_s=0.01, reward_burst=1)
    async with client_for(settings) as (client, _):
        await client.post("/api/studies", json={**STUDY, "budget": {"seconds": 600}})
        tokens = [p["token"] for p in await invited(client, {"count": 2})]
        answers = []
        for token in tokens:
            run = (await consented(client, token))["run_id"]
            for _ in range(2):
                r = await client.post(
                    f"/api/runs/{run}/rewards", json={"value": 1}, headers=as_participant(token)
                )
                answers.append(r.status_code)

    # On one loopback address: each participant's first reward goes, their second waits.
    assert answers == [202, 429, 202, 429]


async def _ticked(client: httpx.AsyncClient, run_id: int, ticks: int) -> None:
    """Wait, on the organiser's read of the run (which settles no one), until it has ticked."""
    async with asyncio.timeout(60):  # a hang guard
        while (await client.get(f"/api/runs/{run_id}")).json()["ticks"] < ticks:
            await asyncio.sleep(0.05)


async def test_a_participant_is_done_once_spent_though_they_never_read_again(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/studies", json=STUDY)  # a budget of 1 s: 10 ticks at 10 Hz
        [gone, stays] = [p["token"] for p in await invited(client, {"count": 2})]
        run = (await consented(client, gone))["run_id"]
        await consented(client, stays)

        # Their tab is closed: no one reads /api/participant; the organiser watches.
        # Both budgets run out about together: wait for this participant's, not any.
        async with asyncio.timeout(60):  # a hang guard
            while True:
                listed = (await client.get("/api/studies/pilot/participants")).json()["data"]
                if [p["status"] for p in listed if p["run_id"] == run] == ["done"]:
                    break
                await asyncio.sleep(0.05)
        studies = (await client.get("/api/studies")).json()["data"]
        assert studies[0]["progress"]["done"] >= 1
        async with asyncio.timeout(60):  # a time budget: the run is stopped, not left ticking
            while (await client.get(f"/api/runs/{run}")).json()["status"] != "stopped":
                await asyncio.sleep(0.05)


async def test_the_participants_list_says_how_far_each_run_has_got(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/studies", json={**STUDY, "budget": {"seconds": 600}})
        trains = (await invited(client, {"count": 2}))[0]["token"]  # the other waits
        run = (await consented(client, trains))["run_id"]

        async def progress() -> dict[int | None, tuple[Any, Any]]:
            listed = (await client.get("/api/studies/pilot/participants")).json()["data"]
            return {p["run_id"]: (p["episodes_done"], p["seconds_done"]) for p in listed}

        async with asyncio.timeout(60):  # a hang guard: until the run has ticked
            while not (await progress())[run][1]:
                await asyncio.sleep(0.05)
        # Paused, the run stands still: the list answers its own count of episodes and
        # its ticks at its rate, as the run reads.
        assert (await client.post(f"/api/runs/{run}/pause")).status_code == 200
        state = (await client.get(f"/api/runs/{run}")).json()
        assert (await progress())[run] == (
            state["episodes_done"],
            round(state["ticks"] / state["hz"], 1),
        )
        assert (await progress())[None] == (None, None)  # invited: no run yet


async def test_a_participant_spent_before_a_restart_is_done_after_it(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        study = {**STUDY, "budget": {"episodes": 1}, "questionnaire": []}
        await client.post("/api/studies", json=study)
        [token] = [p["token"] for p in await invited(client, {"count": 1})]
        run = (await consented(client, token))["run_id"]
    # Stored as if its one episode ended just before the service stopped, with no one
    # reading since: the participant is still training in storage.
    with sqlite3.connect(tmp_path / "api.db") as con:
        con.execute("UPDATE runs SET episodes_done = 1 WHERE id = ?", (run,))
    [(status,)] = sqlite3.connect(tmp_path / "api.db").execute("SELECT status FROM participants")
    assert status == "training"

    async with client_for(settings_for(tmp_path)) as (client, _):
        progress = (await client.get("/api/studies/pilot")).json()["progress"]
        assert progress["done"] == 1 and progress["training"] == 0
        view = (await client.get("/api/participant", headers=as_participant(token))).json()
        assert (view["status"], view["completion_code"]) == ("done", "C0DE42")


async def _spent(client: httpx.AsyncClient, token: str) -> None:
    async with asyncio.timeout(60):  # a hang guard: the budget is one second of the run's clock
        while (await client.get("/api/participant", headers=as_participant(token))).json()[
            "status"
        ] != "done":
            await asyncio.sleep(0.05)


def _answers(path: Path) -> list[tuple[object, ...]]:
    sql = (
        "SELECT participant_id, question_no, question, answer FROM questionnaire_answers "
        "ORDER BY participant_id, question_no"
    )
    with sqlite3.connect(path) as con:
        return list(con.execute(sql))


async def test_answers_are_checked_stored_once_and_open_the_completion_code(
    tmp_path: Path,
) -> None:
    study = {**STUDY, "questionnaire": ["How hard was it?", "Would you again?"]}
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/studies", json=study)
        [token] = [p["token"] for p in await invited(client, {"count": 1})]
        me = as_participant(token)
        await consented(client, token)
        early = await client.post(
            "/api/participant/answers", json={"answers": ["a", "b"]}, headers=me
        )
        assert early.status_code == 409 and "training is done" in early.json()["detail"]
        await _spent(client, token)

        for body, field in (
            ({"answers": ["only one"]}, "answers"),
            ({"answers": ["a", "b", "c"]}, "answers"),
            ({"answers": ["a", ""]}, "answers"),
            ({"answers": []}, "answers"),
            ({}, "answers"),
            ({"answers": ["a", "b"], "extra": 1}, "extra"),
        ):
            bad = await client.post("/api/participant/answers", json=body, headers=me)
            assert bad.status_code == 422, (body, bad.text)
            assert any(field in e["loc"] for e in bad.json()["detail"]), bad.text
        assert _answers(tmp_path / "api.db") == []
        view = (await client.get("/api/participant", headers=me)).json()
        assert (view["status"], view["answered"], view["completion_code"]) == ("done", False, None)

        given = await client.post(
            "/api/participant/answers", json={"answers": ["Hard.", "Yes"]}, headers=me
        )
        assert given.status_code == 201, given.text
        assert (given.json()["answered"], given.json()["completion_code"]) == (True, "C0DE42")
        again = await client.post(
            "/api/participant/answers", json={"answers": ["Easy.", "No"]}, headers=me
        )
        assert again.status_code == 409 and "already" in again.json()["detail"]
        assert _answers(tmp_path / "api.db") == [
            (1, 1, "How hard was it?", "Hard."),
            (1, 2, "Would you again?", "Yes"),
        ]
        view = (await client.get("/api/participant", headers=me)).json()
        assert (view["answered"], view["completion_code"]) == (True, "C0DE42")
        organiser = await client.post("/api/participant/answers", json={"answers": ["a", "b"]})
        assert organiser.status_code == 401


async def test_a_study_without_a_questionnaire_takes_no_answers(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/studies", json={**STUDY, "questionnaire": []})
        [token] = [p["token"] for p in await invited(client, {"count": 1})]
        await consented(client, token)
        await _spent(client, token)
        me = as_participant(token)
        view = (await client.get("/api/participant", headers=me)).json()
        assert view["completion_code"] == "C0DE42"  # no questions: the code straight away
        r = await client.post("/api/participant/answers", json={"answers": ["a"]}, headers=me)
        assert r.status_code == 409 and "no questionnaire" in r.json()["detail"]
        assert _answers(tmp_path / "api.db") == []


def _status_stored(path: Path) -> list[str]:
    with sqlite3.connect(path) as con:
        return [s for (s,) in con.execute("SELECT status FROM participants ORDER BY id")]


async def _stored_done(path: Path) -> None:
    """Wait on storage alone (no route that settles is read) until everyone is done."""
    async with asyncio.timeout(60):  # a hang guard
        while set(_status_stored(path)) != {"done"}:
            await asyncio.sleep(0.05)


async def test_a_spent_time_budget_is_marked_and_stopped_with_no_one_reading(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/studies", json=STUDY)  # 1 s
        [token] = [p["token"] for p in await invited(client, {"count": 1})]
        run = (await consented(client, token))["run_id"]

        await _stored_done(tmp_path / "api.db")

        async with asyncio.timeout(60):  # the service stopped it: no one would watch it
            while (await client.get(f"/api/runs/{run}")).json()["status"] != "stopped":
                await asyncio.sleep(0.05)


async def test_a_run_that_ends_between_two_looks_is_heard(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        await client.post("/api/studies", json={**STUDY, "budget": {"episodes": 1}})
        [person] = await invited(client, {"count": 1})
        # Their run, fast: it starts and ends well within one look of the watch.
        r = await client.post(
            "/api/runs", json={"condition": "expert", "episodes": 1, "seed": 3, "mode": "fast"}
        )
        studies = app.state.srlab.studies
        studies.consent(person["id"], "v2")
        studies.set_run(person["id"], r.json()["id"])
        assert (await client.post(f"/api/runs/{r.json()['id']}/start")).status_code == 200

        await _stored_done(tmp_path / "api.db")


async def test_a_budget_spent_just_before_a_stop_is_marked_on_the_way_out(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(studies_service, "SETTLE_EVERY_S", 3600.0)  # no look while it runs
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/studies", json=STUDY)  # 1 s
        [token] = [p["token"] for p in await invited(client, {"count": 1})]
        run = (await consented(client, token))["run_id"]
        await _ticked(client, run, 10)
        assert _status_stored(tmp_path / "api.db") == ["training"]
    # Stopped with no one having read: the unfinished episode's ticks are not stored, but
    # the watch's last look, after the runs' shutdown, saw them spent.
    assert _status_stored(tmp_path / "api.db") == ["done"]
