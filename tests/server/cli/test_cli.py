"""The `srlab` command line: JSON summary, traces, and clean errors for bad arguments."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench.liveserver import free_port
from server.cli import main

REPO = Path(__file__).resolve().parents[3]


def fail(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Run the CLI expecting exit code 2; return stderr."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "Traceback" not in captured.err
    return captured.err


def test_simulate_json_prints_one_object(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "--condition", "expert", "--episodes", "3", "--seed", "1", "--json"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    summary = json.loads(out)
    assert {"episodes", "successes", "success_rate", "failures", "ticks"} <= set(summary)
    assert summary["episodes"] == 3
    assert set(summary["failures"]) == {
        "wall_collision",
        "obstacle_collision",
        "signal_violation",
        "timeout",
    }
    assert summary["successes"] + sum(summary["failures"].values()) == 3
    assert summary["success_rate"] == pytest.approx(summary["successes"] / 3)
    assert summary["ticks"] > 0


def test_simulate_json_is_reproducible(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "--condition", "delayed", "--episodes", "2", "--seed", "4", "--json"]
    main(argv)
    first = capsys.readouterr().out
    main([*argv, "--quiet"])
    assert capsys.readouterr().out == first


def test_simulate_prints_a_table_for_people(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--condition", "innate", "--episodes", "2", "--quiet"]) == 0
    out = capsys.readouterr().out
    for row in ("episodes", "successes", "success rate", "obstacle collision", "ticks/s"):
        assert row in out


def test_simulate_with_a_strategy(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "--condition", "expert", "--episodes", "1", "--strategy", "priority"]
    assert main([*argv, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["simulate", "--condition", "genius"], "invalid choice: 'genius'"),
        (["simulate", "--condition", "expert", "--episodes", "0"], "must be at least 1, got 0"),
        (["simulate", "--condition", "expert", "--episodes", "-3"], "must be at least 1"),
        (["simulate", "--condition", "expert", "--seed", "-1"], "must be 0 or more, got -1"),
        (["simulate", "--condition", "expert", "--episodes", "ten"], "'ten' is not a whole"),
        (["simulate", "--condition", "expert", "--seed", "1.5"], "'1.5' is not a whole number"),
        (["simulate", "--condition", "expert", "--strategy", "vote"], "invalid choice: 'vote'"),
        (["simulate"], "the following arguments are required: --condition"),
        (["fly"], "invalid choice: 'fly'"),
        ([], "required: COMMAND"),
    ],
)
def test_bad_arguments_exit_2_with_a_message(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = fail(argv, capsys)
    assert message in err
    assert "usage: srlab" in err


def test_trace_writes_one_json_line_per_snapshot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    trace = tmp_path / "trace.jsonl"
    argv = ["simulate", "--condition", "expert", "--episodes", "2", "--seed", "1"]
    assert main([*argv, "--json", "--trace", str(trace)]) == 0
    summary = json.loads(capsys.readouterr().out)
    rows = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
    # A reset snapshot per episode, then one per tick.
    assert len(rows) == summary["ticks"] + 2
    first = rows[0]
    assert (first["episode"], first["episode_tick"], first["behaviour"]) == (0, 0, None)
    for row in rows:
        assert {"x", "y", "heading_rad", "stimuli", "behaviour"} <= set(row)
        assert isinstance(row["x"], float)
        assert isinstance(row["stimuli"], list)
    ticking = [r for r in rows if r["episode_tick"] > 0]
    assert all(isinstance(r["behaviour"], str) for r in ticking)
    assert any("Middle" in r["stimuli"] for r in ticking)
    assert any("Corner" in r["stimuli"] for r in ticking)
    ends = [r for r in rows if "outcome" in r]
    assert [r["episode"] for r in ends] == [0, 1]
    assert [r["tick"] for r in rows if r["episode_tick"] > 0] == list(
        range(1, summary["ticks"] + 1)
    )


@pytest.mark.parametrize("where", ["missing-dir/trace.jsonl", "."])
def test_unwritable_trace_exits_2_with_a_message(
    tmp_path: Path, where: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / where
    err = fail(["simulate", "--condition", "expert", "--trace", str(path)], capsys)
    assert err.startswith("srlab: error: ")
    assert str(path) in err


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "server.cli", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["runs", "--url", "nope://x"], "SQLAlchemy has no dialect or driver 'nope'"),
        (
            ["db", "upgrade", "--url", "postgresql+nodriver://u:secret@h/db"],
            "'postgresql+nodriver://u:***@h/db'",
        ),
        (["db", "upgrade", "--url", "mysql://u:secret@h/db"], "driver is not installed (MySQLdb)"),
        (["db", "upgrade", "--url", "a file name"], "is not a SQLAlchemy URL"),
        (
            ["run", "--condition", "kp", "--episodes", "1", "--url", "REFUSED"],
            "Connection refused",
        ),
        (["runs", "--url", "sqlite:////proc/srlab.db"], "unable to open database file"),
    ],
)
def test_a_bad_or_unreachable_database_is_one_line_without_the_password(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    url = f"postgresql+psycopg://u:secret@127.0.0.1:{free_port()}/db"
    err = fail([url if a == "REFUSED" else a for a in argv], capsys)
    assert message in err
    assert err.startswith("srlab: error: ") and err.count("\n") == 1
    assert "secret" not in err


def test_serve_with_an_unreachable_database_exits_2_with_a_message(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    url = f"postgresql+psycopg://srlab:secret@127.0.0.1:{free_port()}/srlab"
    monkeypatch.setenv("SRLAB_DATABASE_URL", url)
    # Free ports: `serve` checks them first, and another server here may hold 8000.
    monkeypatch.setenv("SRLAB_PORT", str(free_port()))
    monkeypatch.setenv("SRLAB_VISER_PORT", str(free_port()))
    err = fail(["serve"], capsys)
    assert "srlab:***@127.0.0.1" in err and "Connection refused" in err
    assert "secret" not in err


@pytest.mark.slow
def test_console_script_exits_2_without_a_traceback() -> None:
    script = REPO / ".venv" / "bin" / "srlab"
    argv = [str(script)] if script.exists() else [sys.executable, "-m", "server.cli"]
    done = subprocess.run(
        [*argv, "simulate", "--condition", "expert", "--episodes", "0"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2
    assert "must be at least 1" in done.stderr
    assert "Traceback" not in done.stderr
    assert done.stdout == ""


@pytest.mark.slow
def test_module_entry_point_runs_a_json_simulation() -> None:
    done = run_cli("simulate", "--condition", "expert", "--episodes", "1", "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["episodes"] == 1
    assert "Traceback" not in done.stderr


def test_simulate_counts_ticks_by_source_and_names_its_setup(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    trace = tmp_path / "t.jsonl"
    argv = ["simulate", "--condition", "kp", "--episodes", "2", "--seed", "1", "--json"]
    argv += ["--world", "classic", "--sensors", "paper", "--signal", "given", "--quiet"]
    assert main([*argv, "--trace", str(trace)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert (summary["world"], summary["sensors"], summary["signal"]) == (
        "classic",
        "paper",
        "given",
    )
    by_source = summary["ticks_by_source"]
    assert sum(by_source.values()) == summary["ticks"]
    assert by_source["designed"] > 0  # lane keeping and the sonar reflexes of kp's design
    rows = [json.loads(line) for line in trace.read_text().splitlines()]
    assert len(rows) == summary["ticks"] + 2  # each episode's first snapshot too
    ran = [r for r in rows if r["how"] == "released"]
    assert ran and all(r["released_by"] is not None and r["source"] for r in ran)
    assert {r["source"] for r in ran} <= {"innate", "designed", "expert", "kp"}


def test_simulate_refuses_a_condition_the_architecture_does_not_run(
    capsys: pytest.CaptureFixture[str],
) -> None:
    err = fail(["simulate", "--condition", "qlambda", "--episodes", "1"], capsys)
    assert "srlab experiment --conditions qlambda" in err


def test_world_check_prints_each_property_and_writes_its_report(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    argv = ["world-check", "--world", "classic", "--sensors", "path", "--seeds", "2"]
    argv += ["--episodes", "3", "--jobs", "1", "--quiet", "--json", "--out", str(tmp_path)]
    code = main(argv)
    report = json.loads(capsys.readouterr().out)
    (check,) = report["checks"]
    assert check["world"] == "classic" and check["sensors"] == "path"
    assert [p["key"] for p in check["properties"]] == ["a", "b", "c", "d"]
    assert code == (0 if check["holds"] else 1)
    for p in check["properties"]:
        assert p["holds"] == (p["bounds"][0] <= p["success"]["mean"] <= p["bounds"][1])
    md = (tmp_path / "world-check.md").read_text()
    assert "| (b) | the sonar reflexes alone pass only in part | reflexes + signal |" in md
    assert json.loads((tmp_path / "world-check.json").read_text())["checks"] == report["checks"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["world-check", "--world", "moon"], "unknown world 'moon'"),
        (["world-check", "--sensors", "sonar"], "unknown sensor definition 'sonar'"),
        (["simulate", "--condition", "kp", "--world", "moon"], "invalid choice: 'moon'"),
    ],
)
def test_setup_names_are_checked_with_a_clear_error(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert message in fail(argv, capsys)


@pytest.mark.slow
def test_the_command_line_loads_no_command_s_machinery_before_it_runs() -> None:
    """`srlab` (and so every `srlab serve`) starts without the experiment code, gymnasium,
    Ray or the report plots: each command imports what it needs when it runs."""
    heavy = (
        "core.lab.experiment",
        "core.learners.qlambda",
        "gymnasium",
        "ray",
        "server.backends.ray",
        "matplotlib",
    )
    script = f"import sys\nimport server.cli\nprint(*(m for m in {heavy!r} if m in sys.modules))\n"
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == ""
