"""Checkpoints: a simulation's learning state at an episode boundary, as compressed JSON.

Resuming a run rebuilds its simulation from the last checkpoint and replays the command
log after it, so the state needs only what an episode boundary does not reset: LTM, RLTM,
the behaviour network, synthesised behaviours, STM, the exploration generator and the
counters. Names, not ids, so a checkpoint survives a catalogue that grew.
"""

from __future__ import annotations

import json
import zlib
from typing import Any

from core.brain.brain import BrainConfig
from core.brain.catalog import Behaviour, Catalog
from core.brain.network import Association, BehaviourNetwork
from core.errors import CoreError
from core.run.conditions import Condition
from core.run.simulation import Simulation
from core.sim.world import World, WorldConfig

VERSION = 1


class CheckpointError(CoreError):
    """A checkpoint that cannot be read."""


def export_state(sim: Simulation) -> dict[str, Any]:
    """The learning state of a simulation between episodes."""
    brain = sim.brain
    cat = brain.catalog
    s = [x.name for x in cat.stimuli]
    b = [x.name for x in cat.behaviours]
    kp = brain.kp
    return {
        "version": VERSION,
        "episode": sim.episode,
        "tick": sim.tick_count,
        "ltm": [[s[i], b[j], v] for (i, j), v in brain.ltm.items()],
        "rltm": [[s[i], b[j], v] for (i, j), v in (kp.rltm.items() if kp else ())],
        "network": [
            [s[a.stimulus], b[a.behaviour], a.strength, a.source, a.locked] for a in brain.network
        ],
        "synthesized": [
            {
                "name": x.name,
                "family": x.family,
                "speed_mps": x.speed_mps,
                "turn_dps": x.turn_dps,
                "ticks": x.ticks,
                "mode": x.mode,
            }
            for x in cat.behaviours
            if x.synthesized
        ],
        # Taken between episodes: an STM the next episode starts by clearing is dead, but
        # for the records kept aside for rewards pressed at the episode's end.
        "stm": []
        if brain.config.learning.clear_stm_each_episode
        else [[t, s[i], b[j]] for t, i, j in brain.stm],
        "ended_stm": [[t, s[i], b[j]] for t, i, j in brain.kept(sim.tick_count)]
        if brain.config.learning.clear_stm_each_episode
        else [],
        "rng": brain.rng.bit_generator.state,
        "ticks_by_origin": dict(sim.ticks_by_origin),
        # A simulated teacher draws its imperfections from a generator of its own.
        **({"teacher_rng": sim.teacher.rng.bit_generator.state} if sim.teacher else {}),
    }


def encode(state: dict[str, Any]) -> bytes:
    """Compressed JSON of a state."""
    return zlib.compress(json.dumps(state, separators=(",", ":")).encode(), 6)


def decode(blob: bytes) -> dict[str, Any]:
    """The state in a compressed JSON blob."""
    try:
        state: dict[str, Any] = json.loads(zlib.decompress(blob))
    except (zlib.error, ValueError) as e:
        raise CheckpointError(f"unreadable checkpoint: {e}") from e
    if state.get("version") != VERSION:
        raise CheckpointError(f"checkpoint version {state.get('version')!r} is not {VERSION}")
    return state


def restore_simulation(
    condition: Condition,
    seed: int,
    state: dict[str, Any],
    catalog: Catalog,
    *,
    world_config: WorldConfig | None = None,
    defer_rewards: bool = False,
    brain_config: BrainConfig | None = None,
    world: World | None = None,
) -> Simulation:
    """A simulation in the state `export_state` gave, in `world` if given (a robot).

    Its next `reset()` starts the episode after the checkpointed one.
    """
    for spec in state["synthesized"]:
        if not any(x.name == spec["name"] for x in catalog.behaviours):
            catalog = catalog.with_behaviour(Behaviour(id=-1, synthesized=True, **spec))
    sid = {x.name: x.id for x in catalog.stimuli}
    bid = {x.name: x.id for x in catalog.behaviours}
    try:
        network = BehaviourNetwork(
            len(catalog.stimuli),
            (
                Association(sid[st], bid[be], strength, source, locked)
                for st, be, strength, source, locked in state["network"]
            ),
        )
        sim = Simulation(
            condition,
            seed,
            world=world,
            world_config=world_config,
            catalog=catalog,
            network=network,
            defer_rewards=defer_rewards,
            brain_config=brain_config,
        )
        brain = sim.brain
        for st, be, v in state["ltm"]:
            brain.ltm.set(sid[st], bid[be], v)
        if brain.kp is not None:
            for st, be, v in state["rltm"]:
                brain.kp.rltm[(sid[st], bid[be])] = v
        # The ended episode's kept records go into STM: the next episode's reset sets
        # them aside again (absent from checkpoints written before they were kept).
        for t, st, be in [*state.get("ended_stm", ()), *state["stm"]]:
            brain.stm.push((t, sid[st], bid[be]))
    except KeyError as e:
        raise CheckpointError(f"the checkpoint names {e} which the catalogue lacks") from e
    brain.rng.bit_generator.state = state["rng"]
    if sim.teacher is not None and "teacher_rng" in state:
        sim.teacher.rng.bit_generator.state = state["teacher_rng"]
    sim.episode = int(state["episode"])
    sim.tick_count = int(state["tick"])
    # Absent from checkpoints written before the counts were kept: those start at 0.
    sim.ticks_by_origin = {str(k): int(v) for k, v in state.get("ticks_by_origin", {}).items()}
    return sim
