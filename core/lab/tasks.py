"""What an experiment runs and what it gets back: `Task`, `TaskResult`, `Checkpoint`.

Plain values, apart from the running (`core.lab.experiment`) and the summaries
(`core.lab.analysis`), which both read them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from core.params import Params
from core.run.runner import EpisodeSummary
from core.run.setup import Setup

DEFAULT_SETUP = Setup()


@dataclass(frozen=True, slots=True)
class Task:
    """One (condition, seed) run, with the learning parameters it sets (none: defaults).

    It runs in `setup`: a world, a sensor definition and a signal mode (the defaults
    unless given).
    """

    condition: str
    seed: int
    episodes: int
    params: Params = ()
    setup: Setup = DEFAULT_SETUP
    eval_episodes: int = 0
    """Episodes of frozen, held-out evaluation after training (0: none)."""
    eval_after: tuple[int, ...] = ()
    """Training episodes after which the learner is also evaluated frozen, as after the
    last (`eval_episodes` each, into `TaskResult.checkpoints`): a learner frozen at
    several budgets from one run. Evaluating changes nothing the learner learns, so each
    checkpoint is what a task trained for that many episodes would report."""

    def __post_init__(self) -> None:
        if any(not 1 <= n < self.episodes for n in self.eval_after):
            raise ValueError("eval_after needs episode counts between 1 and episodes - 1")
        if self.eval_after and not self.eval_episodes:
            raise ValueError("eval_after needs eval_episodes")


@dataclass(frozen=True, slots=True)
class Checkpoint:
    """A learner frozen after `episodes` training episodes, and evaluated held out."""

    episodes: int
    evaluation: tuple[EpisodeSummary, ...]
    transfer: tuple[EpisodeSummary, ...]


@dataclass(frozen=True, slots=True)
class TaskResult:
    """A task's episodes and its final camera-stimulus reliabilities, or its error.

    `ltm` and `rltm` map "stimulus/behaviour" to the reliability, for the camera obstacle
    stimuli (the paper's Table III); `rltm` is empty unless KP ran. `programmed` holds the
    strengths of the camera pairs the condition's network was designed with (DP's S-R
    editor), which the paper's Table III shows as reliability 1.
    """

    task: Task
    episodes: tuple[EpisodeSummary, ...] = ()
    ticks: int = 0
    ltm: dict[str, float] = field(default_factory=dict)
    rltm: dict[str, float] = field(default_factory=dict)
    programmed: dict[str, float] = field(default_factory=dict)
    error: str | None = None
    ticks_by_origin: dict[str, int] = field(default_factory=dict)
    """Ticks by what made their behaviour run (see `core.run.runner.RunSummary`)."""
    camera_met: dict[str, tuple[int, int, int, int]] = field(default_factory=dict)
    """Per camera obstacle stimulus met: (ticks it was active, encounters, episodes it was
    met in, successes among those episodes)."""
    answers: tuple[tuple[str | None, ...], ...] = ()
    """After each training episode, the behaviour the learner gives each camera obstacle
    stimulus seen alone (catalogue order; None: no answer of its own)."""
    evaluation: tuple[EpisodeSummary, ...] = ()
    """The frozen evaluation's episodes on the held-out seed (see `core.lab.evaluation`)."""
    transfer: tuple[EpisodeSummary, ...] = ()
    """The camera-only transfer test's episodes: frozen, the sonar's obstacle responses
    removed."""
    checkpoints: tuple[Checkpoint, ...] = ()
    """The frozen evaluations after `Task.eval_after`'s episode counts, in their order."""

    def frozen_after(self, episodes: int) -> Checkpoint:
        """The held-out evaluation after `episodes` training episodes (a checkpoint or the end)."""
        if episodes == self.task.episodes:
            return Checkpoint(episodes, self.evaluation, self.transfer)
        for c in self.checkpoints:
            if c.episodes == episodes:
                return c
        raise KeyError(f"no frozen evaluation after {episodes} episodes")

    @property
    def ok(self) -> bool:
        """Whether the task ran to the end."""
        return self.error is None
