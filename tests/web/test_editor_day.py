"""A DP programmer's day in the editor, in real Chromium against a live service.

The editor fits from 1024 px; keystrokes save on commit, not per key; an edit made while
the service is away is kept and sent, version-checked, when it is back; every stimulus,
behaviour and condition says what it means; and "Run this network" runs the open network
(and another version of it on the same seeds) and shows the outcome beside the matrix.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Page, Route, expect
from webpage import cell, eventually, open_view

from bench.liveserver import LiveServer, live_server
from server.cli import main


def association(server: LiveServer, network: str, stimulus: str, behaviour: str) -> Any:
    data = server.client.get(f"/api/networks/{network}/associations").json()["data"]
    return next((a for a in data if (a["stimulus"], a["behaviour"]) == (stimulus, behaviour)), None)


def fresh_network(server: LiveServer, name: str, base: str = "dp") -> None:
    server.client.delete(f"/api/networks/{name}")
    r = server.client.post("/api/networks", json={"name": name, "base": base})
    assert r.status_code == 201, r.text


def versions(server: LiveServer, network: str) -> int:
    return int(server.client.get(f"/api/networks/{network}/versions").json()["count"])


def inside(page: Page, selector: str) -> None:
    """The element lies inside the viewport once scrolled to (nothing cut off at the side)."""
    locator = page.locator(selector)
    locator.scroll_into_view_if_needed()
    box = locator.bounding_box()
    size = page.viewport_size
    assert box is not None and size is not None
    assert box["x"] >= 0 and box["x"] + box["width"] <= size["width"] + 0.5, (selector, box)
    if box["height"] < size["height"] / 2:  # a control: all of it in view
        assert box["y"] >= 0 and box["y"] + box["height"] <= size["height"] + 0.5, (selector, box)


@pytest.mark.parametrize("width", [1024, 1440])
def test_the_editor_fits_the_window(page: Page, server: LiveServer, width: int) -> None:
    fresh_network(server, f"fit{width}")
    page.set_viewport_size({"width": width, "height": 800})
    open_view(page, server, f"editor/fit{width}")
    expect(page.locator("#net-title")).to_have_text(f"fit{width}")
    no_side_scroll = "document.documentElement.scrollWidth <= window.innerWidth"
    assert page.evaluate(no_side_scroll)
    for selector in (
        ".sidebar",
        "#matrix",
        "#cell-card",
        "#cell-save",
        "#run-card",
        "#run-net-start",
        "#history-card",
        "#revert",
        ".toolbar .tools",
    ):
        inside(page, selector)


def test_keystrokes_on_a_cell_are_one_version_saved_on_commit(
    page: Page, server: LiveServer
) -> None:
    fresh_network(server, "commit", base="innate")
    open_view(page, server, "editor/commit")
    page.click(cell(page, "Red", "stop"))
    start = versions(server, "commit")
    for key in ("Space", "5", "3", "l", "l"):
        page.keyboard.press(key)
    expect(page.locator(cell(page, "Red", "stop"))).to_have_text(".3")
    expect(page.locator("#draft-note")).to_contain_text("Unsaved: Red → stop")
    assert versions(server, "commit") == start  # nothing saved per key
    page.keyboard.press("ArrowDown")  # leaving the cell commits it
    eventually(lambda: association(server, "commit", "Red", "stop"))
    assert association(server, "commit", "Red", "stop")["strength"] == 0.3
    assert versions(server, "commit") == start + 1
    # Blur commits too: Space on another cell, then click outside the matrix.
    page.keyboard.press("Space")
    page.click("#net-title")
    eventually(lambda: versions(server, "commit") == start + 2)
    # Esc drops a draft; Enter with none opens the side panel, whose Enter saves.
    page.click(cell(page, "Green", "goforward5"))
    page.keyboard.press("Space")
    page.keyboard.press("Escape")
    expect(page.locator(cell(page, "Green", "goforward5"))).to_have_attribute(
        "data-present", "false"
    )
    page.keyboard.press("Enter")
    page.fill("#cell-form input[name=strength]", "0.25")
    page.keyboard.press("Enter")
    eventually(lambda: association(server, "commit", "Green", "goforward5"))
    assert versions(server, "commit") == start + 3
    expect(page.locator(cell(page, "Green", "goforward5"))).to_have_text(".25")


def test_an_edit_made_offline_is_kept_and_sent_when_the_service_is_back(
    page: Page, server: LiveServer
) -> None:
    fresh_network(server, "away", base="innate")
    open_view(page, server, "editor/away")

    def refuse(route: Route) -> None:
        route.abort()

    page.route("**/api/**", refuse)
    expect(page.locator("#offline")).to_be_visible()
    expect(page.locator("#offline")).to_contain_text("kept in this page")
    page.click(cell(page, "Yellow", "stop"))
    page.keyboard.press("Space")
    page.keyboard.press("7")
    page.keyboard.press("Enter")
    expect(page.locator(".toast").last).to_contain_text("kept in this page")
    expect(page.locator(cell(page, "Yellow", "stop"))).to_have_class(re.compile("waiting"))
    expect(page.locator("#draft-note")).to_contain_text("1 change kept")
    # Meanwhile someone else changes another cell: the kept edit goes on top of it.
    r = server.client.put("/api/networks/away/associations/Red/stop", json={"strength": 0.4})
    assert r.status_code == 200
    assert association(server, "away", "Yellow", "stop") is None

    page.unroute("**/api/**", refuse)
    expect(page.locator("#offline")).to_be_hidden()
    eventually(lambda: association(server, "away", "Yellow", "stop"), what="the kept edit")
    assert association(server, "away", "Yellow", "stop")["strength"] == 0.7
    assert association(server, "away", "Red", "stop")["strength"] == 0.4
    expect(page.locator("#draft-note")).to_be_hidden()
    expect(page.locator(cell(page, "Red", "stop"))).to_have_text(".4")


def test_stimuli_behaviours_and_conditions_say_what_they_mean(
    page: Page, server: LiveServer
) -> None:
    fresh_network(server, "explain")
    open_view(page, server, "editor/explain")
    row = page.locator('#matrix tbody th[scope=row]:text-is("Obstacle_L_R")')
    expect(row).to_have_attribute("title", re.compile("robot in the left lane, obstacle right"))
    head = page.locator('#matrix th.b[title^="goforward3:"]')
    expect(head).to_have_attribute("title", re.compile(r"0\.45 m/s"))
    expect(head.locator("small.sub")).to_have_text("0.45 m/s")
    turn = page.locator('#matrix th.b[title^="leftturn90:"]')
    expect(turn).to_have_attribute("title", re.compile("turning left"))
    page.click(cell(page, "Obstacle_L_R", "leftturn45"))
    expect(page.locator("#cell-meaning")).to_contain_text("obstacle right")
    expect(page.locator("#strength-scale")).to_be_visible()
    texts = page.locator("#matrix td.c .v").all_inner_texts()
    assert texts and not [t for t in texts if t.endswith(".00") or t.endswith(".0")], texts
    page.select_option("#run-net-form select[name=condition]", "kp")
    expect(page.locator("#run-net-condition")).to_contain_text("knowledge propagation")


@pytest.mark.parametrize("width", [1024, 1440])
def test_run_this_network_and_compare_it_with_an_earlier_version(
    page: Page, server: LiveServer, width: int, capsys: pytest.CaptureFixture[str]
) -> None:
    name = f"trial{width}"
    fresh_network(server, name)
    r = server.client.delete(f"/api/networks/{name}/associations/Red/stop", params={"force": True})
    assert r.status_code == 204  # version 2: no stopping at red
    page.set_viewport_size({"width": width, "height": 800})
    open_view(page, server, f"editor/{name}")
    form = "#run-net-form"
    page.fill(f"{form} input[name=episodes]", "0")
    count = server.client.get("/api/runs").json()["count"]
    page.click("#run-net-start")  # the browser refuses it and says why, at the field
    assert page.locator(f"{form} input[name=episodes]").evaluate("e => !e.checkValidity()")
    assert server.client.get("/api/runs").json()["count"] == count

    page.select_option(f"{form} select[name=condition]", "dp")
    page.fill(f"{form} input[name=episodes]", "2")
    page.fill(f"{form} input[name=seeds]", "2")
    page.select_option(f"{form} select[name=compare]", "v:1")
    before = server.client.get("/api/runs").json()["count"]
    page.click("#run-net-start")
    out = page.locator("#run-net-out")
    expect(out).to_have_attribute("data-state", "done")
    expect(out.locator(".side-a")).to_contain_text(f"{name} v2")
    expect(out.locator(".side-b")).to_contain_text(f"{name} v1")
    expect(out.locator(".side-a")).to_contain_text("2 episodes \u00d7 2 seeds")
    expect(out.locator(".run-diff")).to_contain_text(f"{name} v2 \u2212 {name} v1")
    expect(out.locator(".run-diff")).to_contain_text("paired by seed")
    expect(out.locator("svg.run-curve polyline.line-a")).to_have_attribute("data-points", "2")
    expect(out.locator("svg.run-curve polyline.line-b")).to_have_attribute("data-points", "2")
    inside(page, "#run-net-out")
    # Ordinary runs, one per seed and side, fast, on the same seeds.
    runs = server.client.get("/api/runs", params={"offset": before}).json()["data"]
    assert sorted((r["seed"], r["mode"], r["episodes"]) for r in runs) == [
        (0, "fast", 2),
        (0, "fast", 2),
        (1, "fast", 2),
        (1, "fast", 2),
    ]
    assert {r["status"] for r in runs} == {"finished"}
    rate = out.locator(".side-a .big").get_attribute("data-rate")
    successes = sum(r["successes"] for r in runs[:2])
    assert rate is not None and float(rate) == pytest.approx(successes / 4)
    # The command line the panel gives runs the same as the page's run of seed 0.
    cli = out.locator(".run-cli code").inner_text()
    assert cli == f"srlab simulate --condition dp --network {name} --episodes 2 --seed 0"
    capsys.readouterr()
    argv = [*shlex.split(cli)[1:], "--url", f"sqlite:///{server.database}", "--quiet", "--json"]
    assert main(argv) == 0
    seed_0 = next(r for r in runs[:2] if r["seed"] == 0)
    assert json.loads(capsys.readouterr().out)["successes"] == seed_0["successes"]


def test_runs_wait_for_a_free_slot_and_say_so(page: Page, tmp_path: Path) -> None:
    with live_server(tmp_path / "slots.db", env={"SRLAB_MAX_RUNS": "1"}) as server:
        busy = server.client.post(
            "/api/runs", json={"condition": "innate", "mode": "realtime", "hz": 1}
        ).json()
        assert server.client.post(f"/api/runs/{busy['id']}/start").status_code == 200
        open_view(page, server, "editor/dp")  # a built-in network runs as it is
        page.fill("#run-net-form input[name=episodes]", "1")
        page.fill("#run-net-form input[name=seeds]", "1")
        page.click("#run-net-start")
        out = page.locator("#run-net-out")
        expect(out).to_contain_text("waiting for a free run slot")
        assert server.client.post(f"/api/runs/{busy['id']}/stop").status_code == 200
        expect(out).to_have_attribute("data-state", "done")
        expect(out).not_to_contain_text("waiting for a free run slot")
        expect(out.locator(".side-a")).to_contain_text("dp")
        page.goto("about:blank")  # no poll of the page in flight while the service stops
