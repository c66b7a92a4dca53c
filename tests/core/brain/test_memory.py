"""Eq. (1): reinforce, long-term memory and the bounded short-term memory."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from core.brain.memory import Credit, LongTermMemory, ShortTermMemory, reinforce

unit = st.floats(0.0, 1.0, allow_nan=False)
rewards = st.floats(-1.0, 1.0, allow_nan=False)
ticks_apart = st.integers(1, 10_000)


@pytest.mark.parametrize(
    ("v", "reward", "eta", "d_k", "expected"),
    [
        (0.0, 1.0, 0.1, 1, 0.1),
        (0.0, 1.0, 0.1, 2, 0.05),
        (0.5, 1.0, 0.1, 1, 0.55),
        (0.5, 1.0, 0.1, 5, 0.51),
        (0.0, 0.5, 0.1, 1, 0.05),
        (1.0, 1.0, 0.1, 1, 1.0),
        (0.5, -1.0, 0.1, 1, 0.45),
        (0.5, -1.0, 0.1, 2, 0.475),
        (0.8, -0.5, 0.2, 1, 0.72),
        (0.0, -1.0, 0.1, 1, 0.0),
        (0.3, 0.0, 0.1, 1, 0.3),
    ],
)
def test_reinforce_by_hand(v: float, reward: float, eta: float, d_k: int, expected: float) -> None:
    assert reinforce(v, reward, eta, d_k) == pytest.approx(expected, abs=1e-15)


def test_reinforce_rejects_d_k_below_one() -> None:
    with pytest.raises(ValueError, match="d_k"):
        reinforce(0.5, 1.0, 0.1, 0)


@given(v=unit, reward=rewards, eta=unit, d_k=ticks_apart)
def test_reinforce_stays_in_unit_interval(v: float, reward: float, eta: float, d_k: int) -> None:
    assert 0.0 <= reinforce(v, reward, eta, d_k) <= 1.0


@given(v=unit, r1=rewards, r2=rewards, eta=unit, d_k=ticks_apart)
def test_reinforce_is_monotone_in_the_reward(
    v: float, r1: float, r2: float, eta: float, d_k: int
) -> None:
    lo, hi = sorted((r1, r2))
    assert reinforce(v, lo, eta, d_k) <= reinforce(v, hi, eta, d_k)


@given(v=unit, reward=rewards, eta=unit, d1=ticks_apart, d2=ticks_apart)
def test_reinforce_moves_nearer_records_more(
    v: float, reward: float, eta: float, d1: int, d2: int
) -> None:
    near, far = sorted((d1, d2))
    moved_near = abs(reinforce(v, reward, eta, near) - v)
    moved_far = abs(reinforce(v, reward, eta, far) - v)
    assert moved_near >= moved_far
    if reward > 0:
        assert reinforce(v, reward, eta, near) >= reinforce(v, reward, eta, far)
    elif reward < 0:
        assert reinforce(v, reward, eta, near) <= reinforce(v, reward, eta, far)


def test_ltm_apply_credits_each_record_with_its_distance() -> None:
    ltm = LongTermMemory(eta=0.1)
    records = [(9, 2, 5), (8, 3, 5), (5, 2, 5)]  # newest first, as STM pops them
    credits = ltm.apply(records, reward_tick=10, reward=1.0)
    assert all(isinstance(c, Credit) for c in credits)
    assert [(c.tick, c.stimulus, c.behaviour, c.d_k) for c in credits] == [
        (9, 2, 5, 1),
        (8, 3, 5, 2),
        (5, 2, 5, 5),
    ]
    # (2, 5) is credited twice: 0 -> 0.1 at d=1, then 0.1 -> 0.1 + 0.1 * 0.9 / 5 at d=5.
    before_after = [v for c in credits for v in (c.before, c.after)]
    assert before_after == pytest.approx([0.0, 0.1, 0.0, 0.05, 0.1, 0.118])
    assert ltm.reliability(2, 5) == pytest.approx(0.118)
    assert ltm.reliability(3, 5) == pytest.approx(0.05)
    assert ltm.reliability(4, 4) == 0.0
    assert len(ltm) == 2


def test_ltm_apply_clamps_d_k_to_one() -> None:
    ltm = LongTermMemory(eta=0.1)
    (credit,) = ltm.apply([(10, 0, 0)], reward_tick=10, reward=1.0)
    assert credit.d_k == 1
    assert credit.after == pytest.approx(0.1)


def test_ltm_negative_reward_is_the_mirrored_rule() -> None:
    ltm = LongTermMemory(eta=0.1, initial={(1, 1): 0.5})
    (credit,) = ltm.apply([(3, 1, 1)], reward_tick=5, reward=-1.0)
    assert credit.d_k == 2
    assert credit.after == pytest.approx(0.5 - 0.1 * 0.5 / 2)


@pytest.mark.parametrize("reward", [-1.5, 1.01, float("nan")])
def test_ltm_rejects_rewards_outside_minus_one_one(reward: float) -> None:
    with pytest.raises(ValueError, match="reward"):
        LongTermMemory().apply([(1, 0, 0)], 2, reward)


@pytest.mark.parametrize("eta", [-0.1, 1.5])
def test_ltm_rejects_bad_eta(eta: float) -> None:
    with pytest.raises(ValueError, match="eta"):
        LongTermMemory(eta=eta)


@given(
    records=st.lists(
        st.tuples(st.integers(0, 99), st.integers(0, 3), st.integers(0, 3)), max_size=50
    ),
    reward=rewards,
    eta=unit,
)
def test_ltm_reliabilities_stay_in_unit_interval(
    records: list[tuple[int, int, int]], reward: float, eta: float
) -> None:
    ltm = LongTermMemory(eta=eta)
    for _ in range(3):
        credits = ltm.apply(records, 100, reward)
        assert len(credits) == len(records)
        assert all(c.d_k >= 1 for c in credits)
    assert all(0.0 <= v <= 1.0 for _, v in ltm.items())
    assert len(ltm) <= 16


@given(capacity=st.integers(1, 50), n=st.integers(0, 200))
def test_stm_is_bounded_and_pops_newest_first(capacity: int, n: int) -> None:
    stm = ShortTermMemory(capacity)
    for t in range(n):
        stm.push((t, t % 3, t % 5))
        assert len(stm) <= capacity
    kept = min(n, capacity)
    assert len(stm) == kept
    assert list(stm) == [(t, t % 3, t % 5) for t in range(n - kept, n)]
    popped = stm.pop_all()
    assert [r[0] for r in popped] == list(range(n - 1, n - kept - 1, -1))
    assert len(stm) == 0
    assert stm.pop_all() == []


def test_stm_clear_forgets_everything() -> None:
    stm = ShortTermMemory(4)
    stm.push((1, 0, 0))
    stm.clear()
    assert len(stm) == 0
    stm.push((2, 1, 1))
    assert stm.pop_all() == [(2, 1, 1)]


def test_stm_rejects_zero_capacity() -> None:
    with pytest.raises(ValueError, match="capacity"):
        ShortTermMemory(0)
