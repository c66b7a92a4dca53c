"""The CLI's output and arguments, one test each: progress, choices, tables, plain lines, CIs."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from core.lab.analysis import mean_ci
from core.ports import Mode, RunSpec, RunStatus, RunTotals, StoredRun
from core.run.conditions import CONDITIONS
from server.cli import build_parser, main
from server.cli import run as run_cli
from server.cli.common import ENGINE_CONDITIONS
from server.reports.base import fmt as _fmt
from server.schemas import EngineCondition

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def db_url(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    url = f"sqlite:///{tmp_path / 'srlab.db'}"
    monkeypatch.setenv("SRLAB_DATABASE_URL", url)
    return url


@pytest.mark.slow
def test_run_realtime_prints_progress_as_it_goes(db_url: str) -> None:
    # stderr is a pipe here: plain lines, one per realtime episode (a terminal gets a live
    # line instead). 1000 Hz keeps it short; the lines do not depend on how fast it runs.
    argv = ["run", "--condition", "innate", "--mode", "realtime", "--hz", "1000"]
    done = subprocess.run(
        [sys.executable, "-m", "server.cli", *argv, "--episodes", "2"],
        cwd=ROOT,
        env={**os.environ, "SRLAB_DATABASE_URL": db_url},
        capture_output=True,
        text=True,
        timeout=300,  # a hang guard
    )
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert lines[0].startswith("run 1: innate, seed 0,")
    assert "realtime at 1000 Hz (Ctrl-C stops it; srlab run --resume 1 goes on)" in lines[0]
    assert any(line.startswith("1/2 episodes ended, 0 successes, tick ") for line in lines)
    assert any(line.startswith("2/2 episodes ended, 0 successes, tick ") for line in lines)
    assert "Traceback" not in done.stderr
    assert "run 1 finished: 2 episodes" in done.stdout


def test_run_help_offers_exactly_the_conditions_it_accepts(
    capsys: pytest.CaptureFixture[str],
) -> None:
    accepted = set(EngineCondition.__args__)  # type: ignore[attr-defined]
    assert set(ENGINE_CONDITIONS) == accepted
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", "--help"])
    shown = "{" + ",".join(sorted(accepted)) + "}"
    assert shown in capsys.readouterr().out
    for name in set(CONDITIONS) - accepted:  # qlambda and the deep baselines
        with pytest.raises(SystemExit) as e:
            main(["run", "--condition", name])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert f"srlab experiment --conditions {name}" in err
        assert "Traceback" not in err


def stored(i: int, status: RunStatus) -> StoredRun:
    spec = RunSpec("reflexes", 123, 1000, Mode.REALTIME, 10.0, None, {}, "soft-obstacle", "path")
    return StoredRun(i, spec, status, RunTotals(999, 512, 1_234_567), None, (), ())


def test_runs_table_fits_80_columns_with_every_status_whole() -> None:
    runs = [stored(i + 1, s) for i, s in enumerate(RunStatus)]
    out = io.StringIO()
    Console(file=out, width=80).print(run_cli.runs_table(runs, "sqlite:///var/srlab.db"))
    lines = out.getvalue().splitlines()
    assert max(len(line) for line in lines) <= 80
    body = "\n".join(lines)
    for s in RunStatus:
        assert any(f" {s.value} " in line for line in lines), (s, body)
    assert "…" not in body
    assert "1,234,567" in body and "999/1000" in body
    header = next(line for line in lines if line.startswith("id "))
    assert header.split() == [
        "id",
        "condition",
        "seed",
        "world/sensors",
        "mode",
        "status",
        "episodes",
        "ok",
        "ticks",
    ]
    assert " reflexes " in body and " soft-obstacle/path " in body, "nothing wrapped at 80"


def test_db_upgrade_prints_plain_lines(db_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["db", "upgrade"]) == 0
    first = capsys.readouterr().out
    assert "SeedReport" not in first and "added=" not in first
    assert "seeded the catalogue and the shipped networks:" in first
    assert "rows added, 0 updated" in first
    assert main(["db", "upgrade"]) == 0
    assert "already seeded: nothing changed" in capsys.readouterr().out


def test_a_rate_with_two_seeds_prints_an_interval_inside_0_1() -> None:
    stat = mean_ci([0.0, 0.1])  # Student's t half-width 64%: "5% +- 64%" before
    assert stat["ci95"] > 0.6
    assert _fmt(stat, pct=True) == "5% [0, 10]"
    # A malformed interval past [0, 1] is clipped, never printed as is.
    assert (
        _fmt({"mean": 0.05, "low": -0.2, "high": 1.3, "n": 2, "ci95": 0.64}, pct=True)
        == "5% [0, 100]"
    )
    assert _fmt({"mean": 0.5, "low": float("nan"), "high": float("nan"), "n": 1}, pct=True) == "50%"
    assert _fmt({"mean": float("nan")}, pct=True) == "-"


def test_an_unexpected_error_is_one_line_without_a_traceback(
    db_url: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def broken(*_: object) -> int:
        raise RuntimeError("the disk said no\nsecond line")

    monkeypatch.setattr(run_cli, "runs", broken)
    monkeypatch.delenv("SRLAB_DEBUG", raising=False)
    with pytest.raises(SystemExit) as e:
        main(["runs"])
    assert e.value.code == 1
    err = capsys.readouterr().err
    assert err == (
        "srlab: error: RuntimeError: the disk said no (SRLAB_DEBUG=1 shows the traceback)\n"
    )
    monkeypatch.setenv("SRLAB_DEBUG", "1")
    with pytest.raises(RuntimeError):
        main(["runs"])


def test_make_run_says_where_the_cli_is() -> None:
    done = subprocess.run(
        ["make", "-n", "run"], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert "CLI: .venv/bin/srlab" in done.stdout
    assert "uv run --no-dev srlab" in done.stdout and "source .venv/bin/activate" in done.stdout
