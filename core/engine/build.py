"""A run's simulation as the engine starts it: a new run's, stored first, or a stored one's.

`RunEngine.create` and `RunEngine.restore` are these functions and the engine around what
they return; they check the spec (condition, learning parameters, world and sensor
definition, rate) before anything is stored or ticks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from core.brain.brain import BrainConfig
from core.brain.catalog import Catalog
from core.brain.memory import DEFAULT_REACTION_S, ReactionWindow
from core.brain.network import Association, BehaviourNetwork
from core.engine.learning import pair
from core.engine.pacing import Pacer, check_hz
from core.errors import CatalogError, RunStateError
from core.params import applicable, configure
from core.ports import Checkpoint, Mode, RunSpec, RunStatus, RunStore, RunTotals, StoredRun
from core.run.checkpoint import decode, encode, export_state, restore_simulation
from core.run.conditions import Condition, get_condition
from core.run.setup import Setup, condition_network
from core.run.simulation import Simulation
from core.sim.robotfile import robot_of
from core.sim.world import World, WorldConfig

Connect = Callable[[RunSpec], tuple[World, Pacer]]
"""Reaches the robot a run's world names (``ros2:ROBOT``, `core.sim.robotfile`): the world
its ticks sense and act in, and the clock that paces them (`server.robots.connect`)."""


def condition(spec: RunSpec) -> tuple[Condition, BrainConfig]:
    """The spec's condition and brain settings (`RunStateError`, `ValueError` if unfit)."""
    found = get_condition(spec.condition)
    if found.agent != "brain":
        raise RunStateError(f"condition {found.name!r} is not run by the engine")
    params = brain_params(spec)
    unknown = set(params) - {"eta", "epsilon", "synthesize"}
    if unknown:
        raise ValueError(f"unknown learning parameters: {', '.join(sorted(unknown))}")
    # The API accepts these for every condition and ignores those a condition does not use.
    return configure(found, applicable(found, params))


REACTION_WINDOW = "reaction_window_s"
"""The parameter holding a run's reaction window, ``[lo_s, hi_s]``: stored with its spec,
so a replay credits with the window the run had."""


def brain_params(spec: RunSpec) -> dict[str, Any]:
    """The spec's learning parameters the brain takes: all but the reaction window."""
    return {k: v for k, v in spec.params.items() if k != REACTION_WINDOW}


def reaction_seconds(spec: RunSpec) -> tuple[float, float]:
    """The run's reaction window in seconds (TAMER's 0.2-4 s if it names none)."""
    lo_s, hi_s = spec.params.get(REACTION_WINDOW, DEFAULT_REACTION_S)
    return float(lo_s), float(hi_s)


def reaction_window(spec: RunSpec) -> ReactionWindow:
    """The run's reaction window in ticks at the rate it was created with."""
    return ReactionWindow.of_seconds(*reaction_seconds(spec), spec.hz)


def setup(spec: RunSpec, catalog: Catalog | None) -> tuple[Setup, Catalog]:
    """The run's setup and catalogue: `catalog` if given (it must fit), else the setup's.

    A spec that names no sensor definition takes the given catalogue's.
    """
    sensors = spec.sensors or (catalog.definition if catalog is not None else "")
    chosen = Setup(spec.world, sensors)
    if catalog is None:
        return chosen, chosen.catalog()
    if catalog.definition and catalog.definition != chosen.sensors_name:
        raise CatalogError(
            f"the catalogue uses sensor definition {catalog.definition!r}, the run "
            f"{chosen.sensors_name!r}"
        )
    return chosen, catalog


def new_simulation(
    spec: RunSpec,
    catalog: Catalog,
    world_config: WorldConfig,
    network: tuple[Association, ...] | None,
    world: World | None = None,
) -> Simulation:
    """A fresh simulation for a run, in `world` if given (a robot: `server.robots.ros2`).

    Its network is `network`, else the spec's knowledge set, else the condition's own;
    a knowledge set is taken in its variant for the catalogue's sensor definition
    (`core.run.setup.condition_network`).
    """
    cond, config = condition(spec)
    if network is not None:
        net = BehaviourNetwork(len(catalog.stimuli), network)
    else:
        base = cond if spec.network is None else replace(cond, network=spec.network)
        net = condition_network(catalog, base)
    sim = Simulation(
        cond,
        spec.seed,
        catalog=catalog,
        world=world,
        world_config=world_config,
        network=net,
        brain_config=config,
        defer_rewards=True,
    )
    sim.brain.window = reaction_window(spec)
    return sim


def create_run(
    spec: RunSpec,
    store: RunStore,
    *,
    catalog: Catalog | None,
    world_config: WorldConfig | None,
    network: tuple[Association, ...] | None,
    world: World | None = None,
) -> tuple[int, RunSpec, Simulation]:
    """A new run stored with status created: its id, its spec as stored, its simulation.

    The spec is stored with its world preset and sensor definition resolved by name. A
    `world` given (a robot) replaces the preset's simulated one.
    """
    check_hz(spec.hz)
    chosen, catalog = setup(spec, catalog)
    chosen = chosen.resolved()
    spec = replace(spec, world=chosen.world, sensors=chosen.sensors)
    config = world.config if world is not None else world_config or chosen.world_config()
    sim = new_simulation(spec, catalog, config, network, world)
    pairs = tuple(pair(sim, a) for a in sim.brain.network)
    run_id = store.create_run(spec, pairs)
    # A checkpoint before the first tick: a run can be rebuilt whatever network it
    # started from (an edited one may change later) and however early it stopped.
    state = export_state(sim)
    state["last_external_reward_id"] = 0
    store.end_episodes(run_id, (), Checkpoint(0, 0, encode(state)), RunTotals(0, 0, 0))
    return run_id, spec, sim


@dataclass(frozen=True, slots=True)
class Restored:
    """A stored run rebuilt from its last checkpoint, with the log it replays from there."""

    spec: RunSpec
    """As stored, in the mode asked for."""
    sim: Simulation
    stored: StoredRun
    totals: RunTotals
    last_external_id: int
    """The newest trainer's reward the checkpoint holds."""
    pacer: Pacer | None = None
    """A robot's clock (None: the engine's own)."""

    @property
    def replays(self) -> bool:
        """Whether the run re-runs its ticks after the checkpoint: not on a robot.

        A robot cannot run those ticks again: a robot run resumes at the start of the
        episode it stopped in, as a person puts the robot back at the start. The rewards
        and edits logged in that episode stay in the log; the learning they brought is lost.
        """
        return self.pacer is None


def restore_run(
    run_id: int,
    store: RunStore,
    *,
    catalog: Catalog | None,
    world_config: WorldConfig | None,
    mode: Mode | None,
    connect: Connect | None = None,
) -> Restored:
    """A stored run (neither finished nor running) rebuilt from its last checkpoint.

    It runs in the world and sensor definition it was stored with (the defaults for a
    run stored before runs kept them); a robot's run (world ``ros2:ROBOT``) on the robot
    `connect` reaches (`RunStateError` without it).
    """
    stored = store.load_run(run_id)
    if stored.status in (RunStatus.FINISHED, RunStatus.RUNNING):
        raise RunStateError(f"run {run_id} is {stored.status.value}: nothing to resume")
    robot = robot_of(stored.spec.world)
    if robot is None:
        return _restore(run_id, stored, catalog, world_config, mode, None)
    if connect is None:
        raise RunStateError(
            f"run {run_id} drives the robot {robot!r}: `srlab serve` runs it (docs/robots.md)"
        )
    world, pacer = connect(stored.spec)
    try:
        return replace(_restore(run_id, stored, catalog, world_config, mode, world), pacer=pacer)
    except BaseException:
        close = getattr(world, "close", None)
        if close is not None:
            close()
        raise


def _restore(
    run_id: int,
    stored: StoredRun,
    catalog: Catalog | None,
    world_config: WorldConfig | None,
    mode: Mode | None,
    world: World | None,
) -> Restored:
    spec = stored.spec
    chosen, catalog = setup(spec, catalog)
    world_config = world_config or chosen.world_config()
    if mode is not None:
        spec = replace(spec, mode=mode)
    cond, config = condition(spec)
    if stored.checkpoint is None:  # stored before runs got a checkpoint at creation
        sim = new_simulation(spec, catalog, world_config, None, world)
        return Restored(spec, sim, stored, RunTotals(0, 0, 0), 0)
    state = decode(stored.checkpoint.state)
    sim = restore_simulation(
        cond,
        spec.seed,
        state,
        catalog,
        world_config=world_config,
        defer_rewards=True,
        brain_config=config,
        world=world,
    )
    sim.brain.window = reaction_window(spec)
    skip = int(state.get("last_external_reward_id", 0))
    return Restored(spec, sim, stored, stored.totals, skip)
