"""Helpers for driving the editor and console pages."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

from playwright.sync_api import Page
from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

from bench.liveserver import LiveServer

T = TypeVar("T")


def open_view(page: Page, server: LiveServer, route: str) -> None:
    """Open the page at `route` (e.g. "editor/mine") and wait until it has loaded.

    A page that never gets ready fails with what it showed (its toasts, the service's
    health), so a rare stall says where it stood.
    """
    page.goto(f"{server.url}/#/{route}")
    try:
        page.wait_for_selector("body[data-ready=true]")
    except PlaywrightTimeoutError:
        toasts = page.locator(".toast").all_inner_texts()
        health = server.client.get("/api/health")
        raise AssertionError(
            f"the page at #/{route} never got ready; its toasts: {toasts}; "
            f"the service's health: {health.status_code} {health.text}"
        ) from None


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
