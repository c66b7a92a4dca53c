"""Two editor tabs on one network in real Chromium: neither overwrites the other silently.

Each page polls the network's version and redraws the matrix when another tab saved. Each
save carries the version and the cell it was based on: a change of another cell made
elsewhere is kept and ours goes on top; if the cell itself changed, the editor shows what
the other tab did and reapplies only when the user says so; an undo is refused then, so it
never deletes the other tab's write.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Dialog, Page, expect
from webpage import cell, eventually, open_view

from bench.liveserver import LiveServer


def association(server: LiveServer, stimulus: str, behaviour: str) -> Any:
    data = server.client.get("/api/networks/tabs/associations").json()["data"]
    return next((a for a in data if (a["stimulus"], a["behaviour"]) == (stimulus, behaviour)), None)


def version(server: LiveServer) -> int:
    out: int = server.client.get("/api/networks/tabs").json()["version"]
    return out


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


def edit(page: Page, stimulus: str, behaviour: str, *keys: str) -> None:
    page.bring_to_front()  # a background tab's timers and frames are throttled
    page.click(cell(page, stimulus, behaviour))
    for key in keys:
        page.keyboard.press(key)


def test_a_tab_shows_what_another_tab_saved_without_reloading(
    server: LiveServer, tabs: tuple[Page, Page]
) -> None:
    a, b = tabs
    edit(a, "Red", "goforward1", "Space", "Enter")
    eventually(lambda: association(server, "Red", "goforward1"))
    b.bring_to_front()
    # Tab B did nothing: its poll finds version 2 and redraws.
    expect(b.locator(cell(b, "Red", "goforward1"))).to_have_attribute("data-present", "true")
    expect(b.locator("#net-meta")).to_contain_text("version 2")
    expect(b.locator("#versions li")).to_have_count(2)
    # And B's own change then goes on top of A's, both kept.
    edit(b, "Green", "stop", "Space", "Enter")
    eventually(lambda: version(server) == 3)
    assert association(server, "Red", "goforward1") and association(server, "Green", "stop")


def test_a_redraw_for_a_change_elsewhere_keeps_the_draft_unsaved(
    server: LiveServer, tabs: tuple[Page, Page]
) -> None:
    a, _ = tabs
    edit(a, "Green", "stop", "Space", "7")  # a draft: nothing saved until Enter
    expect(a.locator("#draft-note")).to_contain_text("Unsaved: Green → stop")
    r = server.client.put("/api/networks/tabs/associations/Red/stop", json={"strength": 0.4})
    assert r.status_code == 200  # another cell, elsewhere: version 2
    # The poll finds version 2 and redraws the matrix under the draft: the draft stays a
    # draft, its cell keeps the focus, and nothing of it is written.
    expect(a.locator("#net-meta")).to_contain_text("version 2")
    expect(a.locator(cell(a, "Red", "stop"))).to_have_text(".4")
    expect(a.locator("#draft-note")).to_contain_text("Unsaved: Green → stop")
    assert association(server, "Green", "stop") is None and version(server) == 2
    a.keyboard.press("Enter")  # the user's Enter writes it, on top of version 2
    eventually(lambda: (association(server, "Green", "stop") or {}).get("strength") == 0.7)
    assert version(server) == 3


def test_a_change_to_a_cell_changed_elsewhere_asks_and_reapplies_only_if_told(
    server: LiveServer, tabs: tuple[Page, Page]
) -> None:
    a, b = tabs
    # Tab A asks when it writes its draft, on Enter (a poll's redraw under the draft keeps
    # it a draft: test_a_redraw_for_a_change_elsewhere_keeps_the_draft_unsaved). A's
    # questions are answered whenever they come, and each is checked after.
    asked: list[str] = []
    reapply = False

    def answer(dialog: Dialog) -> None:
        asked.append(dialog.message)
        if reapply:
            dialog.accept()
        else:
            dialog.dismiss()

    a.on("dialog", answer)
    edit(a, "Green", "stop", "Space")  # a draft in tab A, not saved yet
    expect(a.locator("#draft-note")).to_contain_text("Unsaved: Green → stop")
    edit(b, "Green", "stop", "Space", "5", "Enter")  # tab B saves the same cell first
    eventually(lambda: (association(server, "Green", "stop") or {}).get("strength") == 0.5)

    a.bring_to_front()
    a.keyboard.press("Enter")
    expect(a.locator(".toast.error").last).to_contain_text("was not saved")
    assert len(asked) == 1, asked
    question = asked[0]
    assert "Green → stop" in question and "Reapply" in question, question
    assert association(server, "Green", "stop")["strength"] == 0.5 and version(server) == 2
    expect(a.locator(cell(a, "Green", "stop"))).to_have_text(".5")

    # Asked again and told yes, tab A's change goes on top of the other writes.
    edit(b, "Red", "stop", "Space", "Enter")  # B moves on: version 3
    eventually(lambda: version(server) == 3)
    reapply = True
    edit(a, "Green", "stop", "8")
    r = server.client.put("/api/networks/tabs/associations/Green/stop", json={"strength": 0.6})
    assert r.status_code == 200  # elsewhere, again: version 4, while A's draft waits
    a.keyboard.press("Enter")
    expect(a.locator("#net-meta")).to_contain_text("version 5")  # asked, answered, saved
    assert len(asked) == 2, asked
    assert "now 0.60" in asked[1] or "0.60" in asked[1]
    eventually(lambda: (association(server, "Green", "stop") or {}).get("strength") == 0.8)
    assert version(server) == 5 and association(server, "Red", "stop")


def test_undo_never_deletes_another_tabs_write(server: LiveServer, tabs: tuple[Page, Page]) -> None:
    a, b = tabs
    edit(a, "Red", "goforward1", "Space", "Enter")  # A: version 2
    eventually(lambda: association(server, "Red", "goforward1"))
    edit(a, "Yellow", "goforward1", "Space", "Enter")  # A: version 3
    eventually(lambda: version(server) == 3)
    b.bring_to_front()
    expect(b.locator(cell(b, "Yellow", "goforward1"))).to_have_attribute("data-present", "true")
    edit(b, "Yellow", "goforward1", "3", "Enter")  # B changes A's cell: version 4
    eventually(lambda: association(server, "Yellow", "goforward1")["strength"] == 0.3)

    a.bring_to_front()
    a.keyboard.press("Control+z")  # would remove Yellow -> goforward1, B's now
    expect(a.locator(".toast.error").last).to_contain_text("changed elsewhere")
    expect(a.locator(".toast.error").last).to_contain_text("not undone")
    assert association(server, "Yellow", "goforward1")["strength"] == 0.3
    assert version(server) == 4
    # The undo before it touches a cell nobody else changed: it goes through.
    a.keyboard.press("Control+z")
    eventually(lambda: association(server, "Red", "goforward1") is None)
    assert association(server, "Yellow", "goforward1")["strength"] == 0.3
    expect(a.locator("#undo")).to_be_disabled()
