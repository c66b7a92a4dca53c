"""A study's export: a folder per participant, the study's tables, study.json, and the zip.

The study is made in the store as the service makes it (invited by recruiters' ids, two
consented with a run each, run fast for a few episodes, one not yet consented).
"""

from __future__ import annotations

import asyncio
import csv
import io
import json
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from apphelpers import client_for, migrated_copy
from clihelpers import exits_2

from core.engine import RunEngine
from core.ports import Mode, RunSpec, RunStatus
from core.studies import UnknownStudyError
from server.cli import main
from server.config import Settings
from server.export import EPISODE_COLUMNS, REWARD_COLUMNS, export_run, export_study
from server.export.tables import ANSWER_COLUMNS
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker
from server.persistence.studies import SqlAlchemyStudyRepository
from server.schemas.studies import StudyCreate
from server.services.studies import invite, study_spec

EXTERNAL_IDS = ["prolific-5f1cA9Z", "prolific-77abQ3X", "prolific-0c0dK8W"]
"""Recruiters' ids: distinctive, so that finding one in an exported byte means it leaked."""
EPISODES = 2
STUDY_FILES = {
    "rewards.jsonl",
    "rewards.csv",
    "episodes.jsonl",
    "episodes.csv",
    "answers.jsonl",
    "answers.csv",
    "study.json",
}
QUESTIONS = ["How hard was it?", "Would you again?"]
RUN_FILES = {
    "rewards.jsonl",
    "rewards.csv",
    "episodes.jsonl",
    "episodes.csv",
    "network.json",
    "manifest.json",
}


@dataclass(frozen=True)
class Stored:
    url: str
    store: SqlAlchemyRunStore
    studies: SqlAlchemyStudyRepository
    tokens: list[str]
    pseudonyms: list[str]
    runs: list[int]
    """The two consented participants' runs, in the order they were invited."""


@pytest.fixture(scope="module")
def stored(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stored]:
    url = migrated_copy(tmp_path_factory.mktemp("study-export") / "srlab.db")
    engine = make_engine(url)
    sessions = make_sessionmaker(engine)
    store, studies = SqlAlchemyRunStore(sessions), SqlAlchemyStudyRepository(sessions)
    body = StudyCreate.model_validate(
        {
            "name": "pilot",
            "conditions": ["rp", "kp"],
            "budget": {"episodes": EPISODES},
            "consent_text": "You will train a simulated robot.",
            "consent_version": "v3",
            "questionnaire": QUESTIONS,
            "completion_code": "C0DE42",
        }
    )
    studies.create(study_spec(body), "5eed" * 16)  # a fixed secret: the same pseudonyms, seeds
    invited = invite(studies, "pilot", EXTERNAL_IDS, "http://127.0.0.1:8000")
    runs = []
    for i in invited[:2]:
        p = studies.consent(i.participant.id, "v3")
        assert p.condition is not None
        seed = int(p.pseudonym[:7], 16)
        run = RunEngine.create(RunSpec(p.condition, seed, EPISODES, Mode.FAST), store)
        assert asyncio.run(run.run()) is RunStatus.FINISHED
        studies.set_run(p.id, run.run_id)
        runs.append(run.run_id)
    studies.answer(invited[1].participant.id, ["Hard, then easy.", 'Yes, "gladly", again'])
    yield Stored(
        url,
        store,
        studies,
        [i.token for i in invited],
        [i.participant.pseudonym for i in invited],
        runs,
    )
    engine.dispose()


def lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def no_external_id_in(files: dict[str, bytes]) -> None:
    for name, data in files.items():
        for external in EXTERNAL_IDS:
            assert external.encode() not in data, f"{external} in {name}"
            assert external.encode("utf-16-le") not in data, f"{external} in {name}"


def test_a_study_export_holds_each_run_under_its_pseudonym_and_the_study_tables(
    stored: Stored, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    done = export_study(stored.store, stored.studies, "pilot", out)

    first, second, waiting = stored.pseudonyms
    assert {p.name for p in out.iterdir()} == STUDY_FILES | {first, second}
    assert (done.participants, done.runs) == (3, 2)
    for pseudonym, run_id in zip((first, second), stored.runs, strict=True):
        folder = out / pseudonym
        assert {p.name for p in folder.iterdir()} == RUN_FILES
        alone = export_run(
            stored.store, run_id, tmp_path / f"alone-{run_id}", participant=pseudonym
        )
        for name in RUN_FILES - {"manifest.json"}:
            assert (folder / name).read_bytes() == (alone.directory / name).read_bytes(), name
    # the study's tables: every participant's rows, in order, each with their pseudonym
    for table, columns in (("rewards", REWARD_COLUMNS), ("episodes", EPISODE_COLUMNS)):
        rows = lines(out / f"{table}.jsonl")
        assert rows == [row for p in (first, second) for row in lines(out / p / f"{table}.jsonl")]
        assert {r["participant"] for r in rows} == {
            p for p in (first, second) if (out / p / f"{table}.jsonl").stat().st_size
        }
        assert all(tuple(r) == columns for r in rows)
        with (out / f"{table}.csv").open(newline="") as f:
            assert len(list(csv.DictReader(f))) == len(rows)
    assert done.rewards == len(lines(out / "rewards.jsonl")) > 0
    assert done.episodes == 2 * EPISODES

    manifest = json.loads((out / "study.json").read_text())
    assert manifest["study"] == {
        "name": "pilot", "conditions": ["rp", "kp"], "assignment": "balanced",
        "budget": {"episodes": EPISODES, "seconds": None}, "consent_version": "v3",
        "questionnaire": QUESTIONS, "created_at": manifest["study"]["created_at"],
    }  # fmt: skip
    assert manifest["srlab"]["version"] and "commit" in manifest["srlab"]
    people = manifest["participants"]
    assert [p["pseudonym"] for p in people] == [first, second, waiting]
    assert [(p["condition"], p["run"], p["status"], p["folder"]) for p in people] == [
        ("rp", stored.runs[0], "training", first),
        ("kp", stored.runs[1], "training", second),
        (None, None, "invited", None),
    ]
    assert [p["seed"] for p in people[:2]] == [int(s[:7], 16) for s in (first, second)]
    assert people[2]["seed"] is None and people[0]["run_status"] == "finished"
    assert manifest["counts"] == {
        "participants": 3, "runs": 2, "rewards": done.rewards, "episodes": 2 * EPISODES,
        "answers": 2,
    }  # fmt: skip
    # the questionnaire's answers by pseudonym: the one participant who answered
    answers = lines(out / "answers.jsonl")
    assert [(a["participant"], a["question_no"], a["question"], a["answer"]) for a in answers] == [
        (second, 1, QUESTIONS[0], "Hard, then easy."),
        (second, 2, QUESTIONS[1], 'Yes, "gladly", again'),
    ]
    assert all(tuple(a) == ANSWER_COLUMNS and a["answered_at"] for a in answers)
    with (out / "answers.csv").open(newline="") as f:
        assert [r["answer"] for r in csv.DictReader(f)] == [a["answer"] for a in answers]
    assert done.answers == 2


def test_an_unknown_study_is_refused_before_anything_is_written(
    stored: Stored, tmp_path: Path
) -> None:
    with pytest.raises(UnknownStudyError, match="'nope'"):
        export_study(stored.store, stored.studies, "nope", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_no_external_id_is_in_any_exported_byte(stored: Stored, tmp_path: Path) -> None:
    out = tmp_path / "out"

    assert main(["study", "export", "pilot", "--out", str(out), "--url", stored.url,
                 "--minari", "--quiet"]) == 0  # fmt: skip

    files = {str(p): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert any("minari" in name for name in files)
    assert sum(len(data) for data in files.values()) > 10_000
    no_external_id_in(files)


# --- srlab study export ----------------------------------------------------------------


def test_the_cli_refuses_a_full_folder_without_force_and_replaces_with_it(
    stored: Stored, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    argv = ["study", "export", "pilot", "--out", str(out), "--url", stored.url, "--quiet"]
    assert main(argv) == 0
    assert "study pilot: 3 participants, 2 runs" in capsys.readouterr().out
    (out / "keep.txt").write_text("mine")
    (out / stored.pseudonyms[0] / "stale.txt").write_text("old")

    err = exits_2(argv, capsys)
    assert f"--out {out} is not empty" in err and "--force" in err
    assert main([*argv, "--force"]) == 0

    assert (out / "keep.txt").read_text() == "mine"  # not the study's: left alone
    assert not (out / stored.pseudonyms[0] / "stale.txt").exists()  # its folder replaced
    assert (out / "study.json").exists()


def test_the_cli_names_an_unknown_study_and_writes_nothing(
    stored: Stored, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    err = exits_2(["study", "export", "nope", "--out", str(out), "--url", stored.url], capsys)
    assert "no study named 'nope'" in err
    assert not out.exists()


# --- GET /api/studies/{name}/export ----------------------------------------------------


@pytest.mark.anyio
async def test_the_api_answers_the_organiser_a_zip_and_refuses_participants(
    stored: Stored, tmp_path: Path
) -> None:
    export_study(stored.store, stored.studies, "pilot", tmp_path / "cli")
    participant = {"Authorization": f"Bearer {stored.tokens[0]}"}
    async with client_for(Settings(database_url=stored.url, viser=False)) as (client, _):
        r = await client.get("/api/studies/pilot/export")
        unknown = await client.get("/api/studies/nope/export")
        refused = await client.get("/api/studies/pilot/export", headers=participant)
        own_run = await client.get(f"/api/runs/{stored.runs[0]}/export", headers=participant)

    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/zip"
    assert "srlab-study-pilot.zip" in r.headers["content-disposition"]
    with zipfile.ZipFile(io.BytesIO(r.content)) as z:
        members = {name: z.read(name) for name in z.namelist()}
    first, second, _ = stored.pseudonyms
    expected = {f"study-pilot/{n}" for n in STUDY_FILES} | {
        f"study-pilot/{p}/{n}" for p in (first, second) for n in RUN_FILES
    }
    assert set(members) == expected
    for name in ("rewards.csv", "episodes.jsonl", f"{first}/rewards.jsonl"):
        assert members[f"study-pilot/{name}"] == (tmp_path / "cli" / name).read_bytes(), name
    no_external_id_in(members)
    assert unknown.status_code == 404 and "nope" in unknown.json()["detail"]
    assert refused.status_code == 403
    assert own_run.status_code == 403 and "organiser" in own_run.json()["detail"]


@pytest.mark.anyio
async def test_with_a_token_set_the_exports_need_it(stored: Stored) -> None:
    settings = Settings(database_url=stored.url, viser=False, token="organiser-secret")
    async with client_for(settings) as (client, _):
        anyone = await client.get("/api/studies/pilot/export")
        run = await client.get(f"/api/runs/{stored.runs[0]}/export")
        organiser = await client.get(
            "/api/studies/pilot/export", headers={"Authorization": "Bearer organiser-secret"}
        )
    assert (anyone.status_code, run.status_code, organiser.status_code) == (401, 401, 200)
