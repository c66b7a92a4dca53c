"""scripts/deep_curve.py: the long-budget curve's files, for learners that need no extra."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import matplotlib.image

ROOT = Path(__file__).resolve().parents[3]


def test_the_curve_script_writes_its_plot_and_every_episode(tmp_path: Path) -> None:
    cmd = [sys.executable, str(ROOT / "scripts" / "deep_curve.py"), str(tmp_path),
           "--episodes", "3", "--seeds", "2", "--learners", "kp,sonar", "--window", "2",
           "--jobs", "1", "--signal", "given"]  # fmt: skip
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True)
    assert "success, last 3 episodes" in done.stdout
    doc = json.loads((tmp_path / "curve.json").read_text())
    assert doc["episodes"] == 3 and doc["seeds"] == [0, 1]
    assert set(doc["successes"]) == {"kp", "sonar"}
    assert all(len(s) == 3 for runs in doc["successes"].values() for s in runs)
    assert matplotlib.image.imread(tmp_path / "curve.png").shape[2] in (3, 4)


def test_an_unknown_learner_is_a_clear_error(tmp_path: Path) -> None:
    cmd = [sys.executable, str(ROOT / "scripts" / "deep_curve.py"), str(tmp_path),
           "--learners", "kp,a2c"]  # fmt: skip
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 2
    assert "unknown learner 'a2c'" in done.stderr and "Traceback" not in done.stderr
