"""Tuning every learner with the same budget, on seeds the experiments never use.

Each learning condition gets a grid of 27 points over three of its own parameters (3 x 3
x 3), run on the same tuning seeds (1000 and up) for the same number of episodes; the
point with the highest mean success over those episodes wins. The winners are kept in
`core/data/tuned.toml` and are what `srlab experiment` runs unless told `--untuned`.
`srlab tune` runs the grids and writes the file; its report lists every point.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from core.errors import CatalogError
from core.events import Outcome
from core.lab.experiment import Backend, LocalBackend, TaskResult, run_tasks
from core.lab.sweep import Axes, Sweep
from core.params import ParamValue, point_label
from core.run.setup import Setup

TUNING_SEED_BASE = 1000
"""Tuning seeds start here: experiments use seeds below 1,000, held-out evaluation
1,000,000 and up."""

_BRAIN: Axes = (
    ("eta", (0.05, 0.1, 0.3)),
    ("epsilon", (0.05, 0.1, 0.2)),
    ("insert_threshold", (0.3, 0.5, 0.7)),
)
_KP: Axes = (
    ("eta", (0.1, 0.3, 0.5)),
    ("kp_window", (10, 20, 40)),
    ("insert_threshold", (0.3, 0.5, 0.7)),
)
_QLAMBDA: Axes = (
    ("alpha", (0.1, 0.3, 0.5)),
    ("lambda", (0.5, 0.8, 0.95)),
    ("epsilon", (0.05, 0.1, 0.2)),
)
_QLAMBDA_DECAY: Axes = (
    ("alpha", (0.1, 0.3, 0.5)),
    ("lambda", (0.5, 0.8, 0.95)),
    ("epsilon_half_life", (10.0, 50.0, 200.0)),
)
"""The decaying variants start at epsilon 0.2, where both constant ones were tuned to
stay, and tune how fast it decays instead."""
_DQN: Axes = (
    ("learning_rate", (2.5e-4, 5e-4, 1e-3)),
    ("target_update_interval", (100, 250, 1000)),
    ("epsilon", (0.05, 0.1, 0.2)),
)
_PPO: Axes = (
    ("learning_rate", (2.5e-4, 5e-4, 1e-3)),
    ("n_steps", (128, 256, 512)),
    ("ent_coef", (0.0, 0.01, 0.05)),
)
GRIDS: dict[str, Axes] = {
    "delayed": _BRAIN,
    "dp": _BRAIN,
    "dp-rare": _BRAIN,
    "rp": _BRAIN,
    "sonar": _BRAIN,
    "kp": _KP,
    "kp-punished": _KP,
    "kp-signal": _KP,
    "beacon": _BRAIN,
    "qlambda": _QLAMBDA,
    "qlambda-hybrid": _QLAMBDA,
    "qlambda-decay": _QLAMBDA_DECAY,
    "qlambda-hybrid-decay": _QLAMBDA_DECAY,
    "dqn": _DQN,
    "ppo": _PPO,
}
"""Each learner's grid: three of its parameters, three values each (27 points)."""


@dataclass(frozen=True, slots=True)
class TunedPoint:
    """One grid point's figures over the tuning seeds."""

    point: dict[str, ParamValue]
    success: float
    per_seed: tuple[float, ...]


def plan(
    conditions: Sequence[str], seeds: Sequence[int], episodes: int, setup: Setup
) -> dict[str, Sweep]:
    """The sweep each learner's tuning runs."""
    unknown = [c for c in conditions if c not in GRIDS]
    if unknown:
        raise CatalogError(f"no tuning grid for {', '.join(unknown)} (grids: {', '.join(GRIDS)})")
    return {c: Sweep(GRIDS[c], (c,), tuple(seeds), episodes, setup.resolved()) for c in conditions}


def tune(
    conditions: Sequence[str],
    seeds: Sequence[int],
    episodes: int,
    setup: Setup,
    backend: Backend | None = None,
    on_result: Callable[[TaskResult], None] | None = None,
) -> dict[str, list[TunedPoint]]:
    """Run every learner's grid; per learner its points, best first."""
    sweeps = plan(conditions, seeds, episodes, setup)
    tasks = [t for s in sweeps.values() for t in s.tasks()]
    results = {r.task: r for r in run_tasks(tasks, backend or LocalBackend(), on_result)}
    out: dict[str, list[TunedPoint]] = {}
    for c, sweep in sweeps.items():
        rows = []
        for point in sweep.points():
            rs = [results[sweep.task(point, c, s)] for s in sweep.seeds]
            bad = [r for r in rs if not r.ok]
            if bad:
                raise RuntimeError(f"tuning task {bad[0].task} failed: {bad[0].error}")
            rates = tuple(
                float(np.mean([e.outcome is Outcome.SUCCESS for e in r.episodes])) for r in rs
            )
            rows.append(TunedPoint(dict(point), float(np.mean(rates)), rates))
        # Best first; ties go to the point listed first (the grid's order).
        order = sorted(range(len(rows)), key=lambda i: (-rows[i].success, i))
        out[c] = [rows[i] for i in order]
    return out


TUNED_HEADER = (
    "# Each learner's parameters as tuned by `srlab tune` (see core/lab/tune.py): the best of\n"
    "# a 27-point grid on the tuning seeds, the same budget for every learner.\n"
    "# `srlab experiment` runs with these unless given --untuned.\n"
)


def tuned_toml(
    best: Mapping[str, TunedPoint], command: str, setup: Setup, previous: str = ""
) -> str:
    """`core/data/tuned.toml`'s text for the winners.

    Each learner's section says which command tuned it; the sections of `previous` (the
    file's text before) for learners not tuned now are kept as they were, so learners can
    be tuned in separate runs (the deep baselines need the srlab[baselines] extra).
    """
    kept = {c: text for c, text in _sections(previous).items() if c not in best}
    lines = [TUNED_HEADER]
    for text in kept.values():
        lines.append(text.rstrip("\n") + "\n")
    for c, p in best.items():
        lines.append(f"[{toml_key(c)}]")
        lines.append(f"# by {command}")
        lines.append(
            f"# in world {setup.world_name}, sensors {setup.sensors_name}, signal "
            f"{setup.signal}; mean success over the tuning seeds: {p.success:.3f}"
        )
        for k, v in p.point.items():
            lines.append(f"{toml_key(k)} = {str(v).lower() if isinstance(v, bool) else v!r}")
        lines.append("")
    return "\n".join(lines)


def _sections(text: str) -> dict[str, str]:
    """The `[learner]` sections of a tuned.toml text, by learner, each with its lines."""
    out: dict[str, str] = {}
    name: str | None = None
    for line in text.splitlines(keepends=True):
        if line.startswith("["):
            name = line.strip()[1:-1].strip('"')
            out[name] = ""
        if name is not None:
            out[name] += line
    return out


def toml_key(name: str) -> str:
    """A TOML key (quoted when it is not a bare key, like qlambda-hybrid's is)."""
    bare = name.replace("_", "").replace("-", "").isalnum()
    return name if bare else f'"{name}"'


def describe(point: Mapping[str, ParamValue]) -> str:
    """A point as people read it."""
    return point_label(dict(point)) or "defaults"
