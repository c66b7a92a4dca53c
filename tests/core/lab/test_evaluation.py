"""Held-out evaluation: frozen knowledge on unseen seeds, and the camera-only transfer test."""

from __future__ import annotations

import numpy as np
import pytest

from core.brain.selection import How
from core.lab.evaluation import EVAL_SEED_OFFSET, eval_seed, evaluate, frozen, without_sonar
from core.lab.experiment import Task, run_task
from core.learners.envs import AmigoTrackEnv
from core.learners.qlambda import QLambdaConfig, evaluate_qlambda, run_qlambda
from core.run.conditions import get_condition
from core.run.runner import run
from core.run.setup import Setup
from core.run.simulation import Simulation

SETUP = Setup(signal="given").resolved()


def test_evaluation_is_reported_and_changes_nothing_learned() -> None:
    trained = run_task(Task("kp", 2, 12, setup=SETUP))
    evaluated = run_task(Task("kp", 2, 12, setup=SETUP, eval_episodes=5))
    assert trained.ok and evaluated.ok, (trained.error, evaluated.error)
    # Training is the same with or without evaluation after it, and so is what it learned.
    assert evaluated.episodes == trained.episodes
    assert (evaluated.ltm, evaluated.rltm) == (trained.ltm, trained.rltm)
    assert evaluated.answers == trained.answers
    assert len(evaluated.evaluation) == len(evaluated.transfer) == 5
    assert trained.evaluation == trained.transfer == ()


def test_a_frozen_simulation_leaves_the_trained_brain_untouched() -> None:
    setup = SETUP
    catalog = setup.catalog()
    condition = setup.condition(get_condition("kp"))
    sim = Simulation(condition, 1, catalog=catalog, world_config=setup.world_config())
    run(condition, 1, 15, simulation=sim)
    ltm, network = sim.brain.ltm.as_dict(), set(sim.brain.network)
    rltm = dict(sim.brain.kp.rltm) if sim.brain.kp else {}
    episodes = evaluate(
        condition, sim.brain.catalog, sim.brain.network, 1, 4,
        world_config=setup.world_config(), brain_config=sim.brain.config,
    )  # fmt: skip
    assert len(episodes) == 4
    assert sim.brain.ltm.as_dict() == ltm
    assert set(sim.brain.network) == network
    assert (dict(sim.brain.kp.rltm) if sim.brain.kp else {}) == rltm


def test_frozen_conditions_neither_learn_nor_explore_nor_are_taught() -> None:
    still = frozen(get_condition("rp"))
    assert (still.learning, still.epsilon, still.success_reward, still.trainer, still.kp) == (
        False, 0.0, None, None, False,
    )  # fmt: skip
    sim = Simulation(still, eval_seed(0), brain_config=still.brain_config())
    result = run(still, eval_seed(0), 3, simulation=sim)
    assert all(e.rewards == 0 for e in result.episodes)
    assert len(sim.brain.ltm) == 0


def test_held_out_seeds_are_never_training_or_tuning_seeds() -> None:
    assert eval_seed(0) == EVAL_SEED_OFFSET >= 2000
    assert eval_seed(999) < EVAL_SEED_OFFSET + 1000


def test_the_camera_only_transfer_removes_exactly_the_sonar_responses() -> None:
    catalog = SETUP.catalog()
    network = Simulation(get_condition("kp"), 0, catalog=catalog).brain.network
    sonar = {s.id for s in catalog.stimuli if s.sensor == "sonar_obstacle"}
    kept = without_sonar(catalog, network)
    assert {a for a in network if a.stimulus not in sonar} == set(kept)
    assert any(a.stimulus in sonar for a in network)
    assert not any(a.stimulus in sonar for a in kept)


def test_the_frozen_evaluation_explores_never() -> None:
    condition = SETUP.condition(get_condition("delayed"))
    still = frozen(condition)
    sim = Simulation(
        still, eval_seed(3), catalog=SETUP.catalog(), brain_config=still.brain_config()
    )
    sim.reset()
    for _ in range(400):
        result = sim.tick()
        assert result.snapshot.how is not How.EXPLORED
        if result.snapshot.done:
            sim.reset()


def test_a_frozen_q_lambda_policy_keeps_its_values() -> None:
    config = QLambdaConfig(defer=True, per_encounter=True)
    env = AmigoTrackEnv(prior="kp", defer=True)
    _, agent, _ = run_qlambda(0, 8, config, env=env)
    before = {k: v.copy() for k, v in agent.q.items()}
    out = evaluate_qlambda(agent, AmigoTrackEnv(prior="kp", defer=True), eval_seed(0), 4)
    again = evaluate_qlambda(agent, AmigoTrackEnv(prior="kp", defer=True), eval_seed(0), 4)
    assert len(out) == 4 and out == again  # greedy and frozen: the same episodes twice
    assert set(agent.q) == set(before)
    assert all(np.array_equal(agent.q[k], v) for k, v in before.items())


def test_evaluation_runs_for_q_lambda_tasks_too() -> None:
    result = run_task(Task("qlambda-hybrid", 1, 6, setup=SETUP, eval_episodes=3))
    assert result.ok, result.error
    assert len(result.episodes) == 6
    assert len(result.evaluation) == len(result.transfer) == 3
    assert len(result.answers) >= 1 and all(len(a) == 9 for a in result.answers)


@pytest.mark.parametrize("condition", ["kp", "qlambda-hybrid-decay"])
def test_a_checkpoint_is_what_a_task_trained_that_long_reports(condition: str) -> None:
    # Frozen after 4 and 9 of 14 episodes: the same held-out and camera-only episodes as
    # tasks trained for 4 and for 9, and the training itself as if nobody had looked.
    long = run_task(Task(condition, 3, 14, setup=SETUP, eval_episodes=3, eval_after=(4, 9)))
    plain = run_task(Task(condition, 3, 14, setup=SETUP, eval_episodes=3))
    assert long.ok and plain.ok, (long.error, plain.error)
    assert long.episodes == plain.episodes and long.answers == plain.answers
    assert (long.evaluation, long.transfer) == (plain.evaluation, plain.transfer)
    assert [c.episodes for c in long.checkpoints] == [4, 9]
    for n in (4, 9):
        short = run_task(Task(condition, 3, n, setup=SETUP, eval_episodes=3))
        assert long.episodes[:n] == short.episodes
        at = long.frozen_after(n)
        assert (at.evaluation, at.transfer) == (short.evaluation, short.transfer)
        assert len(at.evaluation) == len(at.transfer) == 3
    assert long.frozen_after(14).evaluation == long.evaluation
    with pytest.raises(KeyError, match="after 5 episodes"):
        long.frozen_after(5)


def test_checkpoints_must_fall_inside_training_and_need_evaluation_episodes() -> None:
    with pytest.raises(ValueError, match="eval_after"):
        Task("kp", 0, 10, eval_episodes=2, eval_after=(10,))
    with pytest.raises(ValueError, match="eval_after"):
        Task("kp", 0, 10, eval_episodes=2, eval_after=(0,))
    with pytest.raises(ValueError, match="eval_episodes"):
        Task("kp", 0, 10, eval_after=(5,))
