"""Rewards: a trainer's +/- over HTTP (the RP condition by hand), and the reward log."""

from __future__ import annotations

import functools
import math
from typing import Annotated

from fastapi import HTTPException, Query, Request, Response, status
from starlette.concurrency import run_in_threadpool

from core.commands import RewardSource
from core.errors import SeenTickError
from core.ports import RunQueries
from core.run.trace import unpack
from core.studies import ParticipantStatus
from server.api.access import PrincipalDep
from server.api.deps import EnginesDep, StateDep, StoreDep, WriteGuard, bearer
from server.api.ratelimit import client_key
from server.api.routes.runs import RunId
from server.api.routes.studies import current
from server.api.routing import resource_router
from server.schemas import RewardAccepted, RewardCreate, RewardPublic, RewardsPublic

router = resource_router("/runs/{run_id}/rewards", tag="rewards")


@router.post("", status_code=status.HTTP_202_ACCEPTED, dependencies=[WriteGuard])
async def inject_reward(
    run_id: RunId,
    body: RewardCreate,
    request: Request,
    response: Response,
    store: StoreDep,
    engines: EnginesDep,
    state: StateDep,
    who: PrincipalDep,
) -> RewardAccepted:
    """Reward a running or paused run now: answered once the reward is in the reward log.

    It is stamped with the next tick boundary and credits the STM records before it (a
    paused run's at once, at the boundary it is paused at).
    """
    limiter = state.rewards_limiter
    # The trainer: the token when writes need it (checked: this is a write), unless a
    # trusted proxy names each client: SRLAB_TOKEN is one secret all trainers share.
    # A participant is their pseudonym, wherever they are.
    by_token = state.settings.writes_need_token and not state.settings.forwarded_allow_ips
    token = bearer(request) if by_token else None
    address = request.client.host if request.client else None
    client = client_key(address, token, participant=who.participant)
    if who.participant is not None and who.study is not None:
        studies = state.studies
        assert studies is not None
        if (await current(who, studies, store, engines)).status is ParticipantStatus.DONE:
            raise HTTPException(
                status.HTTP_403_FORBIDDEN, "this participant's budget is spent: no more rewards"
            )
    wait = limiter.allow(client, run=run_id)
    if wait > 0:
        settings = state.settings
        why = (
            f"too many rewards to run {run_id}: at most {settings.reward_run_rate_per_s:g}/s "
            "from all trainers (SRLAB_REWARD_RUN_RATE_PER_S)"
            if limiter.limited_by_run(run_id)
            else f"too many rewards from {address} (as client {client}): at most "
            f"{settings.reward_rate_per_s:g}/s (SRLAB_REWARD_RATE_PER_S)"
        )
        raise HTTPException(
            status.HTTP_429_TOO_MANY_REQUESTS,
            why,
            headers={"Retry-After": str(max(1, math.ceil(wait)))},
        )
    engine = engines.get(run_id)
    if engine is None:
        run = await run_in_threadpool(store.run_summary, run_id)  # 404 for an unknown run
        raise HTTPException(
            status.HTTP_409_CONFLICT, f"run {run_id} is {run.status.value}, not running"
        )
    if body.episode is not None and body.tick_seen is None:
        raise seen_error(SeenTickError("episode", "is the episode of `tick_seen`: send both"))
    give = functools.partial(
        engine.reward,
        body.value,
        note=body.note,
        source=RewardSource.TRAINER,
        tick_seen=body.tick_seen,
        seen_episode=body.episode,
    )
    try:
        try:
            ack = await give()
        except SeenTickError as e:
            if e.field != "episode" or body.episode is None or body.tick_seen is None:
                raise
            # An ended episode scrubbed on its replay, at a tick whose window the run no
            # longer holds: its stored trace has the records.
            records = await run_in_threadpool(
                stored_records, store, run_id, body.episode, body.tick_seen
            )
            ack = await give(records=records)
    except SeenTickError as e:
        raise seen_error(e) from e
    return RewardAccepted(
        id=ack.id, tick=ack.tick, episode=ack.episode, value=ack.value, uid=ack.uid,
        tick_seen=ack.tick_seen, seen_episode=ack.seen_episode, window=ack.window,
    )  # fmt: skip


def stored_records(
    store: RunQueries, run_id: int, episode: int, tick_seen: int
) -> tuple[tuple[int, int, int], ...]:
    """A stored episode's STM records up to `tick_seen`, from its trace (blocking).

    A tick's record is what STM held for it: the behaviour and the stimulus it answered
    (`released_by`; none for the default behaviour's ticks). `SeenTickError` for an
    episode not stored or a tick outside it.
    """
    found = store.episode(run_id, episode)
    if found is None:
        raise SeenTickError("episode", f"run {run_id} has no stored episode {episode}")
    first, last = found.start_tick + 1, found.start_tick + found.ticks
    if not first <= tick_seen <= last:
        raise SeenTickError(
            "tick_seen", f"tick {tick_seen} is not in episode {episode} (ticks {first}-{last})"
        )
    rows = unpack(found.trace) if found.trace else []
    return tuple(
        (r.tick, r.released_by, r.behaviour)
        for r in rows
        if r.released_by >= 0 and r.tick <= tick_seen
    )


def seen_error(e: SeenTickError) -> HTTPException:
    """A 422 naming the body's field at fault, as FastAPI's own validation errors do."""
    detail = [{"loc": ["body", e.field], "msg": e.message, "type": "value_error"}]
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, detail)


@router.get("")
def list_rewards(
    run_id: RunId,
    store: StoreDep,
    offset: Annotated[int, Query(ge=0, le=2**62)] = 0,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> RewardsPublic:
    """The run's reward log in log order, a page at a time (`count` is the whole log's).

    Trainers', the task's and reinforcement programs' rewards, each with whether its
    learning was applied and how many STM records it credited.
    """
    page, total = store.rewards_page(run_id, offset, limit)
    data = [
        RewardPublic(
            id=r.id, tick=r.record.tick, episode=r.record.episode, value=r.record.value,
            source=r.record.source, note=r.record.note, applied=r.applied, credited=r.credited,
            uid=r.record.uid, at=r.at, tick_seen=r.record.tick_seen,
            seen_episode=r.record.seen_episode, window=r.record.window,
        )
        for r in page
    ]  # fmt: skip
    return RewardsPublic(data=data, count=total)
