"""docs/extending.md's outside world example, run as written (it needs the srlab[worlds] extra)."""

from __future__ import annotations

import json
from pathlib import Path

import worlds_or_skip  # noqa: F401  # before the environments: skips the module without them
from test_extending_guide import blocks, run_as_written


def test_the_guides_outside_world_runs_as_written(tmp_path: Path) -> None:
    done = run_as_written(tmp_path, "\n".join(blocks(extra=True)))
    assert done.returncode == 0, f"stdout:\n{done.stdout}\nstderr:\n{done.stderr}"
    summary = json.loads((tmp_path / "results" / "lab-minigrid" / "summary.json").read_text())
    assert "kp-eager" in json.dumps(summary)
