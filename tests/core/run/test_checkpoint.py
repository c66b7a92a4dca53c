"""A checkpoint between episodes: the state the episodes after it go on from."""

from __future__ import annotations

from dataclasses import replace

import pytest

from core.brain.brain import BrainConfig
from core.brain.catalog import load_catalog
from core.run.checkpoint import decode, encode, export_state, restore_simulation
from core.run.conditions import get_condition
from core.run.runner import run
from core.run.simulation import Simulation

CATALOG = load_catalog()


def config(clear_stm: bool) -> BrainConfig:
    base = get_condition("kp").brain_config()
    return replace(base, learning=replace(base.learning, clear_stm_each_episode=clear_stm))


@pytest.mark.parametrize("clear_stm", [True, False])
def test_a_restored_checkpoint_runs_the_next_episodes_as_the_run_it_was_taken_from(
    clear_stm: bool,
) -> None:
    condition, brain_config = get_condition("kp"), config(clear_stm)
    sim = Simulation(condition, 4, catalog=CATALOG, brain_config=brain_config)
    run(condition, 4, 6, catalog=CATALOG, simulation=sim)
    state = decode(encode(export_state(sim)))
    carried = len(sim.brain.stm)
    assert carried > 0  # an episode that ended without a reward leaves its records
    # STM a new episode starts by clearing is not kept; one it goes on with is.
    assert len(state["stm"]) == (0 if clear_stm else carried)
    went_on = run(condition, 4, 4, catalog=CATALOG, simulation=sim)
    restored = restore_simulation(condition, 4, state, CATALOG, brain_config=brain_config)
    resumed = run(condition, 4, 4, catalog=CATALOG, simulation=restored)
    assert resumed.ltm == went_on.ltm
    assert resumed.episodes == went_on.episodes
    assert resumed.ticks == went_on.ticks
