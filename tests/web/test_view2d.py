"""The console's 2D view in real Chromium against a live `srlab serve`: the robot drawn
where the run says it is, its controls (pause, step one tick, rate), and the robot beside
the reward buttons, both in the window, from 1024 px up."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
import pytest
from browser import artifact
from conftest import sized_page
from liveharness import wait_status
from PIL import Image
from playwright.sync_api import Browser, FloatRect, Page, expect
from webpage import eventually, open_view

from bench.liveserver import LiveServer

WINDOWS = [(1024, 768), (1440, 768), (1440, 900)]
"""Window sizes (width, height) a trainer uses: from 1024 px wide, typical heights."""

MIN_CANVAS_PX = 240
"""The narrowest 2D view a trainer can still follow the robot in."""

ROBOT_RGB = np.array([0xC4, 0x1E, 0x24])
"""The robot's fill (`ROBOT` in web/js/view2d.js); the red lamp is #dc2626, a close ray
redder still."""
ROBOT_RGB_TOLERANCE = 10


def create_run(server: LiveServer, **body: Any) -> int:
    r = server.client.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run_id: int = r.json()["id"]
    return run_id


def drawn(page: Page) -> dict[str, str]:
    """The canvas's record of what it drew last (its data attributes)."""
    data: dict[str, str] = page.eval_on_selector("#view2d", "c => ({...c.dataset})")
    return data


def pause(server: LiveServer, run_id: int) -> None:
    r = server.client.post(f"/api/runs/{run_id}/pause")
    assert r.status_code == 200, r.text


def test_the_robot_is_drawn_where_the_paused_run_says_it_is(page: Page, server: LiveServer) -> None:
    run_id = create_run(server, condition="kp", mode="realtime", hz=20, seed=3)
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    open_view(page, server, f"console/{run_id}")
    eventually(lambda: drawn(page).get("tick"), what="a tick drawn")
    pause(server, run_id)
    expect(page.locator("#view2d-step")).to_be_enabled()
    # One step: its tick reaches the page over the stream like any other.
    page.click("#view2d-step")
    run = eventually(
        lambda: (
            (r := server.client.get(f"/api/runs/{run_id}").json())["ticks"]
            and page.locator("#view2d-card").get_attribute("data-stepped") == str(r["ticks"])
            and r
        ),
        what="the step's answer",
    )
    eventually(lambda: drawn(page).get("tick") == str(run["ticks"]), what="the stepped tick")
    d = drawn(page)
    assert run["live"]["tick"] == run["ticks"]
    # The pose of that tick's event, on the track's map: metres to pixels, y up.
    world = server.client.get(f"/api/runs/{run_id}/world").json()
    x0, y0, x1, y1 = world["outer_box"]
    box = page.locator("#view2d").bounding_box()
    assert box is not None
    scale = (box["width"] - 24) / (x1 - x0)
    assert abs(float(d["px"]) - (12 + (float(d["x"]) - x0) * scale)) < 1.5
    assert abs(float(d["py"]) - (box["height"] - 12 - (float(d["y"]) - y0) * scale)) < 1.5
    assert x0 < float(d["x"]) < x1 and y0 < float(d["y"]) < y1
    # The robot's body is at the pixel the canvas says it drew it at: the median of the
    # pixels of its own colour, not the mean of any red. A red lamp (and a close sonar's ray)
    # is red too, the lamp's anti-aliased rim has a few pixels of the robot's colour, and
    # which tick the pause lands on, so the lamp's colour, depends on the machine's speed.
    png = page.locator("#view2d").screenshot()
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    sx = image.shape[1] / box["width"]
    sy = image.shape[0] / box["height"]
    red = np.argwhere(np.abs(image - ROBOT_RGB).max(axis=-1) <= ROBOT_RGB_TOLERANCE)
    assert len(red) > 20, f"the robot's body is drawn (lamp {d.get('lamp')})"
    row, col = np.median(red, axis=0)
    assert abs(col / sx - float(d["px"])) < 12 and abs(row / sy - float(d["py"])) < 12
    server.client.post(f"/api/runs/{run_id}/stop")


def test_step_advances_exactly_one_tick_and_the_controls_follow_the_status(
    page: Page, server: LiveServer
) -> None:
    run_id = create_run(server, condition="kp", mode="realtime", hz=10, seed=4)
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    open_view(page, server, f"console/{run_id}")
    expect(page.locator("#view2d-toggle")).to_have_text("❚❚ Pause")
    expect(page.locator("#view2d-step")).to_be_disabled()
    page.click("#view2d-toggle")
    expect(page.locator("#run-status")).to_have_text("paused")
    expect(page.locator("#view2d-toggle")).to_have_text("▶ Resume")
    before = server.client.get(f"/api/runs/{run_id}").json()["ticks"]
    for k in (1, 2):
        expect(page.locator("#view2d-step")).to_be_enabled()
        page.click("#view2d-step")
        expect(page.locator("#view2d-card")).to_have_attribute("data-stepped", str(before + k))
        assert server.client.get(f"/api/runs/{run_id}").json()["ticks"] == before + k
    expect(page.locator("#st-tick")).to_have_text(str(before + 2))
    # The rate: set beside the view, taken by the engine.
    page.fill("#view2d-hz", "25")
    page.click("#view2d-rate-set")
    eventually(
        lambda: server.client.get(f"/api/runs/{run_id}").json()["live"]["hz"] == 25.0,
        what="the new rate",
    )
    page.click("#view2d-toggle")
    expect(page.locator("#run-status")).to_have_text("running")
    expect(page.locator("#view2d-step")).to_be_disabled()
    server.client.post(f"/api/runs/{run_id}/stop")


def in_window(page: Page, selector: str) -> FloatRect:
    """The box of `selector`, asserted to lie wholly inside the window as it is now."""
    size = page.viewport_size
    assert size is not None
    box = page.locator(selector).bounding_box()
    assert box is not None, f"{selector} is not shown"
    assert box["x"] >= 0 and box["x"] + box["width"] <= size["width"], (selector, box, size)
    assert box["y"] >= 0 and box["y"] + box["height"] <= size["height"], (selector, box, size)
    return box


@pytest.mark.parametrize(("width", "height"), WINDOWS)
def test_the_robot_is_beside_the_reward_buttons_in_one_window(
    browser: Browser, server: LiveServer, width: int, height: int
) -> None:
    run_id = create_run(server, condition="trainer", mode="realtime", hz=20, seed=width)
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    try:
        with sized_page(browser, width, height) as page:
            open_view(page, server, f"console/{run_id}")
            expect(page.locator("#run-status")).to_have_text("running")
            eventually(lambda: drawn(page).get("tick"), what="a tick drawn")
            # As the page opens, unscrolled: the robot, its controls and the buttons are
            # all in the window, and nothing is wider than it.
            assert page.evaluate("[window.scrollX, window.scrollY]") == [0, 0]
            canvas = in_window(page, "#view2d")
            for selector in (
                "#view2d-card",
                "#view2d-toggle",
                "#view2d-step",
                "#view2d-hz",
                "#reward-plus",
                "#reward-plus-half",
                "#reward-minus",
                "#reward-minus-half",
            ):
                in_window(page, selector)
            scroll = page.evaluate("document.documentElement.scrollWidth")
            assert scroll <= width, f"the page is {scroll} px wide in a {width} px window"
            for card in ("#live-card", "#heat-card", "#train-card", "#timeline-card"):
                box = page.locator(card).bounding_box()
                assert box is not None and box["x"] >= 0 and box["x"] + box["width"] <= width
            # A view a trainer can follow, drawn to its shape (the track's, about 3:2).
            assert canvas["width"] >= MIN_CANVAS_PX, canvas
            assert canvas["height"] >= MIN_CANVAS_PX / 2, canvas
            # Beside the buttons: to their left, at the same height of the window.
            plus = in_window(page, "#reward-plus")
            assert canvas["x"] + canvas["width"] <= plus["x"]
            assert canvas["y"] < plus["y"] + plus["height"]
            assert plus["y"] < canvas["y"] + canvas["height"]
            # Nothing covers them: the window's own point is the canvas, and a press where
            # the button is seen (no scrolling) is a reward.
            hit = page.evaluate(
                "([x, y]) => document.elementFromPoint(x, y).id",
                [canvas["x"] + canvas["width"] / 2, canvas["y"] + canvas["height"] / 2],
            )
            assert hit == "view2d"
            page.mouse.click(plus["x"] + plus["width"] / 2, plus["y"] + plus["height"] / 2)
            eventually(
                lambda: any(
                    r["source"] == "trainer" and r["value"] == 1.0
                    for r in server.client.get(f"/api/runs/{run_id}/rewards").json()["data"]
                ),
                what="the pressed reward logged",
            )
            assert page.evaluate("[window.scrollX, window.scrollY]") == [0, 0]
            page.screenshot(path=artifact(f"console-view2d-{width}x{height}.png"))
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
    wait_status(server.client, run_id, "stopped")
