"""`srlab db`, `srlab run` and `srlab runs` against a real SQLite file."""

from __future__ import annotations

import io
import json
import os
import re
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from core.brain.catalog import sensor_definitions
from core.run.setup import default_sensors
from core.sim.worlds import default_world, world_names
from server.cli import build_parser, main
from server.cli import run as run_cli
from server.cli.db import open_store

ROOT = Path(__file__).resolve().parents[3]


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


PROGRESS = re.compile(r"^(\d+)/(\d+) episodes ended, (\d+) successes, tick ([\d,]+) \((\w+)\)$")
INTERRUPTED = re.compile(
    r"^run 1 interrupted at tick ([\d,]+), in episode 2/2; stored: 1 episode, \d+ success(es)?, "
    r"to the end of episode 1 \(tick ([\d,]+)\)$"
)


def number(text: str) -> int:
    return int(text.replace(",", ""))


def test_each_progress_line_counts_the_episodes_ended_by_its_tick(
    db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(run_cli, "PROGRESS_EVERY_S", 0.0)  # a line at each look (4 a second)
    argv = ["run", "--condition", "kp", "--episodes", "1", "--mode", "realtime", "--hz", "100"]
    err = io.StringIO()  # no terminal: plain lines
    assert run_cli.run(build_parser().parse_args(argv), io.StringIO(), err) == 0
    store, engine = open_store(db_url)
    try:
        ends = [e.start_tick + e.ticks for e in store.episode_summaries(1)]
    finally:
        engine.dispose()
    assert len(ends) == 1
    lines = err.getvalue().splitlines()[1:]
    claims = [m for m in map(PROGRESS.match, lines) if m]
    assert lines and len(claims) == len(lines), err.getvalue()
    for claim in claims:
        ended, tick = int(claim[1]), number(claim[4])
        assert ended == sum(end <= tick for end in ends), claim[0]
    assert int(claims[0][1]) == 0  # the first look comes long before the episode ends
    assert claims[-1][0].startswith("1/1 episodes ended") and claims[-1][5] == "finished"


@pytest.mark.slow
def test_a_run_interrupted_mid_episode_says_what_resume_keeps_and_goes_on_to_the_same_end(
    db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    env = {**os.environ, "SRLAB_DATABASE_URL": db_url}
    argv = ["--condition", "kp", "--seed", "0", "--episodes", "2"]
    child = srlab("run", *argv, "--mode", "realtime", "--hz", "50", env=env)
    assert child.stderr is not None
    lines = []
    for line in child.stderr:  # a line at the first episode's end (realtime, no terminal)
        lines.append(line)
        if line.startswith("1/2 episodes ended"):
            break
    else:
        pytest.fail(f"no line at the first episode's end: {lines}")
    time.sleep(1)  # some ticks into the second episode (200 ticks long at this seed: 4 s)
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=60)
    assert child.returncode == 0, err
    assert "Traceback" not in err
    said = out.splitlines()
    stopped = INTERRUPTED.match(said[0])
    assert stopped is not None, out
    live, kept = number(stopped[1]), number(stopped[3])
    assert said[1] == (
        f"--resume runs episode 2 again from its start ({live - kept:,} ticks), to the same "
        "end as if it had not stopped"
    )
    assert said[2] == "resume it with: srlab run --resume 1"
    # `srlab runs` shows what the message said was kept, and says what resume does.
    [run] = runs_json(capsys)
    assert (run["status"], run["episodes"], run["ticks"]) == ("interrupted", 1, kept)
    assert 0 < kept < live
    assert main(["runs"]) == 0
    assert "--resume runs the episode it stopped in again" in capsys.readouterr().out

    again = srlab("run", "--resume", "1", env=env)
    out, err = again.communicate(timeout=120)
    assert again.returncode == 0, err
    assert f"resumed from the end of episode 1 (tick {kept:,})" in err.splitlines()[0]
    # The same end as a run that never stopped: the same episodes, ticks and LTM.
    assert main(["run", *argv, "--quiet"]) == 0
    resumed, uninterrupted = runs_json(capsys)
    for key in ("status", "episodes", "successes", "ticks"):
        assert resumed[key] == uninterrupted[key], key
    store, engine = open_store(db_url)
    try:
        assert store.ltm(1) == store.ltm(2)
    finally:
        engine.dispose()
