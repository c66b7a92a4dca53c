"""A run's export: its files, CSV against JSON Lines, the Minari round trip, the CLI, the zip."""

from __future__ import annotations

import asyncio
import csv
import io
import json
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from apphelpers import client_for, migrated_copy
from clihelpers import exits_2

from core.engine import RunEngine
from core.errors import UnknownRunError
from core.ports import Mode, RunSpec, RunStatus
from core.run.setup import Setup
from core.run.trace import unpack
from server.cli import main
from server.config import Settings
from server.export import (
    EPISODE_COLUMNS,
    REWARD_COLUMNS,
    SCHEMA_VERSION,
    MinariMissingError,
    dataset_id,
    export_run,
)
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker

FILES = {
    "rewards.jsonl",
    "rewards.csv",
    "episodes.jsonl",
    "episodes.csv",
    "network.json",
    "manifest.json",
}
EPISODES = 3


@pytest.fixture(scope="module")
def stored(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, SqlAlchemyRunStore]]:
    """A SQLite store with one finished, seeded `rp` run (id 1): a program's rewards."""
    url = migrated_copy(tmp_path_factory.mktemp("export") / "srlab.db")
    engine = make_engine(url)
    store = SqlAlchemyRunStore(make_sessionmaker(engine))
    run = RunEngine.create(RunSpec("rp", 1, EPISODES, Mode.FAST), store)
    assert asyncio.run(run.run()) is RunStatus.FINISHED
    assert run.run_id == 1
    yield url, store
    engine.dispose()


@pytest.fixture
def store(stored: tuple[str, SqlAlchemyRunStore]) -> SqlAlchemyRunStore:
    return stored[1]


def lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def as_cell(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return "" if value is None else str(value)


def test_a_run_export_writes_its_rewards_episodes_network_and_manifest(
    store: SqlAlchemyRunStore, tmp_path: Path
) -> None:
    done = export_run(store, 1, tmp_path / "out")

    out = tmp_path / "out"
    assert {p.name for p in out.iterdir()} == FILES == set(done.files)
    log = store.rewards(1)
    rewards = lines(out / "rewards.jsonl")
    assert len(rewards) == len(log) == done.rewards > 10
    for row, r in zip(rewards, log, strict=True):
        assert tuple(row) == REWARD_COLUMNS
        assert row["participant"] is None and row["run"] == 1
        assert (row["id"], row["uid"], row["episode"], row["tick"]) == (
            r.id, r.record.uid, r.record.episode, r.record.tick,
        )  # fmt: skip
        assert (row["value"], row["source"], row["note"]) == (
            r.record.value, r.record.source, r.record.note,
        )  # fmt: skip
        assert (row["applied"], row["credited"]) == (r.applied, r.credited)
        assert row["at"].endswith("+00:00")  # the log's time, in UTC
    assert sum(row["credited"] for row in rewards) > 0
    episodes = lines(out / "episodes.jsonl")
    assert [tuple(e) for e in episodes] == [EPISODE_COLUMNS] * EPISODES
    assert [
        (e["episode"], e["outcome"], e["cause"], e["ticks"], e["start_tick"], e["rewards"])
        for e in episodes
    ] == [
        (e.episode, e.outcome, e.cause, e.ticks, e.start_tick, e.rewards)
        for e in store.episode_summaries(1)
    ]
    network = json.loads((out / "network.json").read_text())
    assert network["count"] == len(network["data"]) == len(store.network(1)) > 0
    assert [(a["stimulus"], a["behaviour"], a["strength"]) for a in network["data"]] == [
        (p.stimulus, p.behaviour, p.strength) for p in store.network(1)
    ]
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["schema_version"] == SCHEMA_VERSION
    assert manifest["srlab"]["version"] and manifest["participant"] is None
    spec = manifest["run"]
    assert (spec["id"], spec["condition"], spec["seed"], spec["status"]) == (
        1, "rp", 1, "finished",
    )  # fmt: skip
    assert spec["world"] and spec["sensors"] and spec["totals"]["episodes"] == EPISODES
    assert manifest["counts"] == {
        "rewards": len(log), "episodes": EPISODES, "network": network["count"],
    }  # fmt: skip
    assert set(manifest["files"]) == FILES and manifest["minari"] is None
    catalog = Setup(sensors=spec["sensors"]).catalog()
    assert manifest["stimuli"] == [s.name for s in catalog.stimuli]


@pytest.mark.parametrize("table", ["rewards", "episodes"])
def test_the_csv_and_the_json_lines_carry_the_same_rows(
    store: SqlAlchemyRunStore, tmp_path: Path, table: str
) -> None:
    export_run(store, 1, tmp_path, participant="p-7f3a")

    rows = lines(tmp_path / f"{table}.jsonl")
    with (tmp_path / f"{table}.csv").open(newline="") as f:
        cells = list(csv.DictReader(f))
    assert rows and all(r["participant"] == "p-7f3a" for r in rows)
    assert cells == [{k: as_cell(v) for k, v in r.items()} for r in rows]


def test_a_minari_export_loads_back_with_minari(
    store: SqlAlchemyRunStore, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import minari

    done = export_run(store, 1, tmp_path, minari=True)

    assert done.minari == dataset_id(1) and "minari" in done.files
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    dataset = minari.load_dataset(dataset_id(1))
    assert dataset.total_episodes == EPISODES
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    stimuli, behaviours = manifest["stimuli"], manifest["behaviours"]
    log = store.rewards(1)
    for data, summary in zip(dataset.iterate_episodes(), store.episode_summaries(1), strict=True):
        stored = store.episode(1, summary.episode)
        assert stored is not None
        rows = unpack(stored.trace)
        assert len(data.actions) == len(rows) == summary.ticks
        assert data.observations.shape == (len(rows) + 1, len(stimuli))
        for i in (0, len(rows) // 2, len(rows) - 1):
            sensed = {stimuli[j] for j in data.observations[i].nonzero()[0]}
            assert sensed == {stimuli[j] for j in rows[i].stimuli}
            assert behaviours[data.actions[i]] == behaviours[rows[i].behaviour]
        applied = [r for r in log if r.applied and r.record.episode == summary.episode]
        assert data.rewards.sum() == pytest.approx(sum(r.record.value for r in applied))
        assert data.infos["credited"].sum() == sum(r.credited for r in applied)
        assert data.infos["rewards"].sum() == len(applied)
        assert bool(data.terminations[-1] or data.truncations[-1])
        # the task's reward for a lap goes on the lap's last step
        if summary.outcome == "success":
            assert data.rewards[-1] >= 1.0


@pytest.fixture
def no_minari(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "minari", None)  # `import minari` fails


@pytest.mark.usefixtures("no_minari")
def test_a_minari_export_without_the_extra_is_refused_naming_it(
    store: SqlAlchemyRunStore, tmp_path: Path
) -> None:
    with pytest.raises(MinariMissingError, match=r"srlab\[minari\]"):
        export_run(store, 1, tmp_path / "out", minari=True)
    assert not (tmp_path / "out").exists()  # nothing written


def test_an_unknown_run_is_refused_before_anything_is_written(
    store: SqlAlchemyRunStore, tmp_path: Path
) -> None:
    with pytest.raises(UnknownRunError, match="no run 99"):
        export_run(store, 99, tmp_path / "out")
    assert not (tmp_path / "out").exists()


# --- srlab export ----------------------------------------------------------------------


def test_the_cli_exports_each_run_into_its_folder(
    stored: tuple[str, SqlAlchemyRunStore], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    url = stored[0]
    out = tmp_path / "out"

    assert main(["export", "1", "--out", str(out), "--url", url, "--minari", "--quiet"]) == 0

    assert f"run 1: {len(stored[1].rewards(1))} rewards, {EPISODES} episodes" in (
        capsys.readouterr().out
    )
    assert {p.name for p in (out / "run-1").iterdir()} == FILES | {"minari"}
    # a folder that holds files is written into only with --force
    err = exits_2(["export", "1", "--out", str(out), "--url", url], capsys)
    assert f"--out {out} is not empty" in err and "--force" in err
    (out / "run-1" / "rewards.csv").write_text("stale")
    assert main(["export", "1", "--out", str(out), "--url", url, "--force", "--quiet"]) == 0
    assert (out / "run-1" / "rewards.csv").read_text().startswith("participant,run,id")
    assert not (out / "run-1" / "minari").exists()  # the run's folder was replaced


def test_the_cli_names_an_unknown_run_and_writes_nothing(
    stored: tuple[str, SqlAlchemyRunStore], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    err = exits_2(["export", "1", "42", "--out", str(out), "--url", stored[0]], capsys)
    assert "no run 42" in err
    assert not out.exists()


@pytest.mark.usefixtures("no_minari")
def test_the_cli_names_the_extra_a_minari_export_needs(
    stored: tuple[str, SqlAlchemyRunStore], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    err = exits_2(["export", "1", "--out", str(out), "--url", stored[0], "--minari"], capsys)
    assert "srlab[minari]" in err
    assert not out.exists()


# --- GET /api/runs/{id}/export ---------------------------------------------------------


@pytest.mark.anyio
async def test_the_api_answers_a_zip_of_the_same_files(
    stored: tuple[str, SqlAlchemyRunStore], tmp_path: Path
) -> None:
    export_run(stored[1], 1, tmp_path / "cli")
    async with client_for(Settings(database_url=stored[0], viser=False)) as (client, _):
        r = await client.get("/api/runs/1/export")
        unknown = await client.get("/api/runs/99/export")

    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/zip"
    assert "srlab-run-1.zip" in r.headers["content-disposition"]
    with zipfile.ZipFile(io.BytesIO(r.content)) as z:
        assert set(z.namelist()) == {f"run-1/{name}" for name in FILES}
        for name in FILES - {"manifest.json"}:
            assert z.read(f"run-1/{name}") == (tmp_path / "cli" / name).read_bytes(), name
        manifest = json.loads(z.read("run-1/manifest.json"))
    assert manifest["counts"]["rewards"] == len(stored[1].rewards(1))
    assert unknown.status_code == 404 and "99" in unknown.json()["detail"]


@pytest.mark.anyio
@pytest.mark.usefixtures("no_minari")
async def test_the_api_refuses_a_minari_zip_without_the_extra(
    stored: tuple[str, SqlAlchemyRunStore],
) -> None:
    async with client_for(Settings(database_url=stored[0], viser=False)) as (client, _):
        r = await client.get("/api/runs/1/export?minari=true")
    assert r.status_code == 409 and "srlab[minari]" in r.json()["detail"]


def test_rows_are_read_a_page_at_a_time_and_none_is_lost(
    store: SqlAlchemyRunStore, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    export_run(store, 1, tmp_path / "whole")
    monkeypatch.setattr("server.export.tables.PAGE", 7)

    export_run(store, 1, tmp_path / "paged")

    for name in ("rewards.jsonl", "episodes.csv"):
        assert (tmp_path / "paged" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()
