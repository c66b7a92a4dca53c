"""A service on a lab's own data folder: its conditions run, and an edit under it shows."""

from __future__ import annotations

import shutil
from pathlib import Path

from liveharness import wait_status
from playwright.sync_api import Page, expect
from webpage import open_view

from bench.liveserver import live_server
from core.brain.catalog import data_dir

MINE = '\n[[condition]]\nname = "kp-lab"\ndescription = "the lab\'s kp"\nbased_on = "kp"\n'


def test_a_labs_data_folder_is_served_and_an_edit_under_the_service_is_shown(
    tmp_path: Path, page: Page
) -> None:
    data = tmp_path / "data"
    shutil.copytree(data_dir(), data, ignore=shutil.ignore_patterns("__pycache__"))
    conditions = data / "conditions.toml"
    conditions.write_text(conditions.read_text() + MINE)
    with live_server(tmp_path / "lab.db", env={"SRLAB_DATA_DIR": str(data)}) as server:
        api = server.client
        health = api.get("/api/health").json()
        assert health["data_changed"] == [] and len(health["data_version"]) == 12
        r = api.post("/api/runs", json={"condition": "kp-lab", "episodes": 1, "mode": "fast"})
        assert r.status_code == 201, r.text
        assert api.post(f"/api/runs/{r.json()['id']}/start").status_code == 200
        wait_status(api, r.json()["id"], "finished")

        open_view(page, server, "editor")
        banner = page.locator("#data-stale")
        expect(banner).to_be_hidden()
        worlds = data / "worlds.toml"
        worlds.write_text(worlds.read_text() + "\n# a preset being drawn\n")
        expect(banner).to_be_visible()
        expect(banner).to_contain_text("core/data/worlds.toml")
        expect(banner).to_contain_text("restart srlab serve")
        assert api.get("/api/health").json()["data_changed"] == ["worlds.toml"]
