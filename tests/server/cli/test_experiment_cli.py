"""`srlab experiment` and `srlab qlambda-sweep`: the report files and clean argument errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import matplotlib.image
import pytest
from clihelpers import PNG_SIGNATURE, exits_2

from core.lab.stats import holm
from server.cli import main


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report")
    argv = ["experiment", "--conditions", "innate,kp", "--seeds", "2", "--episodes", "3"]
    argv += ["--declare", "kp-innate"]
    assert main([*argv, "--eval-episodes", "2", "--jobs", "1", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.slow
def test_experiment_writes_every_report_file(report: Path) -> None:
    names = {p.name for p in report.iterdir()}
    assert names == {
        "summary.json",
        "summary.md",
        "runs.jsonl",
        "learning_curves.png",
        "reliability.png",
        "knowledge.png",
    }


@pytest.mark.slow
def test_experiment_reports_held_out_evaluation_and_the_probe(report: Path) -> None:
    doc = json.loads((report / "summary.json").read_text())
    assert doc["params"]["eval_episodes"] == 2
    assert doc["params"]["probe"] is not None
    for name in ("innate", "kp"):
        ev = doc["conditions"][name]["evaluation"]
        assert ev["episodes"] == 2
        for key in ("frozen", "camera_only"):
            assert 0.0 <= ev[key]["mean"] <= 1.0
            assert ev[key]["n"] == 2
    pair = doc["paired"]
    assert pair, "every pair of conditions is compared seed by seed"
    md = (report / "summary.md").read_text()
    assert "held-out, frozen" in md


@pytest.mark.slow
def test_experiment_summary_json(report: Path) -> None:
    doc = json.loads((report / "summary.json").read_text())
    params = doc["params"]
    assert params["conditions"] == ["innate", "kp"]
    assert (params["seeds"], params["seed_base"], params["episodes"], params["jobs"]) == (
        2,
        0,
        3,
        1,
    )
    assert params["ticks"] > 0
    assert doc["failed"] == []
    assert set(doc["conditions"]) == {"innate", "kp"}
    for name in ("innate", "kp"):
        c = doc["conditions"][name]
        assert c["seeds"] == 2
        assert c["episodes"] == 3
        assert 0.0 <= c["success_rate"]["mean"] <= 1.0
        assert c["success_rate"]["n"] == 2
        assert len(c["success_curve"]) == 3
        assert "success_by_seed" not in c
    assert doc["conditions"]["innate"]["learns_camera"] is False
    assert doc["conditions"]["kp"]["camera_memory"] == "rltm"


@pytest.mark.slow
def test_experiment_summary_json_agrees_with_runs_jsonl(report: Path) -> None:
    doc = json.loads((report / "summary.json").read_text())
    rows = [json.loads(line) for line in (report / "runs.jsonl").read_text().splitlines()]
    for name in ("innate", "kp"):
        mine = [r for r in rows if r["condition"] == name]
        rate = sum(r["outcome"] == "success" for r in mine) / len(mine)
        assert doc["conditions"][name]["success_rate"]["mean"] == pytest.approx(rate)
    assert doc["params"]["ticks"] == sum(r["ticks"] for r in rows)


@pytest.mark.slow
def test_experiment_runs_jsonl_has_one_line_per_episode(report: Path) -> None:
    lines = (report / "runs.jsonl").read_text().splitlines()
    assert len(lines) == 2 * 2 * 3
    rows = [json.loads(line) for line in lines]
    assert [(r["condition"], r["seed"], r["episode"]) for r in rows] == [
        (c, s, e) for c in ("innate", "kp") for s in (0, 1) for e in range(3)
    ]
    for r in rows:
        assert r["outcome"] in ("success", "failure")
        assert (r["cause"] is None) == (r["outcome"] == "success")
        assert r["ticks"] > 0


@pytest.mark.slow
def test_experiment_summary_md(report: Path) -> None:
    md = (report / "summary.md").read_text()
    assert md.startswith("# srlab experiment\n")
    assert "## Success" in md
    side_by_side = md.index("## Side by side with the paper")
    assert md.index("### Table II", side_by_side) < md.index("### Table III", side_by_side)
    assert "| innate |" in md
    assert "| kp |" in md
    assert "## Failed tasks" not in md
    # Table II: the paper's count with its interval beside srlab's rate over seeds.
    assert "| paper, simulation | 5 | 250 | 2.0% [0.9, 4.6] |" in md
    assert "| srlab, 2 seeds x 3 episodes |" in md
    assert "World `soft-obstacle`, camera stimuli `path`, signal learned" in md
    assert "| innate - kp |" in md  # every pair, first minus second
    sections = ["## Paired by seed (exploratory)", "## Failures by cause", "## What ran"]
    sections += ["## Camera obstacle", "## What was learned, judged by the placement probe"]
    for section in sections:
        assert section in md
    met = md[md.index("## Camera obstacle") :]
    assert "%)" in met  # encounters per seed (success rate of the episodes they were met in)


@pytest.mark.slow
def test_experiment_summary_states_its_interval_and_holm_corrects_the_declared(
    report: Path,
) -> None:
    md = (report / "summary.md").read_text()
    lines = md.splitlines()
    assert lines[0] == "# srlab experiment"
    assert lines[2].startswith("`srlab experiment --conditions innate,kp ")  # the command
    header = md[: md.index("## Success")]
    assert "Intervals: the 95% Student's t interval over seeds" in header
    declared = md.index("## Pre-declared comparisons (Holm-corrected)")
    assert declared < md.index("## Paired by seed (exploratory)")
    assert "named in the command (`--declare`): kp - innate." in md
    assert "| kp - innate | all episodes |" in md[declared:]
    assert "| kp - innate | held-out, frozen |" in md[declared:]
    doc = json.loads((report / "summary.json").read_text())
    assert doc["params"]["declared"] == [["kp", "innate"]]
    tests = doc["declared"]
    assert [(t["pair"], t["on"]) for t in tests] == [
        ("kp - innate", "all"),
        ("kp - innate", "held-out"),
    ]
    assert [t["p_holm"] for t in tests] == pytest.approx(holm([t["p"] for t in tests]))


def test_the_sensors_help_says_which_definition_is_the_papers(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["experiment", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    start = text.index("camera obstacle stimuli")
    sensors = text[start : text.index("--signal {", start)]
    assert "(default path)" in sensors
    assert "paper: Fig. 10" in sensors
    assert "Fig. 10" not in sensors[: sensors.index("paper: ")]  # path is srlab's, not Fig. 10


@pytest.mark.slow
def test_experiment_summary_counts_what_ran_and_what_was_met(report: Path) -> None:
    doc = json.loads((report / "summary.json").read_text())
    assert (doc["params"]["world"], doc["params"]["sensors"]) == ("soft-obstacle", "path")
    innate, kp = doc["conditions"]["innate"], doc["conditions"]["kp"]
    assert set(innate["ticks_by_origin"]) <= {"innate", "default"}
    assert "designed" in kp["ticks_by_origin"]  # lane keeping runs on every tick it can
    assert sum(kp["ticks_by_origin"].values()) == kp["ticks"]
    for met in kp["camera_stimuli_met"].values():
        assert met["episodes"] >= 1 and 0.0 <= met["success_when_met"] <= 1.0
        assert met["encounters_per_seed"] > 0 and 1 <= met["seeds"] <= 2


@pytest.mark.slow
@pytest.mark.parametrize("name", ["learning_curves.png", "reliability.png", "knowledge.png"])
def test_experiment_plots_are_pngs(report: Path, name: str) -> None:
    path = report / name
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    image = matplotlib.image.imread(path)
    assert image.ndim == 3
    height, width = image.shape[:2]
    assert height > 100
    assert width > 100


def test_experiment_unknown_condition_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    err = exits_2(["experiment", "--conditions", "innate,bogus", "--out", str(out)], capsys)
    assert "srlab: error: unknown condition 'bogus'" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--seeds", "0"], "argument --seeds: must be at least 1, got 0"),
        (["--episodes", "-1"], "argument --episodes: must be at least 1, got -1"),
        (["--episodes", "many"], "argument --episodes: 'many' is not a whole number"),
        (["--jobs", "0"], "argument --jobs: must be at least 1, got 0"),
        (["--seed-base", "-3"], "argument --seed-base: must be 0 or more, got -3"),
        (["--conditions", " , "], "srlab: error: no condition given"),
        (["--declare", "kp-bogus"], "srlab: error: comparison 'kp-bogus': no way to read it"),
        (
            ["--conditions", "kp,innate", "--declare", "kp-sonar"],
            "--declare: sonar not among --conditions",
        ),
    ],
)
def test_experiment_bad_arguments_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    out = tmp_path / "out"
    err = exits_2(["experiment", *argv, "--out", str(out), "--quiet"], capsys)
    assert message in err
    assert not out.exists()


def test_qlambda_sweep_json(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["qlambda-sweep", "--seeds", "1", "--episodes", "3", "--alphas", "0.3"]
    assert main([*argv, "--lambdas", "0.9", "--epsilons", "0.1", "--jobs", "1", "--json"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    doc = json.loads(out)
    assert doc["seeds"] == [1000]
    assert doc["episodes"] == 3
    assert len(doc["rows"]) == 1
    row = doc["rows"][0]
    assert (row["alpha"], row["lambda"], row["epsilon"]) == (0.3, 0.9, 0.1)
    assert 0.0 <= row["success_last50"] <= 1.0
    assert 0.0 <= row["success_all"] <= 1.0


def test_qlambda_sweep_grid_is_the_product(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["qlambda-sweep", "--seeds", "1", "--episodes", "1", "--alphas", "0.1,0.5"]
    assert main([*argv, "--lambdas", "0.5,0.9", "--epsilons", "0.1", "--jobs", "1", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert sorted((r["alpha"], r["lambda"]) for r in rows) == [
        (0.1, 0.5),
        (0.1, 0.9),
        (0.5, 0.5),
        (0.5, 0.9),
    ]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--alphas", "2"], "--alphas values must be in [0, 1], got '2'"),
        (["--lambdas", "-0.5"], "--lambdas values must be in [0, 1]"),
        (["--epsilons", "a,b"], "--epsilons takes comma-separated numbers, got 'a,b'"),
        (["--alphas", ","], "--alphas values must be in [0, 1]"),
    ],
)
def test_qlambda_sweep_bad_grid_exits_2(
    capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    err = exits_2(["qlambda-sweep", "--seeds", "1", "--episodes", "1", *argv], capsys)
    assert f"srlab: error: {message}" in err


@pytest.mark.slow
def test_experiment_with_a_failed_task_reports_it_and_exits_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import core.lab.experiment
    from core.run.conditions import Condition
    from core.run.runner import RunSummary
    from core.run.runner import run as real_run

    def run(condition: Condition, seed: int, episodes: int, **kw: Any) -> RunSummary:
        if condition.name == "kp":
            raise RuntimeError("sonar unplugged")
        return real_run(condition, seed, episodes, **kw)

    monkeypatch.setattr(core.lab.experiment, "run", run)
    argv = ["experiment", "--conditions", "innate,kp", "--seeds", "1", "--episodes", "2"]
    assert main([*argv, "--jobs", "1", "--out", str(tmp_path), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "task kp seed 0 failed: RuntimeError: sonar unplugged" in err
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert [(f["condition"], f["seed"]) for f in doc["failed"]] == [("kp", 0)]
    assert doc["conditions"]["kp"] == {"seeds": 0}
    assert doc["conditions"]["innate"]["seeds"] == 1
    md = (tmp_path / "summary.md").read_text()
    assert "## Failed tasks" in md
    assert "- kp seed 0: RuntimeError: sonar unplugged" in md
    assert len((tmp_path / "runs.jsonl").read_text().splitlines()) == 2
    for name in ("learning_curves.png", "reliability.png"):
        assert (tmp_path / name).read_bytes()[:8] == PNG_SIGNATURE


@pytest.mark.slow
def test_experiment_with_noisy_perception_says_so_and_differs_from_exact(tmp_path: Path) -> None:
    argv = ["experiment", "--conditions", "kp", "--seeds", "2", "--episodes", "3", "--jobs", "1"]
    for perception in ("exact", "noisy"):
        out = tmp_path / perception
        assert main([*argv, "--perception", perception, "--out", str(out), "--quiet"]) == 0
    exact = (tmp_path / "exact" / "summary.md").read_text()
    noisy = (tmp_path / "noisy" / "summary.md").read_text()
    assert "--perception noisy" in noisy.splitlines()[2]
    assert "World `soft-obstacle` with perception.camera_bearing_sd_deg 3," in noisy
    assert "perception." not in exact.split("## ")[0]
    ticks = [
        [json.loads(x)["ticks"] for x in (tmp_path / p / "runs.jsonl").read_text().splitlines()]
        for p in ("exact", "noisy")
    ]
    assert ticks[0] != ticks[1]  # the noisy robot's laps run otherwise


def test_an_unknown_perception_is_a_clean_error(capsys: pytest.CaptureFixture[str]) -> None:
    err = exits_2(["experiment", "--conditions", "kp", "--perception", "blurry"], capsys)
    assert "--perception" in err and "'blurry'" in err and "noisy" in err


@pytest.mark.parametrize(
    ("perception", "says"),
    [
        ("noisy,camera_miss_rate=1.5", "camera_miss_rate must be in [0, 1], got 1.5"),
        ("odometry_drift_m=-0.1", "odometry_drift_m must be in [0, 0.5]"),
        ("camera_range_sd_m=far", "camera_range_sd_m: 'far' is not a number"),
        ("echo_range_m=0.2", "unknown perception setting 'echo_range_m'"),
    ],
)
def test_a_bad_perception_setting_is_a_clean_error_naming_it(
    perception: str, says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = exits_2(["experiment", "--conditions", "kp", "--perception", perception], capsys)
    assert "--perception" in err and says in err
