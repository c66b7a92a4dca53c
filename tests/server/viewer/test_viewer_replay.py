"""Replay in the 3D view: the playback clock, and stored episodes shown as they were run."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from sqlalchemy import Engine as DbEngine

from core.brain.catalog import Catalog
from core.engine import RunEngine
from core.errors import UnknownRunError
from core.ports import Mode, RunSpec, RunStatus
from core.run.conditions import get_condition
from core.run.runner import run as headless_run
from core.run.simulation import Simulation, Snapshot
from core.run.trace import TraceRow
from core.sim.world import EpisodeLayout, LampColor, WorldConfig
from core.sim.worlds import load_world
from server.persistence import SqlAlchemyRunStore, make_sessionmaker
from server.viewer.replay import ReplayClock, load_replay, replay_views
from server.viewer.scene import scene_frame, static_scene

# --- the clock ------------------------------------------------------------------------


def test_a_paused_clock_holds_its_tick() -> None:
    clock = ReplayClock(100)
    assert clock.at(0.0) == clock.at(50.0) == 0
    assert not clock.playing


def test_playing_advances_a_tick_per_recorded_period_times_the_speed() -> None:
    clock = ReplayClock(100, dt_s=0.1).play(10.0)
    assert clock.at(10.0) == 0
    assert clock.at(10.55) == 5
    fast = clock.with_speed(4.0, 10.55)
    assert fast.at(10.55) == 5  # no jump when the speed changes
    assert fast.at(10.8) == 15


def test_pause_seek_and_the_end_of_the_episode() -> None:
    clock = ReplayClock(50, dt_s=0.1).play(0.0)
    paused = clock.pause(1.0)
    assert paused.at(1.0) == paused.at(9.0) == 10
    assert paused.seek(40, 9.0).at(99.0) == 40
    assert paused.seek(-3, 0.0).at(0.0) == 0
    assert paused.seek(500, 0.0).at(0.0) == 49
    playing = paused.seek(45, 2.0).play(2.0)
    assert playing.at(2.2) == 47
    assert playing.at(100.0) == 49 and playing.finished(100.0)
    ended = playing.settle(100.0)
    assert not ended.playing and ended.at(200.0) == 49
    assert playing.settle(2.1) is playing  # not at the end yet
    again = ended.play(300.0)  # play at the end starts over
    assert again.at(300.0) == 0 and again.playing


@pytest.mark.parametrize("speed", [0.0, -1.0, float("nan"), float("inf")])
def test_a_clock_refuses_a_speed_that_is_not_positive(speed: float) -> None:
    with pytest.raises(ValueError, match="speed"):
        ReplayClock(10, speed=speed)
    with pytest.raises(ValueError, match="speed"):
        ReplayClock(10).with_speed(speed, 0.0)


def test_a_clock_needs_a_tick() -> None:
    with pytest.raises(ValueError, match="at least one tick"):
        ReplayClock(0)


# --- stored episodes --------------------------------------------------------------------


def run_stored(
    store: SqlAlchemyRunStore, catalog: Catalog, condition: str, seed: int, n: int
) -> int:
    engine = RunEngine.create(RunSpec(condition, seed, n, Mode.FAST), store, catalog=catalog)
    assert asyncio.run(engine.run()) is RunStatus.FINISHED
    return engine.run_id


def headless(
    catalog: Catalog, condition: str, seed: int, n: int
) -> tuple[dict[int, list[Snapshot]], dict[int, EpisodeLayout]]:
    sim = Simulation(get_condition(condition), seed, catalog=catalog)
    ticks: dict[int, list[Snapshot]] = {}
    layouts: dict[int, EpisodeLayout] = {}

    def on_tick(s: Snapshot) -> None:
        if s.episode_tick == 0:
            layouts[s.episode] = sim.world.layout
        else:
            ticks.setdefault(s.episode, []).append(s)

    headless_run(get_condition(condition), seed, n, on_tick=on_tick, simulation=sim)
    return ticks, layouts


def test_a_replayed_episode_shows_the_poses_and_decisions_it_was_run_with(
    sqlite_engine: DbEngine, catalog: Catalog
) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_id = run_stored(store, catalog, "kp", 11, 4)
    recorded, layouts = headless(catalog, "kp", 11, 4)
    assert sorted(recorded) == [0, 1, 2, 3]
    scene = static_scene(WorldConfig())
    for episode, snaps in recorded.items():
        replay = load_replay(store, catalog, run_id, episode)
        assert replay.ticks == len(snaps) > 0
        assert replay.layout == layouts[episode]
        for view, snap in zip(replay.views, snaps, strict=True):
            pose = np.array([snap.x, snap.y, snap.heading_rad], dtype=np.float32)
            shown = np.array([view.x, view.y, view.heading_rad], dtype=np.float32)
            assert shown.tolist() == pose.tolist()
            assert view.tick == snap.tick and view.episode_tick == snap.episode_tick
            assert view.lamp == snap.lamp
            assert view.how == snap.how.value
            assert view.behaviour == catalog.behaviours[snap.behaviour].name
            assert view.stimuli == tuple(catalog.stimuli[i].name for i in snap.stimuli)
            frame = scene_frame(scene, view, replay.layout)
            assert frame.robot_position == (view.x, view.y, 0.0)
            assert frame.obstacle_visible == (layouts[episode].obstacle_center is not None)
        assert replay.heading().startswith(f"**Replay** of run {run_id}, episode {episode}")


def test_replaying_what_is_not_stored_says_what_is_missing(
    sqlite_engine: DbEngine, catalog: Catalog
) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_id = run_stored(store, catalog, "innate", 2, 1)
    with pytest.raises(LookupError, match=f"run {run_id} has no episode 7"):
        load_replay(store, catalog, run_id, 7)
    with pytest.raises(UnknownRunError):
        load_replay(store, catalog, run_id + 100, 0)
    summaries = store.episode_summaries(run_id)
    assert [(e.episode, e.trace) for e in summaries] == [(0, b"")]
    full = store.episode(run_id, 0)
    assert full is not None and full.trace and full.ticks == summaries[0].ticks
    assert store.episode(run_id, 1) is None


def test_a_behaviour_released_by_a_kp_association_is_flagged_kp() -> None:
    stimuli = ["Obstacle_M_M", "Middle"]
    behaviours = ["goforward3", "leftturn30"]

    def row(tick: int, behaviour: int, how: str, active: tuple[int, ...]) -> TraceRow:
        return TraceRow(tick, 1.0, 0.6, 0.0, behaviour, how, int(LampColor.GREEN), active)

    rows = [
        row(5, 1, "released", (0, 1)),  # leftturn30, released, Obstacle_M_M -> it is KP's
        row(6, 1, "explored", (0, 1)),  # the same behaviour tried at random: not KP's
        row(7, 0, "released", (1,)),  # goforward3 by an innate association
        row(8, -1, "default", ()),
    ]
    views = replay_views(3, 2, rows, stimuli, behaviours, {("Obstacle_M_M", "leftturn30")})
    assert [v.kp for v in views] == [True, False, False, False]
    assert [v.episode_tick for v in views] == [1, 2, 3, 4]
    assert views[3].behaviour is None


def test_a_replayed_corridor_episode_shows_every_obstacle_where_the_run_had_it(
    sqlite_engine: DbEngine, catalog: Catalog
) -> None:
    # The l-shape: a seeded obstacle and a trolley moving on the first straight.
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    spec = RunSpec("rp", 6, 1, Mode.FAST, world="l-shape")
    engine = RunEngine.create(spec, store, catalog=catalog)
    assert asyncio.run(engine.run()) is RunStatus.FINISHED
    world = load_world("l-shape").config
    sim = Simulation(get_condition("rp"), 6, catalog=catalog, world_config=world)
    where: dict[int, tuple[tuple[float, float], ...]] = {}

    def on_tick(s: Snapshot) -> None:
        if s.episode == 0:
            where[s.episode_tick] = sim.obstacle_centers()

    headless_run(get_condition("rp"), 6, 1, on_tick=on_tick, simulation=sim)
    replay = load_replay(store, catalog, engine.run_id, 0)
    scene = static_scene(world)
    trolley = set()
    for view in replay.views:
        frame = scene_frame(scene, view, replay.layout)
        shown = [p[:2] for p in frame.obstacle_positions]
        assert len(shown) == 2
        assert np.allclose(shown, where[view.episode_tick], atol=1e-9), view.episode_tick
        trolley.add(shown[1])
    assert len(trolley) > 10
