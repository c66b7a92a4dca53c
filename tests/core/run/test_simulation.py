"""The simulation in a scripted world: every episode outcome, the referee, the rewards."""

from __future__ import annotations

from collections.abc import Mapping

import pytest
from fakes import ScriptedStep, ScriptedWorld, lap_steps

from core.brain.selection import How
from core.commands import InjectReward
from core.errors import SimulationStateError
from core.events import Cause, EpisodeEnded, Event, Outcome, RewardApplied
from core.run.conditions import get_condition
from core.run.simulation import Simulation, TickInputs, TickResult
from core.sim.channels import Channel
from core.sim.types import SensorFrame
from core.sim.world import WorldConfig

STEP_M = 0.5


def play(sim: Simulation, limit: int = 10_000) -> list[TickResult]:
    """Tick until the episode ends."""
    results = []
    for _ in range(limit):
        results.append(sim.tick())
        if results[-1].snapshot.done:
            return results
    raise AssertionError("the episode did not end")


def ended(results: list[TickResult]) -> EpisodeEnded:
    (event,) = [e for r in results for e in r.events if isinstance(e, EpisodeEnded)]
    return event


def rewards(events: list[Event] | tuple[Event, ...]) -> list[RewardApplied]:
    return [e for e in events if isinstance(e, RewardApplied)]


def test_lap_completed_is_a_success() -> None:
    world = ScriptedWorld()
    world = ScriptedWorld(lap_steps(world.geometry, STEP_M))
    sim = Simulation(get_condition("innate"), seed=0, world=world)
    sim.reset()
    results = play(sim)
    lap_ticks = int(world.geometry.lap_length_m // STEP_M) + 1
    assert len(results) == lap_ticks
    last = results[-1].snapshot
    assert (last.outcome, last.cause) == (Outcome.SUCCESS, None)
    assert last.progress_m == pytest.approx(lap_ticks * STEP_M)
    assert ended(results) == EpisodeEnded(0, Outcome.SUCCESS, None, lap_ticks)
    assert rewards(results[-1].events) == []  # innate has no delayed reward
    assert [r.snapshot.episode_tick for r in results] == list(range(1, lap_ticks + 1))
    assert world.resets == [(0, 0)]
    assert len(world.commands) == lap_ticks


@pytest.mark.parametrize(
    ("step", "cause"),
    [
        (ScriptedStep(collision="wall"), Cause.WALL_COLLISION),
        (ScriptedStep(collision="obstacle"), Cause.OBSTACLE_COLLISION),
        (ScriptedStep(violation=True), Cause.SIGNAL_VIOLATION),
    ],
)
def test_referee_failures_end_the_episode_at_once(step: ScriptedStep, cause: Cause) -> None:
    geometry = ScriptedWorld().geometry
    world = ScriptedWorld(lap_steps(geometry, STEP_M, extra={6: step}))
    sim = Simulation(get_condition("delayed"), seed=0, world=world)
    sim.reset()
    results = play(sim)
    assert len(results) == 7
    assert ended(results) == EpisodeEnded(0, Outcome.FAILURE, cause, 7)
    assert results[-1].snapshot.cause is cause
    assert rewards(results[-1].events) == []  # no reward for a failure


def test_timeout_when_the_robot_never_gets_round() -> None:
    world = ScriptedWorld(config=WorldConfig(max_ticks=5))
    sim = Simulation(get_condition("innate"), seed=0, world=world)
    sim.reset()
    results = play(sim)
    assert len(results) == 5
    assert ended(results) == EpisodeEnded(0, Outcome.FAILURE, Cause.TIMEOUT, 5)


def test_first_failure_is_kept_when_episodes_go_on() -> None:
    geometry = ScriptedWorld().geometry
    extra = {3: ScriptedStep(violation=True), 5: ScriptedStep(collision="wall")}
    world = ScriptedWorld(lap_steps(geometry, STEP_M, extra=extra))
    sim = Simulation(get_condition("delayed"), seed=0, world=world, end_on_failure=False)
    sim.reset()
    results = play(sim)
    assert results[3].snapshot.cause is Cause.SIGNAL_VIOLATION
    assert not results[3].snapshot.done
    last = results[-1].snapshot
    assert (last.outcome, last.cause) == (Outcome.FAILURE, Cause.SIGNAL_VIOLATION)
    assert rewards(results[-1].events) == []


def test_delayed_condition_rewards_a_success_and_credits_the_episode() -> None:
    geometry = ScriptedWorld().geometry
    world = ScriptedWorld(lap_steps(geometry, STEP_M))
    sim = Simulation(get_condition("kp"), seed=0, world=world)
    sim.reset()
    results = play(sim)
    n = len(results)
    events = results[-1].events
    assert isinstance(events[0], EpisodeEnded)
    (reward,) = rewards(events)
    assert (reward.value, reward.source, reward.note) == (1.0, "task", "lap completed")
    assert (reward.tick, reward.episode) == (n + 1, 0)
    # Every tick released the designed Middle -> goforward3: each is credited, newest
    # first, d_k = 1 .. n; a designed pair's reliability grows, the network stays as is.
    assert [c.d_k for c in reward.credits] == list(range(1, n + 1))
    assert [c.tick for c in reward.credits] == list(range(n, 0, -1))
    middle = sim.catalog.stimulus("Middle").id
    go = sim.catalog.behaviour("goforward3").id
    assert {(c.stimulus, c.behaviour) for c in reward.credits} == {(middle, go)}
    assert sim.brain.ltm.reliability(middle, go) > 0.0
    association = sim.brain.network.get(middle, go)
    assert association is not None and association.source == "designed"


def test_the_default_behaviour_is_not_credited_as_the_position_stimulus_response() -> None:
    """With nothing released, keeping moving is no S-R pair: a successful lap of the
    innate robot credits nothing, and `Middle -> goforward3` is never promoted."""
    geometry = ScriptedWorld().geometry
    world = ScriptedWorld(lap_steps(geometry, STEP_M))
    sim = Simulation(get_condition("delayed"), seed=0, world=world)
    sim.reset()
    results = play(sim)
    assert all(r.snapshot.origin == "default" for r in results)
    assert all(r.snapshot.released_by == -1 for r in results)
    (reward,) = rewards(results[-1].events)
    assert reward.credits == ()
    middle = sim.catalog.stimulus("Middle").id
    assert all(s != middle for (s, _), _ in sim.brain.ltm.items())
    assert sim.ticks_by_origin == {"default": len(results)}


def test_rewards_between_ticks_credit_the_records_so_far() -> None:
    world = ScriptedWorld()
    sim = Simulation(get_condition("kp"), seed=0, world=world)
    sim.reset()
    for _ in range(4):
        sim.tick()
    event = sim.reward(0.5, note="good")
    assert (event.tick, event.value, event.source, event.note) == (5, 0.5, "trainer", "good")
    assert [(c.tick, c.d_k) for c in event.credits] == [(4, 1), (3, 2), (2, 3), (1, 4)]
    sim.tick()
    result = sim.tick(TickInputs(rewards=(InjectReward(-0.5, note="bad"),)))
    (applied,) = rewards(result.events)
    assert (applied.tick, applied.value) == (6, -0.5)
    assert [(c.tick, c.d_k) for c in applied.credits] == [(5, 1)]


def test_stimuli_of_a_tick_are_those_sensed_before_it() -> None:
    corner = {Channel.CORNER_PENDING: 1.0}
    world = ScriptedWorld([ScriptedStep(), ScriptedStep(corner), ScriptedStep()])
    sim = Simulation(get_condition("innate"), seed=0, world=world)
    sim.reset()
    snaps = [sim.tick().snapshot for _ in range(4)]
    corner_id = sim.catalog.stimulus("Corner").id
    turn = sim.catalog.behaviour("leftturn90").id
    assert [corner_id in s.stimuli for s in snaps] == [False, False, True, False]
    assert (snaps[2].behaviour, snaps[2].how) == (turn, How.RELEASED)
    assert (snaps[3].behaviour, snaps[3].how) == (turn, How.CONTINUED)
    assert world.commands[2].turn_rad_s > 0.0


def test_episodes_restart_the_world_and_count_on() -> None:
    world = ScriptedWorld(config=WorldConfig(max_ticks=3))
    sim = Simulation(get_condition("innate"), seed=9, world=world)
    for episode in range(3):
        first = sim.reset()
        assert (first.episode, first.tick, first.episode_tick) == (episode, 3 * episode, 0)
        assert first.behaviour == -1
        play(sim)
    assert world.resets == [(9, 0), (9, 1), (9, 2)]
    assert sim.tick_count == 9


def test_ticking_out_of_order_raises() -> None:
    sim = Simulation(get_condition("innate"), seed=0, world=ScriptedWorld())
    with pytest.raises(SimulationStateError, match="reset"):
        _ = sim.snapshot
    with pytest.raises(SimulationStateError, match="reset"):
        sim.tick()
    sim = Simulation(
        get_condition("innate"), seed=0, world=ScriptedWorld(config=WorldConfig(max_ticks=1))
    )
    sim.reset()
    sim.tick()
    with pytest.raises(SimulationStateError, match="episode is over"):
        sim.tick()


@pytest.mark.parametrize("penalty", [0.0, 1.0])
def test_a_failed_episode_punishes_kp_rltm_only_when_a_penalty_is_set(penalty: float) -> None:
    from dataclasses import replace

    from core.brain.propagation import RstmRecord
    from core.events import AssociationDemoted

    geometry = ScriptedWorld().geometry
    crash = {4: ScriptedStep(collision="obstacle")}
    world = ScriptedWorld(lap_steps(geometry, STEP_M, extra=crash))
    kp = get_condition("kp")
    config = kp.brain_config()
    config = replace(config, kp=replace(config.kp, failure_penalty=penalty))
    sim = Simulation(kp, seed=0, world=world, brain_config=config)
    sim.reset()
    brain = sim.brain
    assert brain.kp is not None
    catalog = brain.catalog
    mm = catalog.stimulus("Obstacle_M_M").id
    rt30 = catalog.behaviour("rightturn30").id
    front = catalog.stimulus("SonarObstacleFront").id
    # A copy taught before, in the network, and the sonar's response to M_M in the RSTM.
    brain.kp.rltm[(mm, rt30)] = 0.52  # just over the threshold (0.5)
    brain.network.learn(mm, rt30, 0.52, "kp")
    brain.kp.rstm["camera_obstacle"].append(RstmRecord(1, mm, front, rt30))
    results = play(sim)
    assert ended(results).outcome is Outcome.FAILURE
    after = brain.kp.rltm[(mm, rt30)]
    if penalty == 0.0:
        assert after == 0.52, "by default a failure teaches KP nothing"
        assert brain.network.get(mm, rt30) is not None
        return
    v = 0.52 - penalty * brain.config.kp.eta * 0.52
    assert after == pytest.approx(v)
    assert AssociationDemoted(mm, rt30, after) in results[-1].events
    assert brain.network.get(mm, rt30) is None


class LiveWorld(ScriptedWorld):
    """A world whose readings arrive by themselves, like a robot's: `latest()` reads them."""

    def __init__(self, now: Mapping[Channel, float]) -> None:
        super().__init__()
        self.now = now
        self.reads = 0

    def latest(self) -> SensorFrame:
        self.reads += 1
        return self._frame(ScriptedStep(self.now))


def test_a_live_world_is_read_right_before_the_brain_decides() -> None:
    world = LiveWorld({Channel.LATERAL_OFFSET_M: 0.5})  # left of the centre line
    sim = Simulation(get_condition("innate"), seed=0, world=world)
    sim.reset()  # its frame says the robot is on the centre line
    snap = sim.tick().snapshot
    assert world.reads == 1
    assert [sim.catalog.stimuli[s].name for s in snap.stimuli] == ["Left"]


def test_a_world_without_latest_acts_on_the_frame_of_the_last_step() -> None:
    world = ScriptedWorld(initial={Channel.LATERAL_OFFSET_M: 0.5})
    sim = Simulation(get_condition("innate"), seed=0, world=world)
    sim.reset()
    assert [sim.catalog.stimuli[s].name for s in sim.tick().snapshot.stimuli] == ["Left"]
