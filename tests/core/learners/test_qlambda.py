"""Watkins Q(lambda): one backup by hand, trace cutting, and a chain whose answer is known."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from core.learners.qlambda import QLambdaConfig, WatkinsQLambda, epsilon_at, run_qlambda, sweep

LEFT, RIGHT = 0, 1
GOAL = 3


def agent(
    alpha: float = 0.5, gamma: float = 0.9, lam: float = 0.8, epsilon: float = 0.0, seed: int = 0
) -> WatkinsQLambda:
    config = QLambdaConfig(alpha=alpha, gamma=gamma, lam=lam, epsilon=epsilon)
    return WatkinsQLambda(2, config, np.random.default_rng(seed))


def chain_step(state: int, action: int) -> tuple[int, float, bool]:
    """States 0..3 in a row; left at 0 stays there; reaching 3 pays 1 and ends the episode."""
    nxt = max(0, state - 1) if action == LEFT else state + 1
    return nxt, float(nxt == GOAL), nxt == GOAL


def key(state: int) -> bytes:
    return str(state).encode()


def learn_chain(episodes: int, gamma: float, seed: int) -> tuple[WatkinsQLambda, list[int]]:
    """Drive the agent the way run_qlambda drives it, from the left end each episode."""
    q = agent(alpha=0.3, gamma=gamma, lam=0.9, epsilon=0.1, seed=seed)
    lengths = []
    for _ in range(episodes):
        q.start_episode()
        state = 0
        a = q.act(key(state))
        for t in range(1, 1001):
            nxt, reward, terminal = chain_step(state, a)
            a2 = q.act(key(nxt))
            q.update(key(state), a, reward, key(nxt), a2, terminal)
            state, a = nxt, a2
            if terminal:
                lengths.append(t)
                break
        else:
            pytest.fail("an episode of the chain never reached the goal")
    return q, lengths


def test_chain_greedy_policy_goes_right_with_values_discounted_by_distance() -> None:
    gamma = 0.9
    q, lengths = learn_chain(300, gamma, seed=7)
    for s in range(GOAL):
        assert q.greedy(key(s)) == RIGHT, f"state {s}: {q.values(key(s))}"
        # Q*(s, right) = gamma ** (steps to the goal after this one)
        assert q.values(key(s))[RIGHT] == pytest.approx(gamma ** (GOAL - 1 - s), abs=0.02)
    # Q*(s, left) = gamma * Q*(max(0, s - 1), right); left is tried less, so it is looser.
    for s in range(GOAL):
        expected_left = gamma * gamma ** (GOAL - 1 - max(0, s - 1))
        assert q.values(key(s))[LEFT] == pytest.approx(expected_left, abs=0.1)
        assert q.values(key(s))[LEFT] < q.values(key(s))[RIGHT]
    assert float(np.mean(lengths[-50:])) < GOAL + 1


def test_chain_learning_is_deterministic_for_a_seed() -> None:
    q1, lengths1 = learn_chain(50, 0.9, seed=3)
    q2, lengths2 = learn_chain(50, 0.9, seed=3)
    assert lengths1 == lengths2
    assert q1.q.keys() == q2.q.keys()
    for k in q1.q:
        np.testing.assert_array_equal(q1.q[k], q2.q[k])


def test_update_one_step_by_hand() -> None:
    q = agent(alpha=0.5, gamma=0.9, lam=0.8)
    q.values(b"a")[:] = [0.2, 0.4]
    q.values(b"b")[:] = [1.0, 0.5]
    q.start_episode()
    # a2 = 0 is greedy in b: target = 0.5 + 0.9 * 1.0 = 1.4, delta = 1.4 - 0.4 = 1.0
    q.update(b"a", 1, 0.5, b"b", 0, terminal=False)
    np.testing.assert_allclose(q.values(b"a"), [0.2, 0.4 + 0.5 * 1.0])
    np.testing.assert_allclose(q.values(b"b"), [1.0, 0.5])
    # The trace of (a, 1) decayed to gamma * lambda = 0.72 and carries the next error:
    # target = 0 + 0.9 * max Q(c) = 0, delta = 0 - Q(b, 0) = -1.0
    q.update(b"b", 0, 0.0, b"c", 0, terminal=False)
    np.testing.assert_allclose(q.values(b"b"), [1.0 - 0.5, 0.5])
    np.testing.assert_allclose(q.values(b"a"), [0.2, 0.9 - 0.5 * 1.0 * 0.72])
    np.testing.assert_allclose(q.values(b"c"), [0.0, 0.0])


def test_update_targets_the_greedy_value_after_an_exploratory_action() -> None:
    q = agent(alpha=0.5, gamma=0.9, lam=0.8)
    q.values(b"b")[:] = [1.0, 0.5]
    q.start_episode()
    # a2 = 1 is exploratory: the target still uses max Q(b) = 1.0, not Q(b, 1) = 0.5.
    q.update(b"a", 0, 0.0, b"b", 1, terminal=False)
    assert q.values(b"a")[0] == pytest.approx(0.5 * 0.9 * 1.0)


def test_traces_are_cut_after_an_exploratory_action() -> None:
    q = agent(alpha=0.5, gamma=0.9, lam=0.8)
    q.values(b"b")[:] = [1.0, 0.5]
    q.start_episode()
    q.update(b"a", 0, 0.0, b"b", 1, terminal=False)  # a2 = 1 is not greedy in b
    a_before = q.values(b"a").copy()
    q.update(b"b", 1, 1.0, b"c", 0, terminal=False)
    np.testing.assert_array_equal(q.values(b"a"), a_before)
    assert q.values(b"b")[1] == pytest.approx(0.5 + 0.5 * (1.0 - 0.5))


def test_traces_follow_greedy_actions() -> None:
    q = agent(alpha=0.5, gamma=0.9, lam=0.8)
    q.values(b"b")[:] = [1.0, 0.5]
    q.start_episode()
    q.update(b"a", 0, 0.0, b"b", 0, terminal=False)  # a2 = 0 is greedy in b
    a_before = float(q.values(b"a")[0])
    q.update(b"b", 0, 1.0, b"c", 0, terminal=False)
    delta = 1.0 + 0.9 * 0.0 - 1.0
    assert delta == 0.0
    q.update(b"c", 0, 1.0, b"d", 0, terminal=True)
    # Trace of (a, 0): 1 -> 0.72 -> 0.5184 when (c, 0) earns delta = 1.
    assert q.values(b"a")[0] == pytest.approx(a_before + 0.5 * 1.0 * 0.72**2)


def test_terminal_update_uses_the_reward_alone_and_clears_traces() -> None:
    q = agent(alpha=0.5, gamma=0.9, lam=0.8)
    q.values(b"b")[:] = [1.0, 0.5]
    q.start_episode()
    q.update(b"a", 0, 1.0, b"b", 0, terminal=True)
    assert q.values(b"a")[0] == pytest.approx(0.5)
    q.update(b"x", 0, 1.0, b"y", 0, terminal=False)
    assert q.values(b"a")[0] == pytest.approx(0.5)


def test_replacing_trace_clears_the_other_actions_of_a_revisited_state() -> None:
    q = agent(alpha=0.5, gamma=1.0, lam=1.0)
    q.start_episode()
    q.update(b"s", 0, 0.0, b"s", 1, terminal=False)  # all zero: every action is greedy
    q.update(b"s", 1, 0.0, b"t", 0, terminal=False)
    q.update(b"t", 0, 1.0, b"u", 0, terminal=True)
    # (s, 0)'s trace was cleared by the revisit with action 1; (s, 1) and (t, 0) learn.
    np.testing.assert_allclose(q.values(b"s"), [0.0, 0.5])
    np.testing.assert_allclose(q.values(b"t"), [0.5, 0.0])


def test_greedy_breaks_ties_at_random_but_reproducibly() -> None:
    picks = [agent(seed=s).greedy(b"new") for s in range(20)]
    assert set(picks) == {LEFT, RIGHT}
    assert picks == [agent(seed=s).greedy(b"new") for s in range(20)]


def test_act_explores_about_epsilon_of_the_time() -> None:
    q = agent(epsilon=0.2, seed=1)
    q.values(b"s")[:] = [0.0, 1.0]
    lefts = sum(q.act(b"s") == LEFT for _ in range(4000))
    assert lefts / 4000 == pytest.approx(0.1, abs=0.02)  # half the random picks are left


def test_a_decaying_epsilon_halves_every_half_life_and_stays_put_without_one() -> None:
    decaying = QLambdaConfig(epsilon=0.4, epsilon_half_life=10.0)
    assert [epsilon_at(decaying, k) for k in (0, 10, 20, 30)] == pytest.approx(
        [0.4, 0.2, 0.1, 0.05]
    )
    assert epsilon_at(decaying, 5) == pytest.approx(0.4 / 2**0.5)
    constant = QLambdaConfig(epsilon=0.4)
    assert {epsilon_at(constant, k) for k in (0, 10, 1000)} == {0.4}
    with pytest.raises(ValueError, match="epsilon_half_life"):
        QLambdaConfig(epsilon_half_life=-1.0)
    with pytest.raises(ValueError, match="episode"):
        epsilon_at(decaying, -1)


def test_act_explores_at_the_rate_of_its_episode_on_the_schedule() -> None:
    config = QLambdaConfig(epsilon=0.4, epsilon_half_life=2.0)

    def lefts(seed: int, episode: int) -> list[bool]:
        q = WatkinsQLambda(2, config, np.random.default_rng(seed))
        q.start_episode(episode)
        q.values(b"s")[:] = [0.0, 1.0]
        return [q.act(b"s") == LEFT for _ in range(4000)]

    for episode, rate in ((0, 0.4), (2, 0.2), (4, 0.1)):
        assert np.mean(lefts(3, episode)) == pytest.approx(rate / 2, abs=0.02)  # half go left
    assert lefts(3, 2) == lefts(3, 2), "the same seed explores the same way"
    assert lefts(3, 2) != lefts(4, 2)


def test_run_qlambda_sets_each_episodes_epsilon_from_the_schedule() -> None:
    config = QLambdaConfig(epsilon=0.2, epsilon_half_life=1.0)
    seen: list[float] = []
    agents: list[WatkinsQLambda] = []
    episodes, _, _ = run_qlambda(
        5, 3, config, on_agent=agents.append, on_episode=lambda e: seen.append(agents[0].epsilon)
    )
    assert len(episodes) == 3
    assert seen == pytest.approx([0.2, 0.1, 0.05])


CONFIGS: dict[str, Callable[[float], QLambdaConfig]] = {
    "alpha": lambda v: QLambdaConfig(alpha=v),
    "gamma": lambda v: QLambdaConfig(gamma=v),
    "lam": lambda v: QLambdaConfig(lam=v),
    "epsilon": lambda v: QLambdaConfig(epsilon=v),
}


@pytest.mark.parametrize("field", sorted(CONFIGS))
@pytest.mark.parametrize("value", [-0.1, 1.5])
def test_config_rejects_values_outside_0_1(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        CONFIGS[field](value)


def test_run_qlambda_is_deterministic_and_counts_every_episode() -> None:
    eps1, agent1, ticks1 = run_qlambda(5, 4)
    eps2, _, ticks2 = run_qlambda(5, 4)
    assert len(eps1) == 4
    assert [e.episode for e in eps1] == [0, 1, 2, 3]
    assert eps1 == eps2
    assert ticks1 == ticks2 > 0
    assert agent1.q


def test_run_qlambda_rejects_zero_episodes() -> None:
    with pytest.raises(ValueError, match="episodes"):
        run_qlambda(0, 0)


def test_sweep_rows_are_sorted_and_bounded() -> None:
    grid = [QLambdaConfig(alpha=0.3, lam=0.9, epsilon=0.1), QLambdaConfig(alpha=0.1, lam=0.5)]
    rows = sweep(grid, [1000], 2)
    assert len(rows) == 2
    assert {(r["alpha"], r["lambda"]) for r in rows} == {(0.3, 0.9), (0.1, 0.5)}
    for r in rows:
        assert 0.0 <= r["success_last50"] <= 1.0
        assert 0.0 <= r["success_all"] <= 1.0
    keys = [(-r["success_last50"], -r["success_all"]) for r in rows]
    assert keys == sorted(keys)
