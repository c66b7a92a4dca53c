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


EXTRA = "# needs the srlab[worlds] extra"
"""The first line of a block that needs the outside worlds' extra: tests/worlds runs it."""


def blocks(extra: bool = False) -> list[str]:
    """The guide's shell blocks, in order: those that need the extra, or the others."""
    found = re.findall(r"```sh\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.S)
    return [b for b in found if b.startswith(EXTRA) == extra]


def run_as_written(tmp_path: Path, script: str) -> subprocess.CompletedProcess[str]:
    """`script` in bash from a checkout's root: `core/data` there, `srlab` on the PATH."""
    shutil.copytree(ROOT / "core" / "data", tmp_path / "core" / "data",
                    ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "SRLAB_DATA_DIR"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return subprocess.run(
        ["bash", "-c", "set -euo pipefail\n" + script], cwd=tmp_path, env=env,
        capture_output=True, text=True, timeout=900, check=False,  # a hang guard
    )  # fmt: skip


def test_the_guide_has_its_examples() -> None:
    text = "".join(blocks())
    for what in ("behaviours.toml", "sensors.toml", "--network", "srlab experiment"):
        assert what in text
    assert "srlab outside experiment" in "".join(blocks(extra=True))


@pytest.mark.slow
def test_every_example_of_the_guide_runs_as_written(tmp_path: Path) -> None:
    """Those that need the outside worlds' extra run in tests/worlds."""
    done = run_as_written(tmp_path, "\n".join(blocks()))
    assert done.returncode == 0, f"stdout:\n{done.stdout}\nstderr:\n{done.stderr}"
    assert (tmp_path / "results" / "sprint" / "summary.json").is_file()
