r"""Exploration on equal terms: every learner frozen and held out after the same budget.

While training, the baselines keep exploring (qlambda and qlambda-hybrid at their tuned
20%) and KP's robot stops exploring a stimulus once its response is confident, so success
while training mixes what was learned with how much is still explored. Here each learner
trains on the same seeds, and what it learned is frozen (no exploration, no learning) and
run on held-out seeds after 50, 200 and 1,000 episodes (`core.lab.experiment.Task.eval_after`:
one run per learner and seed, evaluated at each budget, the same numbers as one run per
budget). `qlambda-decay` and `qlambda-hybrid-decay` are the Q(lambda) baselines with an
exploration rate that decays (tuned with the same budget as every learner)::

    .venv/bin/python scripts/frozen_budgets.py docs/results/exploration --jobs 2

(what ``scripts/results.sh`` runs, in about 5 minutes on 2 cores). Only the learners the
long comparison needs train to the last budget (`--long`: kp and both qlambda-hybrids);
the others stop at the budget before it. The deep baselines are left out by default (20
seeds x 1,000 episodes of dqn and ppo take about 25 minutes on 2 cores;
`docs/results/deep-curve/` has them over 1,000 episodes on 3 seeds): add them with
``--learners ...,dqn,ppo --long ...,dqn,ppo`` and the srlab[baselines] extra. It writes
``summary.md`` (starting with that command), ``summary.json`` and ``frozen.png`` into the
folder.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from core.events import Outcome
from core.lab.experiment import (
    Checkpoint,
    LocalBackend,
    Task,
    TaskResult,
    parse_conditions,
    run_tasks,
)
from core.lab.stats import Estimate, mean_interval, paired_difference, pct
from core.params import tuned_params
from core.run.conditions import get_condition
from core.run.runner import EpisodeSummary
from core.run.setup import Setup
from server.reports.base import clean_json, cpu_seconds, head, interval_line, row
from server.reports.declared import Comparison, Tested, compare_declared, paired_points, points
from server.reports.plots import colours, save, subplots, success_axes

LEARNERS = ("kp", "qlambda", "qlambda-decay", "qlambda-hybrid", "qlambda-hybrid-decay")
"""kp and the Q(lambda) baselines, each with constant and with decaying exploration. kp's
ablation `sonar` learns nothing for the camera (`docs/results/obstacle/` holds it out);
add it with ``--learners``."""
LONG = ("kp", "qlambda-hybrid", "qlambda-hybrid-decay")
"""The learners trained to the last budget: kp and the strongest baseline, with constant
and with decaying exploration."""
BUDGETS = (50, 200, 1000)
LATE = 100
"""Training episodes at the end of each learner's run whose success (exploring) is shown."""

Frozen = dict[tuple[str, int], list[Checkpoint]]
"""Per (learner, budget), each seed's frozen evaluation after that many episodes."""


def rate(episodes: Sequence[EpisodeSummary]) -> float:
    """The share of successful episodes."""
    return float(np.mean([e.outcome is Outcome.SUCCESS for e in episodes]))


def tasks_for(
    learners: Sequence[str], long: Sequence[str], budgets: Sequence[int], seeds: int, evals: int
) -> list[Task]:
    """One task per learner and seed, trained to its last budget, frozen at the others."""
    setup = Setup(signal="given").resolved()
    out = []
    for c in learners:
        mine = budgets if c in long else budgets[:-1] or budgets
        out += [
            Task(c, s, mine[-1], tuned_params(c), setup=setup, eval_episodes=evals,
                 eval_after=tuple(mine[:-1]))
            for s in range(seeds)
        ]  # fmt: skip
    return out


def main(argv: Sequence[str] | None = None) -> None:
    """Train every learner, freeze it at every budget, evaluate, and write the folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder for summary.md, summary.json, the plot")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--budgets", default=",".join(str(b) for b in BUDGETS))
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument(
        "--learners",
        default=",".join(LEARNERS),
        help=f"comma-separated, the first the reference (default {','.join(LEARNERS)}; "
        "dqn and ppo need the srlab[baselines] extra)",
    )
    parser.add_argument(
        "--long",
        default=",".join(LONG),
        help=f"the learners trained to the last budget (default {','.join(LONG)}); the "
        "others stop at the budget before it",
    )
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    try:
        budgets = sorted({int(b) for b in args.budgets.split(",") if b.strip()})
        learners = parse_conditions(args.learners)
        long = parse_conditions(args.long)
    except Exception as e:  # an unknown learner or a missing extra: a usage error
        parser.error(str(e))
    if not budgets or budgets[0] < 1:
        parser.error("--budgets needs whole numbers of episodes, at least 1")
    if min(args.seeds, args.eval_episodes, args.jobs) < 1:
        parser.error("--seeds, --eval-episodes and --jobs must be >= 1")
    if learners[0] not in long or not set(long) <= set(learners):
        parser.error("--long names learners of --learners, the reference (the first) among them")
    command = "python scripts/frozen_budgets.py " + shlex.join(
        sys.argv[1:] if argv is None else argv
    )
    tasks = tasks_for(learners, long, budgets, args.seeds, args.eval_episodes)
    started, cpu = time.perf_counter(), cpu_seconds()
    results = run_tasks(tasks, LocalBackend(args.jobs))
    elapsed, cpu = time.perf_counter() - started, cpu_seconds() - cpu
    failed = [r for r in results if not r.ok]
    if failed:
        raise SystemExit(f"{failed[0].task}: {failed[0].error}")
    runs: dict[str, list[TaskResult]] = {c: [] for c in learners}
    for r in results:
        runs[r.task.condition].append(r)
    frozen: Frozen = {
        (c, b): [r.frozen_after(b) for r in rs]
        for c, rs in runs.items()
        for b in budgets
        if b <= rs[0].task.episodes
    }
    declared = compare_declared(declared_comparisons(frozen, learners, budgets))
    args.out.mkdir(parents=True, exist_ok=True)
    plot(args.out / "frozen.png", frozen, learners, budgets, args)
    doc: dict[str, Any] = {
        "command": command,
        "seeds": args.seeds,
        "budgets": budgets,
        "trained_to": {c: rs[0].task.episodes for c, rs in runs.items()},
        "eval_episodes": args.eval_episodes,
        "learners": learners,
        "tuned": {c: dict(tuned_params(c)) for c in learners},
        "elapsed_s": elapsed,
        "cpu_s": cpu,
        "jobs": args.jobs,
        "declared": [t.as_dict() for t in declared],
        "frozen": {
            c: {
                str(b): {
                    "held_out": held_out(frozen[(c, b)]).as_dict(),
                    "camera_only": camera_only(frozen[(c, b)]).as_dict(),
                    "held_out_by_seed": [rate(k.evaluation) for k in frozen[(c, b)]],
                }
                for b in budgets
                if (c, b) in frozen
            }
            for c in learners
        },
        "late_training": {c: late(rs).as_dict() for c, rs in runs.items()},
    }
    (args.out / "summary.json").write_text(
        json.dumps(clean_json(doc), indent=1, allow_nan=False) + "\n", encoding="utf-8"
    )
    text = markdown(command, runs, frozen, learners, budgets, declared, args, (elapsed, cpu))
    (args.out / "summary.md").write_text(text, encoding="utf-8")
    sys.stdout.write(
        f"wrote {args.out}/summary.md, summary.json, frozen.png in {elapsed:.0f} s "
        f"({cpu:.0f} s CPU)\n"
    )


def held_out(checkpoints: Sequence[Checkpoint]) -> Estimate:
    """Success frozen on the held-out seeds, over seeds, with its interval."""
    return mean_interval([rate(k.evaluation) for k in checkpoints])


def camera_only(checkpoints: Sequence[Checkpoint]) -> Estimate:
    """Success frozen without the sonar's obstacle responses, over seeds."""
    return mean_interval([rate(k.transfer) for k in checkpoints])


def late(rs: Sequence[TaskResult]) -> Estimate:
    """Success over the last `LATE` training episodes (exploring), over seeds."""
    return mean_interval([rate(r.episodes[-LATE:]) for r in rs])


def declared_comparisons(
    frozen: Frozen, learners: Sequence[str], budgets: Sequence[int]
) -> list[Comparison]:
    """The reference minus each other learner, held out, at the last budget both reached."""
    reference = learners[0]
    out = []
    for c in learners[1:]:
        b = max(b for b in budgets if (c, b) in frozen)
        out.append(
            Comparison(
                f"frozen after {b} episodes, held out: {reference} minus {c}",
                [rate(k.evaluation) for k in frozen[(reference, b)]],
                [rate(k.evaluation) for k in frozen[(c, b)]],
            )
        )
    return out


def paired_cell(frozen: Frozen, a: str, b: str, budget: int) -> str:
    """`a` minus `b` frozen after `budget`, held out, paired by seed, in points."""
    if (a, budget) not in frozen or (b, budget) not in frozen:
        return "not run"
    return paired_points(
        paired_difference(
            [rate(k.evaluation) for k in frozen[(a, budget)]],
            [rate(k.evaluation) for k in frozen[(b, budget)]],
        )
    )


def markdown(
    command: str,
    runs: dict[str, list[TaskResult]],
    frozen: Frozen,
    learners: Sequence[str],
    budgets: Sequence[int],
    declared: Sequence[Tested],
    args: argparse.Namespace,
    cost: tuple[float, float],
) -> str:
    """summary.md."""
    reference = learners[0]
    trained = {c: rs[0].task.episodes for c, rs in runs.items()}
    by_length: dict[int, list[str]] = {}
    for c in learners:
        by_length.setdefault(trained[c], []).append(f"`{c}`")
    what = "; ".join(f"{', '.join(cs)} to {n} episodes" for n, cs in sorted(by_length.items()))
    deep = [c for c in ("dqn", "ppo") if c not in learners]
    lines = [
        "# Exploration on equal terms: learners frozen after the same budget",
        "",
        f"`{command}`",
        "",
        f"{args.seeds} seeds (0-{args.seeds - 1}); world soft-obstacle, camera stimuli path, "
        "signal given (success measures the obstacle). Each learner trains once per seed "
        "with its tuned parameters (`core/data/tuned.toml`); after each budget "
        f"({', '.join(str(b) for b in budgets)} episodes) what it has learned is frozen (no "
        f"exploration, no learning) and runs {args.eval_episodes} episodes on a seed no "
        "training used (*held out*), and as many with the sonar's obstacle responses removed "
        "(*camera only*); training then goes on as if nobody had looked (`Task.eval_after`). "
        f"Trained: {what}"
        + (
            f" ({' and '.join(deep)} not run here: `docs/results/deep-curve/` shows them over "
            "1,000 episodes on 3 seeds, while training)"
            if deep
            else ""
        )
        + (
            "; kp's ablation `sonar`, which learns nothing for the camera, is held out in "
            "`docs/results/obstacle/`"
            if "sonar" not in learners
            else ""
        )
        + f". {cost[0]:.0f} s wall, {cost[1]:.0f} s CPU on {args.jobs} processes. "
        "Differences are paired by seed, in points.",
        "",
        interval_line(),
        "",
        "Exploration while training: "
        + "; ".join(f"`{c}` {_exploration(c)}" for c in learners)
        + ".",
        "",
        "## Pre-declared comparisons (Holm-corrected)",
        "",
        f"{reference} minus each other learner, frozen and held out after the last budget "
        f"both were trained for; p corrected with Holm's method over these {len(declared)}. "
        "Every other figure is exploratory.",
        "",
    ]
    lines += [f"{i}. {t.label}: {points(t)}" for i, t in enumerate(declared, 1)]
    lines += ["", "## Held out, frozen after each budget", ""]
    lines += head(
        ["learner", *(f"after {b}" for b in budgets), f"exploring: last {LATE} training episodes"]
    )
    for c in learners:
        cells = [pct(held_out(frozen[(c, b)])) if (c, b) in frozen else "not run" for b in budgets]
        lines.append(row([f"`{c}`", *cells, f"{pct(late(runs[c]))} (of {trained[c]})"]))
    lines += ["", f"## {reference} minus each learner, held out (paired by seed)", ""]
    lines += head(["learner", *(f"after {b}" for b in budgets)])
    for c in learners[1:]:
        lines.append(row([f"`{c}`", *(paired_cell(frozen, reference, c, b) for b in budgets)]))
    decays = [(c, f"{c}-decay") for c in learners if f"{c}-decay" in learners]
    if decays:
        lines += ["", "Decaying minus constant exploration, held out (paired by seed):", ""]
        lines += head(["learner", *(f"after {b}" for b in budgets)])
        for c, d in decays:
            lines.append(row([f"`{d}` - `{c}`", *(paired_cell(frozen, d, c, b) for b in budgets)]))
    lines += ["", "## Camera only, frozen after each budget", ""]
    lines += head(["learner", *(f"after {b}" for b in budgets)])
    for c in learners:
        cells = [
            pct(camera_only(frozen[(c, b)])) if (c, b) in frozen else "not run" for b in budgets
        ]
        lines.append(row([f"`{c}`", *cells]))
    lines += ["", "![Held out and camera only, frozen after each budget](frozen.png)", ""]
    return "\n".join(lines)


def _exploration(condition: str) -> str:
    """How a learner explores while training, from its tuned parameters, in words."""
    c = get_condition(condition)
    params = dict(tuned_params(condition))
    if c.agent == "ppo":
        return "its stochastic policy"
    eps = float(params.get("epsilon", c.epsilon))
    if c.agent == "brain":
        return f"{eps:.0%} per encounter until a response is confident (0.8)"
    half = float(params.get("epsilon_half_life", c.epsilon_half_life))
    if half:
        return f"{eps:.0%} halving every {half:g} episodes"
    return f"{eps:.0%} for ever"


def plot(
    path: Path,
    frozen: Frozen,
    learners: Sequence[str],
    budgets: Sequence[int],
    args: argparse.Namespace,
) -> None:
    """Held out and camera only against the budget, one line per learner, with intervals."""
    fig, axes = subplots(2, figsize=(12, 4.5))
    palette = colours()
    bases = list(dict.fromkeys(c.removesuffix("-decay") for c in learners))
    for panel, (pick, title) in enumerate(((held_out, "held out"), (camera_only, "camera only"))):
        ax = axes[0][panel]
        for i, c in enumerate(learners):
            xs = [j for j, b in enumerate(budgets) if (c, b) in frozen]
            est = [pick(frozen[(c, budgets[j])]) for j in xs]
            offset = (i - (len(learners) - 1) / 2) * 0.06
            err = [[e.mean - e.low for e in est], [e.high - e.mean for e in est]]
            # A decaying variant has its constant twin's colour, dashed.
            colour = palette[bases.index(c.removesuffix("-decay")) % len(palette)]
            style = "--" if c.endswith("-decay") else "-"
            ax.errorbar(np.array(xs) + offset, [e.mean for e in est], yerr=err, marker="o",
                        capsize=3, color=colour, linestyle=style, label=c)  # fmt: skip
        ax.set_xticks(np.arange(len(budgets)), [str(b) for b in budgets])
        success_axes(ax, xlabel="training episodes before freezing", criterion=False)
        ax.set_ylabel(f"success, {args.eval_episodes} frozen episodes")
        ax.set_title(f"{title} ({args.seeds} seeds, 95% intervals)")
    axes[0][0].legend(loc="lower right", fontsize="small")
    save(fig, path)


if __name__ == "__main__":
    main()
