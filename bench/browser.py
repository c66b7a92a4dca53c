"""Debian's Chromium and the flags DEVELOPERS.md prescribes, for benches and browser tests.

`bench.viewer` drives it itself; tests/browser.py wraps it in Playwright for the web tests.
"""

from __future__ import annotations

import os
from pathlib import Path

CHROMIUM = Path(os.environ.get("SRLAB_CHROMIUM", "/usr/bin/chromium"))
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
