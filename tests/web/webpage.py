"""Helpers for driving the editor and console pages."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar

from playwright.sync_api import ConsoleMessage, Error, Locator, Page, Request, Response, expect
from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

from bench.liveserver import LiveServer

T = TypeVar("T")

NETWORK_CHANGE_WAIT_MS = 15_000
"""How long a page may take to get ready before a load Chromium aborted is tried again."""


def open_view(page: Page, server: LiveServer, route: str) -> None:
    """Open the page at `route` (e.g. "editor/mine") and wait until it has loaded.

    A page that never gets ready fails with what it showed and did (its toasts, its
    connection badge, the requests it still waits for, the answers that were not 2xx, the
    requests that failed, its console's errors, the service's health), so a rare stall
    says where it stood.
    """
    began = time.monotonic()
    pending: dict[Request, float] = {}
    seen: list[str] = []

    def at() -> str:
        return f"{time.monotonic() - began:.1f} s"

    def sent(request: Request) -> None:
        pending[request] = time.monotonic() - began

    def finished(request: Request) -> None:
        pending.pop(request, None)

    def failed(request: Request) -> None:
        pending.pop(request, None)
        seen.append(f"{request.method} {request.url} failed ({request.failure}) at {at()}")

    def answered(response: Response) -> None:
        if not 200 <= response.status < 300:
            seen.append(f"{response.request.method} {response.url} -> {response.status} at {at()}")

    def console(message: ConsoleMessage) -> None:
        if message.type == "error":
            seen.append(f"console error at {at()}: {message.text}")

    def error(exc: Error) -> None:
        seen.append(f"page error at {at()}: {exc}")

    listeners: list[tuple[str, Callable[[Any], None]]] = [
        ("request", sent),
        ("requestfinished", finished),
        ("requestfailed", failed),
        ("response", answered),
        ("console", console),
        ("pageerror", error),
    ]
    for event, listener in listeners:
        page.on(event, listener)  # type: ignore[call-overload]
    try:
        page.goto(f"{server.url}/#/{route}")
        try:
            page.wait_for_selector("body[data-ready=true]", timeout=NETWORK_CHANGE_WAIT_MS)
        except PlaywrightTimeoutError:
            if not any("ERR_NETWORK_CHANGED" in line for line in seen):
                page.wait_for_selector("body[data-ready=true]")
            else:
                # Chromium aborts what it is loading when the machine's interfaces change
                # (podman's tests add and remove networks beside the browser tests): a
                # module that never loaded leaves a page that never starts. Load it again,
                # as a person would.
                seen.append("reloaded after ERR_NETWORK_CHANGED")
                page.reload()
                page.wait_for_selector("body[data-ready=true]")
    except PlaywrightTimeoutError:
        toasts = page.locator(".toast").all_inner_texts()
        badge = page.locator("#conn").get_attribute("class", timeout=5000)
        health = server.client.get("/api/health")
        unanswered = [f"{r.method} {r.url} (sent at {t:.1f} s)" for r, t in pending.items()]
        raise AssertionError(
            f"the page at #/{route} never got ready; its toasts: {toasts}; its badge: "
            f"{badge}; requests it still waits for: {unanswered}; what went wrong: {seen}; "
            f"the service's health: {health.status_code} {health.text}"
        ) from None
    finally:
        for event, listener in listeners:
            page.remove_listener(event, listener)


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
