"""Experiment outputs: summary.json, summary.md, runs.jsonl and the plots."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from core.brain.catalog import Catalog
from core.experiment import CAMERA_SENSOR, TaskResult, paired_against, t_quantile_975

# The paper's Table II and the non-zero cells of its Table III (reliability of LTM after
# 50 episodic trials), keyed by our stimulus and behaviour names.
PAPER_TABLE_II = {"simulation": (5, 250), "robot": (2, 100)}
PAPER_TABLE_III: dict[str, dict[str, dict[str, float]]] = {
    "Obstacle_M_M": {
        "rightturn15": {"dp": 1.0, "rp": 0.13, "kp": 0.27},
        "leftturn30": {"rp": 0.12},
    },
    "Obstacle_M_R": {
        "goforward1": {"rp": 0.13},
        "goforward2": {"rp": 0.17},
        "goforward3": {"dp": 1.0, "rp": 0.19, "kp": 0.73},
        "goforward4": {"rp": 0.33},
        "goforward5": {"rp": 0.13},
    },
    "Obstacle_R_L": {
        "leftturn45": {"dp": 0.08, "rp": 0.1},
        "leftturn30": {"dp": 0.29, "rp": 0.42, "kp": 0.67},
    },
    "Obstacle_R_M": {
        "leftturn45": {"dp": 0.12, "rp": 0.14},
        "leftturn30": {"dp": 0.17, "rp": 0.36, "kp": 0.48},
    },
    "Obstacle_R_R": {"leftturn30": {"dp": 0.04, "rp": 0.23, "kp": 0.33}},
}


def _fmt(stat: dict[str, float], pct: bool = False, digits: int = 2) -> str:
    mean, ci = stat.get("mean", math.nan), stat.get("ci95", math.nan)
    if math.isnan(mean):
        return "-"
    if pct:
        return f"{mean:.0%} ± {ci:.0%}" if not math.isnan(ci) else f"{mean:.0%}"
    return f"{mean:.{digits}f} ± {ci:.{digits}f}" if not math.isnan(ci) else f"{mean:.{digits}f}"


def write_runs(path: Path, results: Sequence[TaskResult]) -> None:
    """Every episode of every task, one JSON object a line."""
    with path.open("w", encoding="utf-8") as f:
        for r in results:
            for e in r.episodes:
                f.write(
                    json.dumps(
                        {
                            "condition": r.task.condition,
                            "seed": r.task.seed,
                            "episode": e.episode,
                            "outcome": e.outcome.value,
                            "cause": e.cause.value if e.cause else None,
                            "ticks": e.ticks,
                            "rewards": e.rewards,
                        }
                    )
                    + "\n"
                )


ROLLING = 5


def plot_learning_curves(path: Path, summary: dict[str, Any]) -> None:
    """Success rate per episode (rolling mean over 5 episodes) over seeds, with a 95% CI band."""
    fig, ax = plt.subplots(figsize=(9, 5), dpi=110)
    for name, s in summary.items():
        if not s.get("seeds"):
            continue
        runs = np.asarray(s["success_by_seed"], dtype=float)
        kernel = np.ones(ROLLING)
        counts = np.convolve(np.ones(runs.shape[1]), kernel)[: runs.shape[1]]
        rolled = np.array([np.convolve(r, kernel)[: len(r)] / counts for r in runs])
        y = rolled.mean(axis=0)
        n = len(rolled)
        ci = (
            t_quantile_975(n - 1) * rolled.std(axis=0, ddof=1) / math.sqrt(n)
            if n > 1
            else np.zeros_like(y)
        )
        x = np.arange(1, len(y) + 1)
        (line,) = ax.plot(x, y, label=f"{name} (n={n})", linewidth=1.8)
        ax.fill_between(
            x, np.clip(y - ci, 0, 1), np.clip(y + ci, 0, 1), color=line.get_color(), alpha=0.15
        )
    ax.set_xlabel("episode")
    ax.set_ylabel(f"success rate (rolling {ROLLING} episodes)")
    ax.set_ylim(-0.02, 1.02)
    ax.axhline(0.8, color="grey", linestyle=":", linewidth=1)
    ax.set_title("Learning curves: mean over seeds, band = 95% CI")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _camera_names(catalog: Catalog) -> list[str]:
    return [s.name for s in catalog.stimuli if s.sensor == CAMERA_SENSOR]


def plot_reliability(path: Path, summary: dict[str, Any], catalog: Catalog) -> None:
    """Heatmaps like Table III: behaviours x camera obstacle stimuli, one per condition."""
    learned = [n for n, s in summary.items() if s.get("seeds") and s.get("learns_camera")]
    stimuli = _camera_names(catalog)
    behaviours = [b.name for b in catalog.behaviours]
    extra = sorted(
        {
            k.split("/", 1)[1]
            for n in learned
            for k in summary[n]["camera_reliability"]
            if k.split("/", 1)[1] not in behaviours
        }
    )
    behaviours += extra
    cols = max(1, len(learned))
    fig, axes = plt.subplots(
        1, cols, figsize=(2.6 * cols + 2.5, 7.5), dpi=110, squeeze=False, sharey=True
    )
    for ax, name in zip(axes[0], learned, strict=False):
        rel = summary[name]["camera_reliability"]
        grid = np.array(
            [[rel.get(f"{s}/{b}", {}).get("mean", 0.0) for s in stimuli] for b in behaviours]
        )
        im = ax.imshow(grid, vmin=0, vmax=1, cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(stimuli)), [s.removeprefix("Obstacle_") for s in stimuli])
        ax.tick_params(axis="x", labelrotation=90, labelsize=7)
        ax.set_title(f"{name} ({summary[name]['camera_memory'].upper()})", fontsize=9)
        for i, j in zip(*np.nonzero(grid >= 0.05), strict=True):
            ax.text(j, i, f"{grid[i, j]:.2f}", ha="center", va="center", fontsize=5, color="w")
    axes[0][0].set_yticks(range(len(behaviours)), behaviours, fontsize=7)
    if learned:
        fig.colorbar(im, ax=axes[0].tolist(), shrink=0.6, label="reliability (mean over seeds)")
    meaning = "where in the view" if catalog.definition == "paper" else "obstacle side"
    fig.suptitle(f"Reliability of camera obstacle S-R pairs (robot lane _ {meaning})")
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def _paired_lines(summary: dict[str, Any]) -> list[str]:
    """The paired-by-seed comparison with kp, when kp ran."""
    reference = "kp"
    if not summary.get(reference, {}).get("seeds"):
        return []
    horizons = [("episodes 1-10", 10), ("all episodes", None)]
    diffs = {label: paired_against(summary, reference, h) for label, h in horizons}
    names = [n for n in summary if n in diffs["all episodes"]]
    if not names:
        return []
    lines = [
        "## Paired by seed, against kp",
        "",
        "Each condition's success minus kp's, seed by seed (every condition meets the same "
        "obstacles and lamp cycles on a seed): the mean difference in points, its 95% "
        "bootstrap interval, and the sign-flip test's two-sided p of no difference. "
        "`sonar` is kp with propagation off, so kp's row against it is what propagation adds.",
        "",
        "| condition - kp | " + " | ".join(label for label, _ in horizons) + " |",
        "|---|" + "---|" * len(horizons),
    ]
    for n in names:
        cells = []
        for label, _ in horizons:
            d = diffs[label].get(n)
            cells.append(
                "-"
                if d is None
                else f"{100 * d['mean']:+.1f} [{100 * d['low']:+.1f}, {100 * d['high']:+.1f}],"
                f" p {d['p']:.3f}"
            )
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def _origin_table(summary: dict[str, Any]) -> list[str]:
    """Rows of the what-ran table: each condition's ticks by origin, as shares."""
    origins: list[str] = []
    for s in summary.values():
        for o in s.get("ticks_by_origin", {}):
            if o not in origins:
                origins.append(o)
    if not origins:
        return ["(no condition ran the paper's architecture)"]
    rows = ["| condition | " + " | ".join(origins) + " |", "|---|" + "---|" * len(origins)]
    for name, s in summary.items():
        counts = s.get("ticks_by_origin") or {}
        total = sum(counts.values())
        if not total:
            continue
        cells = [f"{counts.get(o, 0) / total:.1%}" if counts.get(o) else "-" for o in origins]
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return rows


def summary_markdown(
    summary: dict[str, Any],
    catalog: Catalog,
    params: dict[str, Any],
    failed: Sequence[TaskResult],
) -> str:
    """The experiment's summary as readable tables."""
    lines = [
        "# srlab experiment",
        "",
        f"`{params['command']}`",
        "",
        f"{params['seeds']} seeds x {params['episodes']} episodes per condition; "
        f"{params['ticks']:,} ticks in {params['elapsed_s']:.1f} s.",
        "",
        f"World `{params.get('world', '?')}`, camera stimuli `{params.get('sensors', '?')}`, "
        f"signal {params.get('signal', 'learned')}"
        + (
            " (its correct responses given to every condition, so success measures the obstacle)."
            if params.get("signal") == "given"
            else " (learned as each condition learns)."
        ),
        "",
        "## Results",
        "",
        "| condition | success, all episodes | success, last 10 | episodes to criterion "
        "(median; reached/never) | collisions / episode | violations / episode |",
        "|---|---|---|---|---|---|",
    ]
    for name, s in summary.items():
        if not s.get("seeds"):
            lines.append(f"| {name} | no successful task | | | | |")
            continue
        crit = s["episodes_to_criterion"]
        median = "-" if crit["median"] is None else f"{crit['median']:.0f}"
        lines.append(
            f"| {name} | {_fmt(s['success_rate'], pct=True)} | "
            f"{_fmt(s['success_last10'], pct=True)} | {median} ({crit['reached']}/"
            f"{crit['never']}) | {_fmt(s['collisions_per_episode'])} | "
            f"{_fmt(s['violations_per_episode'])} |"
        )
    lines += [
        "",
        "Episodes to criterion: the first episode after which the success rate over the "
        "last 10 episodes is at least 80%. The ± figures are 95% confidence intervals over "
        "seeds (Student's t).",
        "",
        *_paired_lines(summary),
        "## What ran",
        "",
        "Share of all ticks by what made the behaviour run: the source of the association "
        "that released it (innate, designed, dp, learned, kp, expert), exploration, the "
        "keep-moving default, or an external learner's command. A learned or propagated "
        "pair that never runs has taught the robot nothing.",
        "",
        *_origin_table(summary),
        "",
        "## Reliability of the camera obstacle S-R pairs (Table III)",
        "",
        "Mean reliability over seeds (± 95% CI) of every camera obstacle pair that reached "
        "0.01 in some condition: LTM for delayed, DP and RP, RLTM for KP; DP's programmed "
        "pairs count as 1, as in the paper. Stimulus names are robot lane _ "
        + ("the third of the view." if params.get("sensors") == "paper" else "obstacle side."),
        "",
    ]
    learned = [n for n, s in summary.items() if s.get("seeds") and s.get("learns_camera")]
    keys = sorted(
        {
            k
            for n in learned
            for k, v in summary[n]["camera_reliability"].items()
            if v["mean"] >= 0.01
        },
        key=lambda k: (_camera_names(catalog).index(k.split("/")[0]), k),
    )
    if learned:
        lines.append("| stimulus | behaviour | " + " | ".join(learned) + " |")
        lines.append("|---|---|" + "---|" * len(learned))
        for k in keys:
            stim, beh = k.split("/", 1)
            cells = [
                _fmt(summary[n]["camera_reliability"].get(k, {"mean": 0.0, "ci95": 0.0}))
                for n in learned
            ]
            lines.append(
                f"| {stim.removeprefix('Obstacle_')} | {beh} | " + " | ".join(cells) + " |"
            )
    lines += ["", "## Side by side with the paper", "", "### Table II (innate knowledge only)", ""]
    lines.append("| | successes | episodes | rate |")
    lines.append("|---|---|---|---|")
    for where, (won, played) in PAPER_TABLE_II.items():
        lines.append(f"| paper, {where} | {won} | {played} | {won / played:.0%} |")
    if summary.get("innate", {}).get("seeds"):
        s = summary["innate"]
        total = s["seeds"] * s["episodes"]
        ok = round(s["success_rate"]["mean"] * total)
        lines.append(f"| srlab | {ok} | {total} | {ok / total:.0%} |")
    lines += [
        "",
        "### Table III: the strongest response to each of the paper's stimuli",
        "",
        "Behaviour and reliability of the strongest pair per stimulus, the paper's after 50 "
        "episodes and srlab's (mean over seeds; DP's programmed pairs count as 1, as in the "
        "paper).",
        "",
        "| stimulus | paper DP | srlab DP | paper RP | srlab RP | paper KP | srlab KP |",
        "|---|---|---|---|---|---|---|",
    ]
    for stim, row in PAPER_TABLE_III.items():
        cells = []
        for cname in ("dp", "rp", "kp"):
            paper_best = max(((v.get(cname, 0.0), b) for b, v in row.items()), default=(0.0, ""))
            cells.append(f"{paper_best[1]} {paper_best[0]:.2f}" if paper_best[0] > 0 else "-")
            cond = summary.get(cname, {})
            rel = cond.get("camera_reliability", {}) if cond.get("seeds") else {}
            mine = [(v["mean"], k.split("/", 1)[1]) for k, v in rel.items() if k.startswith(stim)]
            top = max(mine, default=(0.0, ""))
            cells.append(f"{top[1]} {top[0]:.2f}" if top[0] >= 0.005 else "-")
        lines.append(f"| {stim.removeprefix('Obstacle_')} | " + " | ".join(cells) + " |")
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
    lines += ["", note]
    met = [(n, s["camera_stimuli_met"]) for n, s in summary.items() if s.get("camera_stimuli_met")]
    if met:
        lines += [
            "",
            "## Camera obstacle stimuli met",
            "",
            "Encounters per seed (times the stimulus became active) over the whole run, mean "
            "over seeds, and in brackets the success rate of the episodes it was met in, all "
            "seeds together: a pair can only be learned for a stimulus the robot meets, and "
            "from a delayed reward only where the lap succeeds.",
            "",
            "| stimulus | " + " | ".join(n for n, _ in met) + " |",
            "|---|" + "---|" * len(met),
        ]
        for stim in _camera_names(catalog):
            cells = [
                f"{m[stim]['encounters_per_seed']:.1f} ({m[stim]['success_when_met']:.0%})"
                if stim in m
                else "0"
                for _, m in met
            ]
            lines.append(f"| {stim.removeprefix('Obstacle_')} | " + " | ".join(cells) + " |")
    if failed:
        lines += ["", "## Failed tasks", ""]
        for r in failed:
            first = (r.error or "").splitlines()[0]
            lines.append(f"- {r.task.condition} seed {r.task.seed}: {first}")
    return "\n".join(lines) + "\n"


def write_report(
    out: Path,
    results: Sequence[TaskResult],
    summary: dict[str, Any],
    catalog: Catalog,
    params: dict[str, Any],
) -> list[Path]:
    """Write every output file into `out`; returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    failed = [r for r in results if not r.ok]
    paths = [out / n for n in ("summary.json", "summary.md", "runs.jsonl")]
    doc = {
        "params": params,
        "conditions": {
            n: {
                k: v
                for k, v in s.items()
                if k not in ("success_curve_ci95", "success_by_seed", "seed_ids")
            }
            for n, s in summary.items()
        },
        "failed": [
            {"condition": r.task.condition, "seed": r.task.seed, "error": r.error} for r in failed
        ],
    }
    paths[0].write_text(json.dumps(clean_json(doc), indent=2, allow_nan=False) + "\n")
    paths[1].write_text(summary_markdown(summary, catalog, params, failed))
    write_runs(paths[2], results)
    curves = out / "learning_curves.png"
    plot_learning_curves(curves, summary)
    reliability = out / "reliability.png"
    plot_reliability(reliability, summary, catalog)
    return [*paths, curves, reliability]


def clean_json(value: Any) -> Any:
    """JSON has no NaN: undefined figures (a CI over one seed) become null."""
    if isinstance(value, float) and math.isnan(value):
        return None
    if isinstance(value, dict):
        return {k: clean_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [clean_json(v) for v in value]
    return value


def world_check_markdown(report: dict[str, Any]) -> str:
    """`srlab world-check --out`'s tables: each property's success with its interval."""
    lines = [
        "# srlab world-check",
        "",
        f"`{report.get('command', 'srlab world-check')}`",
        "",
        f"{report['seeds']} seeds (from {report['seed_base']}) x {report['episodes']} episodes "
        "per property, no learning anywhere; success is the mean over seeds with its 95% "
        "bootstrap interval.",
    ]
    described: set[str] = set()
    for check in report["checks"]:
        lines += [
            "",
            f"## World `{check['world']}`, camera stimuli `{check['sensors']}`: "
            + ("every property holds" if check["holds"] else "not every property holds"),
            "",
        ]
        if check["world"] not in described:
            described.add(check["world"])
            lines += [check["reasons"].replace("\n", " "), ""]
        lines += [
            "| | property | condition | success [95% CI] | bounds | holds |",
            "|---|---|---|---|---|---|",
        ]
        for p in check["properties"]:
            s = p["success"]
            ci = "" if s["low"] != s["low"] else f" [{100 * s['low']:.0f}, {100 * s['high']:.0f}]"
            lines.append(
                f"| ({p['key']}) | {p['label']} | {p['condition']}"
                f"{' + signal' if p['signal'] == 'given' else ''} | {100 * s['mean']:.0f}%{ci} | "
                f"{100 * p['bounds'][0]:.0f}-{100 * p['bounds'][1]:.0f}% | "
                f"{'yes' if p['holds'] else '**no**'} |"
            )
    return "\n".join(lines) + "\n"
