"""A study in the browser: the organiser's page and three participants' pages.

The organiser makes a study on the page (a refused field says why beside it), invites
three participants by recruiters' ids and copies their links; three people, each in a
browser context of their own, open their link, consent, reward their run with + and -,
cannot see another's run, and reach the completion code once the budget is spent. Every
reward each gave is in their own run's log and in no other run's.
"""

from __future__ import annotations

import re
from typing import Any

from browser import artifact
from playwright.sync_api import Browser, BrowserContext, Page, expect
from studypage import BUDGET_S, CODE, consent, create_study, invite, reward
from webpage import open_view

from bench.liveserver import LiveServer


def test_a_study_from_invitation_to_completion(
    server: LiveServer, browser: Browser, page: Page
) -> None:
    open_view(page, server, "studies")
    create_study(page)
    links = invite(page, ["prolific-a", "prolific-b", "prolific-c"])
    assert all(re.search(r"/#/study/srp_", link) for link in links)
    page.screenshot(path=str(artifact("studies-organiser.png")), full_page=True)

    contexts: list[BrowserContext] = []
    pages: list[Page] = []
    runs: list[int] = []
    given: list[list[dict[str, Any]]] = []
    try:
        for i, link in enumerate(links):
            context = browser.new_context(viewport={"width": 1280, "height": 800})
            contexts.append(context)
            participant = context.new_page()
            pages.append(participant)
            runs.append(consent(participant, link))
            given.append([reward(participant, "+"), reward(participant, "-")])
            given[i].append(reward(participant, "#reward-plus"))
        assert len(set(runs)) == 3
        # The organiser watches each one's run get on: its seconds of the budget's.
        progress = page.locator("#participants td.progress")
        expect(progress).to_have_count(3)
        expect(progress.last).to_contain_text(f" / {BUDGET_S} s")  # the newest trains on
        last = pages[-1]
        last.screenshot(path=str(artifact("study-participant.png")))
        # Blind to their condition: its description, the KP inspector are not on their page.
        mine = server.client.get(f"/api/runs/{runs[-1]}").json()["condition"]
        conditions = server.client.get("/api/conditions").json()
        about = next(c["description"] for c in conditions if c["name"] == mine)
        # Read at once (an expectation would wait until the budget ends and hides it all).
        assert last.locator("#train-card").is_visible()
        assert not last.locator("#train-about").is_visible()
        assert not last.locator("#kp-inspector").is_visible()
        assert not last.locator("#st-origins").is_visible()
        assert about not in last.locator("body").inner_text()
        # Another's run, named in the URL: a clear refusal in place of the console.
        last.evaluate(f"location.hash = '#/console/{runs[0]}'")
        expect(last.locator(".study-error")).to_contain_text("only their own run")
        expect(last.locator("#view-console")).to_be_hidden()
        last.evaluate(f"location.hash = '#/study/{links[-1].split('/#/study/')[1]}'")
        for participant in pages:
            expect(participant.locator("#completion-code")).to_have_text(CODE)
            expect(participant.locator("#view-console")).to_be_hidden()
    finally:
        for context in contexts:
            context.close()

    # Each reward is in its giver's run's log (the organiser's view), and in no other.
    for run_id, acks in zip(runs, given, strict=True):
        log = server.client.get(f"/api/runs/{run_id}/rewards", params={"limit": 1000}).json()
        trainer = [(r["id"], r["value"]) for r in log["data"] if r["source"] == "trainer"]
        assert trainer == [(a["id"], a["value"]) for a in acks]
    assert [a["value"] for a in given[0]] == [1, -1, 1]

    # Progress on the organiser's page; then the recruiters' ids go, after a confirmation.
    done = page.locator('#studies-list tr[data-study="pilot"] td[data-status="done"]')
    expect(done).to_have_text("3")
    expect(page.locator("#participants td.progress")).to_have_text(["budget spent"] * 3)
    page.once("dialog", lambda dialog: dialog.accept())
    page.locator('#studies-list tr[data-study="pilot"] button').click()
    expect(page.locator("#toasts")).to_contain_text("3 recruiter ids of pilot deleted")


def test_an_unknown_link_says_so(server: LiveServer, page: Page) -> None:
    page.goto(f"{server.url}/#/study/srp_not-a-token")
    page.wait_for_selector("body[data-ready=true]")
    expect(page.locator(".study-error")).to_contain_text("This link is not known here")
    expect(page.locator("#view-console")).to_be_hidden()
    expect(page.locator("#tab-editor")).to_be_hidden()
