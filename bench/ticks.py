"""Ticks per second: bare pymunk against the world and the full architecture, and memory.

Run as ``.venv/bin/python -m bench.ticks``. Everything is measured side by side in one run
after a warm-up, so the ratios hold on any machine, for every world preset:

(a) bare pymunk: the preset's track walls and robot box, one physics step and eight sonar
    ray casts (``segment_query_first``) per tick;
(b) the world alone: ``PymunkWorld.step()`` (physics plus analytic sensing; on a corridor
    track from a world file, ``CorridorWorld.step()`` with its walls as segments and its
    moving obstacles);
(c) the full architecture, ``expert``: sense, perceive, select, motor, step, record;
(d) the full architecture, ``kp``: (c) with learning, exploration and propagation.

Then ``delayed`` runs for many episodes under tracemalloc, to show memory stays flat.
"""

from __future__ import annotations

import argparse
import gc
import math
import time
import tracemalloc
from collections.abc import Callable
from functools import partial

import pymunk

from core.run.conditions import get_condition
from core.run.setup import Setup
from core.run.simulation import Simulation
from core.sim.channels import Channel
from core.sim.corridor import CorridorConfig
from core.sim.robot import RobotConfig
from core.sim.types import Geometry, build_geometry
from core.sim.world import MotorCommand, WorldConfig, make_world
from core.sim.worlds import load_world, world_names

Stepper = Callable[[int], None]
"""Runs n ticks."""

CHECK_EVERY = 500
"""Ticks between clock reads while measuring."""


def measure(run: Stepper, seconds: float, warmup_s: float) -> float:
    """Ticks per second of `run`, after `warmup_s` of warm-up."""
    for budget, keep in ((warmup_s, False), (seconds, True)):
        ticks = 0
        start = time.perf_counter()
        while True:
            run(CHECK_EVERY)
            ticks += CHECK_EVERY
            elapsed = time.perf_counter() - start
            if elapsed >= budget:
                break
        if keep:
            return ticks / elapsed
    raise AssertionError("unreachable")


def first_straight(geo: Geometry) -> Callable[[float, float], bool]:
    """Whether a point is past the start leg's last 0.5 m before its corner."""
    x0, y0, th = geo.start_pose
    dx, dy = math.cos(th), math.sin(th)
    end_x, end_y = (float(v) for v in geo.vertices[geo_start_leg(geo)])
    limit = (end_x - x0) * dx + (end_y - y0) * dy - 0.5
    return lambda x, y: (x - x0) * dx + (y - y0) * dy > limit


def geo_start_leg(geo: Geometry) -> int:
    """The leg the start pose is on (the ring's is leg 0)."""
    return geo.config.start_segment if isinstance(geo.config, CorridorConfig) else 0


def bare_pymunk(config: WorldConfig) -> Stepper:
    """The track and the robot in plain pymunk, driven up and down the start leg."""
    robot: RobotConfig = config.robot
    geo = build_geometry(config.track)
    space = pymunk.Space()
    for a, b in geo.wall_segments():
        space.add(pymunk.Segment(space.static_body, a, b, 0.01))
    body = pymunk.Body(
        robot.mass_kg, pymunk.moment_for_box(robot.mass_kg, (robot.length_m, robot.width_m))
    )
    shape = pymunk.Poly.create_box(body, (robot.length_m, robot.width_m))
    shape.filter = pymunk.ShapeFilter(group=1)  # the sonars do not see the robot itself
    space.add(body, shape)
    sonar_filter = pymunk.ShapeFilter(group=1)
    angles = [math.radians(a) for a in robot.sonar_angles_deg]
    mount, reach = robot.sonar_mount_m, robot.sonar_range_m
    x0, y0, th0 = geo.start_pose
    past = first_straight(geo)
    dt, speed = config.dt_s, 0.45
    readings = [0.0] * 8

    def reset() -> None:
        body.position = (x0, y0)
        body.angle = th0
        body.angular_velocity = 0.0
        space.reindex_shapes_for_body(body)

    def run(n: int) -> None:
        for _ in range(n):
            th = body.angle
            body.velocity = (speed * math.cos(th), speed * math.sin(th))
            space.step(dt)
            p = body.position
            th = body.angle
            for i, a in enumerate(angles):
                dx, dy = math.cos(th + a), math.sin(th + a)
                start = (p.x + mount * dx, p.y + mount * dy)
                end = (start[0] + reach * dx, start[1] + reach * dy)
                hit = space.segment_query_first(start, end, 0.0, sonar_filter)
                readings[i] = reach * hit.alpha if hit is not None else reach
            if past(p.x, p.y):
                reset()

    reset()
    return run


def world_only(config: WorldConfig) -> Stepper:
    """The world's `step()` with a heading hold down the start leg, reset before the corner."""
    world = make_world(config)
    episode = 0
    frame = world.reset(0, episode)
    past = first_straight(world.geometry)
    heading_error = int(Channel.HEADING_ERROR_RAD)

    def run(n: int) -> None:
        nonlocal frame, episode
        for _ in range(n):
            world.apply(MotorCommand(0.45, -2.0 * float(frame.channels[heading_error])))
            frame = world.step()
            if frame.collision is not None or past(frame.x, frame.y):
                episode += 1
                frame = world.reset(0, episode)

    return run


def architecture(condition: str, world: str, seed: int = 0) -> Stepper:
    """A whole `Simulation` of a condition in a world preset, reset at every episode's end."""
    setup = Setup(world)
    sim = Simulation(
        get_condition(condition), seed, catalog=setup.catalog(), world_config=setup.world_config()
    )
    sim.reset()
    tick, reset = sim.tick, sim.reset

    def run(n: int) -> None:
        for _ in range(n):
            if tick().snapshot.done:
                reset()

    return run


def memory_check(episodes: int, seed: int = 0) -> None:
    """Run `delayed` for many episodes and print traced memory along the way."""
    marks = sorted({m for m in (10, 100) if m < episodes} | {episodes})
    gc.collect()
    tracemalloc.start()
    sim = Simulation(get_condition("delayed"), seed)
    started = time.perf_counter()
    ticks = 0
    for episode in range(1, episodes + 1):
        sim.reset()
        while not sim.tick().snapshot.done:
            pass
        ticks = sim.tick_count
        if episode in marks:
            gc.collect()
            current, peak = tracemalloc.get_traced_memory()
            print(
                f"  after episode {episode:>5}: {current / 1024:8.1f} KiB traced "
                f"(peak {peak / 1024:8.1f} KiB), STM {len(sim.brain.stm):>4}, "
                f"LTM {len(sim.brain.ltm):>3}, network {len(sim.brain.network):>3}, "
                f"{ticks:,} ticks"
            )
    tracemalloc.stop()
    print(f"  ({time.perf_counter() - started:.1f} s under tracemalloc)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--seconds", type=float, default=5.0, help="measuring time per case (default 5)"
    )
    parser.add_argument(
        "--warmup", type=float, default=1.0, help="warm-up time per case (default 1)"
    )
    parser.add_argument(
        "--world", action="append", choices=world_names(), help="a preset (default: every one)"
    )
    parser.add_argument(
        "--episodes",
        type=int,
        default=1000,
        help="episodes of the memory check (default 1000; 0 skips it)",
    )
    args = parser.parse_args()
    if args.seconds <= 0 or args.warmup < 0 or args.episodes < 0:
        parser.error("--seconds must be positive, --warmup and --episodes not negative")

    print(f"ticks/s, {args.seconds:g} s each after {args.warmup:g} s of warm-up")
    for name in args.world or world_names():
        config = load_world(name).config
        cases: list[tuple[str, Callable[[], Stepper]]] = [
            ("bare pymunk (step + 8 ray casts)", partial(bare_pymunk, config)),
            ("world only (PymunkWorld.step)", partial(world_only, config)),
            ("full architecture, expert", partial(architecture, "expert", name)),
            ("full architecture, kp", partial(architecture, "kp", name)),
        ]
        print(f"world {name}:")
        rates: list[float] = []
        for label, build in cases:
            rate = measure(build(), args.seconds, args.warmup)
            rates.append(rate)
            print(f"  {label:<34} {rate:>10,.0f}")
        bare, world, expert, kp = rates
        print(f"  world / bare    {world / bare:5.2f}")
        print(f"  full / bare     {expert / bare:5.2f}  (expert; goal: full >= 0.7 x bare)")
        print(f"  kp / bare       {kp / bare:5.2f}")

    if args.episodes:
        print(f"memory, delayed, {args.episodes} episodes (tracemalloc):")
        memory_check(args.episodes)


if __name__ == "__main__":
    main()
