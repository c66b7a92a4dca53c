"""Studies made of cells: a condition in a setup with parameters, run on every seed.

An experiment compares conditions; a study compares cells, so the same condition can stand
in several (rp with a perfect teacher and with a mistaken one; kp from Table I and from
its own design). Each cell is summarised as an experiment's condition is
(`core.lab.analysis.summarise`), and cells are compared seed by seed as conditions are: every
cell meets the same obstacles and lamp cycles on a seed. Cells that run the same task
share its result.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from core.lab.analysis import paired, per_seed, summarise
from core.lab.experiment import Backend, Task, TaskResult, run_tasks
from core.params import Params, ParamValue, normalise, tuned_params
from core.run.setup import Setup

HORIZONS = (("1-10", 10), ("all", None))
"""The training horizons a study compares cells over."""
HELD_OUT = "frozen_by_seed"
"""The held-out figure a study compares cells on: what was learned, frozen."""
DECLARED_MEASURES = (("all", "training"), ("held-out", "held out"))
"""What a study's declared comparisons are tested on: all training episodes, and held out."""


@dataclass(frozen=True, slots=True)
class Cell:
    """A condition in a setup with parameters: one row of a study.

    Attributes:
        label: its name in the study's tables.
        condition: the condition it runs.
        params: the parameters it sets (its tuned ones included, when tuned).
        setup: where it runs.
    """

    label: str
    condition: str
    params: Params = ()
    setup: Setup = field(default_factory=Setup)

    def task(self, seed: int, episodes: int, eval_episodes: int) -> Task:
        """The cell's task on `seed`."""
        return Task(self.condition, seed, episodes, self.params, self.setup, eval_episodes)


def cell(
    label: str,
    condition: str,
    setup: Setup,
    *,
    tuned: bool = True,
    params: Mapping[str, ParamValue] | None = None,
) -> Cell:
    """A cell running `condition` with its tuned parameters (unless not `tuned`) and `params`."""
    setup.condition(setup.lookup(condition))  # an unknown name, or a start it cannot take
    base = dict(tuned_params(condition)) if tuned else {}
    return Cell(label, condition, normalise({**base, **(params or {})}), setup.resolved())


def study_tasks(
    cells: Sequence[Cell], seeds: Sequence[int], episodes: int, eval_episodes: int
) -> list[Task]:
    """Every distinct task of the cells, in (cell, seed) order."""
    if len({c.label for c in cells}) != len(cells):
        raise ValueError("cell labels must be distinct")
    return list(dict.fromkeys(c.task(s, episodes, eval_episodes) for c in cells for s in seeds))


def run_study(
    cells: Sequence[Cell],
    seeds: Sequence[int],
    episodes: int,
    eval_episodes: int,
    backend: Backend,
    on_result: Callable[[TaskResult], None] | None = None,
) -> list[TaskResult]:
    """Run every distinct task of the cells on `backend`; results in `study_tasks` order."""
    return run_tasks(study_tasks(cells, seeds, episodes, eval_episodes), backend, on_result)


def summarise_cells(
    cells: Sequence[Cell],
    results: Sequence[TaskResult],
    correct: Mapping[str, frozenset[str]] | None = None,
    camera: Sequence[str] = (),
) -> dict[str, dict[str, Any]]:
    """Each cell's summary over its seeds, as an experiment's condition's, by label."""
    out: dict[str, dict[str, Any]] = {}
    for c in cells:
        mine = [
            r
            for r in results
            if (r.task.condition, r.task.params, r.task.setup) == (c.condition, c.params, c.setup)
        ]
        out[c.label] = summarise(mine, [c.condition], correct, camera)[c.condition]
    return out


def cell_figures(summary: Mapping[str, Any], name: str) -> dict[str, Any]:
    """A cell's success over episodes 1-10, over all, and held out (frozen), as summarised."""
    s = summary[name]
    return {
        "success_1_10": s.get("success_horizons", {}).get("1-10"),
        "success_rate": s.get("success_rate"),
        "held_out": s.get("evaluation", {}).get("frozen"),
    }


def _measures() -> list[tuple[str, int | None, str | None]]:
    """What cells are compared on: each training horizon, then held out (label, horizon, key)."""
    return [*((label, h, None) for label, h in HORIZONS), ("held-out", None, HELD_OUT)]


def compare(summary: Mapping[str, Any], a: str, b: str) -> dict[str, dict[str, float]]:
    """Cell `a`'s success minus cell `b`'s, seed by seed, per horizon and held out.

    Each entry: the mean difference, its 95% interval (`core.lab.stats`), the sign-flip p and the
    seeds paired; a horizon the cells cannot be paired on is left out.
    """
    out: dict[str, dict[str, float]] = {}
    for label, horizon, key in _measures():
        d = paired(summary, a, b, horizon, key)
        if d is not None:
            out[label] = d
    return out


def compare_change(
    summary: Mapping[str, Any], first: tuple[str, str], second: tuple[str, str]
) -> dict[str, dict[str, float]]:
    """How a difference changes: `first`'s a - b minus `second`'s, seed by seed.

    `first` and `second` are (a, b) pairs of cells, e.g. kp and rp in a noisy world and in
    the exact one: the result is how much the noise moves kp's lead over rp, each seed's
    lead in one compared with its own in the other. Per horizon and held out, as `compare`;
    a measure on which fewer than two seeds have all four cells is left out.
    """
    from core.lab.stats import paired_difference

    names = (*first, *second)
    if not all(summary.get(n, {}).get("seeds") for n in names):
        return {}
    out: dict[str, dict[str, float]] = {}
    for label, horizon, key in _measures():
        a1, b1, a2, b2 = (per_seed(summary[n], horizon, key) for n in names)
        seeds = [x for x in a1 if x in b1 and x in a2 and x in b2]
        if len(seeds) < 2:
            continue
        d = paired_difference([a1[x] - b1[x] for x in seeds], [a2[x] - b2[x] for x in seeds])
        out[label] = {**d.diff.as_dict(), "p": d.p, "seeds": len(seeds)}
    return out


def declared_family(
    entries: Sequence[tuple[str, Mapping[str, float] | None]],
) -> list[dict[str, Any]]:
    """The comparisons a study declared before it ran, each p Holm-adjusted over them.

    `entries` are (what is compared, in words; a paired difference as `compare` gives it).
    A difference that could not be paired is left out of the family.
    """
    from core.lab.stats import holm

    family: list[dict[str, Any]] = [{"label": name, **d} for name, d in entries if d is not None]
    for d, adjusted in zip(family, holm([float(d["p"]) for d in family]), strict=True):
        d["p_holm"] = adjusted
    return family
