"""Helpers for driving the editor and console pages."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

from playwright.sync_api import Locator, Page, Request, expect
from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

from bench.liveserver import LiveServer

T = TypeVar("T")


def open_view(page: Page, server: LiveServer, route: str) -> None:
    """Open the page at `route` (e.g. "editor/mine") and wait until it has loaded.

    A page that never gets ready fails with what it showed (its toasts, the service's
    health), so a rare stall says where it stood.
    """
    pending: dict[Request, float] = {}
    began = time.monotonic()

    def sent(request: Request) -> None:
        pending[request] = time.monotonic() - began

    def done(request: Request) -> None:
        pending.pop(request, None)

    page.on("request", sent)
    page.on("requestfinished", done)
    page.on("requestfailed", done)
    try:
        page.goto(f"{server.url}/#/{route}")
        page.wait_for_selector("body[data-ready=true]")
    except PlaywrightTimeoutError:
        toasts = page.locator(".toast").all_inner_texts()
        health = server.client.get("/api/health")
        unanswered = [f"{r.method} {r.url} (sent at {t:.1f} s)" for r, t in pending.items()]
        raise AssertionError(
            f"the page at #/{route} never got ready; its toasts: {toasts}; "
            f"requests it still waits for: {unanswered}; "
            f"the service's health: {health.status_code} {health.text}"
        ) from None
    finally:
        page.remove_listener("request", sent)
        page.remove_listener("requestfinished", done)
        page.remove_listener("requestfailed", done)


def cell(page: Page, stimulus: str, behaviour: str, where: str = "#matrix") -> str:
    """The selector of one matrix cell."""
    return f'{where} td.c[data-s="{stimulus}"][data-b="{behaviour}"]'


def eventually(check: Callable[[], T | None], timeout: float = 90.0, what: str = "") -> T:
    """Poll `check` until it returns something truthy."""
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what or check}")
        time.sleep(0.1)


def set_open(details: Locator, want: bool = True, tries: int = 5) -> None:
    """Open (or close) a `<details>` block by clicking its summary, as a person would.

    A panel that redraws itself (the KP inspector, every second) can replace the block
    between the press and the release of a click, and that click toggles nothing: like a
    person, click again until the block is as wanted.
    """
    for _ in range(tries):
        if details.evaluate("d => d.open") == want:
            return
        details.locator("summary").first.click()
        try:
            expect(details).to_have_js_property("open", want, timeout=2000)
            return
        except AssertionError:
            continue
    raise AssertionError(f"the block never became {'open' if want else 'closed'}")
