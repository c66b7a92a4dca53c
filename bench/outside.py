"""The brain's overhead on the outside worlds: the environment's own step against srlab's tick.

Run as ``.venv/bin/python -m bench.outside`` (needs the srlab[worlds] extra:
``make install-worlds``). For each outside world, side by side in one run, interleaved 50
steps at a time, timing steps only (an episode's reset is left out of all three):

(a) the environment alone: its own step (MiniGrid's ``env.step`` with its observation;
    ir-sim's ``env.step``, which runs its lidar), replaying (c)'s actions;
(b) the adapter: (a) plus the channels mapping (observation -> named channels);
(c) the brain on the adapter, the ``kp`` condition: logical sensors, perception, selection,
    motor, STM, KP's RSTM, then (b).

Goal: (c) at most 1.3 x (a), the brain and the mapping adding at most 30% to the
environment's step time.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from core.outside.run import brain_for, episode_seed
from core.outside.world import OutsideWorld, load_outside, outside_names
from core.sim.types import MotorCommand

GOAL = 1.3


def _bare_step(world: OutsideWorld, env: Any) -> Callable[[int], bool]:
    """One raw environment step for a behaviour id; whether the episode ended."""
    if world.name.startswith("minigrid"):
        gym_env = env.env
        index = [("left", "right", "forward").index(a) for a in world.actions]

        def mg(b: int) -> bool:
            _, _, term, trunc, _ = gym_env.step(index[b])
            return bool(term or trunc)

        return mg
    raw = env.env
    behaviours = world.catalog.behaviours
    wheels = [[b.speed_mps, np.radians(b.turn_dps)] for b in behaviours]

    def irs(b: int) -> bool:
        raw.step(wheels[b])
        env.ticks += 1
        r = raw.robot
        return bool(r.collision or r.arrive or env.ticks >= env.max_ticks)

    return irs


def measure(world: OutsideWorld, steps: int, chunk: int = 50) -> tuple[float, float, float]:
    """Seconds per step of (a), (b) and (c) over `steps` steps each.

    Each runs on its own environment, interleaved `chunk` steps at a time so that the
    machine's drifting speed falls on all three alike: (c) steps first and its behaviours
    are recorded, then (b) and (a) replay them from the same episode seeds, so all three
    drive the same trajectories.
    """
    envs = {mode: world.make() for mode in ("brain", "adapter", "bare")}
    behaviours = world.catalog.behaviours
    wheels = [MotorCommand(b.speed_mps, float(np.radians(b.turn_dps))) for b in behaviours]
    brain = brain_for(world, world.condition("kp"), 0)
    bare = _bare_step(world, envs["bare"])
    chosen: list[int] = []
    spent = dict.fromkeys(envs, 0.0)
    episode = dict.fromkeys(envs, 0)
    channels = envs["brain"].reset(episode_seed(0, 0))
    for mode in ("adapter", "bare"):
        envs[mode].reset(episode_seed(0, 0))
    brain.reset_episode()
    try:
        for first in range(0, steps, chunk):
            last = min(steps, first + chunk)
            for mode, env in envs.items():
                for i in range(first, last):
                    t = time.perf_counter()
                    if mode == "brain":
                        _, command = brain.step(i, channels)
                        b = brain.motor.running
                        r = env.step(world.actions[b], command)
                        ended, channels = r.outcome is not None, r.channels
                        chosen.append(b)
                    elif mode == "adapter":
                        b = chosen[i]
                        ended = env.step(world.actions[b], wheels[b]).outcome is not None
                    else:
                        ended = bare(chosen[i])
                    spent[mode] += time.perf_counter() - t
                    if ended:
                        episode[mode] += 1
                        fresh = env.reset(episode_seed(0, episode[mode]))
                        if mode == "brain":
                            channels = fresh
                            brain.reset_episode()
    finally:
        for env in envs.values():
            env.close()
    return spent["bare"] / steps, spent["adapter"] / steps, spent["brain"] / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000, help="steps per measurement")
    parser.add_argument("--world", action="append", help="an outside world (default: all)")
    args = parser.parse_args()
    print(f"{'world':<18} {'(a) env steps/s':>16} {'(b) adapter':>12} {'(c) brain':>10} "
          f"{'(c)/(a)':>8} {'(c)/(b)':>8}  goal (c)/(a) <= {GOAL}")  # fmt: skip
    for name in args.world or outside_names():
        world = load_outside(name)
        measure(world, min(args.steps, 500))  # warm-up: imports, caches, the first scenes
        a, b, c = measure(world, args.steps)
        verdict = "ok" if c / a <= GOAL else "OVER"
        print(f"{name:<18} {1 / a:>16,.0f} {1 / b:>12,.0f} {1 / c:>10,.0f} "
              f"{c / a:>8.2f} {c / b:>8.2f}  {verdict}")  # fmt: skip


if __name__ == "__main__":
    main()
