"""Two editor tabs on one network in real Chromium: neither overwrites the other silently.

Each save carries the version it was based on; the tab that is behind gets 412, is shown
what the other tab changed, and reapplies its change only when the user says so. Undo
goes through the same check.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from liveserver import LiveServer
from playwright.sync_api import Browser, Dialog, Page, expect
from webpage import cell, open_view


def association(server: LiveServer, stimulus: str, behaviour: str) -> Any:
    data = server.client.get("/api/networks/tabs/associations").json()["data"]
    return next((a for a in data if (a["stimulus"], a["behaviour"]) == (stimulus, behaviour)), None)


@pytest.fixture
def tabs(browser: Browser, server: LiveServer) -> Iterator[tuple[Page, Page]]:
    server.client.delete("/api/networks/tabs")
    r = server.client.post("/api/networks", json={"name": "tabs", "base": "innate"})
    assert r.status_code == 201, r.text
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    pages = (context.new_page(), context.new_page())
    for page in pages:
        page.set_default_timeout(90_000)
        open_view(page, server, "editor/tabs")
    try:
        yield pages
    finally:
        context.close()


def test_the_tab_behind_is_shown_the_other_change_and_reapplies_only_if_asked(
    server: LiveServer, tabs: tuple[Page, Page]
) -> None:
    a, b = tabs
    a.bring_to_front()  # a background tab's timers and frames are throttled
    a.click(cell(a, "Red", "goforward1"))
    a.keyboard.press("Space")  # tab A adds Red -> goforward1: version 2
    expect(a.locator("#net-meta")).to_contain_text("version 2")

    asked: list[str] = []

    def accept(dialog: Dialog) -> None:
        asked.append(dialog.message)
        dialog.accept()

    b.once("dialog", accept)
    b.bring_to_front()
    b.click(cell(b, "Green", "stop"))
    b.keyboard.press("Space")  # tab B still shows version 1
    # Waiting through the page lets Playwright answer the dialog (a sleep would not).
    expect(b.locator(cell(b, "Green", "stop"))).to_have_attribute("data-present", "true")
    expect(b.locator("#net-meta")).to_contain_text("version 3")
    assert association(server, "Green", "stop") is not None
    assert "version 1 → 2" in asked[0] and "+ Red → goforward1" in asked[0], asked
    # Both changes are stored, and tab B now shows A's too.
    assert association(server, "Red", "goforward1") is not None
    expect(b.locator(cell(b, "Red", "goforward1"))).to_have_attribute("data-present", "true")
    assert server.client.get("/api/networks/tabs").json()["version"] == 3

    # Tab A is behind now; its undo (remove Red -> goforward1) asks first, and "no"
    # leaves B's version as it is.
    declined: list[str] = []

    def dismiss(dialog: Dialog) -> None:
        declined.append(dialog.message)
        dialog.dismiss()

    a.once("dialog", dismiss)
    a.bring_to_front()
    a.keyboard.press("Control+z")
    expect(a.locator(".toast.error").last).to_contain_text("was not saved")
    assert "+ Green → stop" in declined[0], declined
    assert server.client.get("/api/networks/tabs").json()["version"] == 3
    assert association(server, "Red", "goforward1") is not None
    expect(a.locator(cell(a, "Green", "stop"))).to_have_attribute("data-present", "true")
