"""Refresh the README's screenshots of the editor and the console (`make screenshots`).

Starts `srlab serve` on a throwaway database, edits a network, runs it against its first
version and trains a run the way a user would, and saves docs/img/editor.png,
editor-run.png, console.png, console-2d.png and kp.png (Debian's Chromium).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from bench.browser import CHROMIUM, chromium
from bench.liveserver import live_server

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "img"


def main() -> None:
    """Drive the pages and save the screenshots."""
    if not CHROMIUM.exists():
        raise SystemExit(f"screenshots: {CHROMIUM} is missing: apt-get install -y chromium")
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, live_server(Path(tmp) / "shots.db") as server:
        api = server.client
        api.post("/api/networks", json={"name": "my-design", "base": "dp"}).raise_for_status()
        # A learned run first, so the heatmap has something to show.
        run = api.post("/api/runs", json={"condition": "kp", "episodes": 60, "seed": 3}).json()
        api.post(f"/api/runs/{run['id']}/start").raise_for_status()
        with chromium() as browser:
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.goto(f"{server.url}/#/editor/my-design")
            page.wait_for_selector("body[data-ready=true]")
            for stimulus, behaviour, keys in (
                ("Yellow", "goforward1", ["Space", "6"]),
                ("Obstacle_M_M", "leftturn30", ["Space", "8", "l"]),
            ):
                page.click(f'#matrix td.c[data-s="{stimulus}"][data-b="{behaviour}"]')
                for key in keys:
                    page.keyboard.press(key)
                page.keyboard.press("Enter")  # a draft is saved, as one version, on commit
                page.wait_for_timeout(400)
            page.check("#versions li:nth-child(1) input")
            page.check("#versions li:nth-last-child(1) input")
            page.click("#diff")
            page.wait_for_timeout(400)
            page.screenshot(path=str(OUT / "editor.png"))
            print(f"saved {OUT / 'editor.png'}")  # noqa: T201

            # Run this network against its first version, on the same seeds.
            form = "#run-net-form"
            page.select_option(f"{form} select[name=condition]", "dp")
            page.fill(f"{form} input[name=episodes]", "20")
            page.fill(f"{form} input[name=seeds]", "4")
            page.select_option(f"{form} select[name=compare]", "v:1")
            page.click("#run-net-start")
            page.wait_for_selector("#run-net-out[data-state=done]", timeout=600_000)
            page.wait_for_timeout(400)
            page.screenshot(path=str(OUT / "editor-run.png"))
            print(f"saved {OUT / 'editor-run.png'}")  # noqa: T201

            while api.get(f"/api/runs/{run['id']}").json()["status"] != "finished":
                time.sleep(0.2)
            # A person training a robot: the trainer condition, rewards from the keyboard.
            live = api.post(
                "/api/runs",
                json={"condition": "trainer", "mode": "realtime", "hz": 20, "seed": 7},
            ).json()
            api.post(f"/api/runs/{live['id']}/start").raise_for_status()
            page.set_viewport_size({"width": 1440, "height": 1100})
            page.goto(f"{server.url}/#/console/{live['id']}")
            page.wait_for_selector("#competition .bar-row", timeout=60_000)
            # A reward credits the STM records before it: before the robot's first turn
            # there may be none, so the trainer goes on rewarding until one has credit.
            credited = page.locator("#reward-effect table")
            for n in range(40):
                page.keyboard.press("+-"[n % 3 == 1])
                page.wait_for_timeout(1500)
                if n >= 2 and credited.count():
                    break
            credited.first.wait_for(timeout=10_000)
            page.wait_for_timeout(800)
            page.screenshot(path=str(OUT / "console.png"))
            print(f"saved {OUT / 'console.png'}")  # noqa: T201
            view = page.locator("#view2d-card")
            view.scroll_into_view_if_needed()
            page.wait_for_timeout(600)
            view.screenshot(path=str(OUT / "console-2d.png"))
            print(f"saved {OUT / 'console-2d.png'}")  # noqa: T201
            api.post(f"/api/runs/{live['id']}/stop")

            # The KP inspector of a kp run that has propagated something.
            kp = api.post(
                "/api/runs",
                json={"condition": "kp", "mode": "realtime", "hz": 200, "seed": 3},
            ).json()
            api.post(f"/api/runs/{kp['id']}/start").raise_for_status()
            deadline = time.monotonic() + 600
            while time.monotonic() < deadline:
                if api.get(f"/api/runs/{kp['id']}/kp").json().get("associations"):
                    break
                time.sleep(1)
            api.post(f"/api/runs/{kp['id']}/pause")
            page.goto(f"{server.url}/#/console/{kp['id']}")
            page.wait_for_selector("#kp-inspector .kp-assoc", timeout=60_000)
            page.locator("#kp-inspector .kp-assoc summary").first.click()
            page.locator("#kp-inspector").scroll_into_view_if_needed()
            page.wait_for_timeout(600)
            page.locator("#kp-inspector").screenshot(path=str(OUT / "kp.png"))
            print(f"saved {OUT / 'kp.png'}")  # noqa: T201
            api.post(f"/api/runs/{kp['id']}/stop")


if __name__ == "__main__":
    main()
