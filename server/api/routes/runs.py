"""Runs: create, list, read, control, and read what they learned."""

from __future__ import annotations

import importlib.util
import math
from collections.abc import Callable
from typing import Annotated

import numpy as np
from fastapi import HTTPException, Path, Query, Request, Response, status
from pydantic_core import to_json
from starlette.concurrency import run_in_threadpool as io

from core.engine.messages import Command, Pause, Resume, SetRate, Stop
from core.errors import UnknownNameError
from core.ports import StoredRun
from core.run.trace import unpack
from core.sim.corridor import CorridorGeometry, floor_quads
from core.sim.corridor_world import obstacle_places
from core.sim.robotfile import INSTALL_HINT, load_robot_file, robot_of
from core.sim.types import WorldConfig, build_geometry
from core.sim.world import episode_layout
from core.sim.worlds import load_world
from server.api.access import PrincipalDep
from server.api.deps import AppState, EnginesDep, NetworksDep, StateDep, StoreDep, WriteGuard
from server.api.errors import ErrorPublic
from server.api.routing import resource_router
from server.runtime import LiveRun
from server.runtime.reads import run_of_state, run_public
from server.schemas import (
    AssociationPublic,
    EpisodeDetail,
    EpisodePublic,
    EpisodesPublic,
    MemoryPublic,
    ReliabilityPublic,
    RunCreate,
    RunNetworkPublic,
    RunPublic,
    RunRate,
    RunsPublic,
    RunWorldPublic,
    SonarPublic,
    ViewChosen,
)
from server.services.runspec import run_spec

router = resource_router("/runs", tag="runs")
RunId = Annotated[int, Path(ge=1, le=2**62, description="a run's id")]
MAX_PAGE = 1000
"""The longest page a list answers: a read's cost never grows with a run's age."""
Offset = Annotated[int, Query(ge=0, le=2**62, description="items to skip")]
Limit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="items to answer at most")]


def _of_stored(run: StoredRun) -> RunPublic:
    return run_public(run.id, run.spec, run.status.value, run.error, run.totals, None)


async def run_now(store: StoreDep, engines: EnginesDep, run_id: int) -> RunPublic:
    """A run's state: live while it runs here, else as stored."""
    live = engines.get(run_id)
    if live is not None:
        return run_of_state(live.spec, live.state)
    # Database work runs in a thread: the event loop also paces realtime ticks.
    return _of_stored(await io(store.run_summary, run_id))


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteGuard],
    responses={409: {"model": ErrorPublic, "description": "a robot cannot run this mode or rate"}},
)
async def create_run(
    body: RunCreate, store: StoreDep, engines: EnginesDep, networks: NetworksDep, state: StateDep
) -> RunPublic:
    """Create a run (status created); start it with POST /api/runs/{id}/start.

    It runs in the world preset and sensor definition it names (GET /api/worlds, GET
    /api/sensor-definitions), else the defaults; the run keeps their names.
    """
    params = {k: v for k, v in body.params.model_dump().items() if v not in (None, False)}
    stored = None if body.network is None else await io(networks.get, body.network)
    spec = run_spec(
        condition=body.condition,
        seed=body.seed,
        episodes=body.episodes,
        mode=body.mode,
        hz=_robot_rate(body) or body.hz,
        network=body.network,
        params=params,
        world=body.world,
        sensors=body.sensors,
        # A past version's run is not today's network's: live edits of it skip the run.
        network_id=None if stored is None or body.network_version is not None else stored.id,
    )
    network = None if body.network is None else await io(networks.pairs, body.network)
    if body.network_version is not None:
        if body.network is None:
            # Schema-valid (JSON Schema cannot say "only with network" for a nullable
            # field), and what it names is not there: a version of no network.
            raise HTTPException(
                status.HTTP_404_NOT_FOUND,
                f"network_version {body.network_version} names a version of no network: "
                "give `network` too",
            )
        snap = await io(networks.snapshot, body.network, body.network_version)
        network = snap.associations
    run_id = await io(engines.create, spec, network)
    return await run_now(store, engines, run_id)


def _conflict(field: str, message: str) -> HTTPException:
    return HTTPException(status.HTTP_409_CONFLICT, f"{field}: {message}")


def _robot_rate(body: RunCreate) -> float | None:
    """A robot's run's rate (its robot file's), or None for a simulated world's run.

    A robot's run ticks in realtime at its robot's rate, through the srlab[ros2] extra:
    otherwise a 409 naming the field (each field is valid alone; it is the robot that
    cannot run them).
    """
    name = robot_of(body.world or "")
    if name is None:
        return None
    robot = load_robot_file(name)  # known: the schema checked the name
    if importlib.util.find_spec("rclpy") is None:
        raise _conflict("world", f"a run on a robot needs the srlab[ros2] extra: {INSTALL_HINT}")
    if body.mode != "realtime":
        raise _conflict("mode", f"a run on a robot ticks in realtime: {body.mode!r} given")
    if "hz" in body.model_fields_set and body.hz != robot.hz:
        raise _conflict(
            "hz", f"the robot {name!r} ticks at {robot.hz:g} Hz (its robot file): {body.hz:g} given"
        )
    return robot.hz


@router.get("")
async def list_runs(
    store: StoreDep, engines: EnginesDep, who: PrincipalDep, offset: Offset = 0, limit: Limit = 100
) -> RunsPublic:
    """The stored runs, oldest first, a page at a time (`count` is how many are stored).

    A participant's token lists their own run only.
    """
    if who.participant is not None:
        own = who.participant.run_id
        mine = [] if own is None or offset > 0 else [await run_now(store, engines, own)]
        return RunsPublic(data=mine, count=0 if own is None else 1)
    page, total = await io(store.run_summaries, offset, limit)
    data = []
    for r in page:
        live = engines.get(r.id)
        data.append(run_of_state(live.spec, live.state) if live is not None else _of_stored(r))
    return RunsPublic(data=data, count=total)


@router.get("/{run_id}")
async def get_run(run_id: RunId, store: StoreDep, engines: EnginesDep) -> RunPublic:
    """A run's state, with its live figures while it runs."""
    return await run_now(store, engines, run_id)


@router.post("/{run_id}/start", dependencies=[WriteGuard])
async def start_run(run_id: RunId, store: StoreDep, engines: EnginesDep) -> RunPublic:
    """Start a created run, or resume a stopped or interrupted one from its checkpoint.

    429 when `SRLAB_MAX_RUNS` runs are running: the run stays as it was.
    """
    await io(store.run_summary, run_id)
    await engines.start(run_id)  # from its checkpoint and log
    await engines.started(run_id)
    return await run_now(store, engines, run_id)


def _live(engines: EnginesDep, run_id: int) -> LiveRun:
    live = engines.get(run_id)
    if live is None:
        raise HTTPException(status.HTTP_409_CONFLICT, f"run {run_id} is not running here")
    return live


async def _control(
    run_id: int, store: StoreDep, engines: EnginesDep, command: Command
) -> RunPublic:
    """Send a control to a live run (409 when its status forbids it: `perform`).

    The status is checked and the control applied in one step where the run ticks, so the
    run cannot change status in between.
    """
    await io(store.run_summary, run_id)
    await _live(engines, run_id).send(command)
    return await run_now(store, engines, run_id)


@router.post("/{run_id}/pause", dependencies=[WriteGuard])
async def pause_run(run_id: RunId, store: StoreDep, engines: EnginesDep) -> RunPublic:
    """Stop ticking until resumed."""
    return await _control(run_id, store, engines, Pause())


@router.post("/{run_id}/resume", dependencies=[WriteGuard])
async def resume_run(run_id: RunId, store: StoreDep, engines: EnginesDep) -> RunPublic:
    """Tick again after a pause."""
    return await _control(run_id, store, engines, Resume())


@router.post(
    "/{run_id}/step",
    dependencies=[WriteGuard],
    responses={409: {"model": ErrorPublic, "description": "not a paused realtime run"}},
)
async def step_run(run_id: RunId, store: StoreDep, engines: EnginesDep) -> RunPublic:
    """Run exactly one tick of a paused realtime run; it stays paused.

    The tick runs at a tick boundary through the engine's tick task, as any other tick:
    rewards and edits due there are applied first. Answered once it has run.
    """
    await io(store.run_summary, run_id)
    await _live(engines, run_id).step()  # RunStateError (409) unless paused and realtime
    return await run_now(store, engines, run_id)


@router.post(
    "/{run_id}/rate",
    dependencies=[WriteGuard],
    responses={409: {"model": ErrorPublic, "description": "not a live realtime run"}},
)
async def set_run_rate(
    run_id: RunId, body: RunRate, store: StoreDep, engines: EnginesDep
) -> RunPublic:
    """Change a live realtime run's tick rate from its next tick (not stored with the run).

    Not a robot's run: it ticks at its robot's rate (409).
    """
    live = engines.get(run_id)
    if live is not None and robot_of(live.spec.world) is not None:
        raise _conflict("hz", f"run {run_id} ticks at its robot's rate, {live.spec.hz:g} Hz")
    return await _control(run_id, store, engines, SetRate(body.hz))


def _world_config(name: str) -> WorldConfig:
    """World preset `name`'s config ("" or gone: the default's)."""
    try:
        return load_world(name or None).config
    except UnknownNameError:
        return load_world().config


def world_public(name: str) -> RunWorldPublic:
    """The fixed parts of world preset `name` ("" or gone: the default) for a 2D view."""
    config = _world_config(name)
    geo = build_geometry(config.track)
    robot = config.robot
    leg = config.track.signal.leg
    d = geo.directions[leg]
    if isinstance(geo, CorridorGeometry):
        centre = geo.centre_line()
        widths = [float(w) for w in geo.widths_m]
    else:  # the ring: leg k runs from vertices[k - 1] to vertices[k]
        centre = [(float(x), float(y)) for x, y in np.roll(geo.vertices, 1, axis=0)]
        widths = [config.track.corridor_width_m] * 4
    half = widths[leg] / 2
    sx, sy = geo.stopline_point
    nx, ny = float(-d[1]) * half, float(d[0]) * half
    mount = robot.sonar_mount_m
    sonars = []
    for deg in robot.sonar_angles_deg:
        a = math.radians(deg)
        sonars.append(SonarPublic(x_m=mount * math.cos(a), y_m=mount * math.sin(a), angle_rad=a))
    return RunWorldPublic(
        world=name,
        outer_box=[float(v) for v in geo.outer_box],
        inner_box=[float(v) for v in geo.inner_box],
        walls=[[*a, *b] for a, b in geo.wall_segments()],
        centre_line=[list(p) for p in centre],
        corridor_widths_m=widths,
        floor=[[list(p) for p in quad] for quad in floor_quads(centre, widths)],
        ring=not isinstance(geo, CorridorGeometry),
        corridor_width_m=config.track.corridor_width_m,
        stopline=[[sx - nx, sy - ny], [sx + nx, sy + ny]],
        lamp=list(geo.lamp_point),
        start_pose=list(geo.start_pose),
        robot_length_m=robot.length_m,
        robot_width_m=robot.width_m,
        sonar_range_m=robot.sonar_range_m,
        sonars=sonars,
        obstacle_size_m=config.track.obstacle.size_m,
    )


@router.get("/{run_id}/world")
async def get_run_world(run_id: RunId, store: StoreDep, engines: EnginesDep) -> RunWorldPublic:
    """The run's track as a top-down view draws it: walls, stop line, lamp, robot, sonars.

    What moves (pose, lamp colour, sonar readings, obstacle) comes with each tick event.
    """
    run = await run_now(store, engines, run_id)
    return world_public(run.world)


STOP_WAIT_S = 10.0
"""How long `POST .../stop` waits for the run to end before answering 202."""


@router.post(
    "/{run_id}/stop",
    dependencies=[WriteGuard],
    responses={202: {"model": RunPublic, "description": "stopping: not ended yet"}},
)
async def stop_run(
    run_id: RunId, store: StoreDep, engines: EnginesDep, response: Response
) -> RunPublic:
    """End the run at the next tick boundary (it can be started again to go on).

    Answered once the run has ended and its end is stored: 200 with its final status
    (`stopped`, or `finished`/`failed` if it ended otherwise first). A run that has not
    ended within 10 s (storage slow to take its last writes) gets 202 with its status as
    now; it ends all the same, and GET /api/runs/{id} says when.
    """
    await _control(run_id, store, engines, Stop())
    if not await engines.ended(run_id, STOP_WAIT_S):
        response.status_code = status.HTTP_202_ACCEPTED
    return await run_now(store, engines, run_id)


def _memory(values: dict[tuple[str, str], float]) -> MemoryPublic:
    data = [
        ReliabilityPublic(stimulus=s, behaviour=b, reliability=v)
        for (s, b), v in sorted(values.items())
    ]
    return MemoryPublic(data=data, count=len(data))


@router.get("/{run_id}/ltm")
def get_ltm(run_id: RunId, store: StoreDep) -> MemoryPublic:
    """The run's LTM reliabilities (as last committed)."""
    return _memory(store.ltm(run_id))


@router.get("/{run_id}/rltm")
def get_rltm(run_id: RunId, store: StoreDep) -> MemoryPublic:
    """The run's KP reliabilities (RLTM)."""
    return _memory(store.rltm(run_id))


@router.get("/{run_id}/network")
def get_run_network(run_id: RunId, store: StoreDep) -> RunNetworkPublic:
    """The run's behaviour network: its design plus what it learned."""
    data = [
        AssociationPublic.model_validate(p, from_attributes=True) for p in store.network(run_id)
    ]
    return RunNetworkPublic(data=data, count=len(data))


@router.get("/{run_id}/episodes")
def list_episodes(
    run_id: RunId, store: StoreDep, offset: Offset = 0, limit: Limit = 100
) -> EpisodesPublic:
    """The run's episodes by number, a page of summaries at a time (`count`: all of them).

    It reads the page only, never a trace (GET .../episodes/{n} has one episode's).
    """
    page, total = store.episode_summaries_page(run_id, offset, limit)
    data = [EpisodePublic.model_validate(e, from_attributes=True) for e in page]
    return EpisodesPublic(data=data, count=total)


@router.get("/{run_id}/episodes/{episode}", response_model=EpisodeDetail)
def get_episode(
    run_id: RunId,
    episode: Annotated[int, Path(ge=0, le=2**62)],
    store: StoreDep,
    state: StateDep,
) -> Response:
    """One episode with its trace: pose, stimuli and behaviour every tick.

    Each row says what made the behaviour run (`origin`: the releasing association's
    source, explored, default or commanded) and the stimulus it answered (`released_by`).
    """
    found = store.episode(run_id, episode)  # that episode's row only
    if found is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"run {run_id} has no episode {episode}")
    stimuli = [s.name for s in state.catalog.stimuli]
    names = [b.name for b in state.catalog.behaviours] + [b.name for b in store.behaviours(run_id)]
    n_stimuli, n_names = len(stimuli), len(names)
    rows = unpack(found.trace) if found.trace else []
    where = _obstacles_of(store.run_summary(run_id), episode) if rows else None
    # The rows are the store's own, so they are written as JSON directly (pydantic-core's
    # encoder; the stdlib's takes 3 ms on floats): a pydantic row each, validated again as
    # the response model, cost two thirds of a long episode's read (4.5 of 7.4 ms for 361
    # ticks). EpisodeDetail stays the documented schema, and
    # tests/server/api/test_runs_api.py validates answers against it.
    trace = [
        {
            "tick": r.tick, "x": r.x, "y": r.y, "heading_rad": r.heading_rad,
            "behaviour": names[r.behaviour] if 0 <= r.behaviour < n_names else None,
            "how": r.how, "origin": r.origin,
            "released_by": stimuli[r.released_by] if 0 <= r.released_by < n_stimuli else None,
            "lamp": r.lamp, "stimuli": [stimuli[i] for i in r.stimuli if i < n_stimuli],
            "obstacles": where(r.tick - found.start_tick) if where else [],
        }
        for r in rows
    ]  # fmt: skip
    body = {
        "episode": found.episode, "outcome": found.outcome, "cause": found.cause,
        "ticks": found.ticks, "start_tick": found.start_tick, "rewards": found.rewards,
        "trace": trace,
    }  # fmt: skip
    return Response(to_json(body), media_type="application/json")


def _obstacles_of(run: StoredRun, episode: int) -> Callable[[int], list[list[float]]]:
    """Where an episode's obstacles are at each of its ticks, as the run's world drew them."""
    config = _world_config(run.spec.world)
    geo = build_geometry(config.track)
    places = obstacle_places(geo, episode_layout(config, geo, run.spec.seed, episode))
    dt = config.dt_s
    return lambda tick: [[x, y] for x, y in places(tick * dt)]


@router.post(
    "/{run_id}/view",
    dependencies=[WriteGuard],
    responses={409: {"model": ErrorPublic, "description": "the 3D view is off on this service"}},
)
async def view_run(run_id: RunId, request: Request, state: StateDep, store: StoreDep) -> ViewChosen:
    """Show the run in the 3D view (live, or where it stopped); answers the view's URL.

    The console's "3D view" button: the view opened at the answer's URL starts on this
    run, live, and stays on it rather than following the newest run (so does the next
    viewer that connects on `/` within a minute). Each viewer has its own run, so the
    viewers already open keep theirs. The URL carries a one-time ticket, good for a
    minute, that the view exchanges for a cookie of the organiser's (what lets the view
    open when reads need a token, and its panel reward beyond loopback). It chooses what
    a viewer sees, so it is a write (a POST, with the token when one is configured), not
    a link an `<img>` on any page could follow.
    """
    await io(store.run_summary, run_id)
    chosen = view_link(request, state, run_id, organiser=True)
    assert state.viewer is not None
    state.viewer.choose(run_id)  # for the viewer opened next; open ones keep theirs
    return chosen


def view_link(request: Request, state: AppState, run_id: int, *, organiser: bool) -> ViewChosen:
    """The 3D view's URL for `run_id`, with a one-time ticket (`server/viewer/passes.py`).

    The organiser's ticket opens a view of every run; a participant's, of that run alone.
    409 when the service has no 3D view.
    """
    viewer = state.viewer
    if viewer is None:
        raise HTTPException(
            status.HTTP_409_CONFLICT, "the 3D view is off on this service (SRLAB_VISER=false)"
        )
    path = viewer.ticket_path(run_id, organiser=organiser)
    host = request.url.hostname or "127.0.0.1"
    if ":" in host:  # an IPv6 address
        host = f"[{host}]"
    return ViewChosen(run=run_id, url=f"{request.url.scheme}://{host}:{viewer.port}{path}")
