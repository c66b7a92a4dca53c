"""A study on a service whose reads need a token (`SRLAB_READS=token`), in real Chromium.

The pages hold a token (the organiser's saved one, a participant's from their link) and
send it with every request, the live event stream included (read with fetch: EventSource
cannot send one), and never in a URL.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from playwright.sync_api import Browser, Page, Request, expect
from studypage import consent

from bench.liveserver import LiveServer, live_server

TOKEN = "organiser-s3cret"
STUDY: dict[str, Any] = {
    "name": "closed",
    "conditions": ["trainer"],
    "budget": {"seconds": 3600},
    "consent_text": "You will train a simulated robot.",
    "consent_version": "v1",
    "completion_code": "C0DE42",
}


@pytest.fixture(scope="module")
def closed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """`srlab serve` whose reads need a token; its client holds the organiser's."""
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


def test_the_organisers_pages_read_with_the_saved_token(closed: LiveServer, page: Page) -> None:
    page.add_init_script(f"localStorage.setItem('srlab.token', {TOKEN!r})")
    page.goto(f"{closed.url}/#/studies")
    page.wait_for_selector("body[data-ready=true]")
    expect(page.locator('#studies-list tr[data-study="closed"]')).to_be_visible()
