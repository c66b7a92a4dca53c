"""Parameter sweeps: a grid of learning parameters x conditions x seeds, summarised per value.

A grid point sets every swept parameter; a condition uses only the parameters that apply to
it (see `core.params`), so the points that differ only in parameters a condition ignores
share one task: sweeping `eta` runs Q(lambda) once per seed, not once per value.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.events import Cause, Outcome
from core.lab.experiment import (
    DEFAULT_SETUP,
    Backend,
    Task,
    TaskResult,
    mean_ci,
    run_tasks,
    summarise,
)
from core.lab.stats import paired_difference
from core.params import Parameter, ParameterError, ParamValue, applicable, get_parameter
from core.run.setup import Setup

Point = dict[str, ParamValue]
Axes = tuple[tuple[str, tuple[ParamValue, ...]], ...]
"""The swept parameters in the order given, each with its values in the order given."""


def parse_param(
    text: str, lookup: Callable[[str], Parameter] = get_parameter
) -> tuple[str, tuple[ParamValue, ...]]:
    """``NAME=V1,V2,...`` as the parameter's name and its checked values.

    `lookup` finds the parameter by name (the learning parameters' by default).
    """
    name, sep, values = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise ParameterError(f"--param takes NAME=V1,V2,..., got {text!r}")
    parameter = lookup(name)
    parts = [v for v in values.split(",") if v.strip()]
    if not parts:
        raise ParameterError(f"--param {name}: no value given")
    return name, checked_values(parameter, [parameter.parse(v) for v in parts])


def checked_values(parameter: Parameter, values: Sequence[ParamValue]) -> tuple[ParamValue, ...]:
    """`values` checked against `parameter`'s kind and bounds, none repeated."""
    checked = tuple(parameter.check(v) for v in values)
    if not checked:
        raise ParameterError(f"--param {parameter.name}: no value given")
    if len(set(checked)) != len(checked):
        raise ParameterError(f"--param {parameter.name}: a value is repeated in {list(values)}")
    return checked


def parse_grid(specs: Sequence[str], lookup: Callable[[str], Parameter] = get_parameter) -> Axes:
    """Every ``--param`` of the command line, each parameter once (see `parse_param`)."""
    if not specs:
        raise ParameterError("give at least one --param NAME=V1,V2,...")
    axes: list[tuple[str, tuple[ParamValue, ...]]] = []
    for spec in specs:
        name, values = parse_param(spec, lookup)
        if any(n == name for n, _ in axes):
            raise ParameterError(f"--param {name} is given twice")
        axes.append((name, values))
    return tuple(axes)


@dataclass(frozen=True, slots=True)
class Sweep:
    """A parameter grid x conditions x seeds x episodes."""

    axes: Axes
    conditions: tuple[str, ...]
    seeds: tuple[int, ...]
    episodes: int
    setup: Setup = DEFAULT_SETUP

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError("episodes must be >= 1")
        if not self.seeds:
            raise ValueError("at least one seed is needed")
        if not self.conditions:
            raise ValueError("at least one condition is needed")
        if not self.axes:
            raise ParameterError("give at least one --param NAME=V1,V2,...")
        conditions = [self.setup.lookup(c) for c in self.conditions]
        for name, values in self.axes:
            parameter = get_parameter(name)
            for v in values:
                parameter.check(v)
            if not any(parameter.applies(c) for c in conditions):
                raise ParameterError(
                    f"--param {name} applies to none of the conditions "
                    f"{', '.join(self.conditions)} (it applies to {parameter.scope})"
                )

    @property
    def names(self) -> tuple[str, ...]:
        """The swept parameters' names."""
        return tuple(n for n, _ in self.axes)

    def points(self) -> list[Point]:
        """Every combination of the parameters' values, the first parameter slowest."""
        return [
            dict(zip(self.names, combo, strict=True))
            for combo in itertools.product(*(values for _, values in self.axes))
        ]

    def applies(self, name: str, condition: str) -> bool:
        """Whether `condition` uses the swept parameter `name`."""
        return get_parameter(name).applies(self.setup.lookup(condition))

    def task(self, point: Mapping[str, ParamValue], condition: str, seed: int) -> Task:
        """The task a (point, condition, seed) runs: only the parameters it uses are set."""
        return Task(
            condition,
            seed,
            self.episodes,
            applicable(self.setup.lookup(condition), point),
            self.setup,
        )

    def tasks(self) -> list[Task]:
        """Every distinct task, in (condition, point, seed) order."""
        return list(
            dict.fromkeys(
                self.task(p, c, s)
                for c in self.conditions
                for p in self.points()
                for s in self.seeds
            )
        )


def run_sweep(
    sweep: Sweep,
    backend: Backend,
    on_result: Callable[[TaskResult], None] | None = None,
) -> list[TaskResult]:
    """Run every distinct task of the sweep; results in `sweep.tasks()` order."""
    return run_tasks(sweep.tasks(), backend, on_result)


def _per_seed(r: TaskResult) -> dict[str, float]:
    eps = r.episodes
    n = len(eps)
    last = eps[-min(10, n) :]

    def rate(cause: Cause) -> float:
        return sum(e.cause is cause for e in eps) / n

    return {
        "success_rate": sum(e.outcome is Outcome.SUCCESS for e in eps) / n,
        "success_last10": sum(e.outcome is Outcome.SUCCESS for e in last) / len(last),
        "collisions_per_episode": rate(Cause.WALL_COLLISION) + rate(Cause.OBSTACLE_COLLISION),
        "violations_per_episode": rate(Cause.SIGNAL_VIOLATION),
    }


FIGURES = ("success_rate", "success_last10", "collisions_per_episode", "violations_per_episode")


def summarise_sweep(sweep: Sweep, results: Sequence[TaskResult]) -> dict[str, Any]:
    """Per grid point the experiment's summary, and per parameter its effect.

    ``points``: one entry per grid point with the experiment summary of every condition.
    ``by_parameter``: for each swept parameter, each condition that uses it and each
    value, the mean over seeds (with its 95% CI) of each seed's figures averaged over the
    grid points with that value, i.e. the other parameters' values averaged out.
    """
    by_task = {r.task: r for r in results}
    points = []
    for point in sweep.points():
        mine = [by_task[sweep.task(point, c, s)] for c in sweep.conditions for s in sweep.seeds]
        points.append({"params": point, "conditions": summarise(mine, sweep.conditions)})
    by_parameter: dict[str, Any] = {}
    for name, values in sweep.axes:
        table: dict[str, Any] = {}
        for c in sweep.conditions:
            if not sweep.applies(name, c):
                continue
            rows = []
            by_seed: list[dict[int, dict[str, float]]] = []
            for v in values:
                at = [p for p in sweep.points() if p[name] == v]
                per_seed: dict[int, dict[str, float]] = {}
                for s in sweep.seeds:
                    runs = [by_task[sweep.task(p, c, s)] for p in at]
                    if all(r.ok and r.episodes for r in runs):
                        figs = [_per_seed(r) for r in runs]
                        per_seed[s] = {f: float(np.mean([x[f] for x in figs])) for f in FIGURES}
                row: dict[str, Any] = {"value": v}
                for f in FIGURES:
                    row[f] = mean_ci([x[f] for x in per_seed.values()])
                if by_seed:
                    # Against the first value, seed by seed (the same episodes on a seed).
                    both = [s for s in sweep.seeds if s in per_seed and s in by_seed[0]]
                    if both:
                        d = paired_difference(
                            [per_seed[s]["success_rate"] for s in both],
                            [by_seed[0][s]["success_rate"] for s in both],
                        )
                        row["success_vs_first"] = {**d.diff.as_dict(), "p": d.p}
                by_seed.append(per_seed)
                rows.append(row)
            table[c] = rows
        by_parameter[name] = {
            "description": get_parameter(name).description,
            "conditions": table,
            "ignored_by": [c for c in sweep.conditions if not sweep.applies(name, c)],
        }
    return {"points": points, "by_parameter": by_parameter}
