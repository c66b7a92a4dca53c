"""`srlab phase` on the local backend: the report, its determinism, clear errors for bad input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from clihelpers import assert_png, exits_2

from server.cli import main

PHASE = [
    "phase",
    "--param",
    "echo_range_m=0.6",
    "--conditions",
    "kp,sonar",
    "--signal",
    "given",
    "--seeds",
    "2",
    "--episodes",
    "3",
    "--quiet",
]
"""A tiny grid: the base world and one point off it, 2 seeds x 3 episodes."""


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("phase")
    assert main([*PHASE, "--jobs", "1", "--out", str(out)]) == 0
    return out


def test_phase_writes_every_report_file(report: Path) -> None:
    assert {p.name for p in report.iterdir()} == {
        "summary.json",
        "summary.md",
        "runs.jsonl",
        "phase.png",
        "phase_by_parameter.png",
    }


def test_phase_summary_md_starts_with_its_command_then_the_declared_grid(report: Path) -> None:
    md = (report / "summary.md").read_text()
    lines = md.splitlines()
    assert lines[0] == "# srlab phase"
    assert lines[2].startswith("`srlab phase --param echo_range_m=0.6 --conditions kp,sonar")
    grid = md.index("## The grid, declared before running")
    assert grid < md.index("## Where each difference holds") < md.index("## By parameter")
    assert "| `echo_range_m` | `track.obstacle.echo_range_m` | m | 0.3 | 0.6 |" in md
    assert "![Each difference against the reflexes' success, per point](phase.png)" in md
    table = md[md.index("### `echo_range_m` (m)") :]
    assert "| echo_range_m (m) | reflexes' success | kp - sonar |" in table
    rows = [line for line in table.splitlines() if line.startswith(("| 0.3", "| 0.6"))]
    assert [r.split(" |")[0] for r in rows] == ["| 0.3 (base)", "| 0.6"]
    assert "Where the sign changes" in table
    assert "## Failed tasks" not in md


def test_phase_summary_json_pairs_each_point_by_seed(report: Path) -> None:
    doc = json.loads((report / "summary.json").read_text())
    params = doc["params"]
    assert params["conditions"] == ["reflexes", "kp", "sonar"]
    assert (params["points"], params["tasks"], params["seeds"]) == (2, 2 * 3 * 2, 2)
    assert doc["grid"] == {"echo_range_m": [0.6]}
    assert doc["base"] == {"echo_range_m": 0.3}
    base, far = doc["points"]
    assert (base["label"], base["settings"]) == ("base", {})
    assert far["settings"] == {"track.obstacle.echo_range_m": 0.6}
    for p in doc["points"]:
        assert p["conditions"]["reflexes"]["seeds"] == 2
        d = p["differences"]["kp - sonar"]
        assert d["seeds"] == 2
        assert d["low"] <= d["mean"] <= d["high"]
        assert 0.0 <= d["p_holm"] <= 1.0
    assert doc["tests"] == 2
    assert doc["axes"]["echo_range_m"]["values"] == [0.3, 0.6]
    assert doc["failed"] == []


def test_phase_runs_jsonl_carries_each_points_world_settings(report: Path) -> None:
    rows = [json.loads(line) for line in (report / "runs.jsonl").read_text().splitlines()]
    assert len(rows) == 2 * 3 * 2 * 3
    far = [r for r in rows if "world_settings" in r]
    assert len(far) == len(rows) // 2
    assert {json.dumps(r["world_settings"]) for r in far} == {
        '{"track.obstacle.echo_range_m": 0.6}'
    }


@pytest.mark.parametrize("name", ["phase.png", "phase_by_parameter.png"])
def test_phase_plots_are_pngs(report: Path, name: str) -> None:
    assert_png(report / name, at_least=300)


@pytest.mark.slow
def test_phase_gives_the_same_numbers_whatever_the_jobs(report: Path, tmp_path: Path) -> None:
    assert main([*PHASE, "--jobs", "2", "--out", str(tmp_path)]) == 0
    one, two = (json.loads((d / "summary.json").read_text()) for d in (report, tmp_path))
    for doc in (one, two):
        for key in ("command", "jobs", "where", "elapsed_s"):
            doc["params"].pop(key)
    assert one == two
    assert (report / "runs.jsonl").read_text() == (tmp_path / "runs.jsonl").read_text()


def test_phase_reads_the_grid_from_a_toml_file(tmp_path: Path) -> None:
    grid = tmp_path / "grid.toml"
    grid.write_text("# declared first\ncruise_speed_mps = [0.6]\n")
    out = tmp_path / "out"
    argv = [*PHASE[:1], "--grid", str(grid), *PHASE[3:], "--episodes", "1", "--seeds", "1"]
    assert main([*argv, "--jobs", "1", "--out", str(out)]) == 0
    doc = json.loads((out / "summary.json").read_text())
    assert doc["grid"] == {"cruise_speed_mps": [0.6]}
    assert doc["params"]["grid_file"] == str(grid)
    assert f"Declared in `{grid}`" in (out / "summary.md").read_text()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--param", "echo=0.2"],
            "srlab: error: unknown world parameter 'echo' (known: echo_range_m,",
        ),
        (["--param", "echo_range_m=far"], "srlab: error: echo_range_m: 'far' is not a number"),
        (["--param", "echo_range_m=0"], "srlab: error: echo_range_m must be in (0, 3], got 0"),
        (["--param", "cruise_speed_mps=0.9"], "cruise_speed_mps must be in (0, 0.75], got 0.9"),
        (["--param", "echo_range_m=0.2,0.2"], "--param echo_range_m: a value is repeated"),
        (
            ["--param", "echo_range_m=0.2", "--param", "echo_range_m=0.4"],
            "--param echo_range_m is given twice",
        ),
        (["--param", "echo_range_m"], "--param takes NAME=V1,V2,..., got 'echo_range_m'"),
        ([], "srlab: error: declare the grid: --grid FILE or --param NAME=V1,V2,..."),
        (["--param", "echo_range_m=0.2", "--conditions", "kp"], "at least two conditions"),
        (["--param", "echo_range_m=0.2", "--conditions", "kp,reflexes"], "leave it out"),
        (["--param", "echo_range_m=0.2", "--conditions", "kp,bogus"], "unknown condition 'bogus'"),
        (["--grid", "/nonexistent/grid.toml"], "srlab: error: [Errno 2] No such file"),
    ],
)
def test_phase_bad_arguments_exit_2_and_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    out = tmp_path / "out"
    err = exits_2(["phase", *argv, "--episodes", "1", "--out", str(out), "--quiet"], capsys)
    assert message in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("echo = [0.2]\n", "unknown world parameter 'echo'"),
        ("echo_range_m = 0.2\n", "echo_range_m needs a list of values, got 0.2"),
        ("echo_range_m = [0.2, 9]\n", "echo_range_m must be in (0, 3], got 9"),
        ("echo_range_m = [\n", "grid.toml: "),
        ("", "grid.toml: no world parameter declared"),
    ],
)
def test_a_bad_grid_file_is_a_clear_error_naming_the_parameter(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    grid = tmp_path / "grid.toml"
    grid.write_text(text)
    err = exits_2(["phase", "--grid", str(grid), "--out", str(tmp_path / "out")], capsys)
    assert message in err
