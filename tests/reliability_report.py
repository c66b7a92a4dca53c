"""Rows of the reliability table: what a check tried and what it measured.

A test calls `record` before its final assertions; the row goes to the JSON-lines file
named by ``SRLAB_RELIABILITY_ROWS`` (`python -m tests.reliability.suite` sets it), and
nowhere otherwise. The suite adds whether the test passed, so a row never claims to have
held on its own.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

ROWS_VARIABLE = "SRLAB_RELIABILITY_ROWS"


def record(check: str, tried: str, measured: str) -> None:
    """Add a row for the running test: the check's name, what it tried, what it measured."""
    path = os.environ.get(ROWS_VARIABLE)
    if not path:
        return
    test = os.environ.get("PYTEST_CURRENT_TEST", "").rsplit(" ", 1)[0]
    row = {"test": test, "check": check, "tried": tried, "measured": measured}
    with Path(path).open("a", encoding="utf-8") as f:
        f.write(json.dumps(row) + "\n")


def count(n: int) -> str:
    """A count with thousands separators."""
    return f"{n:,}"
