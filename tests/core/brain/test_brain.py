"""The brain: one tick of Fig. 6 and one reward of Fig. 3 (STM -> Eq. (1) -> network)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pytest
from fakes import channel_list

from core.brain.brain import Brain, BrainConfig, LearningConfig
from core.brain.catalog import Catalog
from core.brain.memory import reinforce
from core.brain.network import BehaviourNetwork
from core.brain.selection import DEFAULT_DESIRES, How, SelectionConfig
from core.events import AssociationDemoted, AssociationPromoted
from core.sim.channels import Channel
from core.sim.robot import RobotConfig

RED = {Channel.LAMP_COLOR: 1.0, Channel.STOPLINE_AHEAD_M: 0.5}
CORNER = {Channel.CORNER_PENDING: 1.0}
COLLISION = {Channel.BUMPER: 1.0}


def brain(
    catalog: Catalog,
    *,
    network: str = "innate",
    enabled: bool = True,
    eta: float = 0.1,
    threshold: float = 0.5,
    capacity: int = 1000,
) -> Brain:
    net = BehaviourNetwork.from_specs(catalog, catalog.knowledge_set(network).associations)
    config = BrainConfig(
        selection=SelectionConfig(desires=dict.fromkeys(DEFAULT_DESIRES, 1.0)),
        learning=LearningConfig(
            enabled=enabled, eta=eta, insert_threshold=threshold, stm_capacity=capacity
        ),
    )
    return Brain(catalog, net, config, RobotConfig(), np.random.default_rng(0))


def run(b: Brain, first_tick: int, frames: Sequence[Mapping[Channel, float]]) -> list[list[int]]:
    return [b.step(first_tick + i, channel_list(f))[0] for i, f in enumerate(frames)]


def test_step_senses_selects_and_records(catalog: Catalog) -> None:
    b = brain(catalog)
    active, command = b.step(1, channel_list(CORNER))
    corner, turn = catalog.stimulus("Corner").id, catalog.behaviour("leftturn90").id
    assert corner in active
    assert (b.last.behaviour, b.last.stimulus, b.last.how) == (turn, corner, How.RELEASED)
    assert command.speed_mps == 0.25
    assert command.turn_rad_s > 0
    assert list(b.stm) == [(1, corner, turn)]


def test_multi_tick_primitive_continues_and_is_recorded_each_tick(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, [CORNER] + [{}] * 5)
    corner, turn = catalog.stimulus("Corner").id, catalog.behaviour("leftturn90").id
    assert list(b.stm) == [(t, corner, turn) for t in range(1, 7)]
    assert b.last.how is How.CONTINUED
    assert not b.motor.busy
    b.step(7, channel_list())
    assert b.last.behaviour == catalog.behaviour("goforward3").id


def test_a_higher_layer_preempts_a_running_primitive(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, [CORNER, {}])
    back = catalog.behaviour("back").id
    b.step(3, channel_list(COLLISION))
    assert (b.last.behaviour, b.last.how) == (back, How.RELEASED)
    # ...and a lower layer does not pre-empt back.
    b.step(4, channel_list(CORNER))
    assert (b.last.behaviour, b.last.how) == (back, How.CONTINUED)


def test_reward_after_n_ticks_credits_each_record_with_its_distance(catalog: Catalog) -> None:
    b = brain(catalog, eta=0.1)
    n = 5
    run(b, 1, [RED] * n)
    red, go = catalog.stimulus("Red").id, catalog.behaviour("goforward3").id
    outcome = b.reward(n + 1, 1.0)
    assert [(c.tick, c.stimulus, c.behaviour, c.d_k) for c in outcome.credits] == [
        (t, red, go, n + 1 - t) for t in range(n, 0, -1)
    ]
    v = 0.0
    for c in outcome.credits:
        assert c.before == pytest.approx(v)
        v = reinforce(v, 1.0, 0.1, c.d_k)
        assert c.after == pytest.approx(v)
    assert b.ltm.reliability(red, go) == pytest.approx(v)
    assert len(b.ltm) == 1
    assert len(b.stm) == 0
    assert outcome.changes == ()  # 0.2 is below the insert threshold
    assert b.reward(n + 2, 1.0).credits == ()  # STM was popped


def test_reward_promotes_a_pair_that_passes_the_insert_threshold(catalog: Catalog) -> None:
    b = brain(catalog, eta=0.5, threshold=0.5)
    red, go = catalog.stimulus("Red").id, catalog.behaviour("goforward3").id
    b.step(1, channel_list(RED))
    assert b.last.how is How.DEFAULT
    outcome = b.reward(2, 1.0)
    assert outcome.changes == (AssociationPromoted(red, go, 0.5, "learned"),)
    association = b.network.get(red, go)
    assert association is not None
    assert (association.strength, association.source) == (0.5, "learned")
    # Now Red releases the learned response.
    b.step(3, channel_list(RED))
    assert (b.last.behaviour, b.last.stimulus, b.last.how) == (go, red, How.RELEASED)
    # A further reward strengthens it without a second promotion event.
    outcome = b.reward(4, 1.0)
    assert outcome.changes == ()
    association = b.network.get(red, go)
    assert association is not None
    assert association.strength == pytest.approx(0.75)


def test_negative_rewards_demote_a_learned_pair(catalog: Catalog) -> None:
    b = brain(catalog, eta=0.5, threshold=0.5)
    red, go = catalog.stimulus("Red").id, catalog.behaviour("goforward3").id
    b.step(1, channel_list(RED))
    b.reward(2, 1.0)
    b.step(3, channel_list(RED))
    outcome = b.reward(4, -1.0)
    assert outcome.changes == (AssociationDemoted(red, go, 0.25),)
    assert b.network.get(red, go) is None
    assert b.ltm.reliability(red, go) == pytest.approx(0.25)


def test_negative_rewards_never_remove_designed_associations(catalog: Catalog) -> None:
    b = brain(catalog, eta=1.0)
    corner, turn = catalog.stimulus("Corner").id, catalog.behaviour("leftturn90").id
    before = b.network.get(corner, turn)
    b.step(1, channel_list(CORNER))
    outcome = b.reward(2, -1.0)
    assert outcome.changes == ()
    assert b.network.get(corner, turn) == before
    assert b.ltm.reliability(corner, turn) == 0.0


def test_learning_disabled_leaves_ltm_and_network_alone(catalog: Catalog) -> None:
    b = brain(catalog, enabled=False, eta=1.0)
    run(b, 1, [RED] * 3)
    version = b.network.version
    outcome = b.reward(4, 1.0)
    assert (outcome.credits, outcome.changes) == ((), ())
    assert len(b.ltm) == 0
    assert b.network.version == version
    assert len(b.stm) == 0


def test_reset_episode_stops_the_motor_and_forgets_stm(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, [CORNER])
    b.reset_episode()
    assert not b.motor.busy
    assert len(b.stm) == 0
    assert b.last.behaviour == -1


def test_stm_capacity_bounds_what_a_reward_credits(catalog: Catalog) -> None:
    b = brain(catalog, capacity=4)
    run(b, 1, [RED] * 10)
    outcome = b.reward(11, 1.0)
    assert [c.tick for c in outcome.credits] == [10, 9, 8, 7]


# --- learned knowledge acts: the contract of selection with learned and KP pairs ----------

CAMERA_MM = {
    Channel.OBSTACLE_VISIBLE: 1.0,
    Channel.OBSTACLE_DISTANCE_M: 1.2,
    Channel.OBSTACLE_IMAGE_X: 0.0,
    Channel.OBSTACLE_OFFSET_M: 0.0,
    Channel.OBSTACLE_LATERAL_M: 0.0,
}
SONAR_FRONT = {
    Channel.SONAR_2: 0.25,
    Channel.SONAR_2_RESIDUAL: 1.0,
    Channel.SONAR_3: 0.25,
    Channel.SONAR_3_RESIDUAL: 1.0,
}
LEFT_WALL = {Channel.SONAR_0: 0.05, Channel.SONAR_0_RESIDUAL: 0.0}


def kp_brain(catalog: Catalog, *, eta: float = 0.3) -> Brain:
    """The kp condition's brain with its real desires (lane keeping, sonar, KP on)."""
    from core.brain.propagation import KpConfig

    net = BehaviourNetwork.from_specs(catalog, catalog.knowledge_set("kp").associations)
    config = BrainConfig(
        learning=LearningConfig(enabled=True, eta=eta),
        kp=KpConfig(enabled=True, eta=eta),
    )
    return Brain(catalog, net, config, RobotConfig(), np.random.default_rng(0))


def test_a_promoted_camera_pair_outbids_the_designed_position_layer(catalog: Catalog) -> None:
    """Middle -> goforward3 is designed and active on every tick: a learned response just over
    the insertion threshold still wins when its camera stimulus is active."""
    b = kp_brain(catalog)
    mm, turn = catalog.stimulus("Obstacle_M_M").id, catalog.behaviour("rightturn30").id
    b.network.learn(mm, turn, 0.5, "kp")
    b.step(1, channel_list(CAMERA_MM))
    assert (b.last.behaviour, b.last.stimulus, b.last.how) == (turn, mm, How.RELEASED)
    assert b.last.origin == "kp"
    # Without the camera stimulus the position layer cruises, as designed.
    b.reset_episode()
    b.step(2, channel_list())
    assert (b.last.behaviour, b.last.origin) == (catalog.behaviour("goforward3").id, "designed")


@pytest.mark.parametrize(
    ("reflex", "behaviour"), [(COLLISION, "back"), (LEFT_WALL, "leftwallavoid")]
)
def test_a_promoted_camera_pair_loses_to_a_collision_or_wall_reflex(
    catalog: Catalog, reflex: Mapping[Channel, float], behaviour: str
) -> None:
    b = kp_brain(catalog)
    mm, turn = catalog.stimulus("Obstacle_M_M").id, catalog.behaviour("rightturn30").id
    b.network.learn(mm, turn, 0.9, "kp")
    b.step(1, channel_list({**CAMERA_MM, **reflex}))
    assert b.last.behaviour == catalog.behaviour(behaviour).id
    assert b.last.origin == "innate"


def test_a_kp_pair_promoted_by_rewards_runs_when_its_stimulus_comes_back(
    catalog: Catalog,
) -> None:
    """Camera M-M seen, then the sonar's front reflex fires: two rewards propagate it to the
    camera stimulus (d_k = 1 in RLTM), and the next sighting runs the propagated pair."""
    b = kp_brain(catalog, eta=0.3)
    mm = catalog.stimulus("Obstacle_M_M").id
    reflex = catalog.behaviour("rightturn45").id
    tick = 1
    for _ in range(2):
        b.reset_episode()
        b.step(tick, channel_list(CAMERA_MM))
        b.step(tick + 1, channel_list(SONAR_FRONT))
        assert (b.last.behaviour, b.last.origin) == (reflex, "designed")
        tick += 10
        outcome = b.reward(tick, 1.0)
        tick += 1
    assert [(p.stimulus, p.behaviour) for p in outcome.propagated] == [(mm, reflex)]
    association = b.network.get(mm, reflex)
    assert association is not None and association.source == "kp"
    b.reset_episode()
    b.step(tick, channel_list(CAMERA_MM))
    assert (b.last.behaviour, b.last.stimulus, b.last.origin) == (reflex, mm, "kp")


def test_only_learnable_stimuli_are_promoted(catalog: Catalog) -> None:
    """A non-learnable stimulus's released pair is credited in LTM, never promoted."""
    b = brain(catalog, eta=1.0, threshold=0.5)  # the innate network: Corner -> leftturn90
    corner = catalog.stimulus("Corner").id
    go = catalog.behaviour("goforward3").id
    b.stm.push((1, corner, go))  # as if Corner had released goforward3
    outcome = b.reward(2, 1.0)
    assert b.ltm.reliability(corner, go) == 1.0
    assert outcome.changes == ()
    assert b.network.get(corner, go) is None
