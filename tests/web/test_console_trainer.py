"""The trainer console from 1024 px up, as a person training a robot by hand uses it.

The new-run form inside the window with its errors beside their fields, the rewards of
every source on a timeline, graded rewards with notes and an undo that is a new reward,
the credit summed per S-R pair, a learning curve by episode number, keys that do not act
behind a dialog or per key repeat, and messages that do not pile up while offline.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from browser import artifact
from conftest import sized_page
from liveharness import wait_episodes, wait_status
from playwright.sync_api import Browser, Page, Route, expect
from webpage import eventually, open_view

from bench.liveserver import LiveServer, stop_server

WIDTHS = [1024, 1440]


def inside(page: Page, selector: str, vertical: bool = True) -> None:
    """Every element matching `selector` lies inside the viewport (and the page is no wider)."""
    size = page.viewport_size
    assert size is not None
    boxes = page.locator(selector)
    assert boxes.count() > 0, selector
    for i in range(boxes.count()):
        box = boxes.nth(i).bounding_box()
        assert box is not None, f"{selector} #{i} is not shown"
        assert box["x"] >= 0 and box["x"] + box["width"] <= size["width"], (selector, i, box)
        if vertical:
            assert box["y"] >= 0 and box["y"] + box["height"] <= size["height"], (selector, i, box)
    scroll = page.evaluate("document.documentElement.scrollWidth")
    assert scroll <= size["width"], f"the page is {scroll} px wide in a {size['width']} px window"


def create_run(server: LiveServer, **body: Any) -> int:
    r = server.client.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run_id: int = r.json()["id"]
    return run_id


def started(server: LiveServer, **body: Any) -> int:
    run_id = create_run(server, **body)
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    return run_id


def trainer_rewards(server: LiveServer, run_id: int) -> list[dict[str, Any]]:
    log = server.client.get(f"/api/runs/{run_id}/rewards", params={"limit": 1000}).json()
    return [r for r in log["data"] if r["source"] == "trainer"]


def logged(server: LiveServer, run_id: int, n: int) -> list[dict[str, Any]] | None:
    """The run's trainer rewards once there are `n` (None before)."""
    rewards = trainer_rewards(server, run_id)
    return rewards if len(rewards) >= n else None


@pytest.mark.parametrize("width", WIDTHS)
def test_the_new_run_form_lies_inside_the_window(
    browser: Browser, server: LiveServer, width: int
) -> None:
    with sized_page(browser, width) as page:
        open_view(page, server, "console")
        page.click("#new-run > summary")
        form = page.locator("#new-run-form")
        expect(form).to_be_visible()
        inside(page, "#new-run-form")
        inside(page, "#new-run-form label, #new-run-form button[type=submit]")
        page.screenshot(path=artifact(f"console-new-run-{width}.png"))


def test_the_form_names_trainer_for_the_keyboard_and_says_what_a_condition_means(
    page: Page, server: LiveServer
) -> None:
    open_view(page, server, "console")
    page.click("#new-run > summary")
    condition = page.locator("#new-run-form select[name=condition]")
    expect(condition).to_have_value("trainer")
    expect(condition.locator("option[value=trainer]")).to_contain_text("keyboard")
    about = page.locator("#condition-about")
    expect(about).to_contain_text("no reinforcement program")
    condition.select_option("rp")
    expect(about).to_contain_text("reward program rewards by itself")
    condition.select_option("innate")
    expect(about).to_contain_text("change nothing")


def test_a_value_the_api_refuses_is_shown_beside_its_field(
    browser: Browser, server: LiveServer
) -> None:
    with sized_page(browser, 1024) as page:
        open_view(page, server, "console")
        page.click("#new-run > summary")
        form = page.locator("#new-run-form")
        form.locator("input[name=hz]").fill("5000")  # over the API's limit
        form.evaluate("f => f.noValidate = true")  # the API judges it: its 422 names hz
        before = server.client.get("/api/runs").json()["count"]
        form.locator("button[type=submit]").click()
        error = form.locator("label:has(input[name=hz]) .field-error")
        expect(error).to_contain_text("1000")
        expect(form.locator("#new-run-error")).to_be_visible()
        inside(page, "#new-run-form label:has(input[name=hz]) .field-error")
        assert server.client.get("/api/runs").json()["count"] == before
        form.locator("input[name=hz]").fill("20")
        expect(error).to_have_count(0)
        # The browser's own refusal (eta past its max) also shows beside the field.
        form.evaluate("f => f.noValidate = false")
        form.locator("input[name=eta]").fill("2")
        form.locator("button[type=submit]").click()
        expect(form.locator("label:has(input[name=eta]) .field-error")).to_be_visible()
        assert server.client.get("/api/runs").json()["count"] == before


@pytest.mark.parametrize("width", WIDTHS)
def test_the_reward_buttons_fit_and_graded_rewards_with_notes_and_an_undo_are_logged(
    browser: Browser, server: LiveServer, width: int
) -> None:
    run_id = started(server, condition="trainer", mode="realtime", hz=20, seed=width)
    try:
        with sized_page(browser, width) as page:
            open_view(page, server, f"console/{run_id}")
            expect(page.locator("#run-status")).to_have_text("running")
            expect(page.locator("#train-about")).to_contain_text("trainer")
            inside(page, "#train-card .reward-buttons button, #reward-undo, #reward-note", False)
            expect(page.locator("#reward-undo")).to_be_disabled()

            page.fill("#reward-note", "kept its lane")
            page.click("#reward-plus-half")
            given = eventually(lambda: trainer_rewards(server, run_id), what="+0.5 logged")
            assert [(r["value"], r["note"]) for r in given] == [(0.5, "kept its lane")]
            mine = page.locator("#my-rewards li")
            expect(mine.first).to_contain_text("kept its lane")
            expect(page.locator("#reward-note")).to_have_value("")

            page.click("#reward-undo")
            first = given[0]["id"]
            log = eventually(lambda: logged(server, run_id, 2), what="the undo logged")
            assert [(r["value"], r["note"]) for r in log] == [
                (0.5, "kept its lane"),
                (-0.5, f"undo of #{first}"),
            ]
            expect(page.locator(f'#my-rewards li[data-id="{first}"]')).to_contain_text(
                f"undone by #{log[1]['id']}"
            )
            expect(page.locator("#reward-undo")).to_be_disabled()  # the undo is not undone

            page.click("#reward-minus")
            eventually(lambda: len(trainer_rewards(server, run_id)) == 3, what="-1 logged")
            # Every source on the timeline: the person's three rewards at least.
            marks = page.locator('#reward-timeline rect.mark[data-source="trainer"]')
            expect(marks).to_have_count(3)
            expect(page.locator("#reward-counts")).to_contain_text("trainer 3")
            page.screenshot(path=artifact(f"console-train-{width}.png"), full_page=True)
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")


def test_an_rp_runs_program_rewards_are_on_the_timeline_beside_the_persons(
    page: Page, server: LiveServer
) -> None:
    run_id = started(server, condition="rp", mode="realtime", hz=50, seed=1)
    try:
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#train-about")).to_contain_text("use trainer")
        program = page.locator('#reward-timeline rect.mark[data-source="program"]')
        expect(program.first).to_be_attached()
        expect(page.locator("#reward-counts")).to_contain_text("program")
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")


STEPS_TO_A_RESPONSE = 3000
"""A bound on the ticks stepped to the robot's first innate response (its first corner is
about a hundred ticks from the start)."""


def step_to_an_innate_response(server: LiveServer, run_id: int) -> dict[str, Any]:
    """Step the paused run a tick at a time until a tick runs an innate response.

    An innate response (a corner's turn, Table I) answers a stimulus, so its tick leaves a
    record in STM; the step is taken only if that tick did not end the episode (which
    empties STM). Returns the run as that step answered it.
    """
    run: dict[str, Any] = server.client.get(f"/api/runs/{run_id}").json()
    for _ in range(STEPS_TO_A_RESPONSE):
        before = run
        r = server.client.post(f"/api/runs/{run_id}/step")
        assert r.status_code == 200, r.text
        run = r.json()
        innate = run["live"]["ticks_by_origin"].get("innate", 0)
        if (
            innate > before["live"]["ticks_by_origin"].get("innate", 0)
            and run["episodes_done"] == before["episodes_done"]
        ):
            return run
    raise AssertionError(f"no innate response in {STEPS_TO_A_RESPONSE} ticks: {run}")


def test_the_credit_is_summed_per_pair_with_the_raw_rows_one_click_away(
    page: Page, server: LiveServer
) -> None:
    run_id = started(server, condition="trainer", mode="realtime", hz=20, seed=3)
    try:
        # Held, then stepped to a tick that left a record in STM: the reward has something
        # to credit whatever the machine's speed.
        assert server.client.post(f"/api/runs/{run_id}/pause").status_code == 200
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#run-status")).to_have_text("paused")
        run = step_to_an_innate_response(server, run_id)
        # Slowest, so that only a tick or two runs between the resume and the reward's
        # boundary: the robot is turning at a corner then, which ends no episode.
        r = server.client.post(f"/api/runs/{run_id}/rate", json={"hz": 0.5})
        assert r.status_code == 200, r.text
        assert server.client.post(f"/api/runs/{run_id}/resume").status_code == 200
        expect(page.locator("#run-status")).to_have_text("running")
        page.click("#reward-plus")
        applied = eventually(
            lambda: (r := trainer_rewards(server, run_id)) and r[0]["applied"] and r[0],
            what="the reward applied",
        )
        assert applied["episode"] == run["live"]["episode"]
        assert applied["tick"] > run["ticks"]
        assert applied["credited"] > 0, applied
        effect = page.locator("#reward-effect")
        expect(effect.locator(".head")).to_contain_text(f"credited {applied['credited']} STM")
        pairs = effect.locator("table.pairs tbody tr")
        expect(pairs.first).to_be_visible()
        counts = [int(t) for t in pairs.locator("td:nth-child(2)").all_inner_texts()]
        assert sum(counts) == min(applied["credited"], 200)
        assert len(counts) == len(set(pairs.locator("td:first-child").all_inner_texts()))
        raw = effect.locator("details.raw tbody tr")
        expect(raw.first).to_be_hidden()
        effect.locator("details.raw summary").click()
        expect(raw).to_have_count(min(applied["credited"], 200))
        expect(raw.first).to_be_visible()
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")


def test_a_reward_to_a_condition_that_does_not_learn_says_so(
    page: Page, server: LiveServer
) -> None:
    run_id = started(server, condition="innate", mode="realtime", hz=20)
    try:
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#run-status")).to_have_text("running")
        page.click("#reward-minus")
        why = page.locator("#reward-effect .why")
        expect(why).to_contain_text("innate does not learn")
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")


def test_keys_do_not_reach_the_robot_behind_a_dialog_and_a_held_key_is_one_reward(
    page: Page, server: LiveServer
) -> None:
    run_id = started(server, condition="trainer", mode="realtime", hz=20, seed=8)
    try:
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#run-status")).to_have_text("running")
        page.keyboard.press("?")
        expect(page.locator("#help-dialog")).to_be_visible()
        page.keyboard.press("-")  # reads the help: no punishment
        page.keyboard.press("Escape")
        expect(page.locator("#help-dialog")).to_be_hidden()
        # Held: the second and third keydown are repeats.
        page.keyboard.down("=")
        page.keyboard.down("=")
        page.keyboard.down("=")
        page.keyboard.up("=")
        page.keyboard.press("_")  # a marker: once it is logged, so is all before it
        log = eventually(
            lambda: (r := trainer_rewards(server, run_id)) and r[-1]["value"] == -1.0 and r,
            what="the marker logged",
        )
        assert [r["value"] for r in log] == [1.0, -1.0]
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")


def test_the_curve_puts_each_episode_at_its_number(page: Page, server: LiveServer) -> None:
    open_view(page, server, "console")
    # Episodes 0, 1 and 9 only: 9 sits at the right end, the gap is said, nothing shifts.
    xs = page.evaluate(
        """async () => {
          const { learningCurve } = await import("/js/chart.js");
          const box = document.querySelector("#curve");
          learningCurve(box, [{episode: 9, outcome: "success"}, {episode: 0, outcome: "failure"},
                              {episode: 1, outcome: "success"}]);
          return [...box.querySelectorAll(".dots circle")].map(
            (c) => [Number(c.dataset.episode), Number(c.getAttribute("cx"))]);
        }"""
    )
    by_episode = dict(xs)
    assert sorted(by_episode) == [0, 1, 9]
    step = by_episode[1] - by_episode[0]
    assert step > 0 and abs(by_episode[9] - by_episode[0] - 9 * step) < 0.01
    expect(page.locator("#curve .summary")).to_contain_text("2/3 successes")
    expect(page.locator("#curve .summary")).to_contain_text("7 not loaded yet")


def test_episodes_the_first_load_missed_are_fetched_while_the_run_goes_on(
    page: Page, server: LiveServer
) -> None:
    run_id = started(server, condition="expert", mode="realtime", hz=1000, seed=2)
    try:
        wait_episodes(server.client, run_id, 2)
        hidden = {"done": False}

        def first_load_sees_none(route: Route) -> None:
            # As if the page had loaded before these episodes: an empty first page.
            if hidden["done"]:
                route.continue_()
                return
            hidden["done"] = True
            route.fulfill(
                status=200,
                content_type="application/json",
                body=json.dumps({"data": [], "count": 0}),
            )

        page.route(f"**/api/runs/{run_id}/episodes?*", first_load_sees_none)
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#run-status")).to_have_text("running")

        def contiguous() -> bool:
            numbers = sorted(
                int(n)
                for n in page.locator("#curve .dots circle").evaluate_all(
                    "cs => cs.map(c => c.dataset.episode)"
                )
            )
            return len(numbers) >= 2 and numbers == list(range(len(numbers)))

        eventually(contiguous, what="episodes 0.. on the curve with no gap")
        assert hidden["done"]
        assert server.client.get(f"/api/runs/{run_id}").json()["status"] == "running"
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")


def test_offline_messages_do_not_pile_up_and_go_when_the_service_is_back(
    browser: Browser, tmp_path: Path, start_server: Callable[..., LiveServer]
) -> None:
    first = start_server(tmp_path / "offline.db")
    try:
        run_id = create_run(first, condition="trainer", mode="realtime", hz=20)
        with sized_page(browser, 1024) as page:
            open_view(page, first, f"console/{run_id}")
            expect(page.locator("#conn")).to_have_class("conn online")
            stop_server(first)
            banner = page.locator("#offline")
            expect(banner).to_be_visible()
            # It promises only what is true: the console's rewards are not kept (the
            # editor's edits are, and it says so).
            expect(banner).to_contain_text("Rewards and run controls given now are not sent")
            expect(banner).not_to_contain_text("rewards are kept")
            # The console polls every 2 s: the same failure is counted, not stacked.
            offline = page.locator(".toast.offline")
            expect(offline.locator(".count")).to_have_text("\N{MULTIPLICATION SIGN}2")
            expect(offline).to_have_count(1)
            second = start_server(tmp_path / "offline.db", port=first.port)
            try:
                expect(banner).to_be_hidden()
                expect(page.locator(".toast.ok")).to_contain_text("The service is back")
                expect(page.locator(".toast.offline")).to_have_count(0)
            finally:
                stop_server(second)
    finally:
        if first.process.poll() is None:
            stop_server(first)


def test_a_keypress_reward_carries_the_tick_shown_and_the_list_shows_its_credit(
    page: Page, server: LiveServer
) -> None:
    """Paused and stepped past an innate response, the person presses + while the console
    shows tick T: the reward says it saw T, and credits the reaction window before it."""
    run_id = started(server, condition="trainer", mode="realtime", hz=20, seed=3)
    try:
        assert server.client.post(f"/api/runs/{run_id}/pause").status_code == 200
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#run-status")).to_have_text("paused")
        run = step_to_an_innate_response(server, run_id)
        for _ in range(6):  # the response falls inside the window (4 to 80 ticks at 20 Hz)
            run = server.client.post(f"/api/runs/{run_id}/step").json()
        shown = run["live"]["tick"]
        expect(page.locator("#st-tick")).to_have_text(str(shown))
        page.keyboard.press("+")
        applied = eventually(
            lambda: (r := trainer_rewards(server, run_id)) and r[0]["applied"] and r[0],
            what="the reward applied",
        )
        assert applied["tick_seen"] == shown
        assert applied["window"] == [shown - 80, shown]  # paused: up to the tick shown
        assert applied["credited"] > 0, applied
        item = page.locator(f'#my-rewards li[data-id="{applied["id"]}"]')
        expect(item).to_contain_text(
            re.compile(rf"credited {applied['credited']} records?, ticks \d+–\d+")  # noqa: RUF001
        )
        expect(page.locator("#reward-effect .head")).to_contain_text(f"seen at tick {shown}")
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")
