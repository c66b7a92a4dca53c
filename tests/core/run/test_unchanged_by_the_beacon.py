"""The stop-line beacon changes no existing run: its channel is 0 and its stimuli never occur
in a world without one, so every condition's ticks are as they were before it was added.

The digests are of the first 6 episodes of seed 1 in `soft-obstacle` (pose, stimuli,
behaviour, how, origin, outcome each tick), made by the code before the beacon existed.
"""

from __future__ import annotations

import hashlib

import pytest

from core.run.conditions import CONDITIONS
from core.run.runner import run
from core.run.setup import Setup
from core.run.simulation import Snapshot

BEFORE = {
    "kp": "b19db23af59b8bed",
    "sonar": "b19db23af59b8bed",
    "rp": "28d1f43909cb07ff",
    "dp": "0ad260e2f35f8be3",
}


def trace_digest(condition: str, episodes: int = 6) -> str:
    setup = Setup("soft-obstacle").resolved()
    h = hashlib.sha256()

    def tick(s: Snapshot) -> None:
        row = (s.episode, s.tick, round(s.x, 9), round(s.y, 9), s.stimuli, s.behaviour,
               s.how.value, s.origin, s.outcome)  # fmt: skip
        h.update(repr(row).encode())

    run(setup.condition(CONDITIONS[condition]), 1, episodes, world_config=setup.world_config(),
        catalog=setup.catalog(), on_tick=tick)  # fmt: skip
    return h.hexdigest()[:16]


@pytest.mark.parametrize("condition", sorted(BEFORE))
def test_a_condition_runs_as_before_the_beacon(condition: str) -> None:
    assert trace_digest(condition) == BEFORE[condition]


def test_outside_learners_observe_what_they_observed_before() -> None:
    """Their observation leaves out the beacon's stimuli where the world has no beacon."""
    from core.learners.envs import AmigoTrackEnv

    catalog = Setup("soft-obstacle").resolved().catalog()
    without = AmigoTrackEnv(prior="kp", world_config=Setup("soft-obstacle").world_config())
    assert without.observation_space.shape == (len(catalog.stimuli) - 3,)
    with_beacon = AmigoTrackEnv(prior="kp", world_config=Setup("stop-line").world_config())
    assert with_beacon.observation_space.shape == (len(catalog.stimuli),)
