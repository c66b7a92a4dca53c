"""End to end: `srlab serve`, its 3D view in Debian's Chromium, the panel clicked for real.

Chromium runs with --disable-gpu (tests/browser.py); it renders WebGL with SwiftShader,
its software fallback, without further flags (checked with Chromium 150), so the
screenshot is a real rendering and the test reads its pixels.
"""

from __future__ import annotations

import io
import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from browser import artifact
from conftest import BROWSER_WAIT_MS
from liveharness import start_run, wait_status
from PIL import Image
from playwright.sync_api import Browser, Page
from webpage import eventually

from bench.liveserver import LiveServer, free_port, start_server, stop_server
from server.viewer.render import REWARD_NOTE

VIEWPORT = {"width": 1280, "height": 800}
PANEL_LEFT = 900
"""The panel floats at the right: the scene is read left of it."""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A live server of this module's own (`browser` is the module's, tests/conftest.py)."""
    live = start_server(tmp_path_factory.mktemp("viewer") / "viewer.db")
    try:
        yield live
    finally:
        # The browser may still be connected: shutdown must be clean all the same.
        stop_server(live)


def robot_pixels(png: bytes) -> np.ndarray:
    """(row, column) of the pixels with the robot's red, left of the panel."""
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    scene = image[:, :PANEL_LEFT]
    r, g, b = scene[..., 0], scene[..., 1], scene[..., 2]
    red = (r > 120) & (g < 0.45 * r) & (b < 0.45 * r)
    return np.argwhere(red)


def open_view(browser: Browser, server: LiveServer, viewport: dict[str, int] = VIEWPORT) -> Page:
    port = server.client.get("/api/health").json()["viser_port"]
    assert isinstance(port, int)
    page = browser.new_page(viewport=viewport)  # type: ignore[arg-type]
    page.set_default_timeout(BROWSER_WAIT_MS)
    page.goto(f"http://127.0.0.1:{port}/")
    page.get_by_text("srlab 3D view").wait_for(timeout=90_000)
    # The notice that WebGL runs in software covers a corner of the scene: hide it.
    page.add_style_tag(content=".mantine-Notification-root { display: none !important; }")
    return page


def wait_for_robot(page: Page, timeout: float = 90.0) -> tuple[bytes, np.ndarray]:
    deadline = time.monotonic() + timeout
    while True:
        png = page.screenshot()
        pixels = robot_pixels(png)
        if len(pixels) >= 150:
            return png, pixels
        if time.monotonic() > deadline:
            Path(artifact("viewer-no-robot.png")).write_bytes(png)
            raise AssertionError(f"no robot in the 3D view ({len(pixels)} red pixels)")
        time.sleep(0.25)


def rewards(api: httpx.Client, run_id: int) -> list[dict[str, Any]]:
    data: list[dict[str, Any]] = api.get(f"/api/runs/{run_id}/rewards").json()["data"]
    return data


def test_the_view_shows_the_live_robot_and_its_panel_rewards_it(
    server: LiveServer, browser: Browser
) -> None:
    api = server.client

    run_id = start_run(api, condition="kp", mode="realtime", hz=20, seed=3)
    page = open_view(browser, server)
    try:
        page.get_by_text(f"Run {run_id}").first.wait_for(timeout=90_000)
        png, first = wait_for_robot(page)
        artifact("viewer.png").write_bytes(png)
        # The panel tells the decision of the tick shown.
        page.get_by_text("Behaviour:").wait_for(timeout=90_000)
        page.get_by_text("Stimuli:").wait_for(timeout=90_000)
        time.sleep(1.5)
        _, later = wait_for_robot(page)
        moved = np.abs(later.mean(axis=0) - first.mean(axis=0)).max()
        assert moved > 3, f"the robot did not move on screen ({moved:.1f} px)"
        page.get_by_role("button", name="+ reward").click()
        deadline = time.monotonic() + 20
        log = rewards(api, run_id)
        while not (log and log[-1]["applied"]) and time.monotonic() < deadline:
            time.sleep(0.1)
            log = rewards(api, run_id)
        mine = [x for x in log if x["note"] == REWARD_NOTE]
        assert len(mine) == 1, log
        assert mine[0]["value"] == 1.0 and mine[0]["source"] == "trainer"
        assert mine[0]["applied"] and mine[0]["credited"] > 0
        page.get_by_text(f"stored as #{mine[0]['id']}").wait_for(timeout=90_000)
    finally:
        page.close()
        api.post(f"/api/runs/{run_id}/stop")


def test_at_1024_px_the_panel_docks_beside_the_track(server: LiveServer, browser: Browser) -> None:
    api = server.client
    run_id = api.post("/api/runs", json={"condition": "kp", "mode": "realtime", "hz": 5}).json()[
        "id"
    ]
    assert api.post(f"/api/runs/{run_id}/start").status_code == 200
    page = open_view(browser, server, {"width": 1024, "height": 700})
    try:
        page.get_by_text(f"Run {run_id}").first.wait_for(timeout=90_000)
        canvas = page.evaluate("document.querySelector('canvas').getBoundingClientRect().right")
        panel = page.get_by_text("srlab 3D view").first.evaluate(
            "e => e.getBoundingClientRect().left"
        )
        # The panel has its own strip: the canvas (and the track in it) ends where it starts.
        assert canvas <= panel + 1, f"the canvas runs under the panel: {canvas} > {panel}"
        png, _ = wait_for_robot(page)
        artifact("viewer-1024.png").write_bytes(png)
    finally:
        page.close()
        api.post(f"/api/runs/{run_id}/stop")


def test_a_stored_episode_replays_in_the_view(server: LiveServer, browser: Browser) -> None:
    api = server.client
    r = api.post("/api/runs", json={"condition": "kp", "mode": "fast", "seed": 6, "episodes": 2})
    run_id = r.json()["id"]
    api.post(f"/api/runs/{run_id}/start")
    wait_status(api, run_id, "finished")
    page = open_view(browser, server)
    try:
        # Pick the run in the dropdown, then the replay view.
        # Client-scoped panels name no combobox: the Run dropdown is the first.
        page.get_by_role("combobox").first.click()
        page.get_by_role("option", name=f"#{run_id} kp fast").click()
        page.get_by_text(f"Run {run_id}").first.wait_for(timeout=90_000)
        page.get_by_role("button", name="Replay", exact=True).click()
        page.get_by_text(f"of run {run_id}, episode 1").first.wait_for(timeout=90_000)
        page.get_by_role("button", name="Pause", exact=True).click()
        page.get_by_role("button", name="Play", exact=True).wait_for(timeout=90_000)
        png, _ = wait_for_robot(page)
        artifact("viewer-replay.png").write_bytes(png)
        page.get_by_text("Replay of a stored episode").wait_for(timeout=90_000)
    finally:
        page.close()


def header_run(page: Page) -> int | None:
    """The run the panel's header names ("Run 7: kp, seed 3, ...")."""
    found = re.search(r"Run (\d+): ", page.inner_text("body"))
    return int(found[1]) if found else None


def wait_header(page: Page, run_id: int, timeout: float = 90.0) -> None:
    deadline = time.monotonic() + timeout
    while header_run(page) != run_id:
        if time.monotonic() > deadline:
            raise AssertionError(f"the viewer shows run {header_run(page)}, not {run_id}")
        time.sleep(0.2)


def test_two_viewers_watch_different_runs_without_steering_each_other(
    server: LiveServer, browser: Browser
) -> None:
    api = server.client
    runs = []
    for seed in (11, 12):
        body = {"condition": "kp", "mode": "realtime", "hz": 5, "seed": seed}
        run_id = api.post("/api/runs", json=body).json()["id"]
        assert api.post(f"/api/runs/{run_id}/start").status_code == 200
        runs.append(run_id)
    first, second = runs
    pages: list[Page] = []
    try:
        # The console's "3D view" button: the next viewer starts on the chosen run.
        assert api.post(f"/api/runs/{first}/view").status_code == 200
        one = open_view(browser, server)
        pages.append(one)
        wait_header(one, first)
        assert api.post(f"/api/runs/{second}/view").status_code == 200
        two = open_view(browser, server)
        pages.append(two)
        wait_header(two, second)
        # The first viewer was not steered by the second's choice: it keeps its own run.
        time.sleep(1.5)  # a shared view would have switched by now (the bound is generous)
        assert header_run(one) == first
        assert header_run(two) == second
    finally:
        for page in pages:
            page.close()
        for run_id in runs:
            api.post(f"/api/runs/{run_id}/stop")


def test_a_view_opened_on_a_runs_url_keeps_its_run_across_a_restart(
    browser: Browser, tmp_path: Path, start_server: Callable[..., LiveServer]
) -> None:
    # viser's page reconnects by itself after a restart, as a new viewer; on / it would
    # follow the newest run, on /run/<id> it gets its run back.
    database = tmp_path / "restart.db"
    env = {"SRLAB_VISER_PORT": str(free_port())}  # the same view port after the restart
    first = start_server(database, env=env)
    page = browser.new_page(viewport=VIEWPORT)  # type: ignore[arg-type]
    page.set_default_timeout(BROWSER_WAIT_MS)
    try:
        api = first.client
        body = {"condition": "kp", "mode": "realtime", "hz": 5, "seed": 21}
        chosen = api.post("/api/runs", json=body).json()["id"]
        assert api.post(f"/api/runs/{chosen}/start").status_code == 200
        # Newer than the chosen run: the one a viewer on / starts on after the restart.
        newest = api.post("/api/runs", json={**body, "seed": 22}).json()["id"]
        port = api.get("/api/health").json()["viser_port"]
        page.goto(f"http://127.0.0.1:{port}/run/{chosen}")
        wait_header(page, chosen)

        stop_server(first)  # the chosen run is interrupted
        second = start_server(database, port=first.port, env=env)
        try:
            assert second.client.post(f"/api/runs/{newest}/start").status_code == 200

            def reconnected() -> bool:
                # The status shows it is the new service's viewer, not the old one's panel.
                text = page.inner_text("body")
                return header_run(page) == chosen and "interrupted" in text

            def on_chosen(what: str) -> None:
                """Wait until the view shows the chosen run; a timeout says what it shows."""
                try:
                    eventually(reconnected, what=f"{what} on run {chosen}")
                except AssertionError as e:
                    shown = f"run {header_run(page)}: {page.inner_text('body')[:400]!r}"
                    raise AssertionError(f"{e} (the page shows {shown})") from None

            on_chosen("the reconnected view")
            # The view looks for new runs every second: it stays put. The old service's
            # panel stays on the page until the new one's first messages replace it (and
            # it too names the chosen run, interrupted at shutdown), so the page may go
            # blank for a moment after the check above while the new panel is built:
            # what must never show is another run.
            seen = set()
            for _ in range(10):
                time.sleep(0.3)
                seen.add(header_run(page))
            assert seen <= {chosen, None}, f"the view showed runs {seen}, not only {chosen}"
            on_chosen("the view back")
        finally:
            second.client.post(f"/api/runs/{newest}/stop")
            stop_server(second)
    finally:
        page.close()


def test_a_view_past_max_viewers_says_it_is_full_then_opens_when_one_leaves(
    browser: Browser, tmp_path: Path, start_server: Callable[..., LiveServer]
) -> None:
    full = start_server(tmp_path / "full.db", env={"SRLAB_VISER_MAX_VIEWERS": "1"})
    pages: list[Page] = []
    try:
        first = open_view(browser, full)
        pages.append(first)
        port = full.client.get("/api/health").json()["viser_port"]
        second = browser.new_page(viewport=VIEWPORT)  # type: ignore[arg-type]
        pages.append(second)
        second.set_default_timeout(BROWSER_WAIT_MS)
        answer = second.goto(f"http://127.0.0.1:{port}/")
        assert answer is not None and answer.status == 503
        second.get_by_text("The 3D view is full").wait_for()
        assert "SRLAB_VISER_MAX_VIEWERS" in second.inner_text("body")
        # The page tries again by itself: once the first viewer leaves, it is the view.
        first.close()
        second.get_by_text("srlab 3D view").wait_for(timeout=90_000)
    finally:
        for page in pages:
            if not page.is_closed():
                page.close()
        stop_server(full)


def test_the_view_draws_a_corridor_runs_track_and_robot(
    server: LiveServer, browser: Browser
) -> None:
    api = server.client
    run_id = start_run(api, condition="kp", world="l-shape", mode="realtime", hz=20, seed=3)
    page = open_view(browser, server)
    try:
        page.get_by_text(f"Run {run_id}").first.wait_for(timeout=90_000)
        png, _ = wait_for_robot(page)
        artifact("viewer-l-shape.png").write_bytes(png)
        # Both of the l-shape's obstacles stand in the scene: its boxes' brown, lit.
        image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)[:, :PANEL_LEFT]
        r, g, b = image[..., 0], image[..., 1], image[..., 2]
        brown = (r > 90) & (r - g > 25) & (g - b > 25) & (r - b < 160)
        assert brown.sum() > 40, f"{brown.sum()} brown pixels"
    finally:
        page.close()
        api.post(f"/api/runs/{run_id}/stop")
