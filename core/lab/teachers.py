"""Teachers as they really are: rp as each of its teacher's imperfections rises.

The reinforcement program (`rp`) rewards every response at once and never errs: an oracle.
A study here runs it with one imperfection at a time raised through its levels (the others
at 0, `core.run.trainer.Imperfections`), beside the learners that need no teacher at all (`kp`
and `qlambda-hybrid` by default), all on the same seeds, and says at which level the
taught robot falls below each of them: in training, and frozen on held-out seeds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from core.params import TEACHER_PREFIX, ParameterError, ParamValue, format_value, get_parameter
from core.run.conditions import get_condition
from core.run.setup import Setup
from core.run.trainer import PERFECT, teacher_presets

if TYPE_CHECKING:  # the study's machinery is imported when it runs: `srlab` starts without it
    from core.lab.cells import Cell
    from core.lab.experiment import TaskResult

Axes = tuple[tuple[str, tuple[ParamValue, ...]], ...]
"""Imperfections (``teacher_*`` parameters), each with its levels (`core.lab.sweep.Axes`)."""

TAUGHT = "rp"
"""The condition whose teacher is varied."""
REFERENCES = ("kp", "qlambda-hybrid")
"""The learners compared with it by default: kp, and the strongest baseline from its design."""
LEVELS: Axes = (
    ("teacher_mistake", (0.0, 0.1, 0.2, 0.3, 0.4)),
    ("teacher_skip", (0.0, 0.25, 0.5, 0.75, 0.9)),
    ("teacher_delay_s", (0.0, 0.5, 1.0, 2.0, 4.0)),
    ("teacher_bias", (0.0, 0.25, 0.5, 0.75, 1.0)),
    ("teacher_fatigue", (0.0, 0.05, 0.1, 0.2, 0.4)),
)
"""Each imperfection's levels, from none (the perfect teacher) up."""
PRESETS = ("human",)
"""Named teachers with several imperfections at once, run beside the levels."""
MEASURES = (("all", "training, all episodes"), ("held-out", "held-out, frozen"))
"""What the verdicts are drawn on: training success, and what was learned, frozen."""


def level_label(name: str, value: ParamValue) -> str:
    """``rp mistake=0.2``: the taught condition with one imperfection at a level."""
    return f"{TAUGHT} {name.removeprefix(TEACHER_PREFIX)}={format_value(value)}"


@dataclass(frozen=True, slots=True)
class TeacherStudy:
    """rp with each imperfection raised in turn, beside learners needing no teacher.

    Attributes:
        axes: the imperfections (``teacher_*`` parameters) and their levels, each raised
            alone, the others at the perfect teacher's.
        references: the conditions compared with the taught one.
        presets: named teachers (``core/data/trainers/teachers.toml``) run as they are.
        setup: where every cell runs.
        tuned: whether every condition runs with its tuned parameters.
    """

    axes: Axes = LEVELS
    references: tuple[str, ...] = REFERENCES
    presets: tuple[str, ...] = PRESETS
    setup: Setup = field(default_factory=Setup)
    tuned: bool = True

    def __post_init__(self) -> None:
        for name, values in self.axes:
            parameter = get_parameter(name)
            if not name.startswith(TEACHER_PREFIX):
                raise ParameterError(f"--param {name} is not a teacher's imperfection")
            for v in values:
                parameter.check(v)
        for c in self.references:
            if get_condition(c).trainer is not None:
                raise ParameterError(f"{c} has a teacher: compare rp with learners without one")
        known = teacher_presets()
        for p in self.presets:
            if p not in known:
                raise ParameterError(f"unknown teacher {p!r} (presets: {', '.join(known)})")

    def cells(self) -> list[Cell]:
        """The references, the perfect teacher, every level of every axis, the presets."""
        from core.lab.cells import cell

        setup, tuned = self.setup, self.tuned
        out = [cell(c, c, setup, tuned=tuned) for c in self.references]
        out.append(cell(TAUGHT, TAUGHT, setup, tuned=tuned))
        for name, values in self.axes:
            default = getattr(PERFECT, name.removeprefix(TEACHER_PREFIX))
            for v in values:
                # The perfect teacher's own level is the perfect teacher: one task, two rows.
                params = {} if v == default else {name: v}
                out.append(cell(level_label(name, v), TAUGHT, setup, tuned=tuned, params=params))
        for p in self.presets:
            params = {f"{TEACHER_PREFIX}{k}": v for k, v in teacher_presets()[p].changed().items()}
            out.append(cell(f"{TAUGHT} {p}", TAUGHT, setup, tuned=tuned, params=params))
        return out


def _first(levels: Sequence[dict[str, Any]], ref: str, measure: str, test: str) -> Any:
    """The first level whose difference from `ref` passes `test` (None: no level does)."""
    for lv in levels:
        d = lv["vs"].get(ref, {}).get(measure)
        if d is None:
            continue
        if (test == "below" and d["high"] < 0) or (test == "not_above" and d["low"] <= 0):
            return lv["value"]
    return None


def summarise_teachers(study: TeacherStudy, results: Sequence[TaskResult]) -> dict[str, Any]:
    """Per imperfection and level, rp's success and its paired difference from each reference.

    ``cells``: every cell's summary (as an experiment's condition's). ``by_parameter``: per
    imperfection, its levels, each with rp's figures and ``vs`` (per reference, rp minus
    it over episodes 1-10, all episodes and held out), and the verdicts: ``below``, the
    first level at which rp is below the reference (the difference's interval under 0),
    and ``not_above``, the first at which it is no longer above it (the interval reaching
    0), per measure (`MEASURES`). ``presets``: the same for each named teacher.
    ``declared``: what the study's conclusion rests on, named before it runs: rp given by
    the perfect teacher and by each preset, minus the first reference (kp), per measure,
    each p Holm-adjusted over that family.
    """
    from core.lab.cells import compare, declared_family, summarise_cells

    cells = study.cells()
    summary = summarise_cells(cells, results)

    def figures(label: str) -> dict[str, Any]:
        s = summary[label]
        return {
            "label": label,
            "success_rate": s.get("success_rate"),
            "success_1_10": s.get("success_horizons", {}).get("1-10"),
            "held_out": s.get("evaluation", {}).get("frozen"),
            "vs": {ref: compare(summary, label, ref) for ref in study.references},
        }

    by_parameter: dict[str, Any] = {}
    for name, values in study.axes:
        levels = [{"value": v, **figures(level_label(name, v))} for v in values]
        by_parameter[name] = {
            "description": get_parameter(name).description,
            "levels": levels,
            "below": {
                ref: {m: _first(levels, ref, m, "below") for m, _ in MEASURES}
                for ref in study.references
            },
            "not_above": {
                ref: {m: _first(levels, ref, m, "not_above") for m, _ in MEASURES}
                for ref in study.references
            },
        }
    presets = {
        p: {**figures(f"{TAUGHT} {p}"), "teacher": teacher_presets()[p].changed()}
        for p in study.presets
    }
    taught = [("the perfect teacher", figures(TAUGHT))]
    taught += [(f"the `{p}` teacher", f) for p, f in presets.items()]
    declared = declared_family([
        (f"rp given by {who} - {ref}, {title}", f["vs"].get(ref, {}).get(measure))
        for who, f in taught
        for ref in study.references[:1]
        for measure, title in MEASURES
    ])  # fmt: skip
    return {
        "cells": summary,
        "declared": declared,
        "references": {ref: figures(ref) for ref in study.references},
        "perfect": figures(TAUGHT),
        "by_parameter": by_parameter,
        "presets": presets,
    }
