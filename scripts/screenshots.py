"""Refresh the README's screenshots of the editor and the console (`make screenshots`).

Starts `srlab serve` on a throwaway database, edits a network, runs it against its first
version and trains a run the way a user would, and saves docs/img/editor.png,
editor-run.png, console.png, console-2d.png and kp.png, then runs a study's first
participants and saves studies.png and participant.png (Debian's Chromium).
`python scripts/screenshots.py studies` takes the study's two alone.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from bench.browser import CHROMIUM, chromium
from bench.liveserver import LiveServer, live_server

if TYPE_CHECKING:
    from playwright.sync_api import Browser

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "img"


STUDY = {
    "name": "pilot",
    "conditions": ["kp", "trainer"],
    "budget": {"episodes": 5},
    "consent_text": "You will train a simulated robot to lap a track. Press + when it does "
    "well and - when it does badly. It takes about ten minutes.",
    "consent_version": "1",
    "questionnaire": ["How hard was it to teach the robot?"],
    "completion_code": "C0DE42",
}
"""The study of the pictures: two conditions, five episodes each."""


def study_shots(server: LiveServer, browser: Browser) -> None:
    """A study under way: the organiser's Studies tab, and a participant training."""
    api = server.client
    api.post("/api/studies", json=STUDY).raise_for_status()
    invited = api.post("/api/studies/pilot/participants", json={"count": 6})
    tokens = [p["token"] for p in invited.raise_for_status().json()["data"]]
    for token in tokens[1:4]:  # three have consented elsewhere: their runs tick
        api.post(
            "/api/participant/consent",
            json={"consent_version": "1"},
            headers={"Authorization": f"Bearer {token}"},
        ).raise_for_status()
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(f"{server.url}/#/study/{tokens[0]}")
    page.get_by_role("button", name="I agree").click()
    page.wait_for_selector("#competition .bar-row", timeout=60_000)
    credited = page.locator("#reward-effect table")  # a reward that credited records
    for n in range(40):  # a few presses, until one has credit to show
        page.keyboard.press("+-"[n % 3 == 2])
        page.wait_for_timeout(1200)
        if n >= 3 and credited.count():
            break
    page.screenshot(path=str(OUT / "participant.png"))
    print(f"saved {OUT / 'participant.png'}")  # noqa: T201

    organiser = browser.new_page(viewport={"width": 1280, "height": 800})
    organiser.goto(f"{server.url}/#/studies")
    organiser.wait_for_selector("#participants table.participants")
    organiser.wait_for_timeout(600)
    organiser.screenshot(path=str(OUT / "studies.png"))
    print(f"saved {OUT / 'studies.png'}")  # noqa: T201
    for token in tokens[:4]:
        run = api.get("/api/participant", headers={"Authorization": f"Bearer {token}"})
        api.post(f"/api/runs/{run.json()['run_id']}/stop")


def main() -> None:
    """Drive the pages and save the screenshots (`studies`: the study's alone)."""
    if not CHROMIUM.exists():
        raise SystemExit(f"screenshots: {CHROMIUM} is missing: apt-get install -y chromium")
    OUT.mkdir(parents=True, exist_ok=True)
    if sys.argv[1:] == ["studies"]:
        with (
            tempfile.TemporaryDirectory() as tmp,
            live_server(Path(tmp) / "shots.db") as server,
            chromium() as browser,
        ):
            study_shots(server, browser)
        return
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
            study_shots(server, browser)


if __name__ == "__main__":
    main()
