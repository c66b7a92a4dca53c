"""A run's export: its tables, its network, a manifest and, on request, a Minari dataset.

A study's export is a loop over its participants' runs: each run's rows carry the
participant's pseudonym (`participant`), which a run's own export leaves null.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from core.ports import RunQueries, StoredReward, StoredRun
from core.run.setup import Setup
from server.export.dataset import Names, write_minari
from server.export.tables import (
    EPISODE_COLUMNS,
    REWARD_COLUMNS,
    TableWriter,
    episode_rows,
    pages,
    reward_rows,
)
from server.schemas import AssociationPublic, RunNetworkPublic

SCHEMA_VERSION = 1
"""The export's layout (files, columns, manifest keys): raised when one changes meaning."""
MINARI_FOLDER = "minari"
Progress = Callable[[str, int, int], None]
"""Told (what, done, in all) as an export goes: "episodes" while a Minari dataset is built."""
_ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True, slots=True)
class RunExport:
    """What `export_run` wrote."""

    run_id: int
    directory: Path
    files: tuple[str, ...]
    """The files written, relative to `directory` (a Minari dataset as its folder)."""
    rewards: int
    episodes: int
    minari: str | None
    """The Minari dataset's id, None when none was asked for."""


def code_version() -> dict[str, str | None]:
    """Srlab's version, and the git commit of the checkout it runs from (None: not one)."""
    try:
        package = version("srlab")
    except PackageNotFoundError:  # pragma: no cover - the project is always installed
        package = None
    commit = None
    if (_ROOT / ".git").exists():
        try:
            done = subprocess.run(
                ["git", "-C", str(_ROOT), "rev-parse", "HEAD"],
                capture_output=True,
                text=True,
                timeout=10,
                check=False,
            )
        except OSError:  # no git on this machine
            done = None
        if done is not None and done.returncode == 0:
            commit = done.stdout.strip() or None
    return {"version": package, "commit": commit}


def run_names(store: RunQueries, run: StoredRun) -> Names:
    """What the run's traces index: its catalogue's stimuli, its behaviours."""
    catalog = Setup(sensors=run.spec.sensors).catalog()
    behaviours = [b.name for b in catalog.behaviours] + [b.name for b in store.behaviours(run.id)]
    return Names(tuple(s.name for s in catalog.stimuli), tuple(behaviours))


def network_json(store: RunQueries, run_id: int) -> dict[str, Any]:
    """The run's behaviour network as `GET /api/runs/{id}/network` answers it."""
    pairs = store.network(run_id)
    data = [AssociationPublic.model_validate(p, from_attributes=True) for p in pairs]
    return RunNetworkPublic(data=data, count=len(data)).model_dump(mode="json")


def _all_rewards(store: RunQueries, run_id: int) -> list[StoredReward]:
    return list(pages(lambda offset, limit: store.rewards_page(run_id, offset, limit)))


def manifest(
    run: StoredRun, names: Names, counts: dict[str, int], participant: str | None
) -> dict[str, Any]:
    """`manifest.json`: what was exported, from which code, with which spec (docs/export.md)."""
    spec = run.spec
    return {
        "schema_version": SCHEMA_VERSION,
        "srlab": code_version(),
        "exported_at": datetime.now(UTC).isoformat(),
        "participant": participant,
        "run": {
            "id": run.id,
            "status": run.status.value,
            "error": run.error,
            "condition": spec.condition,
            "seed": spec.seed,
            "episodes": spec.episodes,
            "mode": spec.mode.value,
            "hz": spec.hz,
            "world": spec.world,
            "sensors": spec.sensors,
            "network": spec.network,
            "params": dict(spec.params),
            "totals": {
                "episodes": run.totals.episodes,
                "successes": run.totals.successes,
                "ticks": run.totals.ticks,
            },
        },
        "stimuli": list(names.stimuli),
        "behaviours": list(names.behaviours),
        "counts": counts,
    }


def _write_json(path: Path, value: Any) -> None:
    path.write_text(json.dumps(value, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def export_run(
    store: RunQueries,
    run_id: int,
    out: Path,
    *,
    participant: str | None = None,
    minari: bool = False,
    progress: Progress | None = None,
) -> RunExport:
    """Write run `run_id`'s export into the folder `out` (made if missing).

    `UnknownRunError` for an unknown run and `MinariMissingError` for a Minari export
    without the extra come before anything is written. The manifest is written last: a
    folder with one holds a whole export.
    """
    run = store.run_summary(run_id)
    if minari:
        from server.export.dataset import require_minari

        require_minari()
    out.mkdir(parents=True, exist_ok=True)
    with TableWriter(out / "rewards", REWARD_COLUMNS) as rewards:
        for row in reward_rows(store, run_id, participant):
            rewards.write(row)
    with TableWriter(out / "episodes", EPISODE_COLUMNS) as episodes:
        for row in episode_rows(store, run_id, participant):
            episodes.write(row)
    network = network_json(store, run_id)
    _write_json(out / "network.json", network)
    files = [p.name for p in (*rewards.paths, *episodes.paths)] + ["network.json"]
    names = run_names(store, run)
    counts = {"rewards": rewards.rows, "episodes": episodes.rows, "network": network["count"]}
    key = None
    if minari:
        tell = None if progress is None else (lambda done, total: progress("episodes", done, total))
        key, counts["minari_episodes"] = write_minari(
            store, run_id, out / MINARI_FOLDER, names, _all_rewards(store, run_id), progress=tell
        )
        files.append(MINARI_FOLDER)
    document = manifest(run, names, counts, participant)
    document["files"] = [*files, "manifest.json"]
    document["minari"] = key
    _write_json(out / "manifest.json", document)
    return RunExport(run_id, out, (*files, "manifest.json"), rewards.rows, episodes.rows, key)
