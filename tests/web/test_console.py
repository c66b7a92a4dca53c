"""The trainer console in real Chromium against a live `srlab serve`: what a trainer does."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from browser import artifact
from liveharness import wait_status
from playwright.sync_api import Browser, Page, expect
from webpage import cell, eventually, open_view

from bench.liveserver import LiveServer, stop_server


def create_run(server: LiveServer, **body: Any) -> int:
    r = server.client.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run_id: int = r.json()["id"]
    return run_id


def test_a_fast_run_created_in_the_console_fills_the_heatmap_and_the_curve(
    page: Page, server: LiveServer
) -> None:
    open_view(page, server, "console")
    page.click("#new-run > summary")
    form = page.locator("#new-run-form")
    form.locator("select[name=condition]").select_option("kp")
    form.locator("select[name=mode]").select_option("fast")
    form.locator("input[name=episodes]").fill("8")
    form.locator("input[name=seed]").fill("2")
    form.locator("button[type=submit]").click()

    expect(page.locator("#run-status")).to_have_text("finished", timeout=60_000)
    run = server.client.get("/api/runs").json()["data"][-1]
    assert (run["condition"], run["mode"], run["episodes"], run["seed"]) == ("kp", "fast", 8, 2)
    assert page.url.endswith(f"#/console/{run['id']}")

    ltm = server.client.get(f"/api/runs/{run['id']}/ltm").json()["data"]
    assert ltm, "a kp run learns something in 8 episodes"
    for m in ltm[:5]:
        expect(page.locator(cell(page, m["stimulus"], m["behaviour"], "#heatmap"))).to_contain_text(
            f"{m['reliability']:.2f}".lstrip("0") if m["reliability"] < 0.995 else "1"
        )
    filled = page.locator("#heatmap td.c span.v").count()
    assert filled == len(ltm)
    # RLTM: KP's reliabilities for the camera, on the same layout.
    page.check("input[name=memory][value=rltm]")
    rltm = server.client.get(f"/api/runs/{run['id']}/rltm").json()["data"]
    expect(page.locator("#heatmap td.c span.v")).to_have_count(len(rltm))
    # The learning curve has a dot per episode.
    expect(page.locator("#curve svg .dots circle")).to_have_count(8)
    expect(page.locator("#st-success")).to_have_text(str(run["successes"]))


def test_reward_keys_on_a_realtime_run_land_in_the_reward_log_with_their_credit(
    page: Page, server: LiveServer
) -> None:
    run_id = create_run(server, condition="kp", mode="realtime", hz=20, seed=5)
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    open_view(page, server, f"console/{run_id}")
    expect(page.locator("#run-status")).to_have_text("running")
    eventually(lambda: page.locator("#st-tick").inner_text().isdigit(), what="live ticks")
    expect(page.locator("#st-threshold")).to_contain_text("threshold 0.25")
    page.wait_for_timeout(500)  # some STM to credit

    page.keyboard.press("+")
    effect = page.locator("#reward-effect")
    expect(effect).to_contain_text("credited")

    def trainer_rewards() -> list[dict[str, Any]]:
        log = server.client.get(f"/api/runs/{run_id}/rewards").json()["data"]
        return [r for r in log if r["source"] == "trainer"]

    first = eventually(trainer_rewards, what="the reward in the log")
    assert [r["value"] for r in first] == [1.0]
    # The effect shown is the one stored: the same number of credited STM records.
    applied = eventually(lambda: trainer_rewards()[0]["applied"] and trainer_rewards()[0])
    expect(effect.locator(".head")).to_contain_text(f"credited {applied['credited']} STM")
    if applied["credited"]:
        expect(effect.locator("details.raw tbody tr")).to_have_count(min(applied["credited"], 200))

    page.keyboard.press("-")
    eventually(lambda: [r["value"] for r in trainer_rewards()] == [1.0, -1.0], what="-1 logged")
    page.screenshot(path=artifact("console.png"))

    # Run control from the page: pause (Shift+P), resume, stop.
    page.keyboard.press("Shift+P")
    expect(page.locator("#run-status")).to_have_text("paused")
    page.click("#run-resume")
    expect(page.locator("#run-status")).to_have_text("running")
    page.click("#run-stop")
    expect(page.locator("#run-status")).to_have_text("stopped")
    wait_status(server.client, run_id, "stopped")
    expect(page.locator("#reward-plus")).to_be_disabled()


def test_rewarding_a_run_that_is_not_running_shows_why(page: Page, server: LiveServer) -> None:
    run_id = create_run(server, condition="rp", mode="realtime", hz=20)
    open_view(page, server, f"console/{run_id}")
    expect(page.locator("#run-status")).to_have_text("created")
    page.keyboard.press("+")
    expect(page.locator(".toast.error").last).to_contain_text(
        "rewards go to a running or paused run"
    )
    assert server.client.get(f"/api/runs/{run_id}/rewards").json()["count"] == 0


def shows(run_id: int) -> re.Pattern[str]:
    """The 3D view's panel line about a run ("Run 3: kp, seed 0, ...")."""
    return re.compile(rf"\bRun {run_id}:")


def test_the_3d_link_opens_the_view_on_that_run_not_the_newest(
    page: Page, server: LiveServer
) -> None:
    chosen = create_run(server, condition="expert", episodes=1)
    server.client.post(f"/api/runs/{chosen}/start").raise_for_status()
    wait_status(server.client, chosen, "finished")
    newest = create_run(server, condition="delayed", mode="realtime", hz=20)
    server.client.post(f"/api/runs/{newest}/start").raise_for_status()
    try:
        open_view(page, server, f"console/{chosen}")
        link = page.locator("#view3d")
        port = server.client.get("/api/health").json()["viser_port"]
        # A URL naming the run: the view's socket gets it back on every reconnect.
        expect(link).to_have_attribute("href", f"http://127.0.0.1:{port}/run/{chosen}")
        with page.context.expect_page() as opened:
            link.click()  # POST /api/runs/{chosen}/view, then the view opens on the link
        view = opened.value
        view.wait_for_url(f"http://127.0.0.1:{port}/run/{chosen}")
        view.get_by_text(shows(chosen)).first.wait_for(timeout=90_000)
        for _ in range(10):  # the view looks for new runs every second: it stays put
            view.wait_for_timeout(300)
            text = view.inner_text("body")
            assert shows(chosen).search(text) and not shows(newest).search(text), text
        view.close()
    finally:
        server.client.post(f"/api/runs/{newest}/stop")


def test_a_bad_run_shows_the_apis_message_and_keeps_the_form(
    page: Page, server: LiveServer
) -> None:
    open_view(page, server, "console")
    page.click("#new-run > summary")
    form = page.locator("#new-run-form")
    form.locator("input[name=hz]").fill("5000")  # over the API's limit
    form.locator("input[name=seed]").fill("77")
    form.evaluate("f => f.noValidate = true")  # let the API judge it, as a script would
    form.locator("button[type=submit]").click()
    expect(page.locator(".toast.error").last).to_contain_text("hz")
    expect(form).to_be_visible()
    expect(form.locator("input[name=seed]")).to_have_value("77")


@pytest.mark.parametrize("view", ["editor", "console"])
def test_the_page_recovers_when_the_server_restarts(
    browser: Browser, tmp_path: Path, view: str, start_server: Callable[..., LiveServer]
) -> None:
    first = start_server(tmp_path / "restart.db")
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page = context.new_page()
        page.set_default_timeout(90_000)
        assert first.client.post("/api/networks", json={"name": "kept"}).status_code == 201
        run_id = create_run(first, condition="expert", episodes=1)
        open_view(page, first, "editor/kept" if view == "editor" else f"console/{run_id}")
        expect(page.locator("#conn")).to_have_class("conn online")

        stop_server(first)
        expect(page.locator("#offline")).to_be_visible()
        if view == "editor":
            page.fill("#new-network-form input[name=name]", "typed-while-down")
        second = start_server(tmp_path / "restart.db", port=first.port)
        try:
            expect(page.locator("#offline")).to_be_hidden()
            expect(page.locator("#conn")).to_have_class("conn online")
            # The page reloads what it shows once the service is back: act after that.
            expect(page.locator("body")).not_to_have_attribute("aria-busy", "true")
            if view == "editor":
                expect(page.locator("#new-network-form input[name=name]")).to_have_value(
                    "typed-while-down"
                )
                page.click(cell(page, "Red", "stop"))
                page.keyboard.press("Space")
                page.keyboard.press("Enter")  # a cell's keystrokes are saved on commit
                eventually(
                    lambda: second.client.get("/api/networks/kept").json()["version"] == 2,
                    what="an edit after the restart",
                )
            else:
                page.click("#run-start")
                expect(page.locator("#run-status")).to_have_text("finished", timeout=60_000)
        finally:
            stop_server(second)
    finally:
        context.close()


def test_new_associations_appear_in_the_feed_as_they_pass_the_threshold(
    page: Page, server: LiveServer
) -> None:
    run_id = create_run(server, condition="kp", episodes=60, seed=3)
    open_view(page, server, f"console/{run_id}")
    expect(page.locator("#run-status")).to_have_text("created")
    page.click("#run-start")
    expect(page.locator("#run-status")).to_have_text("finished", timeout=60_000)
    feed = page.locator("#assoc-feed li.promoted")
    expect(feed.first).to_be_visible()
    network = server.client.get(f"/api/runs/{run_id}/network").json()["data"]
    learned = {(a["stimulus"], a["behaviour"]) for a in network if a["source"] != "innate"}
    shown = " | ".join(feed.all_inner_texts())
    assert any(f"{s} → {b}" in shown for s, b in learned), (shown, learned)
    # In the heatmap the promoted pair is outlined as part of the run's network.
    s, b = next(iter(sorted(learned)))
    expect(page.locator(cell(page, s, b, "#heatmap"))).to_have_class(re.compile(r"\bin-net\b"))


def test_the_live_state_says_what_made_the_behaviour_run_and_tallies_the_origins(
    page: Page, server: LiveServer
) -> None:
    worlds = server.client.get("/api/worlds").json()
    other = next(w["name"] for w in worlds if not w["default"])
    definitions = server.client.get("/api/sensor-definitions").json()
    sensors = next(d["name"] for d in definitions if not d["default"])
    open_view(page, server, "console")
    page.click("#new-run > summary")
    form = page.locator("#new-run-form")
    form.locator("select[name=condition]").select_option("kp")
    form.locator("select[name=mode]").select_option("realtime")
    form.locator("input[name=hz]").fill("20")
    form.locator("select[name=world]").select_option(other)
    form.locator("select[name=sensors]").select_option(sensors)
    form.locator("button[type=submit]").click()
    expect(page.locator("#run-status")).to_have_text("running")
    run = server.client.get("/api/runs").json()["data"][-1]
    assert (run["world"], run["sensors"]) == (other, sensors)
    try:
        expect(page.locator("#run-select")).to_contain_text(f"{other}/{sensors}")
        # "leftturn30 · released by Obstacle_M_M (kp)": the stimulus and the source.
        how = page.locator("#st-behaviour .how")
        expect(how).to_have_text(
            re.compile(r"^· released by \w+ \((innate|designed|dp|learned|kp|expert)\)"),
            timeout=90_000,
        )
        # The run's ticks by origin, from its live state: "designed 70% · default 20% ...".
        origins = page.locator("#st-origins")
        expect(origins).to_have_text(re.compile(r"^Ticks by origin: [a-z]+ (<1|\d+)%"))
        counts = server.client.get(f"/api/runs/{run['id']}").json()["live"]["ticks_by_origin"]
        most = max(counts, key=counts.get)
        expect(origins).to_contain_text(most)
    finally:
        server.client.post(f"/api/runs/{run['id']}/stop")
    wait_status(server.client, run["id"], "stopped")


def test_an_empty_memory_grid_says_why(page: Page, server: LiveServer) -> None:
    # A run that never learns, and a learning run without KP: their empty grids explain.
    innate = create_run(server, condition="innate", mode="fast", episodes=1, seed=1)
    assert server.client.post(f"/api/runs/{innate}/start").status_code == 200
    wait_status(server.client, innate, "finished", timeout=240)
    open_view(page, server, f"console/{innate}")
    note = page.locator("#memory-empty")
    expect(note).to_contain_text("innate does not learn")
    rp = create_run(server, condition="rp", mode="fast", episodes=1, seed=1)
    assert server.client.post(f"/api/runs/{rp}/start").status_code == 200
    wait_status(server.client, rp, "finished", timeout=240)
    open_view(page, server, f"console/{rp}")
    page.check("input[name=memory][value=rltm]")
    expect(note).to_contain_text("rp runs without it")
    page.check("input[name=memory][value=ltm]")
    if server.client.get(f"/api/runs/{rp}/ltm").json()["data"]:
        expect(note).to_be_hidden()
