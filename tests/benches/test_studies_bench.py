"""bench.studies: its own bookkeeping (rewards sent, acknowledged, logged; foreign reads).

Never its timings: those depend on the machine (docs/benchmarks.md has them).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from bench.studies import figures
from bench.study_trainers import MARKER

ROOT = Path(__file__).resolve().parents[2]


def test_a_quick_study_logs_every_reward_once_and_refuses_every_foreign_read(
    tmp_path: Path,
) -> None:
    out = tmp_path / "figures.json"
    done = subprocess.run(
        [sys.executable, "-m", "bench.studies", "--quick", "--json", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,  # a hang guard, not a speed test
        check=False,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    f = json.loads(out.read_text())
    assert f["sent"] > 0
    assert f["sent"] == f["acknowledged"] == f["logged"]
    assert (f["lost"], f["duplicated"], f["errors"]) == (0, 0, 0)
    assert f["foreign_tries"] >= f["trainers"]  # each tries at their first press
    assert (f["foreign_read"], f["foreign_other"]) == (0, 0)
    assert len(f["lateness_p99_ms"]) == f["trainers"]
    for figure in ("reward ack p50 / p95 / p99", "tick lateness p99, worst run", "goal met"):
        assert figure in done.stdout
    assert "rewards sent" in done.stdout.split("study bench-")[1]  # progress while it runs


def _tally(markers: list[str], acked: dict[str, str], **more: Any) -> dict[str, Any]:
    return {
        "acks_s": [0.001] * len(acked), "markers": markers, "acked": acked, "refused": 0,
        "other": {}, "errors": 0, "foreign_tries": 1, "foreign_read": 0, "foreign_other": 0,
        "ticks": 10, "polls": 0, **more,
    }  # fmt: skip


def _row(mark: str, uid: str) -> dict[str, Any]:
    return {"note": f"{MARKER} {mark}", "uid": uid}


STATE = {"status": "running", "live": {"lateness_p99_ms": 1.0, "overruns": 0}}


def test_the_count_finds_a_lost_a_duplicated_and_a_foreign_read() -> None:
    log = [_row("a", "u1"), _row("b", "u2"), {"note": "by hand", "uid": "u9"}]
    whole = figures([_tally(["a", "b"], {"a": "u1", "b": "u2"})], [STATE], log)
    assert (whole.sent, whole.acknowledged, whole.logged, whole.lost) == (2, 2, 2, 0)
    assert whole.ok

    lost = figures([_tally(["a", "b"], {"a": "u1", "b": "u2"})], [STATE], [_row("a", "u1")])
    assert (lost.lost, lost.logged, lost.ok) == (1, 1, False)

    twice = figures([_tally(["a"], {"a": "u1"})], [STATE], [_row("a", "u1"), _row("a", "u1")])
    assert (twice.duplicated, twice.ok) == (2, False)  # by marker and by uid

    unanswered = figures([_tally(["a", "b"], {"a": "u1"})], [STATE], [_row("a", "u1")])
    assert (unanswered.lost, unanswered.ok) == (0, False)  # sent, never acknowledged

    read = figures([_tally(["a"], {"a": "u1"}, foreign_read=1)], [STATE], [_row("a", "u1")])
    assert (read.foreign_read, read.ok) == (1, False)

    late = {"status": "running", "live": {"lateness_p99_ms": 10.5, "overruns": 2}}
    slow = figures([_tally(["a"], {"a": "u1"})], [late], [_row("a", "u1")])
    assert (slow.overruns, slow.ok) == (2, False)
