"""A run's reward log and episodes as rows, written as JSON Lines and CSV side by side."""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any, TypeVar

from core.ports import RunQueries

PAGE = 1000
"""Rows read a page at a time: an export's memory never grows with a run's age."""
REWARD_COLUMNS = (
    "participant",
    "run",
    "id",
    "uid",
    "episode",
    "tick",
    "at",
    "value",
    "source",
    "note",
    "applied",
    "credited",
    "tick_seen",
    "seen_episode",
    "window_first",
    "window_last",
)
"""`rewards.jsonl`'s keys and `rewards.csv`'s columns, in order (docs/export.md)."""
EPISODE_COLUMNS = (
    "participant",
    "run",
    "episode",
    "outcome",
    "cause",
    "ticks",
    "start_tick",
    "rewards",
)
"""`episodes.jsonl`'s keys and `episodes.csv`'s columns, in order (docs/export.md)."""
ANSWER_COLUMNS = ("participant", "question_no", "question", "answer", "answered_at")
"""A study's `answers.jsonl` keys and `answers.csv` columns, in order (docs/export.md)."""
Row = dict[str, Any]
T = TypeVar("T")


def pages(read: Callable[[int, int], tuple[Sequence[T], int]]) -> Iterator[T]:
    """Every item of a paged read (`read(offset, limit)` -> (page, total)), in order."""
    offset = 0
    while True:
        page, total = read(offset, PAGE)
        yield from page
        offset += len(page)
        if not page or offset >= total:
            return


def reward_rows(store: RunQueries, run_id: int, participant: str | None = None) -> Iterator[Row]:
    """The run's reward log in log order, one row a reward (`REWARD_COLUMNS`)."""
    for r in pages(lambda offset, limit: store.rewards_page(run_id, offset, limit)):
        record = r.record
        yield {
            "participant": participant, "run": run_id, "id": r.id, "uid": record.uid,
            "episode": record.episode, "tick": record.tick,
            "at": r.at.isoformat() if r.at is not None else None, "value": record.value,
            "source": record.source, "note": record.note, "applied": r.applied,
            "credited": r.credited, "tick_seen": record.tick_seen,
            "seen_episode": record.seen_episode,
            "window_first": record.window[0] if record.window else None,
            "window_last": record.window[1] if record.window else None,
        }  # fmt: skip


def episode_rows(store: RunQueries, run_id: int, participant: str | None = None) -> Iterator[Row]:
    """The run's episodes by number, as stored, one row each (`EPISODE_COLUMNS`)."""
    for e in pages(lambda offset, limit: store.episode_summaries_page(run_id, offset, limit)):
        yield {
            "participant": participant, "run": run_id, "episode": e.episode,
            "outcome": e.outcome, "cause": e.cause, "ticks": e.ticks,
            "start_tick": e.start_tick, "rewards": e.rewards,
        }  # fmt: skip


def csv_cell(value: Any) -> str:
    """A value as its CSV cell: null is empty, booleans are true/false as in JSON."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


class TableWriter:
    """Writes rows to `<stem>.jsonl` and `<stem>.csv` at once: the two carry the same data.

    A study's export writes its participants' runs into one table by `write`ing each run's
    rows with its participant's pseudonym.
    """

    def __init__(self, stem: Path, columns: tuple[str, ...]) -> None:
        self.columns = columns
        self.rows = 0
        self.paths = (stem.with_suffix(".jsonl"), stem.with_suffix(".csv"))
        self._jsonl: IO[str] = self.paths[0].open("w", encoding="utf-8")
        self._csv_file: IO[str] = self.paths[1].open("w", encoding="utf-8", newline="")
        self._csv = csv.writer(self._csv_file)
        self._csv.writerow(columns)

    def write(self, row: Row) -> None:
        """One row, its keys exactly `columns`."""
        assert tuple(row) == self.columns, f"a row of {tuple(row)}, not {self.columns}"
        self._jsonl.write(json.dumps(row, ensure_ascii=False, allow_nan=False) + "\n")
        self._csv.writerow(csv_cell(v) for v in row.values())
        self.rows += 1

    def close(self) -> None:
        """Close both files."""
        self._jsonl.close()
        self._csv_file.close()

    def __enter__(self) -> TableWriter:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
