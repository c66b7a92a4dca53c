"""What a new user meets first on the console and the editor, in real Chromium.

Each test is one thing a person saw wrong: the console opening on somebody else's finished
run, two play buttons, a red field after a Create that worked, a comparison that does not
say which side is which, a threshold not named, a sign on nothing, buttons that looked
alive when they were not, and pages laid out for one width only.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from liveharness import wait_status
from playwright.sync_api import Browser, Page, expect
from webpage import open_view

from bench.liveserver import LiveServer

WIDTHS = (1024, 1280, 1920)
OVERFLOWING = """() => [...document.querySelectorAll('.view:not([hidden]) *')].filter((e) => {
  const s = getComputedStyle(e);
  if (s.display === 'none' || !e.offsetParent || e.closest('details:not([open])')) return false;
  if (s.overflowX === 'auto' || s.overflowX === 'scroll') return false;
  return e.clientWidth > 0 && e.scrollWidth > e.clientWidth + 1;
}).map((e) => `${e.tagName}#${e.id}.${e.className}: ${e.textContent.trim().slice(0, 30)}`)"""


def create_run(server: LiveServer, **body: Any) -> int:
    r = server.client.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run_id: int = r.json()["id"]
    return run_id


@pytest.fixture
def fresh(browser: Browser) -> Iterator[Page]:
    """A page in a context of its own: no localStorage from another test."""
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    page.set_default_timeout(90_000)
    try:
        yield page
    finally:
        context.close()


def test_the_console_opens_on_the_run_shown_last_else_a_running_one(
    fresh: Page, server: LiveServer
) -> None:
    running = create_run(server, condition="trainer", mode="realtime", hz=5)
    assert server.client.post(f"/api/runs/{running}/start").status_code == 200
    finished = create_run(server, condition="innate", mode="fast", episodes=1)
    assert server.client.post(f"/api/runs/{finished}/start").status_code == 200
    wait_status(server.client, finished, "finished")
    try:
        # The newest run is a finished one nobody is watching: the running one is shown.
        open_view(fresh, server, "console")
        expect(fresh.locator("#run-select")).to_have_value(str(running))
        # Once this browser has shown the finished one, that is where it opens.
        open_view(fresh, server, f"console/{finished}")
        expect(fresh.locator("#run-status")).to_have_text("finished")
        open_view(fresh, server, "console")
        expect(fresh.locator("#run-select")).to_have_value(str(finished))
    finally:
        server.client.post(f"/api/runs/{running}/stop")


def test_one_play_button_at_a_time_says_what_it_does(page: Page, server: LiveServer) -> None:
    run_id = create_run(server, condition="trainer", mode="realtime", hz=5)
    open_view(page, server, f"console/{run_id}")
    start, resume = page.locator("#run-start"), page.locator("#run-resume")
    expect(start).to_have_text("▶ Start")
    expect(resume).to_be_hidden()
    # Half steps look disabled while nothing can be rewarded.
    half = page.locator("#reward-plus-half")
    expect(half).to_be_disabled()
    assert float(half.evaluate("e => getComputedStyle(e).opacity")) < 0.6
    start.click()
    expect(page.locator("#run-status")).to_have_text("running")
    expect(start).to_be_hidden()
    expect(resume).to_be_visible()
    expect(resume).to_be_disabled()
    expect(half).to_be_enabled()
    assert float(half.evaluate("e => getComputedStyle(e).opacity")) > 0.8
    page.click("#run-pause")
    expect(page.locator("#run-status")).to_have_text("paused")
    expect(resume).to_be_enabled()
    expect(start).to_be_hidden()
    page.click("#run-stop")
    expect(page.locator("#run-status")).to_have_text("stopped")
    expect(resume).to_be_hidden()
    expect(start).to_have_text("▶ Continue")
    expect(start).to_have_attribute(
        "title",
        "Go on from the end of its last stored episode"
        " (the episode it stopped in runs again from its start)",
    )


def test_a_punishment_that_changes_nothing_shows_no_sign(page: Page, server: LiveServer) -> None:
    run_id = create_run(server, condition="trainer", mode="realtime", hz=10, seed=4)
    open_view(page, server, f"console/{run_id}")
    page.click("#run-start")
    expect(page.locator("#run-status")).to_have_text("running")
    try:
        # Punish until a punishment credits STM records: the trainer's pairs are new to
        # LTM, at reliability 0, so a punishment leaves them there.
        pairs = page.locator("#reward-effect table.pairs")
        head = page.locator("#reward-effect .head")
        for _ in range(120):
            before = head.text_content() if head.count() else ""
            page.click("#reward-minus")
            expect(head).not_to_have_text(before or "")  # this punishment's effect
            if pairs.count():
                break
            page.wait_for_timeout(500)
        credit = pairs.locator("tbody td:nth-child(3)")
        expect(credit.first).to_be_visible()
        shown = credit.all_text_contents()
        minus_zero = "\u22120.000"
        assert "0.000" in shown and "+0.000" not in shown and minus_zero not in shown, shown
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")


def test_the_name_field_is_not_red_after_a_create_that_worked(
    page: Page, server: LiveServer
) -> None:
    open_view(page, server, "editor")
    name = page.locator("#new-network-form input[name=name]")
    name.fill("details-net")
    page.click("#new-network-form button[type=submit]")
    expect(page.locator("#net-title")).to_have_text("details-net")
    assert name.input_value() == ""
    assert not name.evaluate("e => e.matches(':user-invalid')")


def test_the_comparison_names_both_sides_and_the_smallest_p_three_seeds_allow(
    page: Page, server: LiveServer
) -> None:
    server.client.post("/api/networks", json={"name": "cmp-net", "base": "dp"})
    r = server.client.delete("/api/networks/cmp-net/associations/Red/stop", params={"force": True})
    assert r.status_code == 204  # version 2
    open_view(page, server, "editor/cmp-net")
    form = "#run-net-form"
    page.select_option(f"{form} select[name=condition]", "dp")
    page.fill(f"{form} input[name=episodes]", "2")
    page.fill(f"{form} input[name=seeds]", "3")
    page.select_option(f"{form} select[name=compare]", "v:1")
    page.click("#run-net-start")
    out = page.locator("#run-net-out")
    expect(out).to_have_attribute("data-state", "done")
    diff = out.locator(".run-diff")
    expect(diff).to_contain_text("cmp-net v2 \u2212 cmp-net v1:")
    expect(diff).to_contain_text("with 3 seeds p cannot go below 0.25")


def test_the_kp_inspector_names_the_threshold(page: Page, server: LiveServer) -> None:
    run_id = create_run(server, condition="kp", mode="fast", episodes=12, seed=1)
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    wait_status(server.client, run_id, "finished")
    threshold = server.client.get(f"/api/runs/{run_id}/kp").json()["insert_threshold"]
    assert threshold is not None
    open_view(page, server, f"console/{run_id}")
    badges = page.locator("#kp-inspector .kp-assoc summary .badge")
    expect(badges.first).to_be_visible()
    for badge in badges.all():
        text = badge.text_content() or ""
        if text == "in network":
            assert f"threshold {threshold:.2f}" in (badge.get_attribute("title") or "")
        else:
            assert text == f"below threshold {threshold:.2f}", text


@pytest.mark.parametrize("width", WIDTHS)
def test_the_pages_fit_each_width(browser: Browser, server: LiveServer, width: int) -> None:
    server.client.post("/api/networks", json={"name": "wide-net", "base": "dp"})
    run_id = create_run(server, condition="kp", mode="realtime", hz=5, seed=2)
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    context = browser.new_context(viewport={"width": width, "height": 900})
    page = context.new_page()
    page.set_default_timeout(90_000)
    try:
        open_view(page, server, "editor/wide-net")
        matrix = page.locator("#matrix")
        expect(matrix.locator("table.matrix")).to_be_visible()
        scroll, client = matrix.evaluate("e => [e.scrollWidth, e.clientWidth]")
        assert scroll <= client, f"the matrix scrolls sideways at {width} px: {scroll} > {client}"
        table = matrix.locator("table.matrix").evaluate("e => e.getBoundingClientRect().width")
        assert table >= 0.95 * client, f"the matrix uses {table} of {client} px at {width} px"
        assert page.evaluate(OVERFLOWING) == []
        open_view(page, server, f"console/{run_id}")
        expect(page.locator("#run-status")).to_have_text("running")
        expect(page.locator("#st-tick")).not_to_have_text("—")
        assert page.evaluate(OVERFLOWING) == []
        assert page.evaluate("document.documentElement.scrollWidth") <= width
    finally:
        context.close()
        server.client.post(f"/api/runs/{run_id}/stop")
