"""A run as a Minari dataset: one Minari episode per srlab episode, from the stored traces.

Observations are the stimuli the robot sensed each tick (a 0/1 vector over the run's
catalogue), actions the behaviour it ran (its index; the last index: none ran), rewards the
applied rewards' values at the step they credit. Minari is the optional `srlab[minari]`
extra, imported only here and only when a Minari export is asked for.
"""

from __future__ import annotations

import os
import threading
import warnings
from collections import defaultdict
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from core.events import Cause
from core.ports import RunQueries, StoredReward
from core.run.trace import unpack

MINARI_EXTRA = "srlab[minari]"
"""The extra that installs Minari."""
_ROOT_VARIABLE = "MINARI_DATASETS_PATH"
_ROOT_LOCK = threading.Lock()
"""Minari finds its datasets' folder by an environment variable only: one export at a time
sets it, so two threads' exports never write into each other's folder."""
Progress = Callable[[int, int], None]
"""Told (episodes done, episodes in all) as a dataset's episodes are built."""


class MinariMissingError(ValueError):
    """A Minari export was asked for where the `srlab[minari]` extra is not installed."""


def require_minari() -> ModuleType:
    """The `minari` module, or `MinariMissingError` naming the extra that installs it."""
    try:
        import minari
    except ImportError:
        raise MinariMissingError(
            f"a Minari export needs the {MINARI_EXTRA} extra: pip install '{MINARI_EXTRA}' "
            "(in a checkout, make install)"
        ) from None
    module: ModuleType = minari
    return module


@dataclass(frozen=True, slots=True)
class Names:
    """What a run's trace indices name: its catalogue's stimuli, its behaviours."""

    stimuli: tuple[str, ...]
    behaviours: tuple[str, ...]
    """The catalogue's, then those the run synthesised, in the order the trace indexes them."""


def dataset_id(run_id: int) -> str:
    """A run's Minari dataset id (namespace `srlab`)."""
    return f"srlab/run{run_id}-v0"


@contextmanager
def _datasets_root(path: Path) -> Iterator[None]:
    with _ROOT_LOCK:
        before = os.environ.get(_ROOT_VARIABLE)
        os.environ[_ROOT_VARIABLE] = str(path)
        try:
            yield
        finally:
            if before is None:
                del os.environ[_ROOT_VARIABLE]
            else:
                os.environ[_ROOT_VARIABLE] = before


def _applied_by_episode(rewards: Sequence[StoredReward]) -> dict[int, list[StoredReward]]:
    out: dict[int, list[StoredReward]] = defaultdict(list)
    for r in rewards:
        if r.applied:
            out[r.record.episode].append(r)
    return out


def episode_buffer(
    index: int,
    trace: bytes,
    cause: str | None,
    rewards: Sequence[StoredReward],
    names: Names,
) -> dict[str, Any] | None:
    """One srlab episode as a Minari episode's arrays (None: its trace has no tick).

    Step i is the trace's tick i. A reward stamped at tick boundary t credits what ran
    before it, so it goes on the step of tick t - 1 (clamped into the episode: a reward
    applied at its first boundary goes on its first step). Minari's infos hold one entry
    more than the steps: infos[0] is the reset's, infos[i + 1] step i's.
    """
    rows = unpack(trace)
    steps = len(rows)
    if not steps:
        return None
    n_stimuli, none = len(names.stimuli), len(names.behaviours)
    observations = np.zeros((steps + 1, n_stimuli), dtype=np.int8)
    for i, row in enumerate(rows):
        observations[i, [s for s in row.stimuli if s < n_stimuli]] = 1
    observations[steps] = observations[steps - 1]  # nothing is sensed after the end
    actions = np.array(
        [r.behaviour if 0 <= r.behaviour < none else none for r in rows], dtype=np.int64
    )
    values = np.zeros(steps, dtype=np.float64)
    credited = np.zeros(steps + 1, dtype=np.int64)
    count = np.zeros(steps + 1, dtype=np.int64)
    first = rows[0].tick
    for r in rewards:
        i = min(max(r.record.tick - 1 - first, 0), steps - 1)
        values[i] += r.record.value
        credited[i + 1] += r.credited
        count[i + 1] += 1
    ticks = np.array([first, *(r.tick for r in rows)], dtype=np.int64)
    terminations = np.zeros(steps, dtype=bool)
    truncations = np.zeros(steps, dtype=bool)
    # A time limit cuts an episode short (truncated); a lap or a failure ends it.
    (truncations if cause == Cause.TIMEOUT else terminations)[-1] = True
    return {
        "id": index,
        "observations": observations,
        "actions": actions,
        "rewards": values,
        "terminations": terminations,
        "truncations": truncations,
        "infos": {"tick": ticks, "credited": credited, "rewards": count},
    }


def write_minari(
    store: RunQueries,
    run_id: int,
    root: Path,
    names: Names,
    rewards: Sequence[StoredReward],
    *,
    progress: Progress | None = None,
) -> tuple[str, int]:
    """Write the run's episodes as a Minari dataset under `root`; its id and episode count.

    `minari.load_dataset(id)` reads it back with `MINARI_DATASETS_PATH=root`.
    """
    minari = require_minari()
    from gymnasium import spaces
    from minari.data_collector.episode_buffer import EpisodeBuffer

    applied = _applied_by_episode(rewards)
    summaries = store.episode_summaries(run_id)
    buffers: list[Any] = []
    for done, summary in enumerate(summaries, 1):
        stored = store.episode(run_id, summary.episode)
        assert stored is not None  # episodes are never deleted from a run
        arrays = episode_buffer(
            len(buffers), stored.trace, stored.cause, applied[summary.episode], names
        )
        if arrays is not None:
            buffers.append(EpisodeBuffer(**arrays))
        if progress is not None:
            progress(done, len(summaries))
    key = dataset_id(run_id)
    root = root.resolve()  # Minari joins a relative root onto itself
    root.mkdir(parents=True, exist_ok=True)
    with _datasets_root(root), warnings.catch_warnings():
        # Minari advises an author, an e-mail, a code link and a Gymnasium environment: a
        # run has none of them (the manifest beside the dataset names its code).
        warnings.filterwarnings("ignore", category=UserWarning, module=r"minari\.")
        minari.create_dataset_from_buffers(
            dataset_id=key,
            buffer=buffers,
            observation_space=spaces.MultiBinary(len(names.stimuli)),
            action_space=spaces.Discrete(len(names.behaviours) + 1),
            algorithm_name="srlab",
            description=f"srlab run {run_id}: stimuli sensed, behaviours run, rewards applied",
        )
    return key, len(buffers)
