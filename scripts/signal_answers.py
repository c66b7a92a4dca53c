"""What the camera's colour stimuli answer after training in the `stop-line` world.

The signal's rule fixes the correct response to each camera colour stimulus: stop on red
and on yellow, go (a forward primitive) on green; the same rule judges the expert's design
and the reinforcement program's rewards. Each condition trains on the experiment's seeds
and episodes with its tuned parameters (`docs/results/signal-kp/`'s runs, deterministically
again); the script reads what the frozen network answers each stimulus perceived alone
(`Brain.answer`) and which source made that pair, and reports per stimulus the share of
seeds answering correctly, wrongly or not at all::

    .venv/bin/python scripts/signal_answers.py docs/results/signal-kp --jobs 2

Before any learner, it also measures what the beacon's reflexes alone would teach the
camera's colour stimuli (`core.lab.copies` with `beacon-reflexes`: KP's RSTM reasoned at
each episode's end, nothing learned), judged by the same rule.

It writes ``answers.md`` (starting with that command), ``answers.json`` and ``answers.png``
into the folder.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from core.lab.copies import Copy, copy_report, reflex_copies
from core.params import configure, tuned_params
from core.run.runner import run
from core.run.setup import Setup
from core.run.simulation import Simulation

STIMULI = ("Red", "Yellow", "Green")
CORRECT = {"Red": "stop", "Yellow": "stop", "Green": "forward"}
"""The signal's rule: the correct response's behaviour family per camera colour stimulus."""


def answers(condition: str, seed: int, episodes: int) -> dict[str, tuple[str | None, str]]:
    """Per colour stimulus: the behaviour answered after training (None: none), its source."""
    setup = Setup("stop-line", signal="learned").resolved()
    catalog = setup.catalog()
    cond, config = configure(setup.condition(setup.lookup(condition)), tuned_params(condition))
    sim = Simulation(cond, seed, catalog=catalog, world_config=setup.world_config(),
                     brain_config=config)  # fmt: skip
    run(cond, seed, episodes, simulation=sim)
    brain = sim.brain
    out: dict[str, tuple[str | None, str]] = {}
    for name in STIMULI:
        s = brain.catalog.stimulus(name).id
        b = brain.answer(s)
        if b < 0:
            out[name] = (None, "")
            continue
        pair = brain.network.get(s, b)
        out[name] = (brain.catalog.behaviours[b].name, pair.source if pair else "")
    return out


RULE = {
    "Red": frozenset({"stop"}),
    "Yellow": frozenset({"stop"}),
    "Green": frozenset(f"goforward{i}" for i in range(1, 6)),
}
"""The signal's rule as sets of correct behaviours (the probe's form, `core.lab.copies`)."""


def copies(seed: int, episodes: int) -> list[Copy]:
    """What the beacon's reflexes would teach the camera over one seed's episodes."""
    setup = Setup("stop-line", signal="learned")
    return [
        c for c in reflex_copies(setup, seed, episodes, "beacon-reflexes") if c.stimulus in RULE
    ]


def judge(stimulus: str, behaviour: str | None) -> str:
    """correct, wrong or none: `behaviour` as the answer to `stimulus` by the signal's rule."""
    if behaviour is None:
        return "none"
    family = (
        "stop"
        if behaviour == "stop"
        else "forward"
        if behaviour.startswith("goforward")
        else "other"
    )
    return "correct" if family == CORRECT[stimulus] else "wrong"


def plot(path: Path, per: dict[str, dict[str, dict[str, int]]], seeds: int) -> None:
    """Seeds answering each colour stimulus correctly, wrongly or not at all, per condition."""
    from server.reports.plots import save, subplots

    conditions = list(per)
    fig, axes = subplots(len(conditions), figsize=(3.2 * len(conditions), 3.2), sharey=True)
    shades = {"correct": "#2a9d8f", "wrong": "#e76f51", "none": "#cccccc"}
    for ax, c in zip(axes[0], conditions, strict=True):
        bottom = [0] * len(STIMULI)
        for verdict, colour in shades.items():
            counts = [per[c][st][verdict] for st in STIMULI]
            ax.bar(STIMULI, counts, bottom=bottom, color=colour, label=verdict)
            bottom = [b + n for b, n in zip(bottom, counts, strict=True)]
        ax.set_title(c)
        ax.set_ylim(0, seeds)
    axes[0][0].set_ylabel("seeds")
    axes[0][-1].legend(loc="lower right", fontsize=8)
    fig.suptitle("The camera's colour stimuli after training, judged by the signal's rule")
    save(fig, path)


def main(argv: list[str] | None = None) -> int:
    """Train, read the answers, write answers.md and answers.json."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--conditions", default="kp-signal,beacon,rp")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    conditions = args.conditions.split(",")
    jobs = [(c, s, args.episodes) for c in conditions for s in range(args.seeds)]
    with ProcessPoolExecutor(args.jobs) as pool:
        results = list(pool.map(answers, *zip(*jobs, strict=True)))
    with ProcessPoolExecutor(args.jobs) as pool:
        taught = list(pool.map(copies, range(args.seeds), [args.episodes] * args.seeds))
    report = copy_report(taught, RULE)
    per: dict[str, dict[str, dict[str, int]]] = {}
    sources: dict[str, dict[str, dict[str, int]]] = {}
    for (c, _, _), got in zip(jobs, results, strict=True):
        for st, (b, src) in got.items():
            verdict = judge(st, b)
            cell = per.setdefault(c, {}).setdefault(st, {"correct": 0, "wrong": 0, "none": 0})
            cell[verdict] += 1
            if b is not None:
                by = sources.setdefault(c, {}).setdefault(st, {})
                by[f"{b} ({src})"] = by.get(f"{b} ({src})", 0) + 1
    command = "python " + " ".join(
        shlex.quote(a) for a in ["scripts/signal_answers.py", *sys.argv[1:]]
    )
    lines = [
        "# What the camera's colour stimuli answer after training",
        "",
        f"`{command}`",
        "",
        f"World `stop-line`, signal learned, {args.seeds} seeds x {args.episodes} episodes per "
        "condition with its tuned parameters (the experiment's training runs). Each colour "
        "stimulus's answer, perceived alone, judged by the signal's rule (red and yellow: stop; "
        "green: a forward primitive): seeds answering correctly / wrongly / not at all, and "
        "what was answered (the pair's source).",
        "",
        "| condition | stimulus | correct | wrong | none | answers (seeds) |",
        "|---|---|---|---|---|---|",
    ]
    for c in conditions:
        for st in STIMULI:
            cell = per[c][st]
            seen = ", ".join(f"{k}: {v}" for k, v in sorted(sources.get(c, {}).get(st, {}).items()))
            lines.append(
                f"| {c} | {st} | {cell['correct']} | {cell['wrong']} | {cell['none']} | {seen} |"
            )
    c, cr = report.correct, report.correct_rewarded
    lines += [
        "",
        "## What the beacon's reflexes would teach",
        "",
        "Before any learner: `beacon-reflexes` (no learning) with KP recording and never "
        "learning; at each episode's end each colour stimulus's RSTM is reasoned over as KP "
        "would on a reward. Share of each seed's copies that the signal's rule judges "
        f"correct, mean over seeds: {c.mean:.0%} [{c.low:.0%}, {c.high:.0%}]; over the copies "
        f"of successful episodes (the only ones KP propagates): {cr.mean:.0%} "
        f"[{cr.low:.0%}, {cr.high:.0%}].",
        "",
        "| stimulus | copies | correct | of successful episodes | correct | behaviours copied |",
        "|---|---|---|---|---|---|",
    ]
    for st, (n, ok, nr, okr, bs) in report.by_stimulus.items():
        copied = ", ".join(f"{b}: {k}" for b, k in bs.items())
        lines.append(f"| {st} | {n} | {ok} | {nr} | {okr} | {copied} |")
    args.out.mkdir(parents=True, exist_ok=True)
    lines += ["", "![Seeds answering each colour stimulus correctly](answers.png)"]
    plot(args.out / "answers.png", per, args.seeds)
    (args.out / "answers.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (args.out / "answers.json").write_text(
        json.dumps(
            {"command": command, "judged": per, "answers": sources, "copies": report.as_dict()},
            indent=1,
        )
        + "\n",
        encoding="utf-8",
    )
    sys.stdout.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
