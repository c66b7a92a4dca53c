"""Phase diagrams: where a comparison between learners holds, across world parameters.

How much knowledge propagation adds depends on the world: how far the sonars hear the
obstacle, how big it is, how far the camera makes it out, how fast the robot cruises. A
phase diagram varies named world parameters one at a time around a base world (a star:
the base point, then each parameter's values with the others at the base's), runs the
sonar reflexes alone (`reflexes`, world-check's (b)) and every condition on each point on
the same seeds, and sets each paired difference (the reference condition minus another)
against the reflexes' own success there. Where the reflexes alone already pass, a camera
response has little to add; the diagram shows where each claim holds and where it flips.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import CatalogError
from core.lab.analysis import paired, summarise
from core.lab.experiment import DEFAULT_SETUP, Backend, Task, TaskResult, run_tasks
from core.lab.stats import holm
from core.lab.sweep import Axes, checked_values, parse_grid
from core.params import Parameter, ParameterError, ParamValue, tuned_params
from core.run.conditions import get_condition
from core.run.setup import Setup
from core.sim.worlds import WorldSettings, get_world_parameter, merge_settings

REFLEXES = "reflexes"
"""The condition every point runs besides the others: its success is the diagram's x."""


def _lookup(name: str) -> Parameter:
    return get_world_parameter(name).parameter


def parse_axes(specs: Sequence[str]) -> Axes:
    """Every ``--param NAME=V1,V2,...`` of the command line, each world parameter once."""
    return parse_grid(specs, _lookup)


def load_grid(path: Path) -> Axes:
    """The grid declared in a TOML file: ``NAME = [V1, V2, ...]`` per world parameter."""
    try:
        with path.open("rb") as f:
            raw = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise CatalogError(f"{path}: {e}") from e
    axes: list[tuple[str, tuple[ParamValue, ...]]] = []
    for name, values in raw.items():
        parameter = _lookup(name)
        if not isinstance(values, list):
            raise ParameterError(f"{path}: {name} needs a list of values, got {values!r}")
        axes.append((name, checked_values(parameter, values)))
    if not axes:
        raise ParameterError(f"{path}: no world parameter declared")
    return tuple(axes)


def merge_axes(*groups: Axes) -> Axes:
    """The axes of every group in order; a parameter given twice is an error."""
    out: list[tuple[str, tuple[ParamValue, ...]]] = []
    for name, values in (a for g in groups for a in g):
        if any(n == name for n, _ in out):
            raise ParameterError(f"world parameter {name} is given twice")
        out.append((name, values))
    return tuple(out)


@dataclass(frozen=True, slots=True)
class PhasePoint:
    """A point of the diagram: the base world, or one parameter moved off it."""

    varies: str | None = None
    """The parameter this point moves (None: the base world itself)."""
    value: float | None = None
    """Its value here (None at the base)."""

    @property
    def settings(self) -> WorldSettings:
        """The world settings that make this point from the base world."""
        if self.varies is None or self.value is None:
            return ()
        return ((get_world_parameter(self.varies).path, self.value),)

    @property
    def label(self) -> str:
        """``echo_range_m=0.4``, or ``base``."""
        return "base" if self.varies is None else f"{self.varies}={self.value:g}"


@dataclass(frozen=True, slots=True)
class Phase:
    """A star of world parameters around a base world x conditions x seeds x episodes.

    `conditions` are compared with the first, the reference (kp minus each other);
    `REFLEXES` runs on every point besides them. With `tuned`, every condition runs with
    its tuned parameters (`core/data/tuned.toml`), the same on every point.
    """

    axes: Axes
    conditions: tuple[str, ...]
    seeds: tuple[int, ...]
    episodes: int
    setup: Setup = DEFAULT_SETUP
    tuned: bool = True

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError("episodes must be >= 1")
        if not self.seeds:
            raise ValueError("at least one seed is needed")
        if not self.axes:
            raise ParameterError("declare at least one world parameter (--grid or --param)")
        for c in self.conditions:
            get_condition(c)
        if REFLEXES in self.conditions:
            raise ValueError(f"{REFLEXES} runs on every point already: leave it out")
        if len(self.conditions) < 2:
            raise ValueError("a phase diagram compares at least two conditions")
        for name, values in self.axes:
            checked_values(_lookup(name), values)

    def base_value(self, name: str) -> float:
        """The base world's value of the parameter `name`."""
        value: Any = self.setup.world_config()
        for part in get_world_parameter(name).path.split("."):
            value = getattr(value, part)
        return float(value)

    def points(self) -> list[PhasePoint]:
        """The base point, then each parameter's values off the base, in declared order."""
        out = [PhasePoint()]
        for name, values in self.axes:
            base = self.base_value(name)
            out += [PhasePoint(name, float(v)) for v in values if float(v) != base]
        return out

    def axis(self, name: str) -> list[tuple[float, PhasePoint]]:
        """Parameter `name`'s points by increasing value, the base point among them."""
        base = self.base_value(name)
        row = [(base, PhasePoint())]
        row += [(p.value, p) for p in self.points() if p.varies == name and p.value is not None]
        return sorted(row, key=lambda x: x[0])

    @property
    def all_conditions(self) -> tuple[str, ...]:
        """`REFLEXES` and the conditions compared: what each point runs."""
        return (REFLEXES, *self.conditions)

    @property
    def differences(self) -> list[tuple[str, str]]:
        """(reference, other) for each other condition: the differences plotted."""
        return [(self.conditions[0], c) for c in self.conditions[1:]]

    def task(self, point: PhasePoint, condition: str, seed: int) -> Task:
        """The task a (point, condition, seed) runs: the base world with the point's setting.

        The base point's task is the plain experiment's (no setting), so the base point
        reproduces `srlab experiment` on the base world.
        """
        return Task(
            condition,
            seed,
            self.episodes,
            tuned_params(condition) if self.tuned else (),
            Setup(
                self.setup.world_name,
                self.setup.sensors_name,
                self.setup.signal,
                merge_settings(self.setup.world_settings, point.settings),
            ),
        )

    def tasks(self) -> list[Task]:
        """Every task, in (point, condition, seed) order."""
        return [
            self.task(p, c, s)
            for p in self.points()
            for c in self.all_conditions
            for s in self.seeds
        ]


def run_phase(
    phase: Phase, backend: Backend, on_result: Callable[[TaskResult], None] | None = None
) -> list[TaskResult]:
    """Run every task of the diagram; results in `phase.tasks()` order."""
    return run_tasks(phase.tasks(), backend, on_result)


def difference_name(a: str, b: str) -> str:
    """``kp - sonar``."""
    return f"{a} - {b}"


def sign_of(d: Mapping[str, float] | None) -> str:
    """``+`` when a difference's interval lies above 0, ``-`` below, ``0`` when it covers it."""
    if d is None or any(math.isnan(float(d[k])) for k in ("low", "high")):
        return "?"
    return "+" if d["low"] > 0 else "-" if d["high"] < 0 else "0"


def summarise_phase(phase: Phase, results: Sequence[TaskResult]) -> dict[str, Any]:
    """Per point each condition's success and each difference; per parameter where it flips.

    ``points``: per point (in `phase.points()` order) its parameter and value, each
    condition's success over all episodes (mean over seeds, 95% interval) and obstacle
    collisions per episode, and each difference paired by seed, with its sign-flip p and
    Holm's adjustment over every (point, difference) of the diagram.
    ``regions``: per difference, the points where its interval lies above 0, covers 0 or
    lies below 0, with the range of the reflexes' success over them.
    ``axes``: per parameter, its points by value and, per difference, the neighbouring
    values between which the mean changes sign.
    """
    by_task = {r.task: r for r in results}
    names = [difference_name(a, b) for a, b in phase.differences]
    points: list[dict[str, Any]] = []
    for point in phase.points():
        mine = [by_task[phase.task(point, c, s)] for c in phase.all_conditions for s in phase.seeds]
        summary = summarise(mine, phase.all_conditions)
        points.append({
            "label": point.label,
            "varies": point.varies,
            "value": point.value,
            "settings": dict(point.settings),
            "conditions": {
                c: {
                    "seeds": s.get("seeds", 0),
                    "success_rate": s.get("success_rate"),
                    "obstacle_collisions_per_episode": s.get("obstacle_collisions_per_episode"),
                }
                for c, s in summary.items()
            },
            "differences": {
                difference_name(a, b): paired(summary, a, b) for a, b in phase.differences
            },
        })  # fmt: skip
    cells = [(p, n) for p in points for n in names if p["differences"][n] is not None]
    for (p, n), adjusted in zip(
        cells, holm([p["differences"][n]["p"] for p, n in cells]), strict=True
    ):
        p["differences"][n]["p_holm"] = adjusted
    return {
        "points": points,
        "tests": len(cells),
        "regions": {n: _regions(points, n) for n in names},
        "axes": {name: _axis(phase, name, points, names) for name, _ in phase.axes},
    }


def _reflexes(point: Mapping[str, Any]) -> float:
    s = point["conditions"][REFLEXES].get("success_rate")
    return math.nan if not s else float(s["mean"])


def _regions(points: Sequence[Mapping[str, Any]], name: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for sign in ("+", "0", "-"):
        mine = [p for p in points if sign_of(p["differences"][name]) == sign]
        xs = [x for p in mine if not math.isnan(x := _reflexes(p))]
        out[sign] = {
            "points": [p["label"] for p in mine],
            "reflexes_low": min(xs) if xs else None,
            "reflexes_high": max(xs) if xs else None,
        }
    return out


def _axis(
    phase: Phase, name: str, points: Sequence[Mapping[str, Any]], names: Sequence[str]
) -> dict[str, Any]:
    at = {p["label"]: i for i, p in enumerate(points)}
    row = [(v, at[point.label]) for v, point in phase.axis(name)]
    flips: dict[str, list[dict[str, Any]]] = {}
    for n in names:
        flips[n] = []
        for (v0, i0), (v1, i1) in itertools.pairwise(row):
            d0, d1 = points[i0]["differences"][n], points[i1]["differences"][n]
            if d0 is None or d1 is None:
                continue
            flip = d0["mean"] * d1["mean"] < 0  # a zero mean is no sign to flip from
            if flip or sign_of(d0) != sign_of(d1):
                flips[n].append({
                    "from": v0, "to": v1, "mean_from": d0["mean"], "mean_to": d1["mean"],
                    "sign_from": sign_of(d0), "sign_to": sign_of(d1), "flips": bool(flip),
                })  # fmt: skip
    return {
        "base": phase.base_value(name),
        "values": [v for v, _ in row],
        "points": [i for _, i in row],
        "changes": flips,
    }
