"""srlab as a wheel: installed (not editable) into a fresh environment, it migrates.

The wheel carries migrations/ and alembic.ini as shared data
(`server.persistence.migrate.find_migrations`), so a database is migrated by the installed
package alone, with no checkout beside it.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from core.errors import StorageError
from server.persistence.migrate import SOURCE_TREE, find_migrations

ROOT = Path(__file__).resolve().parents[2]
UV = ROOT / ".tools" / "bin" / "uv"

pytestmark = pytest.mark.skipif(not UV.exists(), reason="needs the project's uv (make install)")


def _run(*command: str | Path, cwd: Path) -> str:
    done = subprocess.run(
        [str(c) for c in command], cwd=cwd, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_an_installed_wheel_finds_its_migrations_and_migrates(tmp_path: Path) -> None:
    _run(UV, "build", "--wheel", "-q", "-o", tmp_path / "dist", cwd=ROOT)
    (wheel,) = (tmp_path / "dist").glob("srlab-*.whl")
    locked = tmp_path / "requirements.txt"
    locked.write_text(
        _run(UV, "export", "--frozen", "--no-dev", "--no-hashes", "--no-emit-project", cwd=ROOT)
    )
    venv = tmp_path / "venv"
    _run(UV, "venv", "-q", "--python", sys.executable, venv, cwd=tmp_path)
    python = venv / "bin" / "python"
    _run(UV, "pip", "install", "-q", "--python", python, "-r", locked, wheel, cwd=tmp_path)
    out = _run(
        python,
        "-c",
        "from server.persistence.migrate import ROOT, upgrade; "
        f"upgrade('sqlite:///{tmp_path / 'srlab.db'}'); print(ROOT)",
        cwd=tmp_path,  # no checkout here: only the installed package
    )
    assert Path(out.strip()) == venv / "share" / "srlab"


def test_a_checkout_finds_its_own_migrations_and_nothing_is_a_clear_error(
    tmp_path: Path,
) -> None:
    assert find_migrations() == SOURCE_TREE
    shutil.copytree(SOURCE_TREE / "migrations", tmp_path / "share" / "migrations")
    assert find_migrations((tmp_path / "none", tmp_path / "share")) == tmp_path / "share"
    with pytest.raises(StorageError, match=r"migrations are not installed: .* in \S*none$"):
        find_migrations((tmp_path / "none",))
