"""`srlab db`, `srlab run` and `srlab runs` against a real SQLite file."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from core.brain.catalog import sensor_definitions
from core.setup import default_sensors
from core.worlds import default_world, world_names
from server.cli import build_parser, main
from server.cli import run as run_cli

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def db_url(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    url = f"sqlite:///{tmp_path / 'srlab.db'}"
    monkeypatch.setenv("SRLAB_DATABASE_URL", url)
    return url


def runs_json(capsys: pytest.CaptureFixture[str]) -> list[dict[str, object]]:
    capsys.readouterr()
    assert main(["runs", "--json"]) == 0
    out: list[dict[str, object]] = json.loads(capsys.readouterr().out)["runs"]
    return out


def test_db_upgrade_creates_and_seeds_the_database(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["db", "upgrade"]) == 0
    assert "newest schema" in capsys.readouterr().out
    with sqlite3.connect(tmp_path / "srlab.db") as db:
        names = {r[0] for r in db.execute("select name from networks")}
        assert {"innate", "dp", "kp", "expert"} <= names
        assert db.execute("pragma journal_mode").fetchone()[0] == "wal"
    assert main(["db", "upgrade"]) == 0  # again: nothing changes
    assert main(["db", "downgrade", "base"]) == 0
    with sqlite3.connect(tmp_path / "srlab.db") as db:
        tables = {r[0] for r in db.execute("select name from sqlite_master where type='table'")}
    assert "runs" not in tables


def test_run_fast_stores_the_run_and_runs_lists_it(
    db_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "--condition", "kp", "--seed", "3", "--episodes", "4", "--quiet"]) == 0
    assert "run 1 finished: 4 episodes" in capsys.readouterr().out
    [run] = runs_json(capsys)
    assert (run["id"], run["condition"], run["status"], run["episodes"]) == (
        1,
        "kp",
        "finished",
        4,
    )
    assert main(["runs"]) == 0
    table = capsys.readouterr().out
    assert "finished" in table and "kp" in table


def test_run_in_a_world_and_sensor_definition_and_runs_shows_them(
    db_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    other = next(n for n in world_names() if n != default_world())
    sensors = next(d for d in sensor_definitions() if d != default_sensors())
    args = build_parser().parse_args(["run", "--condition", "kp", "--episodes", "1", "--quiet"])
    # As `--world` and `--sensors` set them (the parser reads the names from core's lists).
    args.world, args.sensors = other, sensors
    assert run_cli.run(args, sys.stdout, sys.stderr) == 0
    assert main(["run", "--condition", "kp", "--episodes", "1", "--quiet"]) == 0
    first, second = runs_json(capsys)
    assert (first["world"], first["sensors"]) == (other, sensors)
    assert (second["world"], second["sensors"]) == (default_world(), default_sensors())
    assert main(["runs"]) == 0
    table = capsys.readouterr().out
    assert other in table and sensors in table and default_world() in table


def test_run_with_learning_parameters(db_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["run", "--condition", "rp", "--episodes", "2", "--eta", "0.2", "--epsilon", "0.3"]
    assert main([*argv, "--quiet"]) == 0
    [run] = runs_json(capsys)
    assert run["status"] == "finished"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run"], "run needs --condition"),
        (["run", "--condition", "nope"], "invalid choice"),
        (["run", "--condition", "kp", "--hz", "0"], "must be in (0, 1000]"),
        (["run", "--condition", "kp", "--eta", "2"], "must be in [0, 1]"),
        (["run", "--condition", "qlambda", "--episodes", "1"], "not run by the engine"),
        (["run", "--resume", "99"], "no run 99"),
        (["db"], "required"),
    ],
)
def test_run_bad_arguments_exit_2_with_a_message(
    db_url: str, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err


def test_resume_of_a_finished_run_is_refused(
    db_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "--condition", "innate", "--episodes", "1", "--quiet"]) == 0
    with pytest.raises(SystemExit) as e:
        main(["run", "--resume", "1"])
    assert e.value.code == 2
    assert "finished: nothing to resume" in capsys.readouterr().err


def srlab(*args: str, env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "server.cli", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_running(db: Path, child: subprocess.Popen[str], timeout_s: float = 60) -> None:
    """Until run 1 is running (its signal handlers are in place by then), then a moment more.

    A fixed sleep is not enough on a loaded machine: the CLI's start-up takes seconds there, and
    a signal before the handlers are installed kills it with a traceback.
    """
    deadline = time.monotonic() + timeout_s
    with sqlite3.connect(db, timeout=10) as conn:
        while time.monotonic() < deadline:
            assert child.poll() is None, child.communicate()
            time.sleep(0.2)
            try:
                row = conn.execute("select status from runs where id = 1").fetchone()
            except sqlite3.OperationalError:
                continue
            if row and row[0] == "running":
                time.sleep(0.5)
                return
    pytest.fail(f"run 1 was not running within {timeout_s:g} s")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_a_realtime_run_cleanly_and_it_resumes(
    db_url: str, tmp_path: Path, sig: signal.Signals, capsys: pytest.CaptureFixture[str]
) -> None:
    env = {**os.environ, "SRLAB_DATABASE_URL": db_url}
    child = srlab("run", "--condition", "delayed", "--mode", "realtime", "--hz", "50", env=env)
    wait_running(tmp_path / "srlab.db", child)
    child.send_signal(sig)
    out, err = child.communicate(timeout=30)
    assert child.returncode == 0, err
    assert "run 1 interrupted" in out
    assert "srlab run --resume 1" in out
    assert "Traceback" not in err
    [run] = runs_json(capsys)
    assert run["status"] == "interrupted"

    again = srlab("run", "--resume", "1", "--quiet", env=env)
    wait_running(tmp_path / "srlab.db", again)
    again.send_signal(signal.SIGINT)
    out, err = again.communicate(timeout=30)
    assert again.returncode == 0, err
    assert "run 1 interrupted" in out
