"""A run's live event stream (server-sent events)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import HTTPException, Query, Request, status
from fastapi.responses import StreamingResponse
from starlette.concurrency import run_in_threadpool

from core.brain.catalog import Catalog
from core.engine import Competition, StatusChanged, SubscriptionClosed, TickPublished
from core.events import AssociationDemoted, AssociationPromoted, EpisodeEnded, RewardApplied
from core.ports import RunStatus
from server.api.deps import EnginesDep, StateDep, StoreDep
from server.api.errors import ErrorPublic
from server.api.guard import SitePolicy
from server.api.routes.runs import RunId
from server.api.routing import resource_router
from server.runtime import TooManyStreamsError

router = resource_router("/runs/{run_id}/events", tag="events")
HEARTBEAT_S = 15.0
STREAM_RETRY_AFTER_S = 5
"""What a client refused a stream (503) is told to wait."""


def competition(held: Competition, catalog: Catalog) -> dict[str, Any]:
    """What competed for a tick's stimuli: each released behaviour's value and the threshold.

    Values come from the network as it stood when the tick was published (a live edit or a
    promotion since the tick before shows), strongest first, at most `COMPETITORS`.
    """
    return {
        "threshold": held.threshold,
        "strategy": held.strategy,
        "values": [
            {
                "behaviour": _name(catalog, b),
                "stimulus": catalog.stimuli[st].name,
                "value": round(v, 4),
            }
            for b, v, st in held.values
        ],
    }


def _name(catalog: Catalog, behaviour: int) -> str | None:
    return catalog.behaviours[behaviour].name if 0 <= behaviour < len(catalog.behaviours) else None


def encode(event: object, catalog: Catalog) -> tuple[str, dict[str, Any]] | None:
    """An engine event as an SSE event name and JSON payload (None: not streamed).

    A tick event carries the competition among released behaviours when the engine took
    it (`TickPublished.competition`). A tick
    carries what a top-down view draws: pose, lamp, the sonars' readings and the obstacle
    (the track's fixed parts are GET /api/runs/{id}/world). A tick
    says what made its behaviour run (`origin`: the releasing association's source,
    explored, default or commanded) and the stimulus it answered (`released_by`, or null).
    """
    s = [x.name for x in catalog.stimuli]

    def b(i: int) -> str | None:
        return _name(catalog, i)

    if isinstance(event, TickPublished):
        snap = event.snapshot
        held = event.competition
        extra = {} if held is None else {"competition": competition(held, catalog)}
        return "tick", {**extra,
            "episode": snap.episode, "tick": snap.tick, "episode_tick": snap.episode_tick,
            "x": snap.x, "y": snap.y, "heading_rad": snap.heading_rad,
            "stimuli": [s[i] for i in snap.stimuli], "behaviour": b(snap.behaviour),
            "how": snap.how.value, "origin": snap.origin,
            "released_by": s[snap.released_by] if 0 <= snap.released_by < len(s) else None,
            "lamp": snap.lamp.name.lower(), "progress_m": snap.progress_m,
            "sonar_m": [round(r, 3) for r in event.sonar_m],
            "obstacle": None if event.obstacle is None else list(event.obstacle),
            "obstacles": [list(o) for o in event.obstacles],
        }  # fmt: skip
    if isinstance(event, RewardApplied):
        return "reward", {
            "tick": event.tick, "episode": event.episode, "value": event.value,
            "source": event.source, "note": event.note,
            "credits": [
                {"tick": c.tick, "stimulus": s[c.stimulus], "behaviour": b(c.behaviour),
                 "d_k": c.d_k, "before": c.before, "after": c.after}
                for c in event.credits[:200]
            ],
            "credited": len(event.credits), "uid": event.uid, "tick_seen": event.tick_seen,
            "window": None if event.window is None else list(event.window),
        }  # fmt: skip
    if isinstance(event, EpisodeEnded):
        return "episode", {
            "episode": event.episode, "outcome": event.outcome.value,
            "cause": event.cause.value if event.cause else None, "ticks": event.ticks,
        }  # fmt: skip
    if isinstance(event, AssociationPromoted | AssociationDemoted):
        return "association", {
            "change": "promoted" if isinstance(event, AssociationPromoted) else "demoted",
            "stimulus": s[event.stimulus], "behaviour": b(event.behaviour),
            "reliability": event.reliability,
        }  # fmt: skip
    if isinstance(event, StatusChanged):
        return "status", {"status": event.status.value, "error": event.error}
    return None


def _foreign(request: Request, state: StateDep) -> bool:
    """Whether a browser says the request comes from another site (`server.api.guard`'s rule)."""
    settings = state.settings
    policy = SitePolicy.of(settings.host_names(), settings.cors_origins)
    return policy.origin_problem(request.headers, request.url.scheme) is not None


@router.get(
    "",
    response_class=StreamingResponse,
    responses={
        200: {"content": {"text/event-stream": {}}, "description": "SSE stream"},
        403: {"model": ErrorPublic, "description": "a page of another site (Origin)"},
    },
)
async def stream_events(
    run_id: RunId,
    request: Request,
    store: StoreDep,
    engines: EnginesDep,
    state: StateDep,
    tick_hz: Annotated[
        float, Query(ge=0.0, le=60.0, description="tick snapshots per second (0: none)")
    ] = 2.0,
) -> StreamingResponse:
    """Follow a run live: ticks (throttled), rewards, episode ends, network changes, status.

    Server-sent events; each has an `event:` name (tick, reward, episode, association,
    status) and JSON `data:`. The stream ends when the run does. A run that is not running
    (created, stopped, interrupted, failed) is followed from its next start; a finished
    one cannot start again (409).

    At most `SRLAB_MAX_STREAMS` streams are open at once, `SRLAB_MAX_STREAMS_PER_RUN` to
    one run: past either, 503 with `Retry-After` (checked first, before any database read).
    A page of another site (by `Origin` or `Sec-Fetch-Site`, as for writes) gets 403 and
    holds no slot: it could otherwise take every slot of a run.
    """
    if _foreign(request, state):
        raise HTTPException(
            status.HTTP_403_FORBIDDEN,
            f"a page of another site ({request.headers.get('origin', 'cross-site')}) may not "
            "follow runs here, where each stream holds one of a run's few slots: open the "
            "console this service serves, or allow that origin with SRLAB_CORS_ORIGINS",
            headers={"Vary": "Origin"},
        )
    try:
        sub = engines.subscribe(run_id, maxsize=512, tick_hz=tick_hz)
    except TooManyStreamsError as e:
        raise HTTPException(
            status.HTTP_503_SERVICE_UNAVAILABLE,
            str(e),
            headers={"Retry-After": str(STREAM_RETRY_AFTER_S)},
        ) from None
    try:
        stored = await run_in_threadpool(store.run_summary, run_id)
        if engines.get(run_id) is None and stored.status is RunStatus.FINISHED:
            raise HTTPException(status.HTTP_409_CONFLICT, f"run {run_id} is finished")
    except BaseException:
        engines.unsubscribe(run_id, sub)
        raise
    running = engines.get(run_id)
    now = running.status if running is not None else stored.status

    async def events() -> AsyncIterator[bytes]:
        live = running
        try:
            first = {"status": now.value, "run": run_id}
            yield f"event: status\ndata: {json.dumps(first)}\n\n".encode()
            while True:
                try:
                    async with asyncio.timeout(HEARTBEAT_S):
                        event = await sub.get()
                except SubscriptionClosed:
                    break
                except TimeoutError:
                    if await request.is_disconnected():
                        break
                    yield b": heartbeat\n\n"
                    continue
                # Fed from the run's start on; the run may be let go (its end stored)
                # before its last events are read here: they keep its names.
                live = live or engines.followed(run_id)
                if live is None:
                    continue
                # The brain's catalogue of now: it grows when KP synthesises a behaviour
                # (a new catalogue each time, so reading it here is reading one whole).
                encoded = encode(event, live.catalog)
                if encoded is not None:
                    name, data = encoded
                    yield f"event: {name}\ndata: {json.dumps(data)}\n\n".encode()
        finally:
            engines.unsubscribe(run_id, sub)

    return StreamingResponse(
        events(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )
