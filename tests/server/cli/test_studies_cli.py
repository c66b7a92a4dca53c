"""`srlab teachers`, `equal-start`, `noise`, `experiment --teacher` and `--start`: reports."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from server.cli import main

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SMALL = ["--seeds", "2", "--episodes", "2", "--eval-episodes", "1", "--jobs", "1", "--quiet"]


def exits_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err + captured.out
    return captured.err


@pytest.mark.slow
def test_teachers_writes_its_summary_a_plot_per_imperfection_and_the_verdicts(
    tmp_path: Path,
) -> None:
    argv = ["teachers", "--param", "teacher_mistake=0,0.5", "--param", "teacher_delay_s=0,2"]
    assert main([*argv, "--conditions", "kp", *SMALL, "--out", str(tmp_path)]) == 0
    md = (tmp_path / "summary.md").read_text()
    command = f"srlab {' '.join(argv)} --conditions kp {' '.join(SMALL)} --out {tmp_path}"
    assert md.splitlines()[:3] == ["# srlab teachers", "", f"`{command}`"]
    for name in ("teacher_mistake", "teacher_delay_s"):
        assert (tmp_path / f"{name}.png").read_bytes().startswith(PNG_SIGNATURE)
        assert f"]({name}.png)" in md
    doc = json.loads((tmp_path / "summary.json").read_text())
    mistake = doc["by_parameter"]["teacher_mistake"]
    assert [lv["value"] for lv in mistake["levels"]] == [0.0, 0.5]
    assert set(mistake["below"]["kp"]) == {"all", "held-out"}
    assert mistake["levels"][1]["vs"]["kp"]["all"]["seeds"] == 2
    # The perfect teacher's level is rp itself: the same task, the same figures.
    assert mistake["levels"][0]["success_rate"] == doc["perfect"]["success_rate"]
    assert doc["presets"]["human"]["teacher"]["skip"] == 0.5
    # Declared: rp by the perfect and the `human` teacher minus kp, training and held out.
    assert [d["label"] for d in doc["declared"]] == [
        f"rp given by {who} - kp, {m}"
        for who in ("the perfect teacher", "the `human` teacher")
        for m in ("training, all episodes", "held-out, frozen")
    ]
    assert all(d["p"] <= d["p_holm"] <= 1 for d in doc["declared"])
    assert "## Pre-declared comparisons (Holm-corrected)" in md
    lines = (tmp_path / "runs.jsonl").read_text().splitlines()
    params = {json.dumps(json.loads(x).get("params", {}), sort_keys=True) for x in lines}
    assert any('"teacher_mistake": 0.5' in p for p in params)


@pytest.mark.slow
def test_equal_start_writes_the_grid_and_each_starts_report(tmp_path: Path) -> None:
    argv = ["equal-start", "--conditions", "rp,kp", "--signal", "given", *SMALL]
    assert main([*argv, "--no-probe", "--out", str(tmp_path)]) == 0
    md = (tmp_path / "summary.md").read_text()
    assert md.startswith("# srlab equal-start\n\n`srlab equal-start --conditions rp,kp")
    assert (tmp_path / "equal_start.png").read_bytes().startswith(PNG_SIGNATURE)
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert set(doc["grid"]) == {"rp", "kp"}
    assert set(doc["decomposition"]) == {"rp"}
    assert "## Pre-declared comparisons (Holm-corrected)" in md
    assert "1. kp - rp, both from kp's design, training: " in md and "(Holm " in md
    for start in ("table1", "design"):
        sub = json.loads((tmp_path / start / "summary.json").read_text())
        assert sub["params"]["start"] == start
        assert set(sub["conditions"]) == {"rp", "kp"}


@pytest.mark.slow
def test_noise_writes_both_perceptions_and_each_ones_report(tmp_path: Path) -> None:
    argv = ["noise", "--conditions", "kp,sonar", "--signal", "given", *SMALL]
    argv += ["--perception", "noisy,camera_miss_rate=0.5"]
    assert main([*argv, "--no-probe", "--out", str(tmp_path)]) == 0
    md = (tmp_path / "summary.md").read_text()
    command = f"srlab {' '.join(argv)} --no-probe --out {tmp_path}"
    assert md.splitlines()[:3] == ["# srlab noise", "", f"`{command}`"]
    assert "perception.camera_miss_rate 0.5" in md and "](noise.png)" in md
    assert (tmp_path / "noise.png").read_bytes().startswith(PNG_SIGNATURE)
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert doc["params"]["noise"]["perception.camera_miss_rate"] == 0.5
    assert set(doc["grid"]) == {"kp", "sonar"} and set(doc["change"]) == {"sonar"}
    assert "## Pre-declared comparisons (Holm-corrected)" in md
    assert "1. kp - sonar, noisy perception, training: " in md and "(Holm " in md
    subs = {p: json.loads((tmp_path / p / "summary.json").read_text()) for p in ("exact", "noisy")}
    assert "world_settings" not in subs["exact"]["params"]
    assert "perception.camera_miss_rate 0.5" in subs["noisy"]["params"]["world_settings"]
    assert subs["exact"]["conditions"]["kp"] != subs["noisy"]["conditions"]["kp"]


@pytest.mark.slow
def test_experiment_with_a_teacher_and_a_start_says_so_and_runs_them(tmp_path: Path) -> None:
    base = ["experiment", "--conditions", "rp", "--signal", "given", "--no-probe", *SMALL]
    assert main([*base, "--out", str(tmp_path / "perfect")]) == 0
    argv = [*base, "--teacher", "mistaken,mistake=1", "--start", "design"]
    assert main([*argv, "--out", str(tmp_path / "wrong")]) == 0
    doc = json.loads((tmp_path / "wrong" / "summary.json").read_text())
    assert doc["params"]["teacher"] == {"mistake": 1.0}
    assert doc["params"]["start"] == "design"
    md = (tmp_path / "wrong" / "summary.md").read_text()
    assert "starts from kp's design (--start)" in md and "rp's teacher: mistake 1." in md
    runs = {name: (tmp_path / name / "runs.jsonl").read_text() for name in ("perfect", "wrong")}
    assert runs["perfect"] != runs["wrong"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["experiment", "--teacher", "grumpy"], "unknown teacher 'grumpy'"),
        (["experiment", "--teacher", "mistake=2"], r"teacher mistake must be in \[0, 1\]"),
        (["experiment", "--conditions", "kp", "--teacher", "human"], "none of kp has a teacher"),
        (["experiment", "--conditions", "expert", "--start", "design"], "'expert'"),
        (["experiment", "--start", "later"], "invalid choice: 'later'"),
        (["teachers", "--param", "eta=0.1"], "not a teacher's imperfection"),
        (["teachers", "--conditions", "rp"], "rp has a teacher"),
        (["teachers", "--presets", "grumpy"], "unknown teacher 'grumpy'"),
        (["equal-start", "--conditions", "rp,kp,expert"], "'expert' starts from neither"),
        (["equal-start", "--conditions", "rp,dp"], "the reference 'kp' is not among"),
        (["noise", "--perception", "exact"], "nothing to compare: name a noisy one"),
        (["noise", "--perception", "camera_miss_rate=2"], r"camera_miss_rate must be in \[0, 1\]"),
        (["noise", "--conditions", "rp,dp"], "the reference 'kp' is not among"),
    ],
)
def test_bad_teachers_starts_and_noises_exit_2_naming_what_is_wrong(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    err = exits_2([*argv, "--seeds", "1", "--episodes", "1", "--out", str(tmp_path)], capsys)
    assert re.search(message, err), err
