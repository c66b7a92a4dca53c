"""Debian's Chromium driven by Playwright, the way DEVELOPERS.md prescribes."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from playwright.sync_api import Browser

from bench import browser as bench_browser
from bench.browser import CHROMIUM

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"


def require_chromium() -> None:
    """Skip without Chromium; fail instead where it is required (CI)."""
    if CHROMIUM.exists():
        return
    message = f"{CHROMIUM} is missing: 'apt-get install -y chromium' (make test does it as root)"
    if os.environ.get("SRLAB_REQUIRE_BROWSER") == "1":
        pytest.fail(message)
    pytest.skip(message)


@contextmanager
def chromium() -> Iterator[Browser]:
    """A headless Chromium for one test module."""
    require_chromium()
    with bench_browser.chromium() as launched:
        yield launched


def artifact(name: str) -> Path:
    """Where a test saves a screenshot or trace (kept after the run, ignored by git)."""
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS / name
