"""An outside world's properties and its kp-minus-ablation comparison, over seeds.

Both go through srlab's statistics (`core.lab.stats`): a mean over seeds with Student's t
interval, differences paired by seed (every condition meets the same scenes on a seed) with
a sign-flip p, and the declared comparisons corrected together with Holm.

Properties (`check`), of the world alone, no learning anywhere (`OutsideWorld.reasons` says
why each should hold, written before any learner ran):

1. ``reflex - innate`` > 0: the low-level reflex alone does better than nothing;
2. the reflex's onsets the high-level sensor saw coming, and how many ticks earlier;
3. ``copy - reflex`` >= 0: what KP would copy (the high-level stimuli answered as the reflex
   answers) is mostly right: it does not do worse than the reflex alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from core.lab.stats import Estimate, holm, mean_interval, paired_difference, pct
from core.outside.run import Episode, SeedRun, run_seed
from core.outside.world import OutsideWorld, load_outside

DECLARED_ON = ("all", "held-out")
"""Each declared comparison is tested on all training episodes and held out, frozen."""
PROPERTY_CONDITIONS = ("innate", "reflex", "copy")


@cache
def _world(where: str) -> OutsideWorld:
    return load_outside(Path(where))


def _run(job: tuple[str, str, int, int | None, int | None]) -> SeedRun:
    where, condition, seed, episodes, held_out = job
    world = _world(where)
    return run_seed(world, world.condition(condition), seed, episodes, held_out)


def run_all(
    world: OutsideWorld,
    conditions: Sequence[str],
    seeds: Sequence[int],
    episodes: int | None = None,
    held_out: int | None = None,
    jobs: int = 1,
    on_result: Callable[[SeedRun], None] | None = None,
) -> dict[str, list[SeedRun]]:
    """Every condition on every seed, in `jobs` processes; runs by condition, seed order."""
    for c in conditions:
        world.condition(c)  # an unknown name fails here, naming the known ones
    work = [(str(world.folder), c, s, episodes, held_out) for c in conditions for s in seeds]
    out: dict[str, list[SeedRun]] = {c: [] for c in conditions}
    if jobs <= 1:
        results = map(_run, work)
        for r in results:
            out[r.condition].append(r)
            if on_result is not None:
                on_result(r)
    else:
        with ProcessPoolExecutor(jobs) as pool:
            for r in pool.map(_run, work):
                out[r.condition].append(r)
                if on_result is not None:
                    on_result(r)
    return out


def per_seed(runs: Sequence[SeedRun], measure: str, held_out: bool = False) -> list[float]:
    """Each seed's mean of `measure` (success or return) over its episodes."""
    out = []
    for r in runs:
        eps: Sequence[Episode] = r.held_out if held_out else r.episodes
        values = [float(e.success) if measure == "success" else e.ret for e in eps]
        out.append(float(np.mean(values)) if values else math.nan)
    return out


def _estimate(values: Sequence[float]) -> dict[str, float | int]:
    return mean_interval(list(values)).as_dict()


def condition_summary(runs: Sequence[SeedRun]) -> dict[str, Any]:
    """A condition's figures over seeds: success and return, trained and held out."""
    origins: dict[str, int] = {}
    answers: dict[str, dict[str, int]] = {}
    for r in runs:
        for k, v in r.origins.items():
            origins[k] = origins.get(k, 0) + v
        for s, b in r.answers.items():
            answers.setdefault(s, {})
            answers[s][b or "none"] = answers[s].get(b or "none", 0) + 1
    outcomes: dict[str, float] = {}
    for r in runs:
        for e in r.episodes:
            outcomes[e.outcome] = outcomes.get(e.outcome, 0.0) + 1.0 / len(r.episodes) / len(runs)
    return {
        "seeds": [r.seed for r in runs],
        "success": _estimate(per_seed(runs, "success")),
        "return": _estimate(per_seed(runs, "return")),
        "held_out_success": _estimate(per_seed(runs, "success", True)),
        "held_out_return": _estimate(per_seed(runs, "return", True)),
        "outcomes": outcomes,
        "ticks_by_origin": origins,
        "answers": answers,
    }


def declared(
    runs: dict[str, list[SeedRun]], pairs: Sequence[tuple[str, str]], measure: str
) -> list[dict[str, Any]]:
    """The declared comparisons on `measure`, each on `DECLARED_ON`, one family under Holm."""
    rows: list[dict[str, Any]] = []
    for a, b in pairs:
        if [r.seed for r in runs[a]] != [r.seed for r in runs[b]]:
            raise ValueError(f"{a} and {b} did not run on the same seeds")
        for on in DECLARED_ON:
            held = on == "held-out"
            d = paired_difference(
                per_seed(runs[a], measure, held), per_seed(runs[b], measure, held)
            )
            rows.append({"pair": f"{a} - {b}", "on": on, "diff": d.diff.as_dict(), "p": d.p})
    for r, q in zip(rows, holm([r["p"] for r in rows]), strict=True):
        r["p_holm"] = q
    return rows


def _value(e: Estimate, measure: str) -> str:
    if measure == "success":
        return pct(e)
    if math.isnan(e.low):
        return f"{e.mean:+.3f}"
    return f"{e.mean:+.3f} [{e.low:+.3f}, {e.high:+.3f}]"


def check(
    world: OutsideWorld,
    seeds: Sequence[int],
    episodes: int | None = None,
    jobs: int = 1,
    on_result: Callable[[SeedRun], None] | None = None,
) -> dict[str, Any]:
    """Measure the world's properties (the module's docstring) over `seeds`, no learning."""
    runs = run_all(world, PROPERTY_CONDITIONS, seeds, episodes, 1, jobs, on_result)
    m = world.measure
    better = paired_difference(per_seed(runs["reflex"], m), per_seed(runs["innate"], m))
    copy = paired_difference(per_seed(runs["copy"], m), per_seed(runs["reflex"], m))
    seen = [len(r.leads) / r.onsets if r.onsets else math.nan for r in runs["reflex"]]
    leads = [float(np.mean(r.leads)) if r.leads else math.nan for r in runs["reflex"]]
    seen_est = mean_interval([x for x in seen if not math.isnan(x)])
    lead_est = mean_interval([x for x in leads if not math.isnan(x)])
    props = [
        {"key": "1", "label": "the low-level reflex alone does better than nothing",
         "figure": f"reflex - innate {_value(better.diff, m)}", "diff": better.diff.as_dict(),
         "holds": better.diff.low > 0.0},
        {"key": "2", "label": "the high-level sensor sees the hazard earlier",
         "figure": f"{pct(seen_est)} of reflex onsets seen coming, "
                   f"{lead_est.mean:.1f} [{lead_est.low:.1f}, {lead_est.high:.1f}] ticks before",
         "seen": seen_est.as_dict(), "lead_ticks": lead_est.as_dict(),
         "holds": seen_est.low > 0.5 and lead_est.low > 1.0},
        {"key": "3", "label": "what KP would copy is mostly right (no worse than the reflex)",
         "figure": f"copy - reflex {_value(copy.diff, m)}", "diff": copy.diff.as_dict(),
         "holds": copy.diff.high >= 0.0},
    ]  # fmt: skip
    return {
        "world": world.name,
        "measure": m,
        "seeds": list(seeds),
        "episodes": episodes or world.episodes,
        "reasons": list(world.reasons),
        "conditions": {c: condition_summary(rs) for c, rs in runs.items()},
        "properties": props,
    }


def experiment(
    world: OutsideWorld,
    conditions: Sequence[str],
    pairs: Sequence[tuple[str, str]],
    seeds: Sequence[int],
    episodes: int | None = None,
    held_out: int | None = None,
    jobs: int = 1,
    on_result: Callable[[SeedRun], None] | None = None,
) -> dict[str, Any]:
    """Run `conditions` on `world` over `seeds`; their figures and the declared comparisons."""
    names = list(dict.fromkeys([*conditions, *(n for p in pairs for n in p)]))
    runs = run_all(world, names, seeds, episodes, held_out, jobs, on_result)
    return {
        "world": world.name,
        "description": world.description,
        "measure": world.measure,
        "seeds": list(seeds),
        "episodes": episodes or world.episodes,
        "held_out": held_out or world.held_out,
        "conditions": {c: condition_summary(rs) for c, rs in runs.items()},
        "declared": declared(runs, pairs, world.measure),
    }


def reading(props: dict[str, Any], report: dict[str, Any]) -> list[str]:
    """What the figures say, in words drawn from them (for the summary's top)."""
    failed = [p for p in props["properties"] if not p["holds"]]
    lines = ["## Reading", ""]
    if failed:
        which = "; ".join(f"{p['key']} ({p['label']}: {p['figure']})" for p in failed)
        lines.append(
            f"Not every property of the world holds: {which}. Where one fails the world does "
            "not pose the problem KP is claimed to solve, and the comparison below says how "
            "KP fares there, not whether the claim holds."
        )
    else:
        lines.append("Every property of the world holds: it poses the problem KP addresses.")
    lines.append("")
    for r in report["declared"]:
        d = Estimate.of(r["diff"])
        if r["p_holm"] < 0.05 and d.low > 0:
            verdict = "kp does better than its ablation"
        elif r["p_holm"] < 0.05 and d.high < 0:
            verdict = "kp does worse than its ablation"
        else:
            verdict = "no difference is shown"
        lines.append(
            f"- {r['pair']}, {r['on']}: {_value(d, report['measure'])} "
            f"({_p(r['p_holm'])} after Holm): {verdict}."
        )
    return lines


def _p(p: float) -> str:
    return "p < 0.001" if p < 0.001 else f"p {p:.3f}"


def check_markdown(report: dict[str, Any]) -> list[str]:
    """The properties as markdown lines."""
    lines = [
        f"## Properties of `{report['world']}` (no learning; {len(report['seeds'])} seeds x "
        f"{report['episodes']} episodes; measure: {report['measure']})",
        "",
        "Written down first, with their physical reasons:",
        "",
        *[f"{i}. {r}" for i, r in enumerate(report["reasons"], 1)],
        "",
        "| # | property | figure [95% CI] | holds |",
        "|---|---|---|---|",
    ]
    for p in report["properties"]:
        lines.append(
            f"| {p['key']} | {p['label']} | {p['figure']} | {'yes' if p['holds'] else 'NO'} |"
        )
    lines += ["", "| condition | success | return | outcomes |", "|---|---|---|---|"]
    for c, s in report["conditions"].items():
        lines.append(_condition_row(c, s, held=False))
    return lines


def _condition_row(name: str, s: dict[str, Any], held: bool) -> str:
    outcomes = ", ".join(f"{k} {v:.0%}" for k, v in sorted(s["outcomes"].items()))
    ret = _value(Estimate.of(s["return"]), "return")
    row = f"| {name} | {pct(Estimate.of(s['success']))} | {ret}"
    if held:
        row += (
            f" | {pct(Estimate.of(s['held_out_success']))}"
            f" | {_value(Estimate.of(s['held_out_return']), 'return')}"
        )
    return row + f" | {outcomes} |"


def experiment_markdown(report: dict[str, Any]) -> list[str]:
    """The experiment's figures and declared comparisons as markdown lines."""
    m = report["measure"]
    lines = [
        f"## kp against its ablation on `{report['world']}` ({len(report['seeds'])} seeds x "
        f"{report['episodes']} episodes, then {report['held_out']} held out, frozen)",
        "",
        f"Declared comparisons, on {m} per seed, paired by seed, Holm over the family:",
        "",
        "| comparison | on | difference [95% CI] | p | p (Holm) |",
        "|---|---|---|---|---|",
    ]
    for r in report["declared"]:
        lines.append(
            f"| {r['pair']} | {r['on']} | {_value(Estimate.of(r['diff']), m)} | "
            f"{_p(r['p'])} | {_p(r['p_holm'])} |"
        )
    lines += [
        "",
        "| condition | success | return | held-out success | held-out return | outcomes |",
        "|---|---|---|---|---|---|",
    ]
    for c, s in report["conditions"].items():
        lines.append(_condition_row(c, s, held=True))
    lines += ["", "What each high-level stimulus releases at the end (seeds):", ""]
    for c, s in report["conditions"].items():
        cells = "; ".join(
            f"{st}: " + ", ".join(f"{b} {n}" for b, n in sorted(bs.items()))
            for st, bs in s["answers"].items()
        )
        lines.append(f"- {c}: {cells}")
    lines += ["", "Training ticks by what released the behaviour:", ""]
    for c, s in report["conditions"].items():
        total = sum(s["ticks_by_origin"].values()) or 1
        cells = ", ".join(f"{k} {v / total:.0%}" for k, v in sorted(s["ticks_by_origin"].items()))
        lines.append(f"- {c}: {cells}")
    return lines
