"""The brain's overhead on the outside worlds: the environment's own step against srlab's tick.

Run as ``.venv/bin/python -m bench.outside`` (needs the srlab[worlds] extra:
``make install-worlds``). For each outside world, side by side in one run, timing steps
only (an episode's reset is left out of all three):

(a) the environment alone: its own step (MiniGrid's ``env.step`` with its observation;
    ir-sim's ``env.step``, which runs its lidar), actions drawn at random;
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


def measure(world: OutsideWorld, steps: int) -> tuple[float, float, float]:
    """Seconds per step of (a), (b) and (c) over `steps` steps each."""
    env = world.make()
    n_b = len(world.catalog.behaviours)
    rng = np.random.default_rng(0)
    out = []
    try:
        for mode in ("bare", "adapter", "brain"):
            brain = brain_for(world, world.condition("kp"), 0)
            bare = _bare_step(world, env)
            channels = env.reset(episode_seed(0, 0))
            brain.reset_episode()
            spent, done_steps, episode = 0.0, 0, 0
            while done_steps < steps:
                t = time.perf_counter()
                if mode == "brain":
                    _, wheels = brain.step(done_steps, channels)
                    r = env.step(world.actions[brain.motor.running], wheels)
                    ended = r.outcome is not None
                    channels = r.channels
                elif mode == "adapter":
                    b = int(rng.integers(n_b))
                    beh = world.catalog.behaviours[b]
                    wheels = MotorCommand(beh.speed_mps, float(np.radians(beh.turn_dps)))
                    ended = env.step(world.actions[b], wheels).outcome is not None
                else:
                    ended = bare(int(rng.integers(n_b)))
                spent += time.perf_counter() - t
                done_steps += 1
                if ended:
                    episode += 1
                    channels = env.reset(episode_seed(0, episode))
                    brain.reset_episode()
            out.append(spent / steps)
    finally:
        env.close()
    return out[0], out[1], out[2]


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
