"""The reliability suite at full size: every check, then a table of what held.

    python -m tests.reliability.suite            # what `make reliability` runs (~25 min)
    python -m tests.reliability.suite --quick    # the sizes CI runs (~3 min)

It runs tests/reliability and the schemathesis test with pytest at the sizes below (an
environment variable already set wins), with PostgreSQL from ``SRLAB_TEST_POSTGRES_URL``
(`make reliability` starts one; without it those checks are skipped). It prints a table
with one row per check: what was tried, what was measured, whether it held (the test
passed). The table also goes to docs/reliability.md, replacing the one between its
markers and leaving the page's text around it. The exit status is pytest's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))  # as pytest does: the tests' helpers are top-level
from reliability_outcomes import OUTCOMES_VARIABLE  # noqa: E402
from reliability_report import ROWS_VARIABLE  # noqa: E402

FULL = {
    "SRLAB_SERVE_KILLS": "200",
    "SRLAB_SERVE_KILLS_PG": "25",
    "SRLAB_CRASH_KILLS": "100",
    "SRLAB_SIGTERMS": "20",
    "SRLAB_LOAD_SECONDS": "60",
    "SRLAB_FUZZ_EXAMPLES": "1000",
    "SRLAB_DAY_EPISODES": "10000",
    "SRLAB_DAY_RUNS": "400",
    "SRLAB_STATEFUL_EXAMPLES": "100",
}
"""The full sizes; the tests' own defaults are CI's."""
TESTS = [
    "tests/reliability",
    "tests/server/api/test_schemathesis.py",
    "tests/server/api/test_cross_site.py",
    "tests/server/viewer/test_viewer_malformed.py",
    "tests/web/test_attack_page.py",
    "tests/server/api/test_slow_clients.py",
    "tests/server/api/test_network_versions.py",
    "tests/server/api/test_strict_bodies.py",
]
TABLE_START = "<!-- reliability-table:start -->"
TABLE_END = "<!-- reliability-table:end -->"


@dataclass
class Outcomes:
    """Each test's outcome and duration, in run order, from the child's phase reports."""

    results: dict[str, tuple[str, float, str]] = field(default_factory=dict)

    def add(self, test: str, outcome: str, seconds: float, why: str) -> None:
        """Keep the worst phase's outcome; add up the phases' durations."""
        was, total, reason = self.results.get(test, ("passed", 0.0, ""))
        if outcome != "passed" and was == "passed":
            was, reason = outcome, why
        self.results[test] = (was, total + seconds, reason)

    @classmethod
    def read(cls, path: Path) -> Outcomes:
        """The outcomes the plugin wrote (none when the child wrote nothing)."""
        outcomes = cls()
        lines = path.read_text(encoding="utf-8").splitlines() if path.exists() else []
        for line in lines:
            r = json.loads(line)
            outcomes.add(r["test"], r["outcome"], float(r["seconds"]), r["why"])
        return outcomes


class LoadSampler:
    """The machine's 1-minute load average every few seconds while the suite runs."""

    def __init__(self, every_s: float = 10.0) -> None:
        self.samples = [os.getloadavg()[0]]
        self._stop = threading.Event()
        self._every_s = every_s
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._every_s):
            self.samples.append(os.getloadavg()[0])

    def stop(self) -> str:
        """The load seen: at the start, the mean, the highest and at the end."""
        self._stop.set()
        self._thread.join()
        s = [*self.samples, os.getloadavg()[0]]
        return f"start {s[0]:.2f}, mean {sum(s) / len(s):.2f}, max {max(s):.2f}, end {s[-1]:.2f}"


def _cell(text: str) -> str:
    return text.replace("|", "/").replace("\n", " ")


def table(rows: list[dict[str, str]], outcomes: Outcomes) -> str:
    """The markdown table: a row per check, tests that recorded nothing included."""
    by_test: dict[str, list[dict[str, str]]] = {}
    for row in rows:
        by_test.setdefault(row["test"], []).append(row)
    lines = [
        "| check | tried | measured | held | time |",
        "|---|---|---|---|---|",
    ]
    for test, (outcome, seconds, why) in outcomes.results.items():
        held = {"passed": "yes", "failed": "**NO**", "skipped": "skipped"}.get(outcome, outcome)
        recorded = by_test.get(test) or [
            {"check": test.split("::")[-1], "tried": "", "measured": why or outcome}
        ]
        for row in recorded:
            measured = row["measured"]
            if outcome != "passed" and why and why not in measured:
                measured += f" ({outcome}: {why})"
            lines.append(
                f"| {_cell(row['check'])} | {_cell(row['tried'])} | {_cell(measured)} | "
                f"{held} | {seconds:.0f} s |"
            )
    return "\n".join(lines)


def _git(*args: str) -> str:
    done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False)
    return done.stdout.strip()


def main(argv: list[str] | None = None) -> int:
    """Run the suite, print and write the table; pytest's exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="CI's sizes, not the full ones")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "reliability.md")
    parser.add_argument("pytest_args", nargs="*", help="more pytest arguments (after --)")
    args = parser.parse_args(argv)
    sizes = {} if args.quick else FULL
    for name, value in sizes.items():
        os.environ.setdefault(name, value)
    if not os.environ.get("SRLAB_TEST_POSTGRES_URL"):
        sys.stderr.write(
            "reliability: SRLAB_TEST_POSTGRES_URL is not set, the PostgreSQL checks will be "
            "skipped (`make reliability` starts a server)\n"
        )
    commit = _git("rev-parse", "--short", "HEAD") + (" (modified)" if _git("status", "-s") else "")
    started = time.monotonic()
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    load = LoadSampler()
    with tempfile.TemporaryDirectory(prefix="srlab-reliability-") as tmp:
        rows_file = Path(tmp) / "rows.jsonl"
        outcomes_file = Path(tmp) / "outcomes.jsonl"
        env = {**os.environ, ROWS_VARIABLE: str(rows_file), OUTCOMES_VARIABLE: str(outcomes_file)}
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "tests"), env.get("PYTHONPATH", "")])
        # pytest in a child: whatever ends it, the outcomes so far and the rows make the table.
        command = [sys.executable, "-m", "pytest", *TESTS, "-q", "-p", "no:cacheprovider"]
        command += ["-p", "reliability_outcomes", *args.pytest_args]
        status = subprocess.run(command, cwd=ROOT, env=env, check=False).returncode
        outcomes = Outcomes.read(outcomes_file)
        rows = (
            [json.loads(line) for line in rows_file.read_text().splitlines()]
            if rows_file.exists()
            else []
        )
    minutes = (time.monotonic() - started) / 60
    sizes_used = ", ".join(f"{k}={os.environ[k]}" for k in FULL if k in os.environ)
    header = (
        f"`{'python -m tests.reliability.suite' + (' --quick' if args.quick else '')}` "
        f"(`make reliability`), {when}, commit {commit}, {minutes:.0f} min on "
        f"{os.cpu_count()} cores; load average {load.stop()}; sizes: {sizes_used or 'CI'}."
    )
    body = table(rows, outcomes)
    sys.stdout.write(f"\n{header}\n\n{body}\n")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    old = args.out.read_text() if args.out.exists() else ""
    block = f"{TABLE_START}\n{header}\n\n{body}\n{TABLE_END}"
    if TABLE_START in old and TABLE_END in old:
        # Replace the table only: the page's account of the suite around it stays.
        before, rest = old.split(TABLE_START, 1)
        _, after = rest.split(TABLE_END, 1)
        args.out.write_text(before + block + after)
    else:
        args.out.write_text(f"# Reliability\n\n{block}\n")
    sys.stdout.write(f"\nwritten to {args.out}\n")
    if status != 0 and not outcomes.results:
        sys.stderr.write(f"reliability: pytest ended with status {status} before any test ran\n")
    return int(status)


if __name__ == "__main__":
    raise SystemExit(main())
