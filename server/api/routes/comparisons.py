"""Success rates of runs over seeds, and the paired difference of two sets of runs.

The editor's "run this network" starts ordinary runs (one per seed) through the runs API
and asks here what they show: nothing is stored for a comparison. A seed is the unit of
replication (`core.lab.stats`): each run's value is its success rate over the first episodes
every run has done, so runs still going are compared on equal terms.
"""

from __future__ import annotations

import math
from typing import Annotated, Any

from fastapi import HTTPException, Query, status
from fastapi.exceptions import RequestValidationError
from pydantic import Field
from starlette.concurrency import run_in_threadpool as io

from core.lab.stats import Estimate, mean_interval, paired_difference
from core.ports import RunStatus, StoredRun
from server.api.deps import EnginesDep, StoreDep
from server.api.errors import ErrorPublic
from server.api.routing import resource_router
from server.schemas import ComparisonPublic, EstimatePublic

router = resource_router("/comparisons", tag="runs")
MAX_SEEDS = 32
"""Runs per side at most: a comparison reads every run's episodes."""
MAX_EPISODES = 1000
"""The most episodes of each run a comparison reads: its rates are over the first
`min(done, MAX_EPISODES)` episodes, so a read's cost never grows with the runs' age."""
RunIdItem = Annotated[int, Field(ge=1, le=2**62)]
_IDS = {"uniqueItems": True}
"""Each run once per side: a run given twice would count twice."""
RunIds = Annotated[
    list[RunIdItem],
    Query(
        min_length=1,
        max_length=MAX_SEEDS,
        description="run ids, one per seed, each once",
        json_schema_extra=_IDS,
    ),
]
_ENDED = (RunStatus.FINISHED, RunStatus.STOPPED, RunStatus.FAILED, RunStatus.INTERRUPTED)


def _number(x: float) -> float | None:
    return None if math.isnan(x) else x


def _public(e: Estimate) -> EstimatePublic:
    return EstimatePublic(mean=_number(e.mean), low=_number(e.low), high=_number(e.high), n=e.n)


def _rate(store: StoreDep, run_id: int, episodes: int) -> float:
    if episodes == 0:
        return math.nan
    page, _ = store.episode_summaries_page(run_id, 0, episodes)
    return sum(e.outcome == "success" for e in page) / len(page)


def _repeated(ids: list[int], side: str) -> dict[str, Any] | None:
    """A 422 entry for the first run id `ids` repeats, or None."""
    seen: set[int] = set()
    for i, run_id in enumerate(ids):
        if run_id in seen:
            return {
                "type": "value_error",
                "loc": ["query", side, i],
                "msg": f"run {run_id} is given twice in {side}: each run counts once",
                "input": run_id,
            }
        seen.add(run_id)
    return None


@router.get(
    "",
    responses={
        404: {"model": ErrorPublic, "description": "no such run"},
        409: {"model": ErrorPublic, "description": "runs a and b are not on the same seeds"},
    },
)
async def compare_runs(
    store: StoreDep,
    engines: EnginesDep,
    a: RunIds,
    b: Annotated[
        list[RunIdItem] | None,
        Query(
            max_length=MAX_SEEDS,
            description="runs to compare with, on a's seeds in order, each once; as many as a",
            json_schema_extra=_IDS,
        ),
    ] = None,
) -> ComparisonPublic:
    """Runs `a`' success rate over seeds (95% Student's t), and `a - b` paired by seed.

    Over the first episodes every run has done, at most 1,000. Each side names each run
    once, and b names one run for each of a (or none).
    """
    b = b or []
    repeated = [e for e in (_repeated(a, "a"), _repeated(b, "b")) if e is not None]
    if repeated:
        raise RequestValidationError(repeated)
    if b and len(b) != len(a):
        raise HTTPException(
            422,
            f"a has {len(a)} runs and b {len(b)}: pair one run of b with each of a",
        )
    summaries = {i: await io(store.run_summary, i) for i in dict.fromkeys((*a, *b))}
    runs: list[StoredRun] = [summaries[i] for i in (*a, *b)]
    for run_a, run_b in zip(runs[: len(b)], runs[len(a) :], strict=True):
        if run_a.spec.seed != run_b.spec.seed:
            raise HTTPException(
                status.HTTP_409_CONFLICT,
                f"run {run_a.id} has seed {run_a.spec.seed} and run {run_b.id} seed "
                f"{run_b.spec.seed}: "
                "a comparison pairs runs on the same seed",
            )
    done: list[int] = []
    ended: list[bool] = []
    for r in summaries.values():
        live = engines.get(r.id)
        done.append(live.state.totals.episodes if live is not None else r.totals.episodes)
        ended.append((live.status if live is not None else r.status) in _ENDED)
    horizon = min(*done, MAX_EPISODES)
    complete = all(ended)

    def rates(ids: list[int]) -> dict[int, float]:
        return {i: _rate(store, i, horizon) for i in ids}

    rate = await io(rates, list(summaries))  # a run on both sides is read once
    ra = [rate[i] for i in a]
    rb = [rate[i] for i in b]
    seeds = [r.spec.seed for r in runs[: len(a)]]
    if horizon == 0:
        empty = EstimatePublic(mean=None, low=None, high=None, n=len(a))
        return ComparisonPublic(
            episodes=0,
            seeds=seeds,
            a=empty,
            b=empty if b else None,
            diff=empty if b else None,
            p=None,
            complete=complete,
        )
    paired = paired_difference(ra, rb) if b else None
    return ComparisonPublic(
        episodes=horizon,
        seeds=seeds,
        a=_public(mean_interval(ra)),
        b=_public(mean_interval(rb)) if b else None,
        diff=_public(paired.diff) if paired else None,
        p=_number(paired.p) if paired else None,
        complete=complete,
    )
