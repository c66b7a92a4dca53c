"""scripts/wrong_teacher.py and scripts/frozen_budgets.py: their folders, on a tiny budget."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import pytest

from server.reports.declared import Comparison, compare_declared, points

ROOT = Path(__file__).resolve().parents[3]


def test_declared_comparisons_are_paired_by_seed_and_corrected_together() -> None:
    tested = compare_declared(
        [Comparison("a", [1.0] * 8, [0.0] * 8), Comparison("b", [0.5] * 8, [0.5] * 8)]
    )
    assert [t.label for t in tested] == ["a", "b"]
    assert tested[0].paired.diff.mean == 1.0
    assert tested[0].p_holm == pytest.approx(min(1.0, 2 * tested[0].paired.p))
    assert tested[1].paired.p == 1.0 and tested[1].p_holm == 1.0
    assert points(tested[1]) == "+0.0 [+0.0, +0.0], p 1.000 (Holm 1.000)"


@pytest.mark.slow
def test_the_wrong_teacher_script_writes_its_folder(tmp_path: Path) -> None:
    cmd = [sys.executable, str(ROOT / "scripts" / "wrong_teacher.py"), str(tmp_path),
           "--seeds", "2", "--episodes", "3", "--eval-episodes", "1", "--copy-episodes", "2",
           "--doses", "0.5", "--jobs", "1"]  # fmt: skip
    subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True)
    summary = (tmp_path / "summary.md").read_text()
    assert summary.startswith("# A teacher that is wrong\n\n`python scripts/wrong_teacher.py ")
    assert "Student's t interval" in summary and "bootstrap interval" not in summary
    assert "## Smaller penalties (exploratory)" in summary
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert set(doc["worlds"]) == {"crossed-sonar", "soft-obstacle"}
    assert len(doc["declared"]) == 4
    assert set(doc["worlds"]["soft-obstacle"]["conditions"]) == {
        "kp", "kp-punished", "sonar", "penalty 0.5",
    }  # fmt: skip
    kp = doc["worlds"]["crossed-sonar"]["conditions"]["kp"]
    assert len(kp["success_by_seed"]) == 2 and len(kp["success_by_seed"][0]) == 3
    assert matplotlib.image.imread(tmp_path / "wrong-teacher.png").shape[2] in (3, 4)


@pytest.mark.slow
def test_the_frozen_budgets_script_writes_its_folder(tmp_path: Path) -> None:
    cmd = [sys.executable, str(ROOT / "scripts" / "frozen_budgets.py"), str(tmp_path),
           "--seeds", "2", "--budgets", "1,2,4", "--eval-episodes", "1",
           "--learners", "kp,sonar,qlambda-hybrid-decay", "--long", "kp,qlambda-hybrid-decay",
           "--jobs", "1"]  # fmt: skip
    subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True)
    summary = (tmp_path / "summary.md").read_text()
    assert summary.startswith("# Exploration on equal terms")
    assert "`python scripts/frozen_budgets.py " in summary.splitlines()[2]
    assert "Student's t interval" in summary and "bootstrap interval" not in summary
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert doc["budgets"] == [1, 2, 4]
    # Only the long learners train to the last budget; sonar stops at the one before.
    assert doc["trained_to"] == {"kp": 4, "sonar": 2, "qlambda-hybrid-decay": 4}
    assert {c: list(f) for c, f in doc["frozen"].items()} == {
        "kp": ["1", "2", "4"], "sonar": ["1", "2"], "qlambda-hybrid-decay": ["1", "2", "4"],
    }  # fmt: skip
    assert [t["label"] for t in doc["declared"]] == [
        "frozen after 2 episodes, held out: kp minus sonar",
        "frozen after 4 episodes, held out: kp minus qlambda-hybrid-decay",
    ]
    assert matplotlib.image.imread(tmp_path / "frozen.png").shape[2] in (3, 4)


def test_an_unknown_learner_is_a_usage_error(tmp_path: Path) -> None:
    cmd = [sys.executable, str(ROOT / "scripts" / "frozen_budgets.py"), str(tmp_path),
           "--learners", "kp,a2c"]  # fmt: skip
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 2
    assert "unknown condition 'a2c'" in done.stderr and "Traceback" not in done.stderr
    cmd[-1] = "kp,sonar"
    done = subprocess.run([*cmd, "--long", "sonar"], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 2 and "the reference (the first) among them" in done.stderr
