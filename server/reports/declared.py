"""Pre-declared comparisons: the few paired differences a summary's conclusions rest on.

Each is a difference between two conditions' per-seed figures, paired by seed, with its
interval and sign-flip p (`core.lab.stats.paired_difference`); the family of them is corrected
for multiplicity with Holm's step-down method (`core.lab.stats.holm`), so a conclusion drawn
from any of them keeps the family's error rate at 5%. Every other figure in a summary is
exploratory.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from core.lab.stats import Paired, holm, p_text, paired_difference
from server.reports.base import diff


@dataclass(frozen=True, slots=True)
class Comparison:
    """One declared difference: what it compares, in words, and the per-seed figures."""

    label: str
    a: Sequence[float]
    b: Sequence[float]


@dataclass(frozen=True, slots=True)
class Tested:
    """A declared comparison's result: the paired difference and its Holm-adjusted p."""

    label: str
    paired: Paired
    p_holm: float

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "label": self.label,
            "diff": self.paired.diff.as_dict(),
            "p": self.paired.p,
            "p_holm": self.p_holm,
        }


def compare_declared(comparisons: Sequence[Comparison]) -> list[Tested]:
    """Every comparison paired by seed, its p corrected with Holm's over the family."""
    paired = [paired_difference(c.a, c.b) for c in comparisons]
    adjusted = holm([p.p for p in paired])
    return [Tested(c.label, p, q) for c, p, q in zip(comparisons, paired, adjusted, strict=True)]


def paired_points(paired: Paired) -> str:
    """A paired difference of rates in points: ``+9.1 [+5.7, +12.3], p 0.004``."""
    return diff({**paired.diff.as_dict(), "p": paired.p})


def holm_text(p_holm: float) -> str:
    """``(Holm 0.012)``, ``(Holm < 0.001)``."""
    return f"(Holm {p_text(p_holm).removeprefix('p ')})"


def points(tested: Tested) -> str:
    """``+9.1 [+5.7, +12.3], p 0.004 (Holm 0.012)``, in points."""
    return f"{paired_points(tested.paired)} {holm_text(tested.p_holm)}"


def declared_section(family: Sequence[dict[str, Any]], declared_as: str) -> list[str]:
    """A summary's section of the comparisons `family` (`core.lab.cells.declared_family`).

    `declared_as` says, in a sentence's words, what was declared (e.g. "kp minus each other
    method with the starting knowledge equal, in training and held out").
    """
    return [
        "## Pre-declared comparisons (Holm-corrected)",
        "",
        f"Declared before the study ran: {declared_as}; p corrected with Holm's method over "
        f"these {len(family)}. Every other figure below is exploratory.",
        "",
        *(
            f"{i}. {d['label']}: {diff(d)} {holm_text(d['p_holm'])}"
            for i, d in enumerate(family, 1)
        ),
        "",
    ]
