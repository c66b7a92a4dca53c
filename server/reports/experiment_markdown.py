"""The experiment's summary.md: each section's table, and the document under its title."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from core.brain.catalog import Catalog
from core.lab.analysis import CRITERION_RATE, CRITERION_WINDOW, HELD_OUT, HORIZONS, paired_table
from core.lab.experiment import CAMERA_SENSOR, TaskResult
from core.lab.stats import p_text, wilson
from core.sim.worlds import load_world
from server.reports.base import diff, failed_lines, head, interval_line, row
from server.reports.paper import PAPER_TABLE_II, PAPER_TABLE_III


def camera_names(catalog: Catalog) -> list[str]:
    """The camera's stimuli, in catalogue order."""
    return [s.name for s in catalog.stimuli if s.sensor == CAMERA_SENSOR]


def _origin_table(summary: dict[str, Any]) -> list[str]:
    """Rows of the what-ran table: each condition's ticks by origin, as shares."""
    origins: list[str] = []
    for s in summary.values():
        for o in s.get("ticks_by_origin", {}):
            if o not in origins:
                origins.append(o)
    if not origins:
        return ["(no condition ran the paper's architecture)"]
    rows = head(["condition", *origins])
    for name, s in summary.items():
        counts = s.get("ticks_by_origin") or {}
        total = sum(counts.values())
        if not total:
            continue
        cells = [f"{counts.get(o, 0) / total:.1%}" if counts.get(o) else "-" for o in origins]
        rows.append(row([name, *cells]))
    return rows


def _ci(stat: dict[str, float] | None, pct: bool = True, digits: int = 0) -> str:
    """A mean with its 95% interval: ``52% [40, 63]`` (or ``0.25 [0.20, 0.31]``)."""
    if not stat:
        return "-"
    mean = stat.get("mean", math.nan)
    if mean is None or math.isnan(mean):
        return "-"
    low, high = stat.get("low", math.nan), stat.get("high", math.nan)
    scale, unit = (100.0, "%") if pct else (1.0, "")
    d = digits if pct else max(digits, 2)
    head = f"{scale * mean:.{d}f}{unit}"
    if low is None or high is None or math.isnan(low) or math.isnan(high):
        return head
    return f"{head} [{scale * low:.{d}f}, {scale * high:.{d}f}]"


def _points(stat: dict[str, float] | None) -> str:
    """A rate of change in points, with its interval: ``+2.1 [+0.4, +3.9]``."""
    if not stat or stat.get("mean") is None or math.isnan(stat["mean"]):
        return "-"
    low, high = stat.get("low", math.nan), stat.get("high", math.nan)
    head = f"{100 * stat['mean']:+.1f}"
    if low is None or high is None or math.isnan(low) or math.isnan(high):
        return head
    return f"{head} [{100 * low:+.1f}, {100 * high:+.1f}]"


def _setup_line(params: dict[str, Any]) -> str:
    start = {"table1": "Table I", "design": "kp's design"}.get(params.get("start", ""))
    teacher = params.get("teacher")
    return (
        f"World `{params.get('world', '?')}`"
        + (f" with {params['world_settings']}" if params.get("world_settings") else "")
        + f", camera stimuli `{params.get('sensors', '?')}`, "
        f"signal {params.get('signal', 'learned')}"
        + (
            " (its correct responses given to every condition, so success measures the obstacle)."
            if params.get("signal") == "given"
            else " (learned as each condition learns)."
        )
        + (f" Every condition's robot starts from {start} (--start)." if start else "")
        + (
            " rp's teacher: " + ", ".join(f"{k} {v:g}" for k, v in teacher.items()) + "."
            if teacher
            else ""
        )
    )


def _teacher(params: dict[str, Any]) -> str:
    """Whose responses the camera-only test removes: the low-level ones KP learns from."""
    world = params.get("world")
    beacon = bool(world) and load_world(str(world)).config.track.signal.beacon
    return "stop-line beacon's signal" if beacon else "sonar's obstacle"


def _success_lines(summary: dict[str, Any], params: dict[str, Any]) -> list[str]:
    labels = [label for label, _ in HORIZONS]
    present = [
        lab for lab in labels if any(lab in s.get("success_horizons", {}) for s in summary.values())
    ]
    evaluated = any("evaluation" in s for s in summary.values())
    columns = ["condition", *(f"success, {_horizon(lab)}" for lab in present)]
    columns.append("trend / 10 episodes")
    if evaluated:
        columns += ["held-out, frozen", "held-out, camera only"]
    lines = [
        "## Success",
        "",
        "Mean over seeds of each seed's success rate, with its 95% interval. The "
        "trend is the per-seed least-squares slope of success against the episode, in points "
        "per 10 episodes."
        + (
            f" Held-out: after training, what was learned frozen (no exploration, no learning) "
            f"for {params.get('eval_episodes')} episodes on seeds the training never used; "
            f"camera only: the same with the {_teacher(params)} responses removed."
            if evaluated
            else ""
        ),
        "",
        *head(columns),
    ]
    for name, s in summary.items():
        if not s.get("seeds"):
            lines.append(f"| {name} | no successful task |" + " |" * (len(columns) - 2))
            continue
        cells = [_ci(s["success_horizons"].get(lab)) for lab in present]
        cells.append(_points(s.get("trend_per_10")))
        if evaluated:
            ev = s.get("evaluation", {})
            cells += [_ci(ev.get("frozen")), _ci(ev.get("camera_only"))]
        lines.append(row([name, *cells]))
    return [*lines, ""]


def _failure_lines(summary: dict[str, Any]) -> list[str]:
    causes = [
        ("obstacle collisions", "obstacle_collisions_per_episode"),
        ("wall collisions", "wall_collisions_per_episode"),
        ("signal violations", "violations_per_episode"),
        ("timeouts", "timeouts_per_episode"),
    ]
    lines = [
        "## Failures by cause",
        "",
        "Failed episodes per episode, by cause: mean over seeds [95% interval].",
        "",
        *head(["condition", *(c for c, _ in causes)]),
    ]
    for name, s in summary.items():
        if s.get("seeds"):
            lines.append(row([name, *(_ci(s[k], pct=False) for _, k in causes)]))
    return [*lines, ""]


def _horizon(label: str) -> str:
    """A horizon's column title: ``episodes 1-10``, ``all episodes``, ``held-out, frozen``."""
    named = {"all": "all episodes", "held-out": "held-out, frozen",
             "camera only": "held-out, camera only"}  # fmt: skip
    return named.get(label, f"episodes {label}")


def _paired_lines(summary: dict[str, Any]) -> list[str]:
    """Every pair of conditions, paired by seed, per horizon: exploratory."""
    table = paired_table(summary)
    if not table:
        return []
    labels = [label for label, _ in (*HORIZONS, *HELD_OUT)]
    horizons = [label for label in labels if any(label in r for r in table.values())]
    lines = [
        "## Paired by seed (exploratory)",
        "",
        "Every pair of conditions: the first's success minus the second's, seed by seed "
        "(every condition meets the same obstacles and lamp cycles on a seed), in points, "
        "with its 95% interval and the sign-flip test's two-sided p of no difference; the "
        "held-out columns compare the frozen evaluations, which every condition runs on the "
        "same held-out seed per training seed. `kp - sonar` is what propagation adds "
        "(`sonar` is kp without it). These are exploratory: the p-values are not corrected "
        "for the many comparisons, so a small one is a lead to test, not a finding; the "
        "findings are the pre-declared comparisons above.",
        "",
        *head(["pair", *(_horizon(h) for h in horizons)]),
    ]
    for pair, diffs in table.items():
        lines.append(row([pair, *(diff(diffs.get(h)) for h in horizons)]))
    return [*lines, ""]


def _correctness_lines(summary: dict[str, Any], params: dict[str, Any]) -> list[str]:
    judged = {n: s["correctness"] for n, s in summary.items() if s.get("correctness")}
    probe = params.get("probe")
    if not judged or not probe:
        return []
    stimuli = list(probe["stimuli"])
    lines = [
        "## What was learned, judged by the placement probe",
        "",
        f"`srlab probe --world {probe['world']} --sensors {probe['sensors']}` placed robot "
        f"and obstacle {probe['k']} times inside each camera stimulus's definition and ran "
        "every behaviour as its response; a response is correct when it gets the robot past "
        f"the obstacle in at least {probe['correct_share']:.0%} of them:",
        "",
        "| stimulus | correct responses |",
        "|---|---|",
    ]
    for stim in stimuli:
        good = probe["stimuli"][stim]["correct"]
        lines.append(f"| {stim.removeprefix('Obstacle_')} | {', '.join(good) or 'none'} |")
    first = next(iter(judged.values()))
    for checkpoint in first["checkpoints"]:
        lines += [
            "",
            f"After episode {checkpoint}: the share of seeds whose learner answers each "
            "stimulus (seen alone) correctly / wrongly / not at all.",
            "",
            *head(["condition", *(s.removeprefix("Obstacle_") for s in stimuli)]),
        ]
        for name, c in judged.items():
            shares = c["checkpoints"].get(checkpoint)
            if shares is None:
                continue
            cells = [
                f"{shares[s]['correct']:.0%} / {shares[s]['wrong']:.0%} / {shares[s]['none']:.0%}"
                for s in stimuli
            ]
            lines.append(row([name, *cells]))
    lines += [
        "",
        "The knowledge criterion: the first episode after which a seed's answer to the "
        "stimulus is correct and stays correct to the end; median over the seeds that get "
        "there, and how many do (of all seeds).",
        "",
        *head(["condition", *(s.removeprefix("Obstacle_") for s in stimuli)]),
    ]
    for name, c in judged.items():
        cells = []
        for s in stimuli:
            per_seed = c["criterion"][s]["per_seed"]
            got = sorted(x for x in per_seed if x is not None)
            cells.append(
                f"{np.median(got):.0f} ({len(got)}/{len(per_seed)})"
                if got
                else f"- (0/{len(per_seed)})"
            )
        lines.append(row([name, *cells]))
    return [*lines, ""]


def _criterion_lines(summary: dict[str, Any]) -> list[str]:
    lines = [
        "## Episodes to the success criterion (secondary)",
        "",
        f"The first episode after which at least {CRITERION_RATE:.0%} of the last "
        f"{CRITERION_WINDOW} episodes succeeded, beside what a process that learns nothing "
        "scores on it: independent episodes at each seed's own success rate (the null's "
        "median, and the share of its runs that reach the criterion at all). A criterion "
        "reached no sooner than its null says nothing about learning.",
        "",
        "| condition | median (reached/never) | null: median, share reaching it |",
        "|---|---|---|",
    ]
    for name, s in summary.items():
        if not s.get("seeds"):
            continue
        crit = s["episodes_to_criterion"]
        median = "-" if crit["median"] is None else f"{crit['median']:.0f}"
        null = crit.get("null", {})
        nmed = "-" if null.get("median") is None else f"{null['median']:.0f}"
        share = null.get("reached_share", math.nan)
        lines.append(
            f"| {name} | {median} ({crit['reached']}/{crit['never']}) | {nmed}, {share:.0%} |"
        )
    return [*lines, ""]


def _table3_lines(summary: dict[str, Any], catalog: Catalog, params: dict[str, Any]) -> list[str]:
    probe = params.get("probe") or {}
    correct = {s: set(v["correct"]) for s, v in probe.get("stimuli", {}).items()}

    def mark(stim: str, behaviour: str) -> str:
        if stim not in correct:
            return ""
        return " (correct)" if behaviour in correct[stim] else " (wrong)"

    lines = [
        "### Table III: the strongest response to each of the paper's stimuli",
        "",
        "Behaviour and reliability of the strongest pair per stimulus, the paper's after 50 "
        "episodes and srlab's (mean over seeds; DP's programmed pairs count as 1, as in the "
        "paper); srlab's marked correct or wrong by the placement probe.",
        "",
        "| stimulus | paper DP | srlab DP | paper RP | srlab RP | paper KP | srlab KP |",
        "|---|---|---|---|---|---|---|",
    ]
    for stim, paper in PAPER_TABLE_III.items():
        cells = []
        for cname in ("dp", "rp", "kp"):
            paper_best = max(((v.get(cname, 0.0), b) for b, v in paper.items()), default=(0.0, ""))
            cells.append(f"{paper_best[1]} {paper_best[0]:.2f}" if paper_best[0] > 0 else "-")
            cond = summary.get(cname, {})
            rel = cond.get("camera_reliability", {}) if cond.get("seeds") else {}
            mine = [(v["mean"], k.split("/", 1)[1]) for k, v in rel.items() if k.startswith(stim)]
            top = max(mine, default=(0.0, ""))
            cells.append(f"{top[1]} {top[0]:.2f}{mark(stim, top[1])}" if top[0] >= 0.005 else "-")
        lines.append(row([stim.removeprefix("Obstacle_"), *cells]))
    if params.get("sensors") == "paper":
        note = (
            "These are the paper's own stimuli (Fig. 10: robot lane x the third of the "
            "camera's view the obstacle appears in), so the table compares cell by cell."
        )
    else:
        note = (
            'The paper\'s stimuli are "position x vision" (`--sensors paper`); these are '
            "srlab's path stimuli, robot lane x the obstacle's side of the corridor, active "
            "only while the obstacle is in the robot's path, so a pair like M-R (obstacle in "
            "the path, right of the centre line) needs a turn where the paper's robot could "
            "go straight. Compare the shape (which condition learns which response, how "
            "reliably) rather than cell by cell."
        )
    return [*lines, "", note]


def _reliability_lines(
    summary: dict[str, Any], catalog: Catalog, params: dict[str, Any]
) -> list[str]:
    learned = [n for n, s in summary.items() if s.get("seeds") and s.get("learns_camera")]
    lines = [
        "## Reliability of the camera obstacle S-R pairs (Table III)",
        "",
        "Mean reliability over seeds [95% interval] of every camera obstacle pair "
        "that reached 0.01 in some condition: LTM for delayed, DP and RP, RLTM for KP; DP's "
        "programmed pairs count as 1, as in the paper. Reliability is Eq. (1)'s V, not "
        "correctness: KP's RLTM credits each success at d_k = 1, LTM at d_k of hundreds of "
        "ticks, by construction. Stimulus names are robot lane _ "
        + ("the third of the view." if params.get("sensors") == "paper" else "obstacle side."),
        "",
    ]
    keys = sorted(
        {
            k
            for n in learned
            for k, v in summary[n]["camera_reliability"].items()
            if v["mean"] >= 0.01
        },
        key=lambda k: (camera_names(catalog).index(k.split("/")[0]), k),
    )
    if learned:
        lines += head(["stimulus", "behaviour", *learned])
        for k in keys:
            stim, beh = k.split("/", 1)
            cells = [
                _ci(summary[n]["camera_reliability"].get(k, {"mean": 0.0}), pct=False)
                for n in learned
            ]
            lines.append(row([stim.removeprefix("Obstacle_"), beh, *cells]))
    return [*lines, ""]


def _met_lines(summary: dict[str, Any], catalog: Catalog) -> list[str]:
    met = [(n, s["camera_stimuli_met"]) for n, s in summary.items() if s.get("camera_stimuli_met")]
    if not met:
        return []
    lines = [
        "## Camera obstacle stimuli met",
        "",
        "Encounters per seed (times the stimulus became active) over the whole run, mean "
        "over seeds, and in brackets the success rate of the episodes it was met in, all "
        "seeds together: a pair can only be learned for a stimulus the robot meets, and "
        "from a delayed reward only where the lap succeeds. (`-`: not recorded for the "
        "learners that run through the Gymnasium environment.)",
        "",
        *head(["stimulus", *(n for n, _ in met)]),
    ]
    for stim in camera_names(catalog):
        cells = [_met_cell(m[stim]) if stim in m else "0" for _, m in met]
        lines.append(row([stim.removeprefix("Obstacle_"), *cells]))
    return [*lines, ""]


def _met_cell(m: dict[str, float]) -> str:
    rate = m["success_when_met"]
    won = "-" if rate is None or math.isnan(rate) else f"{rate:.0%}"
    return f"{m['encounters_per_seed']:.1f} ({won})"


def _table2_lines(summary: dict[str, Any], params: dict[str, Any]) -> list[str]:
    """The paper's Table II beside srlab's innate condition, each rate with its interval."""
    lines = [
        "### Table II (innate knowledge only)",
        "",
        "The paper's counts with their 95% Wilson interval (one run of episodes); srlab's "
        "rate is the mean over seeds of each seed's rate, with its interval over seeds"
        + (
            ", the signal not given, as in the paper."
            if params.get("signal") != "given"
            else "; here the signal's responses are given, so it is not the paper's setting."
        ),
        "",
        "| | successes | episodes | rate [95% CI] |",
        "|---|---|---|---|",
    ]
    for where, (won, played) in PAPER_TABLE_II.items():
        low, high = wilson(won, played)
        rate = f"{won / played:.1%} [{100 * low:.1f}, {100 * high:.1f}]"
        lines.append(f"| paper, {where} | {won} | {played} | {rate} |")
    s = summary.get("innate", {})
    if s.get("seeds"):
        total = s["seeds"] * s["episodes"]
        ok = round(s["success_rate"]["mean"] * total)
        who = f"srlab, {s['seeds']} seeds x {s['episodes']} episodes"
        lines.append(f"| {who} | {ok} | {total} | {_ci(s['success_rate'], digits=1)} |")
    return [*lines, ""]


def _declared_lines(declared: Sequence[dict[str, Any]], params: dict[str, Any]) -> list[str]:
    """The pre-declared comparisons with their raw and Holm-adjusted p."""
    if not declared:
        return []
    named = params.get("declared")
    how = (
        "named in the command (`--declare`)"
        if params.get("declared_given")
        else "srlab's default declaration (`--declare`: kp against sonar, rp, qlambda-hybrid "
        "and dp, those that ran)"
    )
    lines = [
        "## Pre-declared comparisons (Holm-corrected)",
        "",
        f"The comparisons this experiment's conclusions rest on, {how}"
        + (f": {', '.join(f'{a} - {b}' for a, b in named)}" if named else "")
        + ". Each is tested on all training episodes and held out (frozen), "
        f"{len(declared)} tests in one family; Holm's step-down correction keeps the chance "
        "of any false finding among them below 5%. A difference holds where its Holm p is "
        "below 0.05. Every other comparison in this summary is exploratory.",
        "",
        *head(["comparison", "on", "difference, points [95% CI]", "p", "Holm p", "holds"]),
    ]
    for d in declared:
        lines.append(
            row(
                [
                    d["pair"],
                    _horizon(d["on"]),
                    _points(d),
                    p_text(d["p"]).removeprefix("p "),
                    p_text(d["p_holm"]).removeprefix("p "),
                    "yes" if d["p_holm"] < 0.05 else "no",
                ]
            )
        )
    return [*lines, ""]


def summary_markdown(
    summary: dict[str, Any],
    catalog: Catalog,
    params: dict[str, Any],
    failed: Sequence[TaskResult],
    declared: Sequence[dict[str, Any]] = (),
    title: str = "srlab experiment",
) -> str:
    """The experiment's summary as readable tables, under `title`.

    `declared` holds the pre-declared comparisons (`core.lab.analysis.declared_comparisons`).
    """
    lines = [
        f"# {title}",
        "",
        f"`{params['command']}`",
        "",
        f"{params['seeds']} seeds x {params['episodes']} episodes per condition; "
        f"{params['ticks']:,} ticks in {params['elapsed_s']:.1f} s.",
        "",
        interval_line(),
        "",
        _setup_line(params),
        "",
        *_success_lines(summary, params),
        *_failure_lines(summary),
        *_declared_lines(declared, params),
        *_paired_lines(summary),
        *_correctness_lines(summary, params),
        "## What ran",
        "",
        "Share of all ticks by what made the behaviour run: the source of the association "
        "that released it (innate, designed, dp, learned, kp, expert), exploration, the "
        "keep-moving default, or an external learner's command. A learned or propagated "
        "pair that never runs has taught the robot nothing.",
        "",
        *_origin_table(summary),
        "",
        *_reliability_lines(summary, catalog, params),
        "## Side by side with the paper",
        "",
        *_table2_lines(summary, params),
        *_table3_lines(summary, catalog, params),
        "",
    ]
    lines += _criterion_lines(summary)
    lines += _met_lines(summary, catalog)
    if failed:
        lines += failed_lines(failed)
    return "\n".join(lines).rstrip() + "\n"
