"""Held-out evaluation: what a trained robot knows, frozen, on seeds its training never used.

After training, the robot's knowledge is frozen (no exploration, no learning, no
reinforcement program, no propagation) and it runs on held-out seeds: the obstacles and
lamp cycles of seed `EVAL_SEED_OFFSET + s` for a task trained on seed `s`. Two tests:

- **frozen**: the whole trained network, as it stands;
- **camera-only transfer**: the same network with every association of the sonar's
  obstacle stimuli removed, so the obstacle is met by what the camera learned (or was
  given) alone, apart from the reflexes and from exploration luck.

Evaluation never changes what was learned: it runs on a copy of the network, in a fresh
simulation whose own learning is off.
"""

from __future__ import annotations

from dataclasses import replace

from core.brain.brain import BrainConfig
from core.brain.catalog import Catalog
from core.brain.network import BehaviourNetwork
from core.run.conditions import Condition
from core.run.runner import EpisodeSummary, run
from core.run.simulation import Simulation
from core.sim.world import WorldConfig

EVAL_SEED_OFFSET = 1_000_000
"""Held-out seeds: experiments use seeds below 1,000 and tuning seeds 1,000-1,999."""
SONAR_SENSOR = "sonar_obstacle"


def eval_seed(seed: int) -> int:
    """The held-out seed a task trained on `seed` is evaluated on."""
    return EVAL_SEED_OFFSET + seed


def frozen(condition: Condition) -> Condition:
    """`condition` with every way of learning or being taught switched off."""
    return replace(
        condition,
        name=f"{condition.name} (frozen)",
        learning=False,
        epsilon=0.0,
        success_reward=None,
        trainer=None,
        kp=False,
    )


BEACON_SENSOR = "beacon"


def without_sonar(catalog: Catalog, network: BehaviourNetwork) -> BehaviourNetwork:
    """A copy of `network` without the low-level responses KP learns from.

    The sonar's obstacle responses and the stop-line beacon's signal responses (which only
    a world with a beacon raises): what is left of the camera's is what it learned.
    """
    low = {s.id for s in catalog.stimuli if s.sensor in (SONAR_SENSOR, BEACON_SENSOR)}
    return BehaviourNetwork(len(catalog.stimuli), (a for a in network if a.stimulus not in low))


def frozen_config(config: BrainConfig) -> BrainConfig:
    """`config` with exploration, learning and propagation off; selection as it was."""
    return replace(
        config,
        selection=replace(config.selection, epsilon=0.0),
        learning=replace(config.learning, enabled=False),
        kp=replace(config.kp, enabled=False),
    )


def evaluate(
    condition: Condition,
    catalog: Catalog,
    network: BehaviourNetwork,
    seed: int,
    episodes: int,
    *,
    world_config: WorldConfig | None = None,
    brain_config: BrainConfig | None = None,
) -> tuple[EpisodeSummary, ...]:
    """Run `network` frozen for `episodes` episodes of the held-out seed of `seed`.

    `brain_config` is the trained brain's (its selection parameters are kept); learning,
    exploration and propagation are switched off.
    """
    if episodes < 1:
        return ()
    still = frozen(condition)
    sim = Simulation(
        still,
        eval_seed(seed),
        catalog=catalog,
        world_config=world_config,
        network=network.copy(),
        brain_config=frozen_config(brain_config or still.brain_config()),
    )
    return run(still, eval_seed(seed), episodes, simulation=sim).episodes
