"""What the low-level reflexes would teach the camera: KP's copies, measured with no learning.

A property of a world and of the designed reflexes alone, like `core.lab.worldcheck`'s: the
`reflexes` condition (kp's design, no learning) runs with a KP module that records its
RSTM but never learns, and at each episode's end every camera stimulus's RSTM records are
reasoned over as KP's reasoning does (the vector sum of the sonar's responses, snapped to
a primitive). That is the response KP would copy to the stimulus had the lap been
rewarded. The placement probe (`core.lab.probe`) says whether each copy is correct.

KP itself propagates only from a successful lap, so each copy says whether its episode
succeeded: the copies of the successful episodes are what a rewarded teacher would pass on.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from core.brain.propagation import KpConfig
from core.events import Outcome
from core.lab.stats import Estimate, mean_interval
from core.run.conditions import get_condition
from core.run.runner import EpisodeSummary, run
from core.run.setup import Setup
from core.run.simulation import Simulation

CONDITION = "reflexes"
"""The sonar reflexes alone: the teacher, never taught."""


@dataclass(frozen=True, slots=True)
class Copy:
    """The response the reflexes of one episode would teach one camera stimulus."""

    episode: int
    stimulus: str
    behaviour: str
    sources: int
    """The sonar responses reasoned over."""
    success: bool
    """Whether the episode succeeded (only then would KP have propagated it)."""


def reflex_copies(setup: Setup, seed: int, episodes: int, teacher: str = CONDITION) -> list[Copy]:
    """Every copy the reflexes would teach over `episodes` episodes of `seed`, in order.

    `teacher` is the condition whose reflexes teach: the sonar's (`reflexes`) by default,
    the stop-line beacon's (`beacon-reflexes`) for the camera's colour stimuli.
    """
    setup = setup.resolved()
    catalog = setup.catalog()
    condition = setup.condition(get_condition(teacher))
    base = condition.brain_config()
    # KP records (it is enabled) but learns nothing: the condition has no reward at all,
    # and learning is off, so nothing ever reaches RLTM or the network.
    config = replace(base, kp=KpConfig(enabled=True, window_ticks=base.kp.window_ticks))
    sim = Simulation(
        condition, seed, catalog=catalog, world_config=setup.world_config(), brain_config=config
    )
    kp = sim.brain.kp
    assert kp is not None
    out: list[Copy] = []

    def after(e: EpisodeSummary) -> None:
        by_high: dict[int, list[int]] = defaultdict(list)
        for records in kp.rstm.values():
            for r in records:
                by_high[r.high].append(r.behaviour)
        for s1, behaviours in sorted(by_high.items()):
            b, _ = kp.reasoning(behaviours)
            out.append(
                Copy(
                    e.episode,
                    catalog.stimuli[s1].name,
                    b.name,
                    len(behaviours),
                    e.outcome is Outcome.SUCCESS,
                )
            )

    run(condition, seed, episodes, simulation=sim, on_episode=after)
    return out


@dataclass(frozen=True, slots=True)
class CopyReport:
    """How often what the reflexes would teach is correct, over seeds.

    Attributes:
        correct: per seed, the share of its copies that are correct; the mean over seeds
            with its interval (seeds without a copy left out).
        correct_rewarded: the same over the copies of successful episodes only.
        by_stimulus: per camera stimulus, (copies, correct ones, copies of successful
            episodes, correct ones among those), summed over seeds, and the behaviours
            copied with their counts.
    """

    correct: Estimate
    correct_rewarded: Estimate
    by_stimulus: dict[str, tuple[int, int, int, int, dict[str, int]]]

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "correct": self.correct.as_dict(),
            "correct_rewarded": self.correct_rewarded.as_dict(),
            "by_stimulus": {
                s: {
                    "copies": n, "correct": ok, "rewarded": nr, "rewarded_correct": okr,
                    "behaviours": dict(bs),
                }
                for s, (n, ok, nr, okr, bs) in self.by_stimulus.items()
            },
        }  # fmt: skip


def copy_report(
    per_seed: Sequence[Sequence[Copy]], correct: Mapping[str, frozenset[str]]
) -> CopyReport:
    """Summarise the copies of each seed against the probe's correct responses."""
    shares: list[float] = []
    rewarded: list[float] = []
    counts: dict[str, list[int]] = {}
    behaviours: dict[str, dict[str, int]] = {}
    for copies in per_seed:
        good = [c.behaviour in correct.get(c.stimulus, frozenset()) for c in copies]
        if good:
            shares.append(float(np.mean(good)))
        good_rewarded = [g for g, c in zip(good, copies, strict=True) if c.success]
        if good_rewarded:
            rewarded.append(float(np.mean(good_rewarded)))
        for c, g in zip(copies, good, strict=True):
            row = counts.setdefault(c.stimulus, [0, 0, 0, 0])
            row[0] += 1
            row[1] += g
            row[2] += c.success
            row[3] += g and c.success
            bs = behaviours.setdefault(c.stimulus, {})
            bs[c.behaviour] = bs.get(c.behaviour, 0) + 1
    by_stimulus = {
        s: (n, ok, nr, okr, dict(sorted(behaviours[s].items(), key=lambda kv: -kv[1])))
        for s, (n, ok, nr, okr) in sorted(counts.items())
    }
    return CopyReport(mean_interval(shares), mean_interval(rewarded), by_stimulus)
