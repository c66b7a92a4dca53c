"""Feedback on replay in the console, in real Chromium against a live `srlab serve`: a
stored episode scrubbed to a tick is drawn and described as its stored trace says, and
+ then rewards that tick of that episode (`tick_seen`, `episode`) with the credit shown,
or the API's refusal; leaving the replay gives the keys back to the live robot."""

from __future__ import annotations

import json
import re
from typing import Any

from browser import artifact
from liveharness import start_run, wait_episodes, wait_status
from playwright.sync_api import Page, expect
from webpage import eventually, open_view

from bench.liveserver import LiveServer

REPLAYING = re.compile(r"\breplaying\b")
"""The page's class while a replay is open (the reward buttons are outlined then)."""

REACTION_TICKS = range(2, 41)
"""The ticks before the tick seen that the default reaction window (0.2-4 s) spans at a
run's 10 Hz (a fast run's rate too, though it does not wait for it): the scrubbed tick is
chosen with responses there, so the reward has records to credit."""


def started(server: LiveServer, **body: Any) -> int:
    return start_run(server.client, **body)


def finished(server: LiveServer, episodes: int, seed: int) -> int:
    """A fast trainer run of `episodes` episodes, once it has finished."""
    run_id = started(server, condition="trainer", mode="fast", episodes=episodes, seed=seed)
    wait_status(server.client, run_id, "finished")
    return run_id


def trace(server: LiveServer, run_id: int, episode: int) -> list[dict[str, Any]]:
    """The episode's stored trace, once it is stored (the run's writer follows its ticks)."""
    url = f"/api/runs/{run_id}/episodes/{episode}"
    eventually(lambda: server.client.get(url).status_code == 200, what=url)
    rows: list[dict[str, Any]] = server.client.get(url).json()["trace"]
    return rows


def drawn(page: Page) -> dict[str, str]:
    """The replay canvas's record of what it drew last (its data attributes)."""
    data: dict[str, str] = page.eval_on_selector("#replay-canvas", "c => ({...c.dataset})")
    return data


def open_replay(page: Page, episode: int) -> None:
    page.locator("#replay-episode").select_option(str(episode))
    page.click("#replay-open")
    expect(page.locator("#replay-body")).to_be_visible()


def scrub(page: Page, index: int) -> None:
    page.locator("#replay-tick").fill(str(index))


def shows(page: Page, row: dict[str, Any]) -> None:
    """The replay shows trace row `row`: its tick, its behaviour, the robot where it was."""
    expect(page.locator("#replay-at")).to_contain_text(f"tick {row['tick']} ")
    expect(page.locator("#replay-what")).to_have_text(row["behaviour"] or "no behaviour")
    if row["released_by"]:
        expect(page.locator("#replay-why")).to_contain_text(row["released_by"])
    eventually(lambda: drawn(page).get("tick") == str(row["tick"]), what="the tick drawn")
    d = drawn(page)
    assert abs(float(d["x"]) - row["x"]) < 1e-3 and abs(float(d["y"]) - row["y"]) < 1e-3


def posted_reward(page: Page, key: str) -> dict[str, Any]:
    """Press `key` and answer the body of the reward it posted."""
    with page.expect_request(
        lambda r: r.method == "POST" and r.url.endswith("/rewards")
    ) as request:
        page.keyboard.press(key)
    body: dict[str, Any] = json.loads(request.value.post_data or "{}")
    return body


def test_a_scrubbed_tick_is_drawn_and_described_as_its_trace_row(
    page: Page, server: LiveServer
) -> None:
    run_id = finished(server, episodes=3, seed=5)
    rows = trace(server, run_id, 1)
    assert len(rows) > 20
    open_view(page, server, f"console/{run_id}")
    open_replay(page, 1)
    shows(page, rows[0])
    # A tick whose behaviour a stimulus released, if the episode has one.
    index = next((i for i, r in enumerate(rows) if r["released_by"] and i > 0), len(rows) // 2)
    scrub(page, index)
    shows(page, rows[index])
    # The arrows step a tick at a time while the replay has the focus (one tick, not the
    # slider's own step as well).
    page.keyboard.press("ArrowRight")
    shows(page, rows[index + 1])
    page.keyboard.press("ArrowLeft")
    page.keyboard.press("ArrowLeft")
    shows(page, rows[index - 1])
    page.locator("#replay-card").screenshot(path=artifact("console-replay.png"))
    # Play runs through the episode to its last tick, and stops there.
    page.click("#replay-play")
    shows(page, rows[-1])
    expect(page.locator("#replay-play")).to_contain_text("Play")


def test_a_reward_on_replay_names_the_tick_and_episode_and_a_refusal_is_shown(
    page: Page, server: LiveServer
) -> None:
    run_id = finished(server, episodes=2, seed=6)
    rows = trace(server, run_id, 0)
    open_view(page, server, f"console/{run_id}")
    open_replay(page, 0)
    scrub(page, 10)
    shows(page, rows[10])
    before = server.client.get(f"/api/runs/{run_id}/rewards").json()["count"]
    body = posted_reward(page, "+")
    assert body == {"value": 1, "tick_seen": rows[10]["tick"], "episode": 0}
    # A finished run takes no reward: the panel says what the API said to the same body.
    refused = server.client.post(f"/api/runs/{run_id}/rewards", json=body)
    assert refused.status_code in (409, 422), refused.text
    detail = refused.json()["detail"]
    answer = page.locator("#replay-answer")
    for said in [detail] if isinstance(detail, str) else [e["msg"] for e in detail]:
        expect(answer).to_contain_text(said)
    assert server.client.get(f"/api/runs/{run_id}/rewards").json()["count"] == before
    # Leaving gives the keys back: the replay is closed, and so is its hold on the buttons.
    page.keyboard.press("Escape")
    expect(page.locator("#replay-body")).to_be_hidden()
    expect(page.locator("body")).not_to_have_class(REPLAYING)


def logged_reward(server: LiveServer, run_id: int, reward_id: int) -> dict[str, Any] | None:
    """Reward `reward_id` as the run's reward log has it (its newest page), if it is there."""
    url = f"/api/runs/{run_id}/rewards"
    count = server.client.get(url, params={"limit": 1}).json()["count"]
    page = server.client.get(url, params={"limit": 1000, "offset": max(0, count - 1000)})
    return next((r for r in page.json()["data"] if r["id"] == reward_id), None)


def best_tick(rows: list[dict[str, Any]]) -> int:
    """The index whose reaction window holds the most responses (rows a stimulus released)."""
    released = [1 if r["released_by"] else 0 for r in rows]

    def held(i: int) -> int:
        return sum(released[i - k] for k in REACTION_TICKS if i - k >= 0)

    return max(range(len(rows)), key=held)


def test_a_reward_on_replay_credits_that_episodes_records_and_says_how_many(
    page: Page, server: LiveServer
) -> None:
    """Needs the reward API's `tick_seen` and `episode` (a body without them is refused)."""
    run_id = started(server, condition="trainer", mode="fast", hz=10, seed=7)
    try:
        wait_episodes(server.client, run_id, 3)
        paused = server.client.post(f"/api/runs/{run_id}/pause")
        assert paused.status_code == 200, paused.text
        # A stored episode (the one that ended last, or the one before it, as the pause
        # falls): credited from its stored trace.
        n = paused.json()["episodes_done"] - 2
        rows = trace(server, run_id, n)
        index = best_tick(rows)
        assert any(rows[index - k]["released_by"] for k in REACTION_TICKS if index >= k)
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#run-status")).to_have_text("paused")
        open_replay(page, n)
        scrub(page, index)
        shows(page, rows[index])
        with page.expect_response(
            lambda r: r.request.method == "POST" and r.url.endswith("/rewards")
        ) as answered:
            page.keyboard.press("+")
        response = answered.value
        body = json.loads(response.request.post_data or "{}")
        assert body == {"value": 1, "tick_seen": rows[index]["tick"], "episode": n}
        assert response.status == 202, response.text()
        ack = response.json()
        # The run goes on at once: the reward was credited while it was paused (even just
        # as an episode ended), and the panel finds it in the log though the run's own
        # rewards soon run past it.
        resumed = server.client.post(f"/api/runs/{run_id}/resume")
        assert resumed.status_code == 200, resumed.text
        logged = eventually(
            lambda: (x := logged_reward(server, run_id, ack["id"])) and x["applied"] and x,
            what="the replay's reward applied",
        )
        assert logged["seen_episode"] == n and logged["tick_seen"] == rows[index]["tick"]
        assert logged["credited"] > 0, logged
        expect(page.locator("#replay-answer")).to_contain_text(
            f"credited {logged['credited']} record"
        )
        # The Train card's buttons reward the replay too, and a paused run takes them.
        with page.expect_request(
            lambda r: r.method == "POST" and r.url.endswith("/rewards")
        ) as sent:
            page.click("#reward-minus")
        assert json.loads(sent.value.post_data or "{}")["episode"] == n
        # Leaving the replay gives the keys back to the live robot: its episode, not n.
        page.locator("#replay-tick").focus()
        page.keyboard.press("Escape")
        expect(page.locator("#replay-body")).to_be_hidden()
        page.locator("body").click(position={"x": 5, "y": 5})
        live = posted_reward(page, "+")
        assert live["value"] == 1 and live.get("episode") != n, live
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")


def test_a_participant_replays_an_episode_of_their_own_run(page: Page, server: LiveServer) -> None:
    study = {
        "name": "replayers", "conditions": ["trainer"], "budget": {"episodes": 50},
        "consent_text": "You will train a simulated robot.", "consent_version": "1",
    }  # fmt: skip
    r = server.client.post("/api/studies", json=study)
    assert r.status_code == 201, r.text
    r = server.client.post("/api/studies/replayers/participants", json={"count": 1})
    assert r.status_code == 201, r.text
    invited = r.json()["data"][0]
    as_participant = {"Authorization": f"Bearer {invited['token']}"}
    r = server.client.post(
        "/api/participant/consent", json={"consent_version": "1"}, headers=as_participant
    )
    assert r.status_code == 200, r.text
    run_id = r.json()["run_id"]
    # The organiser hurries their run to a stored episode and holds it there.
    assert server.client.post(f"/api/runs/{run_id}/rate", json={"hz": 1000}).status_code == 200
    wait_episodes(server.client, run_id, 1)
    assert server.client.post(f"/api/runs/{run_id}/pause").status_code == 200
    rows = trace(server, run_id, 0)
    try:
        page.goto(f"{server.url}/#/study/{invited['token']}")
        page.wait_for_selector("body[data-ready=true]")
        expect(page.locator("#view-console")).to_be_visible()
        open_replay(page, 0)
        scrub(page, len(rows) // 2)
        shows(page, rows[len(rows) // 2])
        body = posted_reward(page, "-")
        assert body == {"value": -1, "tick_seen": rows[len(rows) // 2]["tick"], "episode": 0}
        # The Train card's buttons reward the replay of the paused run, outlined as such.
        expect(page.locator("body")).to_have_class(REPLAYING)
        expect(page.locator("#reward-plus")).to_be_enabled()
        # Leaving gives the keys back to the live robot: a reward of the run as it stands.
        page.locator("#replay-tick").focus()
        page.keyboard.press("Escape")
        expect(page.locator("#replay-body")).to_be_hidden()
        expect(page.locator("body")).not_to_have_class(REPLAYING)
        page.locator("#replay-card").focus()
        live = posted_reward(page, "+")
        assert live["value"] == 1 and live.get("episode") != 0, live
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")
