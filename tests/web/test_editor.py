"""The S-R editor in real Chromium against a live `srlab serve`: what a DP programmer does."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from browser import artifact
from playwright.sync_api import Page, expect
from webpage import cell, eventually, open_view

from bench.liveserver import LiveServer


def association(server: LiveServer, network: str, stimulus: str, behaviour: str) -> Any:
    data = server.client.get(f"/api/networks/{network}/associations").json()["data"]
    return next((a for a in data if (a["stimulus"], a["behaviour"]) == (stimulus, behaviour)), None)


def fresh_network(server: LiveServer, name: str, base: str = "dp") -> None:
    r = server.client.post("/api/networks", json={"name": name, "base": base})
    assert r.status_code == 201, r.text


def test_edit_a_cell_by_keyboard_find_it_through_the_api_then_undo_and_redo(
    page: Page, server: LiveServer
) -> None:
    fresh_network(server, "keys")
    open_view(page, server, "editor/keys")
    expect(page.locator("#net-title")).to_have_text("keys")
    assert association(server, "keys", "Red", "goforward1") is None

    page.click(cell(page, "Red", "goforward1"))
    page.keyboard.press("Space")  # add with strength 1, dp: a draft until Enter
    expect(page.locator(cell(page, "Red", "goforward1"))).to_have_attribute("data-present", "true")
    expect(page.locator(cell(page, "Red", "goforward1"))).to_have_class(re.compile("draft"))
    page.keyboard.press("Enter")
    added = eventually(lambda: association(server, "keys", "Red", "goforward1"))
    assert added == {
        "stimulus": "Red",
        "behaviour": "goforward1",
        "strength": 1.0,
        "source": "dp",
        "locked": False,
    }
    page.keyboard.press("4")  # strength 0.4
    page.keyboard.press("Enter")
    eventually(lambda: association(server, "keys", "Red", "goforward1")["strength"] == 0.4)
    expect(page.locator(cell(page, "Red", "goforward1"))).to_have_text(".4")

    page.keyboard.press("Control+z")
    eventually(lambda: association(server, "keys", "Red", "goforward1")["strength"] == 1.0)
    page.keyboard.press("Control+z")
    expect(page.locator(cell(page, "Red", "goforward1"))).to_have_attribute("data-present", "false")
    assert association(server, "keys", "Red", "goforward1") is None
    expect(page.locator("#undo")).to_be_disabled()

    page.keyboard.press("Control+Shift+z")
    eventually(lambda: association(server, "keys", "Red", "goforward1"))
    # Every save was a version, undo and redo included.
    versions = server.client.get("/api/networks/keys/versions").json()["data"]
    assert [v["note"] for v in versions[-3:]] == ["undo", "undo", "redo"]
    expect(page.locator("#versions li")).to_have_count(len(versions))


def test_edit_a_cell_in_the_side_panel_with_the_mouse(page: Page, server: LiveServer) -> None:
    fresh_network(server, "mouse")
    open_view(page, server, "editor/mouse")
    page.click(cell(page, "Obstacle_M_M", "leftturn45"))
    expect(page.locator("#cell-name")).to_have_text("Obstacle_M_M → leftturn45 (none yet)")
    page.fill("#cell-form input[name=strength]", "0.65")
    page.select_option("#cell-form select[name=source]", "kp")
    page.fill("#cell-form input[name=note]", "swerve left")
    page.click("#cell-save")
    stored = eventually(lambda: association(server, "mouse", "Obstacle_M_M", "leftturn45"))
    assert stored["strength"] == 0.65 and stored["source"] == "kp"
    versions = server.client.get("/api/networks/mouse/versions").json()["data"]
    assert versions[-1]["note"] == "swerve left"
    page.click("#cell-remove")
    eventually(lambda: association(server, "mouse", "Obstacle_M_M", "leftturn45") is None)


def test_a_locked_cell_refuses_a_learned_overwrite_and_keyboard_slips(
    page: Page, server: LiveServer
) -> None:
    fresh_network(server, "locks", base="innate")
    open_view(page, server, "editor/locks")
    page.click(cell(page, "Green", "goforward3"))
    page.keyboard.press("Space")
    expect(page.locator(cell(page, "Green", "goforward3"))).to_have_attribute(
        "data-present", "true"
    )
    page.keyboard.press("l")
    expect(page.locator(cell(page, "Green", "goforward3"))).to_have_attribute("data-locked", "true")
    page.keyboard.press("Enter")
    eventually(lambda: (association(server, "locks", "Green", "goforward3") or {}).get("locked"))

    # What learning would do: overwrite it as "learned". The API refuses without force.
    r = server.client.put(
        "/api/networks/locks/associations/Green/goforward3",
        json={"strength": 0.2, "source": "learned"},
    )
    assert r.status_code == 409 and "lock" in r.json()["detail"]
    # The editor refuses a change too, and says how to make one.
    page.keyboard.press("2")
    expect(page.locator(".toast.error").last).to_contain_text("is locked: unlock it first")
    assert association(server, "locks", "Green", "goforward3")["strength"] == 1.0
    # Unlocking is a deliberate act, and then the change goes through.
    page.keyboard.press("l")
    page.keyboard.press("Enter")
    eventually(lambda: association(server, "locks", "Green", "goforward3")["locked"] is False)
    page.keyboard.press("2")
    page.keyboard.press("Enter")
    eventually(lambda: association(server, "locks", "Green", "goforward3")["strength"] == 0.2)


def test_history_diff_and_revert(page: Page, server: LiveServer) -> None:
    fresh_network(server, "history", base="innate")
    open_view(page, server, "editor/history")
    page.click(cell(page, "Red", "stop"))
    page.keyboard.press("Space")
    page.keyboard.press("Enter")
    expect(page.locator("#versions li")).to_have_count(2)
    page.click(cell(page, "Corner", "leftturn90"))
    page.keyboard.press("Delete")
    page.keyboard.press("Enter")
    expect(page.locator("#versions li")).to_have_count(3)

    page.check("#versions input[value='1']")
    page.check("#versions input[value='3']")
    page.click("#diff")
    diff = page.locator("#diff-out")
    expect(diff).to_contain_text("v1 → v3")
    expect(diff.locator(".added + ul")).to_contain_text("Red → stop")
    expect(diff.locator(".removed + ul")).to_contain_text("Corner → leftturn90")

    page.uncheck("#versions input[value='3']")
    page.once("dialog", lambda d: d.accept())
    page.click("#revert")
    expect(page.locator("#net-meta")).to_contain_text("version 4")
    assert association(server, "history", "Red", "stop") is None
    assert association(server, "history", "Corner", "leftturn90") is not None
    page.screenshot(path=artifact("editor.png"))


def test_export_then_import_under_a_new_name(
    page: Page, server: LiveServer, tmp_path: Path
) -> None:
    open_view(page, server, "editor/kp")
    expect(page.locator("#readonly-note")).to_be_visible()
    with page.expect_download() as download:
        page.click("#export")
    saved = tmp_path / "kp.json"
    download.value.save_as(saved)
    doc = json.loads(saved.read_text())
    assert doc["format"] == "srlab-network/1" and doc["name"] == "kp"

    page.click("details:has(#import-form) > summary")
    page.set_input_files("#import-form input[name=file]", str(saved))
    page.fill("#import-form input[name=name]", "kp-copy")
    page.click("#import-form button[type=submit]")
    expect(page.locator("#net-title")).to_have_text("kp-copy")
    copy = server.client.get("/api/networks/kp-copy").json()
    original = server.client.get("/api/networks/kp").json()
    assert copy["associations"] == original["associations"]


def test_api_errors_show_a_message_and_keep_what_was_typed(page: Page, server: LiveServer) -> None:
    open_view(page, server, "editor/innate")
    page.fill("#new-network-form input[name=name]", "dp")  # taken: a built-in network
    page.fill("#new-network-form input[name=description]", "my careful description")
    page.click("#new-network-form button[type=submit]")
    expect(page.locator(".toast.error").last).to_contain_text("Creating dp")
    expect(page.locator(".toast.error").last).to_contain_text("exists")
    expect(page.locator("#new-network-form input[name=name]")).to_have_value("dp")
    expect(page.locator("#new-network-form input[name=description]")).to_have_value(
        "my careful description"
    )

    bad = {"format": "srlab-network/1", "name": "bad", "associations": [{"stimulus": "Nope"}]}
    page.click("details:has(#import-form) > summary")
    page.fill("#import-form textarea[name=text]", json.dumps(bad))
    page.click("#import-form button[type=submit]")
    message = page.locator(".toast.error").last
    expect(message).to_contain_text("associations.0.behaviour")
    expect(page.locator("#import-form textarea[name=text]")).to_have_value(json.dumps(bad))

    # A built-in network is read-only, and the page says so instead of failing silently.
    page.click(cell(page, "Red", "stop"))
    page.keyboard.press("Space")
    expect(page.locator(".toast.error").last).to_contain_text("read-only")


def test_keystrokes_faster_than_the_server_are_all_applied_in_order(
    page: Page, server: LiveServer
) -> None:
    fresh_network(server, "fast-keys", base="innate")
    open_view(page, server, "editor/fast-keys")
    page.click(cell(page, "Yellow", "stop"))
    for key in ("Space", "3", "l", "ArrowDown", "Space", "ArrowUp", "l", "7", "Enter"):
        page.keyboard.press(key)  # no waiting between them
    expected = {"strength": 0.7, "source": "dp", "locked": False}
    eventually(
        lambda: (
            (association(server, "fast-keys", "Yellow", "stop") or {}).items() >= expected.items()
        ),
        what="Yellow -> stop at 0.7, unlocked",
    )
    assert association(server, "fast-keys", "Green", "stop")["strength"] == 1.0
    notes = [
        v["note"] for v in server.client.get("/api/networks/fast-keys/versions").json()["data"]
    ]
    # Created, then one version per cell edited (leaving a cell or Enter saves it), none lost.
    assert len(notes) == 1 + 3
