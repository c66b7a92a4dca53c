"""A study's export: each participant's run export under their pseudonym, and the study's.

The study-wide tables hold every participant's rows (the same rows their folders hold);
`study.json` names the study's settings, the code, and each participant by pseudonym.
Nothing here reads the recruiters' ids: the export cannot carry one.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from core.ports import RunQueries
from core.studies import Answer, Participant, Study, StudyRepository
from server.export.run import SCHEMA_VERSION, code_version, export_run
from server.export.tables import (
    ANSWER_COLUMNS,
    EPISODE_COLUMNS,
    REWARD_COLUMNS,
    TableWriter,
    episode_rows,
    reward_rows,
)

MANIFEST = "study.json"
TABLES = (
    "rewards.jsonl",
    "rewards.csv",
    "episodes.jsonl",
    "episodes.csv",
    "answers.jsonl",
    "answers.csv",
)
Progress = Callable[[Participant, int, int], None]
"""Told (the participant just exported, done, in all) as a study's export goes."""


@dataclass(frozen=True, slots=True)
class StudyExport:
    """What `export_study` wrote."""

    study: str
    directory: Path
    participants: int
    runs: int
    """Participants with a run, each a folder named by their pseudonym."""
    rewards: int
    episodes: int
    answers: int
    """Questionnaire answers, one a participant and question."""


def answer_row(a: Answer) -> dict[str, Any]:
    """A questionnaire answer as a row of `answers.jsonl` (`ANSWER_COLUMNS`)."""
    return {
        "participant": a.participant, "question_no": a.question_no, "question": a.question,
        "answer": a.answer, "answered_at": a.answered_at.isoformat(),
    }  # fmt: skip


def study_files(participants: tuple[Participant, ...]) -> list[str]:
    """What a study's export writes into its folder: the tables, the folders, the manifest."""
    return [*TABLES, *(p.pseudonym for p in participants if p.run_id is not None), MANIFEST]


def clear(out: Path, participants: tuple[Participant, ...]) -> None:
    """Remove what an earlier export of this study left in `out` (and nothing else)."""
    for name in study_files(participants):
        path = out / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()


def _budget(study: Study) -> dict[str, Any]:
    return {"episodes": study.spec.budget_episodes, "seconds": study.spec.budget_s}


def export_study(
    store: RunQueries,
    studies: StudyRepository,
    name: str,
    out: Path,
    *,
    minari: bool = False,
    progress: Progress | None = None,
) -> StudyExport:
    """Write study `name`'s export into the folder `out` (made if missing).

    `UnknownStudyError` for an unknown study and `MinariMissingError` for a Minari export
    without the extra come before anything is written. A participant who has not consented
    has no run: `study.json` lists them with their status, and no folder is written. The
    manifest is written last: a folder with one holds a whole export.
    """
    study = studies.get(name)
    participants = studies.participants(name)
    if minari:
        from server.export.dataset import require_minari

        require_minari()
    out.mkdir(parents=True, exist_ok=True)
    listed: list[dict[str, Any]] = []
    with (
        TableWriter(out / "rewards", REWARD_COLUMNS) as rewards,
        TableWriter(out / "episodes", EPISODE_COLUMNS) as episodes,
    ):
        for done, p in enumerate(participants, 1):
            entry: dict[str, Any] = {
                "pseudonym": p.pseudonym, "status": p.status.value, "condition": p.condition,
                "consent_version": p.consent_version, "seed": None, "run": p.run_id,
                "run_status": None, "folder": None,
            }  # fmt: skip
            if p.run_id is not None:
                run = store.run_summary(p.run_id)
                export_run(
                    store, p.run_id, out / p.pseudonym, participant=p.pseudonym, minari=minari
                )
                for row in reward_rows(store, p.run_id, p.pseudonym):
                    rewards.write(row)
                for row in episode_rows(store, p.run_id, p.pseudonym):
                    episodes.write(row)
                entry |= {
                    "seed": run.spec.seed,
                    "run_status": run.status.value,
                    "folder": p.pseudonym,
                }
            listed.append(entry)
            if progress is not None:
                progress(p, done, len(participants))
    with TableWriter(out / "answers", ANSWER_COLUMNS) as answers:
        for a in studies.answers(name):
            answers.write(answer_row(a))
    spec = study.spec
    runs = sum(p.run_id is not None for p in participants)
    document = {
        "schema_version": SCHEMA_VERSION,
        "srlab": code_version(),
        "exported_at": datetime.now(UTC).isoformat(),
        "study": {
            "name": spec.name,
            "conditions": list(spec.conditions),
            "assignment": spec.assignment.value,
            "budget": _budget(study),
            "consent_version": spec.consent_version,
            "questionnaire": list(spec.questionnaire),
            "created_at": study.created_at.isoformat(),
        },
        "participants": listed,
        "counts": {
            "participants": len(participants),
            "runs": runs,
            "rewards": rewards.rows,
            "episodes": episodes.rows,
            "answers": answers.rows,
        },
        "files": study_files(participants),
        "minari": minari,
    }
    (out / MANIFEST).write_text(
        json.dumps(document, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    return StudyExport(
        spec.name, out, len(participants), runs, rewards.rows, episodes.rows, answers.rows
    )
