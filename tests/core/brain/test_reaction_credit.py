"""A person's reward credits the reaction window before the tick they saw."""

from __future__ import annotations

import numpy as np
import pytest
from fakes import channel_list

from core.brain.brain import Brain, BrainConfig, LearningConfig
from core.brain.catalog import Catalog
from core.brain.memory import (
    LongTermMemory,
    ReactionWindow,
    ShortTermMemory,
    credit_seen,
    reinforce,
)
from core.brain.network import BehaviourNetwork
from core.brain.selection import DEFAULT_DESIRES, SelectionConfig
from core.sim.channels import Channel
from core.sim.robot import RobotConfig

CORNER = {Channel.CORNER_PENDING: 1.0}


@pytest.mark.parametrize(
    ("lo_s", "hi_s", "hz", "ticks"),
    [
        (0.2, 4.0, 10.0, (1, 40)),  # TAMER's window at the default rate
        (0.2, 4.0, 20.0, (3, 80)),
        (0.2, 4.0, 0.5, (0, 2)),  # a tick on screen 2 s: the seen tick itself may count
        (0.3, 0.7, 10.0, (2, 7)),  # 0.3 * 10 is 3.0000000000000004: still 3, less the tick
        (0.25, 0.29, 10.0, (2, 2)),  # narrower than a tick: its one tick
        (0.0, 1.0, 10.0, (0, 10)),  # lo 0: the seen tick itself is credited
        (0.15, 0.45, 10.0, (1, 4)),
    ],
)
def test_window_in_ticks_rounds_inwards(
    lo_s: float, hi_s: float, hz: float, ticks: tuple[int, int]
) -> None:
    w = ReactionWindow.of_seconds(lo_s, hi_s, hz)
    assert (w.lo_ticks, w.hi_ticks) == ticks


@pytest.mark.parametrize(("lo_s", "hi_s", "hz"), [(1.0, 0.5, 10.0), (-0.1, 1.0, 10.0), (0, 1, 0)])
def test_window_rejects_bad_seconds(lo_s: float, hi_s: float, hz: float) -> None:
    with pytest.raises(ValueError, match="reaction window"):
        ReactionWindow.of_seconds(lo_s, hi_s, hz)


def stm_of(ticks: range) -> ShortTermMemory:
    stm = ShortTermMemory()
    for t in ticks:
        stm.push((t, 1, t))  # a behaviour per tick: each record its own LTM pair
    return stm


def test_credit_seen_credits_the_window_newest_first_from_d_k_1() -> None:
    stm, ltm = stm_of(range(1, 21)), LongTermMemory(eta=0.1)
    credits = credit_seen(stm, ltm, 1.0, ReactionWindow(2, 5).span(15))
    # The window of tick 15 is ticks 10..13: d_k = 13 - tick + 1.
    assert [(c.tick, c.d_k) for c in credits] == [(13, 1), (12, 2), (11, 3), (10, 4)]
    for c in credits:
        assert ltm.reliability(1, c.tick) == reinforce(0.0, 1.0, 0.1, c.d_k)
    # Newer than the window: kept for the next reward; older: popped without credit.
    assert [t for t, _, _ in stm] == list(range(14, 21))
    assert {pair for pair, _ in ltm.items()} == {(1, t) for t in range(10, 14)}


def test_credit_seen_then_the_next_reward_credits_what_stayed() -> None:
    stm, ltm = stm_of(range(1, 21)), LongTermMemory(eta=0.1)
    credit_seen(stm, ltm, 1.0, ReactionWindow(2, 5).span(15))
    credits = credit_seen(stm, ltm, -1.0, ReactionWindow(2, 5).span(20))
    assert [(c.tick, c.d_k) for c in credits] == [(18, 1), (17, 2), (16, 3), (15, 4)]
    assert [t for t, _, _ in stm] == [19, 20]
    assert ltm.reliability(1, 14) == 0.0  # older than the second window: dropped


def test_credit_seen_with_a_window_from_zero_credits_the_seen_tick() -> None:
    stm, ltm = stm_of(range(1, 6)), LongTermMemory(eta=0.1)
    credits = credit_seen(stm, ltm, 1.0, ReactionWindow(0, 1).span(5))
    assert [(c.tick, c.d_k) for c in credits] == [(5, 1), (4, 2)]


def test_credit_seen_before_any_record_credits_nothing_and_keeps_stm() -> None:
    stm, ltm = stm_of(range(10, 15)), LongTermMemory(eta=0.1)
    assert credit_seen(stm, ltm, 1.0, ReactionWindow(2, 5).span(11)) == []
    assert len(stm) == 5
    assert len(ltm) == 0


def test_the_paper_rule_is_unchanged_beside_it() -> None:
    """Without a seen tick every record before the boundary is credited from the boundary."""
    stm, ltm = stm_of(range(1, 6)), LongTermMemory(eta=0.1)
    credits = ltm.apply(stm.pop_before(6), 6, 1.0)
    assert [(c.tick, c.d_k) for c in credits] == [(5, 1), (4, 2), (3, 3), (2, 4), (1, 5)]


# --- the brain: STM, and the ended episode's last records -------------------------------


def brain(catalog: Catalog, *, clear: bool = True) -> Brain:
    net = BehaviourNetwork.from_specs(catalog, catalog.knowledge_set("innate").associations)
    config = BrainConfig(
        selection=SelectionConfig(desires=dict.fromkeys(DEFAULT_DESIRES, 1.0)),
        learning=LearningConfig(enabled=True, eta=0.1, clear_stm_each_episode=clear),
    )
    b = Brain(catalog, net, config, RobotConfig(), np.random.default_rng(0))
    b.window = ReactionWindow(2, 5)
    return b


def run(b: Brain, first: int, last: int) -> None:
    for t in range(first, last + 1):
        b.step(t, channel_list(CORNER))


def ltm_of(b: Brain) -> dict[tuple[int, int], float]:
    return b.ltm.as_dict()


def test_brain_reward_with_a_seen_tick_credits_its_window_from_stm(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, 20)
    outcome = b.reward(21, 1.0, tick_seen=18)
    assert outcome.window == (13, 16)
    assert [(c.tick, c.d_k) for c in outcome.credits] == [(16, 1), (15, 2), (14, 3), (13, 4)]
    assert [t for t, _, _ in b.stm] == [17, 18, 19, 20]


def test_brain_reward_with_the_window_it_arrived_with_credits_that(catalog: Catalog) -> None:
    """A paused run's window ends at the seen tick: the engine passes it as it arrived."""
    b = brain(catalog)
    run(b, 1, 20)
    outcome = b.reward(21, 1.0, tick_seen=18, window=(13, 18))
    assert [(c.tick, c.d_k) for c in outcome.credits][:2] == [(18, 1), (17, 2)]
    assert [t for t, _, _ in b.stm] == [19, 20]


def test_brain_reward_without_a_seen_tick_keeps_the_paper_rule(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, 5)
    outcome = b.reward(6, 1.0)
    assert outcome.window is None
    assert [(c.tick, c.d_k) for c in outcome.credits] == [(5, 1), (4, 2), (3, 3), (2, 4), (1, 5)]
    assert len(b.stm) == 0


def test_a_reward_pressed_just_after_a_crash_credits_the_ended_episode(
    catalog: Catalog,
) -> None:
    """The episode ends at tick 10 (a crash); the trainer saw it and presses: the reward
    arrives 1-3 ticks into the next episode, whose STM is empty of what they saw."""
    for arrives_after in (1, 2, 3):
        b = brain(catalog)
        run(b, 1, 10)
        b.reset_episode(10)
        run(b, 11, 10 + arrives_after - 1)
        before = ltm_of(b)
        outcome = b.reward(10 + arrives_after, -1.0, tick_seen=10)
        assert [(c.tick, c.d_k) for c in outcome.credits] == [(8, 1), (7, 2), (6, 3), (5, 4)]
        assert ltm_of(b) != before
        # The new episode's own records are left for later rewards.
        assert [t for t, _, _ in b.stm] == list(range(11, 10 + arrives_after))


def test_the_ended_episode_keeps_only_its_window(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, 10)
    b.reset_episode(10)
    # What a reward seen at its last tick could credit, paused or not: ticks 5..10.
    assert [t for t, _, _ in b.ended] == [5, 6, 7, 8, 9, 10]
    assert len(b.stm) == 0


def test_a_reward_pressed_after_the_window_credits_nothing(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, 10)
    b.reset_episode(10)
    run(b, 11, 15)  # hi_ticks = 5 ticks after the end: the last boundary the records live
    late = b.reward(17, 1.0, tick_seen=10)  # 6 ticks after the end
    assert late.credits == ()
    assert len(b.ltm) == 0
    assert len(b.ended) == 0


def test_the_last_boundary_inside_the_window_still_credits(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, 10)
    b.reset_episode(10)
    run(b, 11, 15)
    assert len(b.reward(16, 1.0, tick_seen=10).credits) == 4


def test_rewards_without_a_seen_tick_never_touch_the_ended_records(catalog: Catalog) -> None:
    b = brain(catalog)
    run(b, 1, 10)
    b.reset_episode(10)
    outcome = b.reward(11, 1.0)
    assert outcome.credits == ()
    assert [t for t, _, _ in b.ended] == [5, 6, 7, 8, 9, 10]


def test_a_seen_tick_in_the_current_episode_never_reaches_into_the_ended_one(
    catalog: Catalog,
) -> None:
    b = brain(catalog)
    run(b, 1, 10)
    b.reset_episode(10)
    run(b, 11, 13)
    outcome = b.reward(14, 1.0, tick_seen=13)  # window 8..11: only 11 is this episode's
    assert [c.tick for c in outcome.credits] == [11]
    assert [t for t, _, _ in b.ended] == [5, 6, 7, 8, 9, 10]


def test_without_clearing_stm_the_window_reads_stm_across_episodes(catalog: Catalog) -> None:
    b = brain(catalog, clear=False)
    run(b, 1, 10)
    b.reset_episode(10)
    run(b, 11, 12)
    outcome = b.reward(13, 1.0, tick_seen=10)
    assert [c.tick for c in outcome.credits] == [8, 7, 6, 5]
    assert [t for t, _, _ in b.stm] == [9, 10, 11, 12]
