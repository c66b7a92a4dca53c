"""docs/extending.md's worked examples, run exactly as written, in order, in one shell."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "extending.md"


def blocks() -> list[str]:
    """The guide's shell blocks, in order."""
    return re.findall(r"```sh\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.S)


def test_the_guide_has_its_examples() -> None:
    text = "".join(blocks())
    for what in ("behaviours.toml", "sensors.toml", "--network", "srlab experiment"):
        assert what in text


@pytest.mark.slow
def test_every_example_of_the_guide_runs_as_written(tmp_path: Path) -> None:
    """From a checkout's root: `core/data` is there, `srlab` on the PATH."""
    shutil.copytree(ROOT / "core" / "data", tmp_path / "core" / "data",
                    ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    script = "set -euo pipefail\n" + "\n".join(blocks())
    env = {k: v for k, v in os.environ.items() if k != "SRLAB_DATA_DIR"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    done = subprocess.run(
        ["bash", "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
        timeout=900, check=False,  # a hang guard, not a speed test
    )  # fmt: skip
    assert done.returncode == 0, f"stdout:\n{done.stdout}\nstderr:\n{done.stderr}"
    assert (tmp_path / "results" / "sprint" / "summary.json").is_file()
