r"""Exploration on equal terms: every learner frozen and held out after the same budget.

While training, the baselines keep exploring (qlambda and qlambda-hybrid at their tuned
20%) and KP's robot stops exploring a stimulus once its response is confident, so success
while training mixes what was learned with how much is still explored. Here each learner
trains on the same seeds for a budget of episodes, then what it learned is frozen (no
exploration, no learning) and run on held-out seeds, after 50, 200 and 1,000 episodes.
`qlambda-decay` and `qlambda-hybrid-decay` are the Q(lambda) baselines with an exploration
rate that decays (tuned with the same budget as every learner)::

    .venv/bin/python scripts/frozen_budgets.py docs/results/exploration \
        --learners kp,sonar,qlambda,qlambda-decay,qlambda-hybrid,qlambda-hybrid-decay,dqn,ppo \
        --jobs 2

(what ``bash scripts/results.sh exploration`` runs, only when named: it is the longest
folder, 20 seeds x 1,250 training episodes per learner, over an hour on 2 cores with the
deep baselines, which need the srlab[baselines] extra). A budget's run trains from
scratch, so the 50-episode figures are the first 50 episodes of the longer runs, frozen
there. It writes ``summary.md`` (starting with that command),
``summary.json`` and ``frozen.png`` into the folder.
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
from core.experiment import LocalBackend, Task, TaskResult, parse_conditions, run_tasks
from core.params import tuned_params
from core.setup import Setup
from core.stats import bootstrap_mean, paired_difference, pct
from server.reports.base import clean_json, head, row
from server.reports.declared import Comparison, compare_declared, paired_points, points
from server.reports.plots import colours, save, subplots, success_axes

REFERENCE = "kp"
LEARNERS = (
    "kp", "sonar", "qlambda", "qlambda-decay", "qlambda-hybrid", "qlambda-hybrid-decay",
)  # fmt: skip
DEEP = ("dqn", "ppo")
BUDGETS = (50, 200, 1000)
LATE = 100
"""Training episodes at the end of the longest budget whose success (exploring) is shown."""


def rate(episodes: Sequence[Any]) -> float:
    """The share of successful episodes."""
    return float(np.mean([e.outcome is Outcome.SUCCESS for e in episodes]))


def main(argv: Sequence[str] | None = None) -> None:
    """Train every learner for every budget, freeze, evaluate, and write the folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder for summary.md, summary.json, the plot")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--budgets", default=",".join(str(b) for b in BUDGETS))
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument(
        "--learners",
        default=",".join(LEARNERS),
        help=f"comma-separated, the first the reference (default {','.join(LEARNERS)}; "
        f"add {','.join(DEEP)} with the srlab[baselines] extra)",
    )
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    try:
        budgets = sorted({int(b) for b in args.budgets.split(",") if b.strip()})
        learners = parse_conditions(args.learners)
    except Exception as e:  # an unknown learner or a missing extra: a usage error
        parser.error(str(e))
    if not budgets or budgets[0] < 1:
        parser.error("--budgets needs whole numbers of episodes, at least 1")
    command = "python scripts/frozen_budgets.py " + shlex.join(
        sys.argv[1:] if argv is None else argv
    )
    setup = Setup(signal="given").resolved()
    seeds = list(range(args.seeds))
    tasks = [
        Task(c, s, b, tuned_params(c), setup=setup, eval_episodes=args.eval_episodes)
        for c in learners
        for b in budgets
        for s in seeds
    ]
    started = time.perf_counter()
    results = run_tasks(tasks, LocalBackend(args.jobs))
    elapsed = time.perf_counter() - started
    failed = [r for r in results if not r.ok]
    if failed:
        raise SystemExit(f"{failed[0].task}: {failed[0].error}")
    by: dict[tuple[str, int], list[TaskResult]] = {}
    for r in results:
        by.setdefault((r.task.condition, r.task.episodes), []).append(r)

    reference, others = learners[0], learners[1:]
    last = budgets[-1]
    declared = compare_declared(
        [
            Comparison(
                f"frozen after {last} episodes, held out: {reference} minus {c}",
                [rate(r.evaluation) for r in by[(reference, last)]],
                [rate(r.evaluation) for r in by[(c, last)]],
            )
            for c in others
        ]
    )
    args.out.mkdir(parents=True, exist_ok=True)
    plot(args.out / "frozen.png", by, learners, budgets, args)
    doc: dict[str, Any] = {
        "command": command,
        "seeds": args.seeds,
        "budgets": budgets,
        "eval_episodes": args.eval_episodes,
        "learners": learners,
        "tuned": {c: dict(tuned_params(c)) for c in learners},
        "elapsed_s": elapsed,
        "jobs": args.jobs,
        "declared": [t.as_dict() for t in declared],
        "frozen": {
            c: {
                str(b): {
                    "held_out": bootstrap_mean([rate(r.evaluation) for r in by[(c, b)]]).as_dict(),
                    "camera_only": bootstrap_mean([rate(r.transfer) for r in by[(c, b)]]).as_dict(),
                    "training": bootstrap_mean([rate(r.episodes) for r in by[(c, b)]]).as_dict(),
                    "held_out_by_seed": [rate(r.evaluation) for r in by[(c, b)]],
                }
                for b in budgets
            }
            for c in learners
        },
        "late_training": {
            c: bootstrap_mean([rate(r.episodes[-LATE:]) for r in by[(c, last)]]).as_dict()
            for c in learners
        },
    }
    (args.out / "summary.json").write_text(
        json.dumps(clean_json(doc), indent=1, allow_nan=False) + "\n", encoding="utf-8"
    )
    (args.out / "summary.md").write_text(
        markdown(command, by, learners, budgets, declared, args, elapsed), encoding="utf-8"
    )
    sys.stdout.write(f"wrote {args.out}/summary.md, summary.json, frozen.png in {elapsed:.0f} s\n")


def paired_cell(by: dict[tuple[str, int], list[TaskResult]], a: str, b: str, budget: int) -> str:
    """`a` minus `b` frozen after `budget`, held out, paired by seed, in points."""
    return paired_points(
        paired_difference(
            [rate(r.evaluation) for r in by[(a, budget)]],
            [rate(r.evaluation) for r in by[(b, budget)]],
        )
    )


def markdown(
    command: str,
    by: dict[tuple[str, int], list[TaskResult]],
    learners: Sequence[str],
    budgets: Sequence[int],
    declared: Sequence[Any],
    args: argparse.Namespace,
    elapsed: float,
) -> str:
    """summary.md."""
    reference = learners[0]
    last = budgets[-1]
    lines = [
        "# Exploration on equal terms: learners frozen after the same budget",
        "",
        f"`{command}`",
        "",
        f"{args.seeds} seeds (0-{args.seeds - 1}); world soft-obstacle, camera stimuli path, "
        "signal given (success measures the obstacle). Each learner trains from scratch for "
        f"each budget ({', '.join(str(b) for b in budgets)} episodes) with its tuned "
        "parameters (`core/data/tuned.toml`), then what it learned is frozen (no exploration, "
        f"no learning) and runs {args.eval_episodes} episodes on a seed no training used "
        "(*held out*), and as many with the sonar's obstacle responses removed (*camera "
        f"only*). {elapsed:.0f} s on {args.jobs} processes. Intervals are 95% bootstrap "
        "intervals over seeds; differences are paired by seed, in points.",
        "",
        "Exploration while training: "
        + "; ".join(f"`{c}` {_exploration(c)}" for c in learners)
        + ".",
        "",
        "## Pre-declared comparisons",
        "",
        f"{reference} minus each other learner, frozen after {last} episodes, held out; p "
        f"corrected with Holm's method over these {len(declared)}. Every other figure is "
        "exploratory.",
        "",
    ]
    lines += [f"{i}. {t.label}: {points(t)}" for i, t in enumerate(declared, 1)]
    lines += ["", "## Held out, frozen after each budget", ""]
    late_n = min(LATE, last)
    lines += head(
        ["learner", *(f"after {b}" for b in budgets), f"training, last {late_n} of {last}"]
    )
    for c in learners:
        cells = [pct(bootstrap_mean([rate(r.evaluation) for r in by[(c, b)]])) for b in budgets]
        late = pct(bootstrap_mean([rate(r.episodes[-LATE:]) for r in by[(c, last)]]))
        lines.append(row([f"`{c}`", *cells, late]))
    lines += ["", f"## {reference} minus each learner, held out (paired by seed)", ""]
    lines += head(["learner", *(f"after {b}" for b in budgets)])
    for c in learners[1:]:
        lines.append(row([f"`{c}`", *(paired_cell(by, reference, c, b) for b in budgets)]))
    decays = [(c, f"{c}-decay") for c in learners if f"{c}-decay" in learners]
    if decays:
        lines += ["", "Decaying minus constant exploration, held out (paired by seed):", ""]
        lines += head(["learner", *(f"after {b}" for b in budgets)])
        for c, d in decays:
            lines.append(row([f"`{d}` - `{c}`", *(paired_cell(by, d, c, b) for b in budgets)]))
    lines += ["", "## Camera only, frozen after each budget", ""]
    lines += head(["learner", *(f"after {b}" for b in budgets)])
    for c in learners:
        cells = [pct(bootstrap_mean([rate(r.transfer) for r in by[(c, b)]])) for b in budgets]
        lines.append(row([f"`{c}`", *cells]))
    lines += ["", "![Held out and camera only, frozen after each budget](frozen.png)", ""]
    return "\n".join(lines)


def _exploration(condition: str) -> str:
    """How a learner explores while training, from its tuned parameters, in words."""
    from core.conditions import get_condition

    c = get_condition(condition)
    params = dict(tuned_params(condition))
    if c.agent == "ppo":
        return "its stochastic policy"
    if c.agent == "brain":
        eps = float(params.get("epsilon", c.epsilon))
        return f"{eps:.0%} per encounter until a response is confident (0.8)"
    eps = float(params.get("epsilon", c.epsilon))
    half = float(params.get("epsilon_half_life", c.epsilon_half_life))
    if half:
        return f"{eps:.0%} halving every {half:g} episodes"
    return f"{eps:.0%} for ever"


def plot(
    path: Path,
    by: dict[tuple[str, int], list[TaskResult]],
    learners: Sequence[str],
    budgets: Sequence[int],
    args: argparse.Namespace,
) -> None:
    """Held out and camera only against the budget, one line per learner, with intervals."""
    fig, axes = subplots(2, figsize=(12, 4.5))
    palette = colours()
    x = np.arange(len(budgets))
    for panel, (key, title) in enumerate((("evaluation", "held out"), ("transfer", "camera only"))):
        ax = axes[0][panel]
        bases = list(dict.fromkeys(c.removesuffix("-decay") for c in learners))
        for i, c in enumerate(learners):
            est = [bootstrap_mean([rate(getattr(r, key)) for r in by[(c, b)]]) for b in budgets]
            offset = (i - (len(learners) - 1) / 2) * 0.06
            means = [e.mean for e in est]
            err = [[e.mean - e.low for e in est], [e.high - e.mean for e in est]]
            # A decaying variant has its constant twin's colour, dashed.
            colour = palette[bases.index(c.removesuffix("-decay")) % len(palette)]
            style = "--" if c.endswith("-decay") else "-"
            ax.errorbar(x + offset, means, yerr=err, marker="o", capsize=3, color=colour,
                        linestyle=style, label=c)  # fmt: skip
        ax.set_xticks(x, [str(b) for b in budgets])
        success_axes(ax, xlabel="training episodes before freezing", criterion=False)
        ax.set_ylabel(f"success, {args.eval_episodes} frozen episodes")
        ax.set_title(f"{title} ({args.seeds} seeds, 95% intervals)")
    axes[0][0].legend(loc="lower right", fontsize="small")
    save(fig, path)


if __name__ == "__main__":
    main()
