"""A teacher that is wrong: what kp, and kp punished when an episode fails, learn from it.

In `kp` what KP learns only grows: a copy the sonar taught wrongly is never weakened.
`kp-punished` is kp whose RLTM a failed episode also punishes (`kp_failure_penalty` 1).
Both, and their ablation `sonar` (no propagation), learn on the same seeds in two worlds:
`crossed-sonar`, where the front sonars' cables are crossed so the reflex answers an
obstacle in the path on the wrong side, and `soft-obstacle`, where the reflex is right.
Before any learner, the script measures what the reflexes alone would teach the camera
there (`core.lab.copies`); then it trains every condition, signal given, and reports success,
the frozen held-out evaluation and what each variant answers each camera stimulus
(judged by the placement probe) as the episodes go by::

    .venv/bin/python scripts/wrong_teacher.py docs/results/wrong-teacher --jobs 2

(what ``scripts/results.sh`` runs). ``--doses 0.1,0.3`` adds kp with smaller penalties
(exploratory; each dose costs as much as another condition). It writes ``summary.md``
(starting with that command), ``summary.json`` and ``wrong-teacher.png`` into the folder.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.events import Outcome
from core.lab.copies import Copy, CopyReport, copy_report, reflex_copies
from core.lab.experiment import CAMERA_SENSOR, LocalBackend, Task, TaskResult, run_tasks
from core.lab.stats import Estimate, mean_interval, mean_intervals, paired_difference, pct
from core.params import Params, normalise, tuned_params
from core.run.setup import Setup
from core.sim.worlds import load_world
from server.reports.base import clean_json, cpu_seconds, head, interval_line, row
from server.reports.declared import (
    Comparison,
    Tested,
    compare_declared,
    paired_points,
    points,
)
from server.reports.plots import colours, save, subplots, success_axes
from server.services.probe_cache import cached_probe

WORLDS = ("crossed-sonar", "soft-obstacle")
CONDITIONS = ("kp", "kp-punished", "sonar")


def variants(doses: Sequence[float]) -> dict[str, tuple[str, Params]]:
    """Each row's label: its condition and the parameters set over the tuned ones.

    `doses` are smaller penalties than kp-punished's, on kp otherwise (exploratory: how the
    effect grows with the penalty; `--doses`).
    """
    return {
        **{c: (c, ()) for c in CONDITIONS},
        **{f"penalty {d:g}": ("kp", (("kp_failure_penalty", d),)) for d in doses},
    }


CHECKPOINTS = (10, 50)
"""Episodes after which what was learned is shown, besides the last."""
WINDOW = 20
"""Episodes in the plot's rolling success."""


def _copies(args: tuple[str, int, int]) -> list[Copy]:
    world, seed, episodes = args
    return reflex_copies(Setup(world, signal="given"), seed, episodes)


def verdicts(
    results: Sequence[TaskResult], camera: Sequence[str], correct: dict[str, frozenset[str]]
) -> np.ndarray[Any, np.dtype[np.int8]]:
    """Per seed, episode and camera stimulus: 1 a correct answer, -1 a wrong one, 0 none."""
    out = np.zeros((len(results), len(results[0].answers), len(camera)), dtype=np.int8)
    for i, r in enumerate(results):
        for e, answers in enumerate(r.answers):
            for j, (stim, answer) in enumerate(zip(camera, answers, strict=True)):
                if answer is not None:
                    out[i, e, j] = 1 if answer in correct.get(stim, frozenset()) else -1
    return out


def success(r: TaskResult, first: int = 1, last: int | None = None) -> float:
    """A task's success rate over training episodes `first`..`last` (1-based, inclusive)."""
    eps = r.episodes[first - 1 : last]
    return float(np.mean([e.outcome is Outcome.SUCCESS for e in eps]))


def held_out(r: TaskResult) -> float:
    """A task's success in its frozen, held-out evaluation."""
    return float(np.mean([e.outcome is Outcome.SUCCESS for e in r.evaluation]))


def share(values: np.ndarray[Any, Any]) -> Estimate:
    """The share of seeds where `values` (booleans, one per seed) holds, with its interval."""
    return mean_interval(values.astype(float).tolist())


def ever_wrong(marks: dict[str, np.ndarray[Any, Any]], camera: Sequence[str]) -> list[str]:
    """The camera stimuli some seed of kp or kp-punished answers wrongly at some episode."""
    return [
        stim
        for k, stim in enumerate(camera)
        if any((marks[c][:, :, k] == -1).any() for c in ("kp", "kp-punished"))
    ]


def met(rs: Sequence[TaskResult], stimulus: str) -> tuple[float, float]:
    """Episodes per seed in which `stimulus` was met, and the success among them (pooled)."""
    rows = [r.camera_met.get(stimulus, (0, 0, 0, 0)) for r in rs]
    episodes = sum(m[2] for m in rows)
    won = sum(m[3] for m in rows)
    return episodes / len(rs), (won / episodes if episodes else float("nan"))


def plot(
    path: Path,
    runs: dict[str, dict[str, list[TaskResult]]],
    marks: dict[str, dict[str, np.ndarray[Any, Any]]],
    camera: Sequence[str],
) -> None:
    """Per world: rolling success per condition; the share of seeds answering wrongly."""
    fig, axes = subplots(2, len(WORLDS), figsize=(12, 4.2 * len(WORLDS)))
    palette = colours()
    for w, world in enumerate(WORLDS):
        ax = axes[w][0]
        for c, condition in enumerate(CONDITIONS):
            rows = np.array(
                [
                    [e.outcome is Outcome.SUCCESS for e in r.episodes]
                    for r in runs[world][condition]
                ],
                dtype=float,
            )
            kernel = np.ones(WINDOW)
            counts = np.convolve(np.ones(rows.shape[1]), kernel)[: rows.shape[1]]
            rolled = np.array([np.convolve(x, kernel)[: rows.shape[1]] / counts for x in rows])
            x = np.arange(1, rows.shape[1] + 1)
            ax.plot(x, rolled.mean(axis=0), color=palette[c], label=condition)
            low, high = mean_intervals(rolled.T)  # each episode's interval over seeds
            ax.fill_between(x, low, high, color=palette[c], alpha=0.15)
        success_axes(ax, criterion=False)
        ax.set_ylabel(f"success, last {WINDOW} episodes")
        ax.set_title(f"{world}: success while learning (95% band)")
        ax.legend(loc="lower right")
        ax = axes[w][1]
        for j, stim in enumerate(ever_wrong(marks[world], camera)):
            k = list(camera).index(stim)
            for condition, style in (("kp", "-"), ("kp-punished", "--")):
                wrong = (marks[world][condition][:, :, k] == -1).mean(axis=0)
                x = np.arange(1, len(wrong) + 1)
                colour = palette[(3 + j) % len(palette)]
                ax.plot(x, wrong, style, color=colour, label=f"{stim[9:]}, {condition}")
        success_axes(ax, criterion=False)
        ax.set_ylabel("share of seeds answering wrongly")
        ax.set_title(f"{world}: wrong answers (solid kp, dashed kp-punished)")
        if ax.get_legend_handles_labels()[0]:  # no seed answered wrongly: nothing to name
            ax.legend(loc="upper left", fontsize="small", ncol=2)
    save(fig, path)


def main(argv: Sequence[str] | None = None) -> None:
    """Measure the teachers, train the variants, and write the folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder for summary.md, summary.json, the plot")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument("--copy-episodes", type=int, default=50)
    parser.add_argument(
        "--doses",
        default="",
        help="comma-separated smaller penalties to run on kp too, in (0, 1) (default: none)",
    )
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    if min(args.seeds, args.episodes, args.eval_episodes, args.copy_episodes, args.jobs) < 1:
        parser.error(
            "--seeds, --episodes, --eval-episodes, --copy-episodes and --jobs must be >= 1"
        )
    try:
        args.doses = sorted({float(d) for d in args.doses.split(",") if d.strip()})
    except ValueError:
        parser.error(f"--doses needs numbers, not {args.doses!r}")
    if any(not 0.0 < d < 1.0 for d in args.doses):
        parser.error("--doses are penalties between 0 and 1 (kp-punished's is 1)")
    rows = variants(args.doses)
    args.checkpoints = tuple(sorted({c for c in CHECKPOINTS if c <= args.episodes} |
                                    {args.episodes}))  # fmt: skip
    # The episode after which an answer counts as learned early: 50, or the last.
    args.early = min(CHECKPOINTS[-1], args.episodes)
    command = "python scripts/wrong_teacher.py " + shlex.join(
        sys.argv[1:] if argv is None else argv
    )
    seeds = list(range(args.seeds))
    started, cpu = time.perf_counter(), cpu_seconds()

    # Every world's copies in one pool and every world's training in one run, so that the
    # two workers stay busy to the end.
    correct = {w: cached_probe(Setup(w, signal="given"))[0].correct() for w in WORLDS}
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        copies = list(
            pool.map(_copies, [(w, s, args.copy_episodes) for w in WORLDS for s in seeds])
        )
    teachers = {
        w: copy_report(copies[i * len(seeds) : (i + 1) * len(seeds)], correct[w])
        for i, w in enumerate(WORLDS)
    }
    tasks = {
        (world, label): [
            Task(condition, seed, args.episodes,
                 normalise(dict(tuned_params(condition)) | dict(extra)),
                 setup=Setup(world, signal="given").resolved(), eval_episodes=args.eval_episodes)
            for seed in seeds
        ]
        for world in WORLDS
        for label, (condition, extra) in rows.items()
    }  # fmt: skip
    results = run_tasks([t for ts in tasks.values() for t in ts], LocalBackend(args.jobs))
    failed = [r for r in results if not r.ok]
    if failed:
        raise SystemExit(f"{failed[0].task}: {failed[0].error}")
    by_task = {r.task: r for r in results}
    runs: dict[str, dict[str, list[TaskResult]]] = {w: {} for w in WORLDS}
    for (world, label), ts in tasks.items():
        runs[world][label] = [by_task[t] for t in ts]
    elapsed, cpu = time.perf_counter() - started, cpu_seconds() - cpu

    camera = [s.name for s in Setup().catalog().stimuli_of_sensor(CAMERA_SENSOR)]
    marks = {w: {c: verdicts(runs[w][c], camera, correct[w]) for c in rows} for w in WORLDS}
    cs = runs["crossed-sonar"]
    soft = runs["soft-obstacle"]
    span = f"episodes 1-{args.episodes}"
    declared = compare_declared(
        [
            Comparison(
                f"crossed-sonar, {span}: kp-punished minus kp",
                [success(r) for r in cs["kp-punished"]], [success(r) for r in cs["kp"]],
            ),
            Comparison(
                "crossed-sonar, held out: kp-punished minus kp",
                [held_out(r) for r in cs["kp-punished"]], [held_out(r) for r in cs["kp"]],
            ),
            Comparison(
                f"crossed-sonar, {span}: kp minus sonar",
                [success(r) for r in cs["kp"]], [success(r) for r in cs["sonar"]],
            ),
            Comparison(
                f"soft-obstacle, {span}: kp-punished minus kp",
                [success(r) for r in soft["kp-punished"]], [success(r) for r in soft["kp"]],
            ),
        ]
    )  # fmt: skip
    args.out.mkdir(parents=True, exist_ok=True)
    plot(args.out / "wrong-teacher.png", runs, marks, camera)
    study = Study(args, command, (elapsed, cpu), teachers, correct, runs, marks, camera, declared)
    doc = report_json(study)
    (args.out / "summary.json").write_text(
        json.dumps(clean_json(doc), indent=1, allow_nan=False) + "\n", encoding="utf-8"
    )
    (args.out / "summary.md").write_text(
        markdown(study),
        encoding="utf-8",
    )
    sys.stdout.write(
        f"wrote {args.out}/summary.md, summary.json, wrong-teacher.png in {elapsed:.0f} s "
        f"({cpu:.0f} s CPU)\n"
    )


def _answers_at(marks: np.ndarray[Any, Any], episode: int, k: int) -> dict[str, Estimate]:
    at = marks[:, episode - 1, k]
    return {"correct": share(at == 1), "wrong": share(at == -1), "none": share(at == 0)}


def _unlearned(marks: np.ndarray[Any, Any], at: int) -> tuple[int, int]:
    """Of the (seed, stimulus) answers wrong after episode `at`, how many are not at the end."""
    wrong = marks[:, at - 1, :] == -1
    fixed = wrong & (marks[:, -1, :] != -1)
    return int(fixed.sum()), int(wrong.sum())


@dataclass(frozen=True, slots=True)
class Study:
    """Everything the folder reports: the arguments, the teachers, the runs, the verdicts."""

    args: argparse.Namespace
    command: str
    cost: tuple[float, float]
    """Wall and CPU seconds."""
    teachers: dict[str, CopyReport]
    correct: dict[str, dict[str, frozenset[str]]]
    runs: dict[str, dict[str, list[TaskResult]]]
    marks: dict[str, dict[str, np.ndarray[Any, Any]]]
    """Per world and variant, `verdicts` of its seeds' answers."""
    camera: Sequence[str]
    declared: list[Tested]


def report_json(study: Study) -> dict[str, Any]:
    """summary.json: every figure summary.md states, and the per-seed figures behind them."""
    args, runs, marks, camera = study.args, study.runs, study.marks, study.camera
    command, (elapsed, cpu), teachers, declared = (
        study.command, study.cost, study.teachers, study.declared,
    )  # fmt: skip
    worlds: dict[str, Any] = {}
    for w in WORLDS:
        conds: dict[str, Any] = {}
        for c in runs[w]:
            rs = runs[w][c]
            conds[c] = {
                "success_all": mean_interval([success(r) for r in rs]).as_dict(),
                "success_1_50": mean_interval([success(r, 1, 50) for r in rs]).as_dict(),
                "success_last_50": mean_interval(
                    [success(r, max(1, args.episodes - 49)) for r in rs]
                ).as_dict(),
                "held_out": mean_interval([held_out(r) for r in rs]).as_dict(),
                "success_by_seed": [
                    [int(e.outcome is Outcome.SUCCESS) for e in r.episodes] for r in rs
                ],
                "answers": {
                    str(n): {
                        stim: {v: e.as_dict() for v, e in _answers_at(marks[w][c], n, k).items()}
                        for k, stim in enumerate(camera)
                    }
                    for n in args.checkpoints
                },
                "unlearned_after_early": _unlearned(marks[w][c], args.early),
                "ticks_by_origin": _origins(rs),
                "met": {stim: met(rs, stim) for stim in camera},
            }
        worlds[w] = {"teacher": teachers[w].as_dict(), "conditions": conds}
    return {
        "command": command,
        "seeds": args.seeds,
        "episodes": args.episodes,
        "eval_episodes": args.eval_episodes,
        "copy_episodes": args.copy_episodes,
        "elapsed_s": elapsed,
        "cpu_s": cpu,
        "jobs": args.jobs,
        "doses": args.doses,
        "declared": [t.as_dict() for t in declared],
        "worlds": worlds,
    }


def _origins(rs: Sequence[TaskResult]) -> dict[str, float]:
    """Ticks by what made the behaviour run, as shares of all ticks."""
    total: dict[str, int] = {}
    for r in rs:
        for k, v in r.ticks_by_origin.items():
            total[k] = total.get(k, 0) + v
    n = sum(total.values())
    return {k: v / n for k, v in sorted(total.items())}


def markdown(study: Study) -> str:
    """summary.md."""
    args, runs, marks, camera = study.args, study.runs, study.marks, study.camera
    command, (elapsed, cpu), teachers, declared, correct = (
        study.command, study.cost, study.teachers, study.declared, study.correct,
    )  # fmt: skip
    n, e = args.seeds, args.episodes
    lines = [
        "# A teacher that is wrong",
        "",
        f"`{command}`",
        "",
        f"{n} seeds (0-{n - 1}) x {e} episodes per condition and world, signal given (success "
        "measures the obstacle), each condition with its tuned parameters "
        f"(`core/data/tuned.toml`); held out: {args.eval_episodes} frozen episodes on a seed no "
        f"training used. {elapsed:.0f} s wall, {cpu:.0f} s CPU on {args.jobs} processes. "
        "Differences are paired by seed.",
        "",
        interval_line(),
        "",
        "`kp-punished` is `kp` whose RLTM a failed episode also punishes "
        "(`kp_failure_penalty` 1: a reward of -1 to what the RSTM would teach and to the "
        "KP-made pairs that ran in the episode); `kp` is its ablation, `sonar` (no "
        "propagation) kp's.",
        "",
        "## The worlds and their teachers, before any learner",
        "",
    ]
    for w in WORLDS:
        lines += [f"- `{w}`: {load_world(w).description}"]
    lines += [
        "",
        f"What the sonar reflexes alone would teach the camera (`core/lab/copies.py`: `reflexes` "
        f"with a KP module that records and never learns, {args.copy_episodes} episodes x "
        f"{n} seeds; each episode's RSTM reasoned over as KP does, the copy judged by the "
        "placement probe). KP propagates only after a successful lap, so the copies of "
        "successful episodes are those a rewarded teacher passes on:",
        "",
        *head(["world", "copies correct", "copies of successful episodes correct"]),
    ]
    for w in WORLDS:
        t = teachers[w]
        lines.append(row([f"`{w}`", pct(t.correct), pct(t.correct_rewarded)]))
    lines += ["", *head(["world", "stimulus", "copies", "correct", "of successful", "correct",
                         "copied (count)", "correct responses (probe)"])]  # fmt: skip
    for w in WORLDS:
        for stim, (k, ok, kr, okr, bs) in teachers[w].by_stimulus.items():
            copied = ", ".join(f"{b} {c}" for b, c in bs.items())
            good = ", ".join(sorted(correct[w].get(stim, frozenset()))) or "none"
            lines.append(row([f"`{w}`", stim[9:], str(k), str(ok), str(kr), str(okr), copied,
                              good]))  # fmt: skip
    lines += [
        "",
        "## Pre-declared comparisons (Holm-corrected)",
        "",
        "Declared before the run; p corrected with Holm's method over these four. Every other "
        "figure below is exploratory.",
        "",
    ]
    lines += [f"{i}. {t.label}: {points(t)}" for i, t in enumerate(declared, 1)]
    lines += [
        "",
        "## Success",
        "",
        *head(
            ["world", "condition", "episodes 1-50", f"1-{e}", f"{max(1, e - 49)}-{e}", "held out"]
        ),
    ]
    for w in WORLDS:
        for c in CONDITIONS:
            rs = runs[w][c]
            lines.append(
                row([
                    f"`{w}`", f"`{c}`",
                    pct(mean_interval([success(r, 1, 50) for r in rs])),
                    pct(mean_interval([success(r) for r in rs])),
                    pct(mean_interval([success(r, max(1, e - 49)) for r in rs])),
                    pct(mean_interval([held_out(r) for r in rs])),
                ])
            )  # fmt: skip
    lines += [
        "",
        "![Success while learning, and the share of seeds answering wrongly](wrong-teacher.png)",
        "",
        "## What was learned, judged by the placement probe",
        "",
        "The share of seeds whose learner answers each camera stimulus (seen alone) correctly "
        "/ wrongly (95% intervals) / not at all, after the episodes given, for the stimuli "
        "met on most seeds (M-L, M-M, M-R: lane keeping holds the middle lane) and those "
        "some seed answers wrongly at some episode. *Unlearned*: of the (seed, stimulus) "
        f"answers wrong after episode {args.early}, how many are no longer wrong after "
        f"episode {e}; "
        "*wrong at the end*: (seed, stimulus) answers wrong then, of all seeds' answers.",
        "",
    ]
    main_stimuli = ("Obstacle_M_L", "Obstacle_M_M", "Obstacle_M_R")
    for w in WORLDS:
        shown = [st for st in camera if st in main_stimuli or st in ever_wrong(marks[w], camera)]
        lines += [f"### `{w}`", ""]
        lines += head(["condition", "after", *(st[9:] for st in shown), "unlearned",
                       "wrong at the end"])  # fmt: skip
        for c in CONDITIONS[:2]:
            for at in args.checkpoints:
                cells = []
                for stim in shown:
                    a = _answers_at(marks[w][c], at, list(camera).index(stim))
                    cells.append(f"{pct(a['correct'])} / {pct(a['wrong'])} / {a['none'].mean:.0%}")
                fixed, was = _unlearned(marks[w][c], args.early)
                wrong_end = int((marks[w][c][:, -1, :] == -1).sum())
                tail = [f"{fixed} of {was}", str(wrong_end)] if at == e else ["", ""]
                lines.append(row([f"`{c}`", str(at), *cells, *tail]))
        lines += ["", "Where those stimuli were met, and how those episodes ended (all "
                  f"{e} episodes, every seed pooled):", ""]  # fmt: skip
        lines += head(["stimulus", *(f"`{c}`: episodes met per seed, success" for c in CONDITIONS)])
        for stim in shown:
            cells = []
            for c in CONDITIONS:
                per_seed, won = met(runs[w][c], stim)
                cells.append(f"{per_seed:.1f}, {won:.0%}" if per_seed else "-")
            lines.append(row([stim[9:], *cells]))
        lines.append("")
    if args.doses:
        lines += _doses(args, runs)
    lines.append("")
    return "\n".join(lines)


def _doses(args: argparse.Namespace, runs: dict[str, dict[str, list[TaskResult]]]) -> list[str]:
    """The smaller penalties' section: each minus kp, paired by seed (exploratory)."""
    e = args.episodes
    lines = [
        "## Smaller penalties (exploratory)",
        "",
        f"`kp` with `kp_failure_penalty` {', '.join(f'{d:g}' for d in args.doses)} over its "
        "tuned parameters (kp-punished's is 1), minus `kp`, paired by seed, in points:",
        "",
        *head(["world", "penalty", f"episodes 1-{e}", "held out", f"minus kp, 1-{e}",
               "minus kp, held out"]),
    ]  # fmt: skip
    for w in WORLDS:
        for label in [f"penalty {d:g}" for d in args.doses] + ["kp-punished"]:
            rs, base = runs[w][label], runs[w]["kp"]
            trained = paired_difference([success(r) for r in rs], [success(r) for r in base])
            frozen = paired_difference([held_out(r) for r in rs], [held_out(r) for r in base])
            penalty = label.removeprefix("penalty ") if label != "kp-punished" else "1"
            lines.append(
                row([
                    f"`{w}`", penalty,
                    pct(mean_interval([success(r) for r in rs])),
                    pct(mean_interval([held_out(r) for r in rs])),
                    paired_points(trained), paired_points(frozen),
                ])
            )  # fmt: skip
    return [*lines, ""]


if __name__ == "__main__":
    main()
