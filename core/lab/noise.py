"""Noisy perception beside exact: every condition sensing both ways, on the same seeds.

By default every stimulus comes from the true pose and obstacle; `core.sim.perception`
computes them from a camera and odometry that err. A study here runs each condition with
exact perception and with a noisy one (`--perception`) on the same seeds, so that each
figure is paired by seed across the two: what the noise costs each condition (noisy minus
exact), the reference's lead over each other condition under each, and how much the noise
moves that lead (its lead with noise minus its lead without, seed by seed). The noise
draws from a stream of its own, so on a seed both meet the same obstacles and lamp cycles.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

from core.errors import UnknownNameError
from core.run.conditions import get_condition
from core.run.setup import Setup
from core.sim.worlds import PERCEPTION_PREFIX, PERCEPTION_PRESETS, WorldSettings, merge_settings

if TYPE_CHECKING:  # the study's machinery is imported when it runs: `srlab` starts without it
    from core.lab.cells import Cell
    from core.lab.experiment import TaskResult

Perception = Literal["exact", "noisy"]
PERCEPTIONS: tuple[Perception, ...] = ("exact", "noisy")
CONDITIONS = ("kp", "sonar", "rp", "qlambda-hybrid", "dp")
"""The headline's declared comparisons' conditions: kp, its ablation and the three methods."""
REFERENCE = "kp"
"""The condition every other is compared with."""


def label(condition: str, perception: str) -> str:
    """``rp@noisy``: a condition sensing one way."""
    return f"{condition}@{perception}"


@dataclass(frozen=True, slots=True)
class NoiseStudy:
    """Every condition with exact and with noisy perception.

    Attributes:
        conditions: the conditions compared.
        noise: the noisy side's perception settings (``perception.*`` world settings;
            `core.sim.worlds.parse_perception`).
        setup: where every cell runs; its world settings set no perception (the study
            does).
        reference: the condition the others are compared with.
        tuned: whether every condition runs with its tuned parameters (the same both ways).
    """

    conditions: tuple[str, ...] = CONDITIONS
    noise: WorldSettings = PERCEPTION_PRESETS["noisy"]
    setup: Setup = field(default_factory=Setup)
    reference: str = REFERENCE
    tuned: bool = True

    def __post_init__(self) -> None:
        for c in self.conditions:
            get_condition(c)
        if self.reference not in self.conditions:
            raise UnknownNameError(f"the reference {self.reference!r} is not among the conditions")
        if not self.noise:
            raise ValueError("the noisy side perceives exactly: name a noise to compare with")
        if any(not path.startswith(PERCEPTION_PREFIX) for path, _ in self.noise):
            raise ValueError("the noise may set perception settings only")
        if any(path.startswith(PERCEPTION_PREFIX) for path, _ in self.setup.world_settings):
            raise ValueError("the study sets perception itself: give a setup without it")

    def perception_setup(self, perception: Perception) -> Setup:
        """The setup of the cells sensing as `perception` says."""
        noise = self.noise if perception == "noisy" else ()
        settings = merge_settings(self.setup.world_settings, noise)
        return replace(self.setup, world_settings=settings).resolved()

    def cells(self) -> list[Cell]:
        """Every condition sensing each way, exact first."""
        from core.lab.cells import cell

        return [
            cell(label(c, p), c, self.perception_setup(p), tuned=self.tuned)
            for p in PERCEPTIONS
            for c in self.conditions
        ]


def summarise_noise(
    study: NoiseStudy,
    results: Sequence[TaskResult],
    correct: Mapping[str, frozenset[str]] | None = None,
    camera: Sequence[str] = (),
) -> dict[str, Any]:
    """Each condition both ways, the reference's leads both ways, and what noise moves.

    ``cells``: every cell's summary. ``grid``: per condition, per perception its success
    (episodes 1-10, all, held out), and ``noise_effect`` (noisy minus exact). ``lead``:
    per perception, the reference minus each other condition. ``change``: per other
    condition, the reference's lead with noise minus its lead without, seed by seed.
    ``declared``: the comparisons the study's conclusion rests on, named before it runs:
    the reference minus each other condition with noise, in training (all episodes) and
    held out, each p Holm-adjusted over that family. Each difference is paired by seed,
    per horizon and held out (`core.lab.cells.compare`).
    """
    from core.lab.cells import (
        DECLARED_MEASURES,
        cell_figures,
        compare,
        compare_change,
        declared_family,
        summarise_cells,
    )

    summary = summarise_cells(study.cells(), results, correct, camera)

    ref = study.reference
    others = [c for c in study.conditions if c != ref]
    grid = {
        c: {
            **{p: cell_figures(summary, label(c, p)) for p in PERCEPTIONS},
            "noise_effect": compare(summary, label(c, "noisy"), label(c, "exact")),
        }
        for c in study.conditions
    }
    lead = {
        p: {c: compare(summary, label(ref, p), label(c, p)) for c in others} for p in PERCEPTIONS
    }
    change = {
        c: compare_change(
            summary,
            (label(ref, "noisy"), label(c, "noisy")),
            (label(ref, "exact"), label(c, "exact")),
        )
        for c in others
    }
    declared = declared_family([
        (f"{ref} - {c}, noisy perception, {title}", lead["noisy"][c].get(measure))
        for c in others
        for measure, title in DECLARED_MEASURES
    ])  # fmt: skip
    return {"cells": summary, "grid": grid, "lead": lead, "change": change, "declared": declared}
