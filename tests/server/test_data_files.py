"""Data files changed under a running service are reported, never silently ignored."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import pytest

from core.brain.catalog import data_dir
from server.services.datafiles import DataWatch


@pytest.fixture
def data(tmp_path: Path) -> Path:
    """A lab's own copy of srlab's data folder."""
    copy = tmp_path / "data"
    shutil.copytree(data_dir(), copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def test_a_file_edited_added_or_removed_is_reported_until_it_is_as_it_was(
    data: Path, caplog: pytest.LogCaptureFixture
) -> None:
    watch = DataWatch(data)
    version = watch.version
    assert watch.changed() == []
    conditions = data / "conditions.toml"
    before = conditions.read_text()
    conditions.write_text(before + '\n[[condition]]\nname = "mine"\nbased_on = "kp"\n')
    (data / "networks" / "extra.toml").write_text('name = "extra"\n')
    (data / "trainers" / "rp.toml").unlink()
    with caplog.at_level(logging.WARNING, logger="srlab.data"):
        assert watch.changed() == ["conditions.toml", "networks/extra.toml", "trainers/rp.toml"]
        assert watch.changed() == ["conditions.toml", "networks/extra.toml", "trainers/rp.toml"]
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 3, "one warning a file"
    assert "conditions.toml changed since the service started" in warned[0]
    conditions.write_text(before)  # the edit undone: the file is as the service read it
    assert watch.changed() == ["networks/extra.toml", "trainers/rp.toml"]
    assert watch.version == version, "the version is the data the service runs on"


def test_the_version_is_the_datas_content(data: Path, tmp_path: Path) -> None:
    assert DataWatch(data).version == DataWatch(data_dir()).version
    (data / "worlds.toml").write_text((data / "worlds.toml").read_text() + "\n# edited\n")
    assert DataWatch(data).version != DataWatch(data_dir()).version
