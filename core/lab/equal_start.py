"""Equal starting knowledge: each method from Table I and from kp's design, on the same seeds.

In the paper's comparison the methods do not start alike: `rp` and `dp` start from Table
I, `kp` (and the baselines built on it) from kp's design, which adds lane keeping and the
sonar's obstacle responses; and `dp` can leave different stimuli to learn (`dp-rare`, the
paper's split, or srlab's `dp`). A study here runs every method from both starts
(`core.run.conditions.with_start`), so that a difference between two methods is measured
with the knowledge equal, and the headline's difference between a method at its own
start and kp at its own splits exactly into the method's part and the start's:

    kp@design - X@own = (kp@design - X@design) + (X@design - X@own)

seed by seed, so the means add up and each part has its own paired interval.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from core.errors import UnknownNameError
from core.run.conditions import PROGRAMMED_ON_TABLE_I, START_SETS, STARTS, Start, get_condition
from core.run.setup import Setup

if TYPE_CHECKING:  # the study's machinery is imported when it runs: `srlab` starts without it
    from core.lab.cells import Cell
    from core.lab.experiment import TaskResult

METHODS = ("dp-rare", "dp", "rp", "kp", "qlambda-hybrid")
"""The methods of the grid: DP with the paper's split and srlab's, RP, KP, the baseline."""
REFERENCE = "kp"
"""The method every other is compared with."""
START_NAMES: dict[str, str] = {"table1": "Table I", "design": "kp's design"}


def own_start(condition: str) -> Start:
    """The start a condition has as it is: Table I, or kp's design."""
    network = get_condition(condition).network
    if network == START_SETS["design"]:
        return "design"
    if network == START_SETS["table1"] or network in PROGRAMMED_ON_TABLE_I:
        return "table1"
    raise UnknownNameError(f"condition {condition!r} starts from neither Table I nor kp's design")


def label(condition: str, start: str) -> str:
    """``rp@design``: a method from a start."""
    return f"{condition}@{start}"


@dataclass(frozen=True, slots=True)
class EqualStartStudy:
    """Every method from every start.

    Attributes:
        methods: the conditions compared.
        setup: where every cell runs (its start is the study's to set).
        reference: the method the others are compared with.
        tuned: whether every condition runs with its tuned parameters (a method runs with
            the same ones from either start).
    """

    methods: tuple[str, ...] = METHODS
    setup: Setup = field(default_factory=Setup)
    reference: str = REFERENCE
    tuned: bool = True

    def __post_init__(self) -> None:
        if self.reference not in self.methods:
            raise UnknownNameError(f"the reference {self.reference!r} is not among the methods")
        for m in self.methods:
            own_start(m)
        if self.setup.start:
            raise ValueError("the study sets the start itself: give a setup without one")

    def start_setup(self, start: Start) -> Setup:
        """The setup of the cells from `start`."""
        return replace(self.setup, start=start).resolved()

    def cells(self) -> list[Cell]:
        """Every method from every start, start by start."""
        from core.lab.cells import cell

        return [
            cell(label(m, s), m, self.start_setup(s), tuned=self.tuned)
            for s in STARTS
            for m in self.methods
        ]


def summarise_equal_start(
    study: EqualStartStudy,
    results: Sequence[TaskResult],
    correct: Mapping[str, frozenset[str]] | None = None,
    camera: Sequence[str] = (),
) -> dict[str, Any]:
    """The grid, the methods compared at equal start, and the headline split in two.

    ``cells``: every cell's summary. ``grid``: per method, per start its success (episodes
    1-10, all, held out), its own start, and ``start_effect`` (from kp's design minus from
    Table I). ``method``: per start, the reference minus each other method.
    ``declared``: the comparisons the study's conclusion rests on, named before it runs:
    the reference minus each other method, both from the reference's start, in training
    (all episodes) and held out, with each p Holm-adjusted over that family.
    ``decomposition``: per method other than the reference, ``headline`` (the reference
    at its own start minus the method at its own), ``method`` (the two at the
    reference's start) and ``start`` (the method at the reference's start minus at its
    own); each a paired difference per horizon and held out.
    """
    from core.lab.cells import (
        DECLARED_MEASURES,
        cell_figures,
        compare,
        declared_family,
        summarise_cells,
    )

    summary = summarise_cells(study.cells(), results, correct, camera)

    ref = study.reference
    ref_own = own_start(ref)
    grid = {
        m: {
            "own_start": own_start(m),
            **{s: cell_figures(summary, label(m, s)) for s in STARTS},
            "start_effect": compare(summary, label(m, "design"), label(m, "table1")),
        }
        for m in study.methods
    }
    method = {
        s: {m: compare(summary, label(ref, s), label(m, s)) for m in study.methods if m != ref}
        for s in STARTS
    }
    decomposition = {
        m: {
            "own_start": own_start(m),
            "headline": compare(summary, label(ref, ref_own), label(m, own_start(m))),
            "method": compare(summary, label(ref, ref_own), label(m, ref_own)),
            "start": compare(summary, label(m, ref_own), label(m, own_start(m))),
        }
        for m in study.methods
        if m != ref
    }
    declared = declared_family([
        (f"{ref} - {m}, both from {START_NAMES[ref_own]}, {title}", d.get(measure))
        for m, d in method[ref_own].items()
        for measure, title in DECLARED_MEASURES
    ])  # fmt: skip
    return {
        "cells": summary,
        "grid": grid,
        "method": method,
        "declared": declared,
        "decomposition": decomposition,
    }
