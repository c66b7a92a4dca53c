"""A study end to end in real Chromium, on a service whose reads need a token
(`SRLAB_READS=token`), as a lab would serve one.

The organiser makes a study on the Studies page and invites three people; each, in a
browser context of their own, opens their link, consents, trains with + and -, answers
the questionnaire once their budget is spent and sees the completion code. The organiser
exports the study: each participant's reward rows are exactly what their console listed,
and no byte carries a recruiter's id. The pages hold a token (the organiser's saved one, a
participant's from their link) and send it with every request, the live event stream
included (read with fetch: EventSource cannot send one), and never in a URL. Every wait
is on a condition, never a fixed time.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from collections.abc import Iterator

import httpx
import pytest
from browser import artifact
from conftest import BROWSER_WAIT_MS
from playwright.sync_api import Browser, BrowserContext, Page, Request, expect
from routewalk import study_body
from studypage import CODE, consent, create_study, invite, reward

from bench.liveserver import LiveServer, live_server

TOKEN = "organiser-s3cret"
STUDY = study_body("closed", consent_version="v1", completion_code="C0DE42")


@pytest.fixture(scope="module")
def closed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """`srlab serve` whose reads need a token, with its 3D view; its client holds the
    organiser's token."""
    env = {"SRLAB_READS": "token", "SRLAB_TOKEN": TOKEN}
    with live_server(tmp_path_factory.mktemp("closed") / "web.db", env) as server:
        server.client.headers["Authorization"] = f"Bearer {TOKEN}"
        yield server


def test_a_participants_console_goes_live_with_their_token(
    closed: LiveServer, browser: Browser
) -> None:
    api = closed.client
    assert api.post("/api/studies", json=STUDY).status_code == 201
    [invited] = api.post("/api/studies/closed/participants", json={"count": 1}).json()["data"]
    token = invited["token"]
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    context.set_default_timeout(BROWSER_WAIT_MS)  # a load on a busy machine
    sent: list[Request] = []
    try:
        page = context.new_page()
        page.on("request", lambda r: sent.append(r))
        run_id = consent(page, invited["link"])

        # Ticks arrive on the stream (only its ticks show the lamp and the behaviour).
        expect(page.locator("#st-lamp")).not_to_have_text("—")
        expect(page.locator("#st-behaviour")).not_to_have_text("—")
        streams = [r for r in sent if r.url.endswith(f"/api/runs/{run_id}/events?tick_hz=10")]
        assert streams and all(r.headers.get("authorization") == f"Bearer {token}" for r in streams)
        assert not [r.url for r in sent if token in r.url]  # never in a URL
    finally:
        context.close()

    # Without a token the same stream is refused; the health check is anyone's.
    anonymous = httpx.get(f"{closed.url}/api/runs/{run_id}/events", timeout=10)
    assert anonymous.status_code == 401
    assert httpx.get(f"{closed.url}/api/health", timeout=10).status_code == 200


def test_a_participant_opens_the_3d_view_of_their_own_run_alone(
    closed: LiveServer, browser: Browser
) -> None:
    api = closed.client
    assert api.post("/api/studies", json={**STUDY, "name": "viewed"}).status_code == 201
    invited = api.post("/api/studies/viewed/participants", json={"count": 2}).json()["data"]
    viser_port = api.get("/api/health").json()["viser_port"]
    view = f"http://127.0.0.1:{viser_port}"
    # Without a ticket's cookie the view answers nobody here (reads need a token).
    assert httpx.get(f"{view}/", timeout=10).status_code == 401
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    context.set_default_timeout(BROWSER_WAIT_MS)
    sent: list[Request] = []
    try:
        page = context.new_page()
        other = consent(context.new_page(), invited[1]["link"])
        run_id = consent(page, invited[0]["link"])
        context.on("request", lambda r: sent.append(r))
        with context.expect_page() as opened:
            page.click("#study-view3d")
        viewer = opened.value
        viewer.get_by_text(f"Run {run_id}:").first.wait_for()
        # The ticket is traded for a cookie and gone from the URL; the token never in one.
        # (viser's page adds its socket's URL as `?websocket=`.)
        assert viewer.url.split("?")[0] == f"{view}/run/{run_id}"
        assert "ticket" not in viewer.url
        token = invited[0]["token"]
        assert not [r.url for r in sent if token in r.url]
        # Read-only, this run alone: no run list, no rewards, no tick rate.
        expect(viewer.get_by_text("srlab 3D view")).to_be_visible()
        for control in ("+ reward", "- reward"):
            expect(viewer.get_by_role("button", name=control)).to_be_hidden()
        expect(viewer.get_by_text("Tick rate (Hz)")).to_be_hidden()
        expect(viewer.get_by_text(re.compile(r"^Run$"))).to_be_hidden()
        viewer.screenshot(path=str(artifact("study-participant-3d.png")))
        # Another's run, or the view of every run, in the same browser: refused.
        for path in (f"/run/{other}", "/"):
            refused = context.request.get(f"{view}{path}")
            assert refused.status in (401, 403), (path, refused.status)
    finally:
        context.close()


def test_the_organisers_pages_read_with_the_saved_token(closed: LiveServer, page: Page) -> None:
    made = closed.client.post("/api/studies", json={**STUDY, "name": "watched"})
    assert made.status_code == 201, made.text
    page.add_init_script(f"localStorage.setItem('srlab.token', {TOKEN!r})")
    page.goto(f"{closed.url}/#/studies")
    page.wait_for_selector("body[data-ready=true]")
    expect(page.locator('#studies-list tr[data-study="watched"]')).to_be_visible()


def test_the_organisers_3d_link_opens_the_view_with_a_writable_panel(
    closed: LiveServer, page: Page
) -> None:
    api = closed.client
    body = {"condition": "trainer", "mode": "realtime", "hz": 10, "seed": 4}
    run_id = api.post("/api/runs", json=body).json()["id"]
    assert api.post(f"/api/runs/{run_id}/start").status_code == 200
    try:
        page.add_init_script(f"localStorage.setItem('srlab.token', {TOKEN!r})")
        page.goto(f"{closed.url}/#/console/{run_id}")
        page.wait_for_selector("body[data-ready=true]")
        with page.context.expect_page() as opened:
            page.click("#view3d")  # POST .../view with the saved token: a ticket for it
        viewer = opened.value
        viewer.set_default_timeout(BROWSER_WAIT_MS)
        viewer.get_by_text(f"Run {run_id}:").first.wait_for()
        expect(viewer.get_by_role("button", name="+ reward")).to_be_enabled()
    finally:
        api.post(f"/api/runs/{run_id}/stop")


QUESTIONS = ("How hard was it?", "What did you reward?")
RECRUITER_IDS = ["prolific-e2eA7Q", "prolific-e2eB3Z", "prolific-e2eC9K"]
"""Distinctive: finding one in an exported byte means it leaked."""
PRESSES: list[list[tuple[str, str]]] = [
    [("+", ""), ("-", ""), ("#reward-plus", "went straight")],
    [("-", ""), ("#reward-minus", "hit the wall"), ("+", "")],
    [("+", ""), ("+", ""), ("-", ""), ("#reward-plus-half", "almost")],
]
"""What each participant presses (a key, or a button after typing a note), in order."""


def organiser_page(browser: Browser, server: LiveServer) -> tuple[BrowserContext, Page]:
    """The Studies page in a context of its own, holding the organiser's saved token."""
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    context.set_default_timeout(BROWSER_WAIT_MS)  # a load on a busy machine
    context.add_init_script(f"localStorage.setItem('srlab.token', {TOKEN!r})")
    page = context.new_page()
    page.goto(f"{server.url}/#/studies")
    page.wait_for_selector("body[data-ready=true]")
    return context, page


def train(page: Page, presses: list[tuple[str, str]]) -> None:
    """Press + and - as `presses` says; wait until the console lists each, credited."""
    for press, note in presses:
        if note:
            page.fill("#reward-note", note)
        reward(page, press)
        page.locator("#reward-note").blur()  # the keys go to the console, not the note
    mine = page.locator("#my-rewards li")
    expect(mine).to_have_count(len(presses))
    # Credits come on the event stream: every reward shown credited means it is live.
    expect(mine.locator(".muted", has_text="credited")).to_have_count(len(presses))


def listed(page: Page) -> list[tuple[int, str, float, int, str]]:
    """The participant's rewards as their console lists them, oldest first:
    (id, uid, value, tick, note), read from the page."""
    shown: list[dict[str, str]] = page.locator("#my-rewards li").evaluate_all(
        """items => items.map(li => ({
            id: li.dataset.id, uid: li.dataset.uid,
            value: li.querySelector('.v').textContent,
            what: li.querySelector('.what').textContent,
            note: li.querySelector('.reward-note')?.textContent ?? '',
        }))"""
    )
    out = []
    for item in reversed(shown):
        tick = re.search(r"tick (\d+)", item["what"])
        assert tick is not None, item
        value = float(item["value"].replace("\u2212", "-").replace("½", "0.5"))
        note = item["note"].removeprefix(" · ")
        out.append((int(item["id"]), item["uid"], value, int(tick.group(1)), note))
    return out


def finish(page: Page, answers: list[str]) -> None:
    """Once the budget is spent: answer the questions, then the completion code shows."""
    expect(page.locator("#questionnaire")).to_be_visible()
    expect(page.locator("#completion-code")).to_have_count(0)  # not before the answers
    for n, text in enumerate(answers, 1):
        page.fill(f"#answer-{n}", text)
    page.click("#answers-submit")
    expect(page.locator("#completion-code")).to_have_text(CODE)


def test_a_study_end_to_end_its_export_matches_each_console(
    closed: LiveServer, browser: Browser
) -> None:
    context, organiser = organiser_page(browser, closed)
    contexts = [context]
    shown: list[list[tuple[int, str, float, int, str]]] = []
    runs: list[int] = []
    try:
        create_study(organiser, questions=QUESTIONS)
        links = invite(organiser, RECRUITER_IDS)
        pages = []
        for link, presses in zip(links, PRESSES, strict=True):
            person = browser.new_context(viewport={"width": 1280, "height": 800})
            person.set_default_timeout(BROWSER_WAIT_MS)  # a load on a busy machine
            contexts.append(person)
            page = person.new_page()
            pages.append(page)
            runs.append(consent(page, link))
            train(page, presses)
            shown.append(listed(page))
        for i, page in enumerate(pages):
            finish(page, [f"answer {i}.{n}" for n in range(1, len(QUESTIONS) + 1)])
        pages[-1].screenshot(path=str(artifact("study-e2e-participant.png")))
        done = organiser.locator('#studies-list tr[data-study="pilot"] td[data-status="done"]')
        expect(done).to_have_text("3")
    finally:
        for each in contexts:
            each.close()

    r = closed.client.get("/api/studies/pilot/export", timeout=60)
    assert r.status_code == 200, r.text
    with zipfile.ZipFile(io.BytesIO(r.content)) as z:
        files = {name: z.read(name) for name in z.namelist()}
    for name, data in files.items():  # no recruiter's id anywhere
        for external in RECRUITER_IDS:
            assert external.encode() not in data, f"{external} in {name}"
    manifest = json.loads(files["study-pilot/study.json"])
    by_run = {p["run"]: p["pseudonym"] for p in manifest["participants"]}
    assert sorted(by_run) == sorted(runs)
    assert all(p["status"] == "done" for p in manifest["participants"])
    rows = [json.loads(line) for line in files["study-pilot/rewards.jsonl"].splitlines()]
    for run_id, on_page, presses in zip(runs, shown, PRESSES, strict=True):
        exported = [
            (row["id"], row["uid"], row["value"], row["tick"], row["note"])
            for row in rows
            if row["participant"] == by_run[run_id] and row["source"] == "trainer"
        ]
        assert exported == on_page
        assert [note for *_, note in exported] == [note for _, note in presses]
        assert all(row["run"] == run_id for row in rows if row["participant"] == by_run[run_id])
    answers = [json.loads(line) for line in files["study-pilot/answers.jsonl"].splitlines()]
    assert [(a["participant"], a["question"], a["answer"]) for a in answers] == [
        (by_run[run_id], q, f"answer {i}.{n}")
        for i, run_id in enumerate(runs)
        for n, q in enumerate(QUESTIONS, 1)
    ]
