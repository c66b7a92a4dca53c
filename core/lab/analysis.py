"""The analysis of an experiment: what each condition achieved, and how they compare.

A seed is the unit of replication: each figure is computed per seed, then summarised over
seeds with a 95% Student's t interval (`core.lab.stats`, which says why); comparisons pair
seeds, since every condition meets the same obstacles and lamp cycles on a seed. Reported
per condition:

- success over fixed horizons (episodes 1-10, 1-50, all) and the per-seed trend;
- failures by cause; the frozen, held-out evaluation and the camera-only transfer test;
- what was learned, judged by the placement probe's correct responses (`core.lab.probe`): at
  checkpoints, the share of seeds whose answer to each camera stimulus is correct, wrong or
  missing, and the knowledge criterion (the first episode after which the answer is
  correct and stays correct);
- episodes to the success criterion, only beside what a process that learns nothing
  would score on it.

Comparisons: the few declared before running (`DECLARED`, each on all episodes and held
out) form one family, Holm-corrected; every other pair is exploratory.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from core.errors import UnknownNameError
from core.events import Cause, Outcome
from core.lab.stats import holm, mean_interval, paired_difference, t_quantile
from core.lab.tasks import TaskResult
from core.run.conditions import CONDITIONS, condition_definition

CRITERION_WINDOW = 10
CRITERION_RATE = 0.8
HORIZONS: tuple[tuple[str, int | None], ...] = (("1-10", 10), ("1-50", 50), ("all", None))
CHECKPOINTS = (10, 25, 50)
"""Episodes after which what was learned is judged (and the last episode)."""
NULL_DRAWS = 200
"""Simulated no-learning runs per seed for the criterion's null."""


def t_quantile_975(df: int) -> float:
    """Student's t 97.5% quantile for `df` degrees of freedom (NaN below 1)."""
    return t_quantile(df, 0.95)


def mean_ci(values: Sequence[float]) -> dict[str, float]:
    """The mean over seeds, its 95% interval (`low`, `high`), and `ci95`.

    The interval is `core.lab.stats.mean_interval`'s (Student's t, clipped to the values'
    range); `ci95` is the t interval's half-width before clipping.
    """
    n = len(values)
    if n == 0:
        return {"mean": math.nan, "ci95": math.nan, "low": math.nan, "high": math.nan, "n": 0}
    arr = np.asarray(values, dtype=np.float64)
    mean = float(arr.mean())
    est = mean_interval(arr.tolist())
    if n == 1:
        return {"mean": mean, "ci95": math.nan, "low": math.nan, "high": math.nan, "n": 1}
    sd = float(arr.std(ddof=1))
    ci = t_quantile_975(n - 1) * sd / math.sqrt(n)
    return {"mean": mean, "ci95": ci, "low": est.low, "high": est.high, "n": n}


def episodes_to_criterion(
    successes: Sequence[bool], window: int = CRITERION_WINDOW, rate: float = CRITERION_RATE
) -> int | None:
    """The first episode count after which the rolling success over `window` is >= `rate`."""
    need = math.ceil(rate * window - 1e-9)
    count = 0
    for i, s in enumerate(successes):
        count += s
        if i >= window:
            count -= successes[i - window]
        if i + 1 >= window and count >= need:
            return i + 1
    return None


def criterion_null(success_by_seed: Sequence[Sequence[int]], seed: int = 0) -> dict[str, Any]:
    """Episodes to criterion of a process that learns nothing, beside each real seed.

    For every seed, independent episodes succeeding at that seed's own overall rate, drawn
    `NULL_DRAWS` times: the median over all draws of the episode the criterion is reached
    (None where it mostly is not), and the share of draws that reach it at all. A
    criterion reached no sooner than this says nothing about learning.
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 8191]))
    reached: list[int] = []
    draws = 0
    for row in success_by_seed:
        n = len(row)
        p = float(np.mean(row)) if n else 0.0
        for _ in range(NULL_DRAWS):
            draws += 1
            x = episodes_to_criterion(list(rng.random(n) < p))
            if x is not None:
                reached.append(x)
    share = len(reached) / draws if draws else math.nan
    median = float(np.median(reached)) if reached and share >= 0.5 else None
    return {"median": median, "reached_share": share}


def trend_per_10(row: Sequence[int]) -> float:
    """The least-squares slope of a seed's successes against the episode, per 10 episodes."""
    y = np.asarray(row, dtype=np.float64)
    if len(y) < 2:
        return math.nan
    x = np.arange(len(y), dtype=np.float64)
    slope = float(np.polyfit(x, y, 1)[0])
    return 10.0 * slope


def _horizon_rates(success: np.ndarray[Any, Any]) -> dict[str, dict[str, float]]:
    out = {}
    n_ep = success.shape[1]
    for label, h in HORIZONS:
        if h is not None and h > n_ep:
            continue
        out[label] = mean_ci(success[:, :h].mean(axis=1).tolist())
    return out


def _ticks_by_origin(results: Sequence[TaskResult]) -> dict[str, int]:
    """Ticks summed over seeds by what made their behaviour run, most first."""
    total: dict[str, int] = {}
    for r in results:
        for origin, n in r.ticks_by_origin.items():
            total[origin] = total.get(origin, 0) + n
    return dict(sorted(total.items(), key=lambda kv: (-kv[1], kv[0])))


def _camera_met(results: Sequence[TaskResult]) -> dict[str, dict[str, float]]:
    """What each camera stimulus met: its ticks and encounters per seed, and more.

    Also the seeds that met it, the episodes it was met in (all seeds together) and the
    success rate of those episodes.
    """
    names = sorted({n for r in results for n in r.camera_met})
    out = {}
    for n in names:
        met = [r.camera_met.get(n, (0, 0, 0, 0)) for r in results]
        episodes = sum(m[2] for m in met)
        out[n] = {
            "ticks_per_seed": float(np.mean([m[0] for m in met])),
            "encounters_per_seed": float(np.mean([m[1] for m in met])),
            "seeds": sum(1 for m in met if m[1] > 0),
            "episodes": episodes,
            "success_when_met": sum(m[3] for m in met) / episodes if episodes else math.nan,
        }
    return out


def _rate_of(episodes: Iterable[Any]) -> float:
    eps = list(episodes)
    return sum(e.outcome is Outcome.SUCCESS for e in eps) / len(eps) if eps else math.nan


def _verdict(answer: str | None, correct: frozenset[str] | None) -> str:
    """correct, wrong or none (no answer), for one answer; unknown without a probe."""
    if answer is None:
        return "none"
    if correct is None:
        return "unknown"
    return "correct" if answer in correct else "wrong"


def correctness(
    results: Sequence[TaskResult],
    camera: Sequence[str],
    correct: Mapping[str, frozenset[str]],
) -> dict[str, Any]:
    """What the seeds' learners answer each camera stimulus, judged by the probe.

    At each checkpoint episode (and the last): per stimulus, the share of seeds whose
    answer is correct, wrong, or missing. Per stimulus also the knowledge criterion of
    each seed: the first episode after which its answer is correct and stays correct to
    the end (None: never), with the survival curve over seeds (the share not yet there
    after each episode).
    """
    rs = [r for r in results if r.answers]
    if not rs:
        return {}
    n_ep = min(len(r.answers) for r in rs)
    checkpoints = sorted({c for c in CHECKPOINTS if c <= n_ep} | {n_ep})
    at: dict[str, dict[str, dict[str, float]]] = {}
    for c in checkpoints:
        row: dict[str, dict[str, float]] = {}
        for j, stim in enumerate(camera):
            verdicts = [_verdict(r.answers[c - 1][j], correct.get(stim)) for r in rs]
            row[stim] = {v: verdicts.count(v) / len(rs) for v in ("correct", "wrong", "none")}
        at[str(c)] = row
    criterion: dict[str, Any] = {}
    for j, stim in enumerate(camera):
        good = correct.get(stim)
        per_seed: list[int | None] = []
        for r in rs:
            ok = [good is not None and r.answers[e][j] in good for e in range(n_ep)]
            first: int | None = None
            for e in range(n_ep - 1, -1, -1):
                if not ok[e]:
                    break
                first = e + 1
            per_seed.append(first)
        survival = [
            sum(1 for x in per_seed if x is None or x > e) / len(per_seed)
            for e in range(1, n_ep + 1)
        ]
        criterion[stim] = {"per_seed": per_seed, "survival": survival}
    return {"checkpoints": at, "criterion": criterion, "has_correct": sorted(correct)}


def summarise(
    results: Sequence[TaskResult],
    conditions: Sequence[str],
    correct: Mapping[str, frozenset[str]] | None = None,
    camera: Sequence[str] = (),
) -> dict[str, Any]:
    """Per condition, over seeds: the figures of the experiment's summary.

    `correct` (the probe's correct responses by stimulus) and `camera` (the camera obstacle
    stimuli's names, in the order of `TaskResult.answers`) add the correctness figures.
    """
    out: dict[str, Any] = {}
    for c in conditions:
        rs = [r for r in results if r.task.condition == c and r.ok]
        if not rs:
            out[c] = {"seeds": 0}
            continue
        n_ep = min(len(r.episodes) for r in rs)
        success = np.array([[e.outcome is Outcome.SUCCESS for e in r.episodes[:n_ep]] for r in rs])
        last = min(CRITERION_WINDOW, n_ep)
        crit = [episodes_to_criterion(list(row)) for row in success]
        reached = sorted(x for x in crit if x is not None)

        def per_episode(cause: Cause, rs: list[TaskResult] = rs) -> list[float]:
            return [sum(e.cause is cause for e in r.episodes) / len(r.episodes) for r in rs]

        collisions = [
            a + b
            for a, b in zip(
                per_episode(Cause.WALL_COLLISION),
                per_episode(Cause.OBSTACLE_COLLISION),
                strict=True,
            )
        ]
        condition = rs[0].task.setup.lookup(c)
        memory = "rltm" if condition.kp else "ltm"

        def reliability(r: TaskResult, key: str, memory: str = memory) -> float:
            learned: dict[str, float] = getattr(r, memory)
            return max(learned.get(key, 0.0), r.programmed.get(key, 0.0))

        keys = sorted({k for r in rs for k in (*getattr(r, memory), *r.programmed)})
        reliab = {k: mean_ci([reliability(r, k) for r in rs]) for k in keys}
        rows = success.astype(int).tolist()
        summary: dict[str, Any] = {
            "description": condition.description,
            "seeds": len(rs),
            "episodes": n_ep,
            "success_rate": mean_ci(success.mean(axis=1).tolist()),
            "success_last10": mean_ci(success[:, -last:].mean(axis=1).tolist()),
            "success_horizons": _horizon_rates(success),
            "trend_per_10": mean_ci([trend_per_10(row) for row in rows]),
            "success_curve": success.mean(axis=0).tolist(),
            "success_by_seed": rows,
            "seed_ids": [r.task.seed for r in rs],
            "success_curve_ci95": [
                mean_ci(success[:, i].astype(float).tolist())["ci95"] for i in range(n_ep)
            ],
            "episodes_to_criterion": {
                "median": float(np.median(reached)) if reached else None,
                "reached": len(reached),
                "never": len(crit) - len(reached),
                "per_seed": crit,
                "null": criterion_null(rows),
            },
            "collisions_per_episode": mean_ci(collisions),
            "obstacle_collisions_per_episode": mean_ci(per_episode(Cause.OBSTACLE_COLLISION)),
            "wall_collisions_per_episode": mean_ci(per_episode(Cause.WALL_COLLISION)),
            "violations_per_episode": mean_ci(per_episode(Cause.SIGNAL_VIOLATION)),
            "timeouts_per_episode": mean_ci(per_episode(Cause.TIMEOUT)),
            "camera_memory": memory if condition.agent == "brain" else None,
            "learns_camera": condition.agent == "brain" and condition.learning,
            "camera_reliability": reliab,
            "ticks": sum(r.ticks for r in rs),
            "ticks_by_origin": _ticks_by_origin(rs),
            "camera_stimuli_met": _camera_met(rs),
        }
        if any(r.evaluation for r in rs):
            frozen = [_rate_of(r.evaluation) for r in rs]
            camera_only = [_rate_of(r.transfer) for r in rs]
            summary["evaluation"] = {
                "frozen": mean_ci(frozen),
                "camera_only": mean_ci(camera_only),
                "episodes": len(rs[0].evaluation),
                "frozen_by_seed": frozen,
                "camera_only_by_seed": camera_only,
            }
        if camera and correct is not None:
            summary["correctness"] = correctness(rs, camera, correct)
        if CONDITIONS.get(c) != condition:  # a researcher's: what it was, for a rerun
            summary["definition"] = condition_definition(condition)
        out[c] = summary
    return out


def paired_against(
    summary: Mapping[str, Any], reference: str, horizon: int | None = None
) -> dict[str, dict[str, float]]:
    """Each condition's success minus `reference`'s, paired by seed.

    Over the first `horizon` episodes (None: all): the mean difference, its 95% interval
    and the sign-flip p, per condition.
    """
    return {
        name: d
        for name in summary
        if name != reference and (d := paired(summary, name, reference, horizon)) is not None
    }


HELD_OUT = (("held-out", "frozen_by_seed"), ("camera only", "camera_only_by_seed"))
"""The held-out figures compared seed by seed: their labels and per-seed keys."""


def per_seed(s: Mapping[str, Any], horizon: int | None, key: str | None) -> dict[int, float]:
    """A condition's figure per seed id: success over a horizon, or a held-out rate."""
    if key is None:
        values = [float(np.mean(row[:horizon])) for row in s["success_by_seed"]]
    else:
        values = list(s.get("evaluation", {}).get(key, []))
        if len(values) != len(s["seed_ids"]):
            return {}
    return {x: v for x, v in zip(s["seed_ids"], values, strict=True) if not math.isnan(v)}


def paired(
    summary: Mapping[str, Any],
    a: str,
    b: str,
    horizon: int | None = None,
    held_out: str | None = None,
) -> dict[str, float] | None:
    """Condition `a`'s success minus `b`'s, seed by seed.

    Over the first `horizon` training episodes, or with `held_out` (a key of
    `HELD_OUT`) the held-out evaluation's rate, which every condition runs on the same
    held-out seed per training seed. None when the two share fewer than two seeds.
    """
    sa, sb = summary.get(a, {}), summary.get(b, {})
    if not sa.get("seeds") or not sb.get("seeds"):
        return None
    mine, theirs = per_seed(sa, horizon, held_out), per_seed(sb, horizon, held_out)
    seeds = [x for x in mine if x in theirs]
    if len(seeds) < 2:
        return None
    d = paired_difference([mine[x] for x in seeds], [theirs[x] for x in seeds])
    return {**d.diff.as_dict(), "p": d.p, "seeds": len(seeds)}


def paired_table(summary: Mapping[str, Any]) -> dict[str, dict[str, dict[str, float]]]:
    """Every pair of conditions (in order, first minus second), per horizon."""
    names = [n for n, s in summary.items() if s.get("seeds")]
    n_ep = min((summary[n]["episodes"] for n in names), default=0)
    out: dict[str, dict[str, dict[str, float]]] = {}
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            row = {}
            for label, h in HORIZONS:
                if h is not None and h > n_ep:
                    continue
                d = paired(summary, a, b, h)
                if d is not None:
                    row[label] = d
            for label, key in HELD_OUT:
                d = paired(summary, a, b, held_out=key)
                if d is not None:
                    row[label] = d
            if row:
                out[f"{a} - {b}"] = row
    return out


DECLARED: tuple[tuple[str, str], ...] = (
    ("kp", "sonar"),
    ("kp", "rp"),
    ("kp", "qlambda-hybrid"),
    ("kp", "dp"),
)
"""The comparisons the results' conclusions rest on, declared before any run: what
propagation adds (its ablation), and kp against the reinforcement program, the strongest
baseline from kp's design, and direct programming."""
DECLARED_ON: tuple[tuple[str, int | None, str | None], ...] = (
    ("all", None, None),
    ("held-out", None, "frozen_by_seed"),
)
"""Each declared comparison is tested on all training episodes and held out, frozen."""


def parse_pairs(text: str, names: Collection[str] = CONDITIONS) -> list[tuple[str, str]]:
    """Comma-separated comparisons ``a-b`` of condition `names`, in order, no repeats.

    Condition names hold hyphens themselves (``kp-qlambda-hybrid`` is kp against
    qlambda-hybrid), so each comparison is split where both sides name a condition; a
    comparison that splits no way or more than one way is an error.
    """
    pairs: list[tuple[str, str]] = []
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        splits = [
            (item[:i], item[i + 1 :])
            for i, ch in enumerate(item)
            if ch == "-" and item[:i] in names and item[i + 1 :] in names
        ]
        if len(splits) != 1:
            known = "no" if not splits else "more than one"
            raise UnknownNameError(
                f"comparison {item!r}: {known} way to read it as a-b of two conditions "
                f"(known: {', '.join(names)})"
            )
        if splits[0][0] == splits[0][1]:
            raise UnknownNameError(f"comparison {item!r} compares a condition with itself")
        if splits[0] not in pairs:
            pairs.append(splits[0])
    if not pairs:
        raise UnknownNameError("no comparison given")
    return pairs


def declared_comparisons(
    summary: Mapping[str, Any], pairs: Sequence[tuple[str, str]] = DECLARED
) -> list[dict[str, Any]]:
    """The declared comparisons, each on `DECLARED_ON`, as one family corrected with Holm.

    Per test: the pair (``a - b``), where (`all` or `held-out`), the paired difference with
    its interval, its raw sign-flip p and its Holm-adjusted p (`p_holm`) over every test
    in the family. A pair whose conditions did not both run is left out of the family.
    """
    rows: list[dict[str, Any]] = []
    for a, b in pairs:
        for label, horizon, held_out in DECLARED_ON:
            d = paired(summary, a, b, horizon, held_out)
            if d is not None:
                rows.append({"pair": f"{a} - {b}", "on": label, **d})
    for r, q in zip(rows, holm([r["p"] for r in rows]), strict=True):
        r["p_holm"] = q
    return rows
