"""A pytest plugin for the reliability suite: each test phase's outcome, as it happens.

Loaded with ``-p reliability_outcomes`` by `tests.reliability.suite`, which runs pytest in
a child process: every phase's report goes to the JSON-lines file named by
``SRLAB_RELIABILITY_OUTCOMES`` at once, so the table is written whatever ends the child
(a crash at exit, a warning turned into an error, a kill).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

OUTCOMES_VARIABLE = "SRLAB_RELIABILITY_OUTCOMES"


def why(report: pytest.TestReport) -> str:
    """The last line of a report's reason (its skip message or its failure)."""
    if report.skipped and isinstance(report.longrepr, tuple):
        text = str(report.longrepr[2])
    else:
        text = str(report.longrepr) if report.longrepr else ""
    return text.strip().splitlines()[-1] if text.strip() else ""


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Append the phase's outcome and duration."""
    path = os.environ.get(OUTCOMES_VARIABLE)
    if not path:
        return
    line = {
        "test": report.nodeid,
        "outcome": report.outcome,
        "seconds": report.duration,
        "why": "" if report.passed else why(report),
    }
    with Path(path).open("a", encoding="utf-8") as f:
        f.write(json.dumps(line) + "\n")
