"""The console's 2D view of a corridor track in real Chromium against a live `srlab serve`:
the l-shape's walls and floor, its two obstacles, the trolley moving from tick to tick,
live and in a replay of a stored episode."""

from __future__ import annotations

import io
from functools import partial
from typing import Any

import numpy as np
from browser import artifact
from liveharness import start_run, wait_status
from PIL import Image
from playwright.sync_api import Page, expect
from webpage import eventually, open_view

from bench.liveserver import LiveServer

FLOOR = (0xB0, 0xB4, 0xBA)
GROUND = (0xF5, 0xF5, 0xF0)
WALL = (0x47, 0x55, 0x69)
"""web/js/view2d.js's colours."""


def started(server: LiveServer, **body: Any) -> int:
    return start_run(server.client, **body)


def drawn(page: Page, canvas: str) -> dict[str, str]:
    data: dict[str, str] = page.eval_on_selector(canvas, "c => ({...c.dataset})")
    return data


def obstacles(d: dict[str, str]) -> list[tuple[float, float]]:
    """The obstacles' centres the canvas says it drew."""
    return [(float(a), float(b)) for a, b in (p.split(",") for p in d["obstacles"].split())]


def colour_at(page: Page, canvas: str, world: dict[str, Any], x: float, y: float) -> np.ndarray:
    """The canvas's colour at (x, y) metres, as the 2D view maps metres to pixels."""
    box = page.locator(canvas).bounding_box()
    assert box is not None
    x0, y0, x1, _ = world["outer_box"]
    scale = (box["width"] - 24) / (x1 - x0)
    px, py = 12 + (x - x0) * scale, box["height"] - 12 - (y - y0) * scale
    png = page.locator(canvas).screenshot()
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    sx, sy = image.shape[1] / box["width"], image.shape[0] / box["height"]
    out: np.ndarray = image[round(py * sy), round(px * sx)]
    return out


def on_track(page: Page, world: dict[str, Any]) -> dict[str, str] | None:
    """What the 2D view drew, once it drew a tick on `world`'s track (None before)."""
    d = drawn(page, "#view2d")
    return d if d.get("tick") and d["walls"] == str(len(world["walls"])) else None


def near(colour: np.ndarray, rgb: tuple[int, int, int]) -> bool:
    return bool(np.abs(colour - np.asarray(rgb)).max() <= 6)


def test_a_corridor_runs_walls_floor_and_moving_trolley_are_drawn_live(
    page: Page, server: LiveServer
) -> None:
    run_id = started(server, condition="kp", world="l-shape", mode="realtime", hz=20, seed=3)
    world = server.client.get(f"/api/runs/{run_id}/world").json()
    assert not world["ring"]
    open_view(page, server, f"console/{run_id}")
    eventually(lambda: drawn(page, "#view2d").get("tick"), what="a tick drawn")
    first = drawn(page, "#view2d")
    assert first["walls"] == str(len(world["walls"])) == "12"
    assert len(obstacles(first)) == 2

    # A later tick: the seeded obstacle stands where it stood, the trolley has moved.
    def moved() -> dict[str, str] | None:
        d = drawn(page, "#view2d")
        return d if d["tick"] != first["tick"] and obstacles(d)[1] != obstacles(first)[1] else None

    later = eventually(moved, what="the trolley moved")
    assert obstacles(later)[0] == obstacles(first)[0]
    server.client.post(f"/api/runs/{run_id}/pause")
    wait_status(server.client, run_id, "paused")
    # The floor is the corridor's, the inside of the L is not floor, the walls are drawn.
    assert near(colour_at(page, "#view2d", world, 0.35, 5.65), FLOOR)  # a corner's floor
    assert near(colour_at(page, "#view2d", world, 2.0, 2.0), GROUND)  # inside the L
    assert near(colour_at(page, "#view2d", world, 0.0, 4.2), WALL)  # the left outer wall
    page.locator("#view2d-card").screenshot(path=artifact("view2d-l-shape-trolley.png"))
    server.client.post(f"/api/runs/{run_id}/stop")


def test_a_replayed_corridor_episode_moves_its_trolley_with_the_scrubbed_tick(
    page: Page, server: LiveServer
) -> None:
    run_id = started(server, condition="rp", world="l-shape", mode="fast", episodes=2, seed=4)
    wait_status(server.client, run_id, "finished")
    rows = server.client.get(f"/api/runs/{run_id}/episodes/0").json()["trace"]
    assert len(rows) > 40
    open_view(page, server, f"console/{run_id}")
    page.locator("#replay-episode").select_option("0")
    page.click("#replay-open")
    expect(page.locator("#replay-body")).to_be_visible()
    seen = []
    for index in (0, 40):
        page.locator("#replay-tick").fill(str(index))
        tick = str(rows[index]["tick"])
        eventually(lambda: drawn(page, "#replay-canvas").get("tick") == tick, what=tick)  # noqa: B023
        d = drawn(page, "#replay-canvas")
        assert d["walls"] == "12"
        seen.append(obstacles(d))
        for (x, y), (ex, ey) in zip(seen[-1], rows[index]["obstacles"], strict=True):
            assert abs(x - ex) < 1e-3 and abs(y - ey) < 1e-3
    assert seen[0][0] == seen[1][0] and seen[0][1] != seen[1][1]
    page.locator("#replay-card").screenshot(path=artifact("console-replay-l-shape.png"))


def test_every_preset_is_drawn_without_an_error(page: Page, server: LiveServer) -> None:
    names = [w["name"] for w in server.client.get("/api/worlds").json()]
    assert {"l-shape", "figure-8", "narrow-passage", "soft-obstacle"} <= set(names)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    for name in names:
        run_id = started(server, condition="kp", world=name, mode="realtime", hz=20, seed=2)
        world = server.client.get(f"/api/runs/{run_id}/world").json()
        open_view(page, server, f"console/{run_id}")
        d = eventually(partial(on_track, page, world), what=f"a tick of {name} on its track")
        assert len(d.get("obstacles", "").split()) <= (1 if world["ring"] else 2), name
        page.locator("#view2d-card").screenshot(path=artifact(f"view2d-{name}.png"))
        server.client.post(f"/api/runs/{run_id}/stop")
        wait_status(server.client, run_id, "stopped")
    assert not errors
