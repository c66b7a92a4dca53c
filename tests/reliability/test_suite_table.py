"""The reliability suite's table: outcomes from the child's reports, rows per check."""

from __future__ import annotations

import json
from pathlib import Path

from suite import Outcomes, table


def test_the_worst_phase_wins_and_durations_add_up(tmp_path: Path) -> None:
    path = tmp_path / "outcomes.jsonl"
    phases = [
        ("t.py::a", "passed", 0.5, ""),
        ("t.py::a", "failed", 1.0, "AssertionError: no"),
        ("t.py::a", "passed", 0.25, ""),
        ("t.py::b", "skipped", 0.0, "needs PostgreSQL"),
    ]
    reports = [{"test": t, "outcome": o, "seconds": s, "why": w} for t, o, s, w in phases]
    path.write_text("".join(json.dumps(r) + "\n" for r in reports))
    outcomes = Outcomes.read(path)
    assert outcomes.results == {
        "t.py::a": ("failed", 1.75, "AssertionError: no"),
        "t.py::b": ("skipped", 0.0, "needs PostgreSQL"),
    }
    rows = [{"test": "t.py::a", "check": "kill -9", "tried": "100 kills", "measured": "0 lost"}]
    lines = table(rows, outcomes).splitlines()
    assert (
        lines[2] == "| kill -9 | 100 kills | 0 lost (failed: AssertionError: no) | **NO** | 2 s |"
    )
    assert lines[3] == "| b |  | needs PostgreSQL | skipped | 0 s |"


def test_a_child_that_wrote_nothing_gives_no_outcomes(tmp_path: Path) -> None:
    assert Outcomes.read(tmp_path / "missing.jsonl").results == {}
