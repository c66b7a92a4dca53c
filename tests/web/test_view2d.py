"""The console's 2D view in real Chromium against a live `srlab serve`: the robot drawn
where the run says it is, and its controls (pause, step one tick, rate)."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
from liveserver import LiveServer
from PIL import Image
from playwright.sync_api import Page, expect
from webpage import eventually, open_view


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
    # The robot's red is at the pixel the canvas says it drew it at.
    png = page.locator("#view2d").screenshot()
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    sx = image.shape[1] / box["width"]
    sy = image.shape[0] / box["height"]
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    red = np.argwhere((r > 150) & (g < 0.4 * r) & (b < 0.4 * r))
    assert len(red) > 20, "the robot's body is drawn"
    row, col = red.mean(axis=0)
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
