"""The stop line's beacon on constructed frames: heard near the line, never far from it.

The robot is placed still on the signal's leg, its nose a given distance before the stop
line, and the lamp cycles through red, green and yellow. Near the line the `beacon_phase`
channel carries the lamp's colour from the beacon's last message (repeated every
`beacon_period_s`); far from it, and in a world without a beacon, it is 0. The beacon's
stimuli follow the channel; the camera's colour stimuli are the far ones.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from core.brain.catalog import load_catalog
from core.brain.sensors import compile_detector
from core.sim.channels import Channel
from core.sim.types import LampColor
from core.sim.world import PymunkWorld
from core.sim.worlds import load_world

TICKS = 400
"""Long enough for the lamp to show each colour at least once (a cycle is <= 17.5 s)."""
COLOURS = {LampColor.RED: "Red", LampColor.YELLOW: "Yellow", LampColor.GREEN: "Green"}


def watch(
    world_name: str, front_to_line_m: float, seed: int = 3
) -> list[tuple[int, float, LampColor, list[str]]]:
    """(tick, beacon_phase, lamp, active stimulus names) each tick, the robot held still."""
    world = PymunkWorld(load_world(world_name).config)
    world.reset(seed, 0)
    geo = world.geometry
    leg = world.config.track.signal.leg
    d = geo.directions[leg]
    back = front_to_line_m + world.config.robot.length_m / 2
    x, y = np.asarray(geo.stopline_point) - d * back
    frame = world.place(float(x), float(y), math.atan2(d[1], d[0]), None)
    catalog = load_catalog()
    detect = compile_detector(catalog)
    out = []
    for _ in range(TICKS):
        channels = frame.channels.tolist()
        names = [catalog.stimuli[i].name for i in detect(channels)]
        out.append((frame.tick, channels[Channel.BEACON_PHASE], frame.lamp, names))
        frame = world.step()
    return out


def test_near_the_line_the_beacon_tells_each_colour_at_its_last_message() -> None:
    config = load_world("stop-line").config.track.signal
    period = round(config.beacon_period_s / 0.1)
    seen = watch("stop-line", 0.02)
    lamps = {t: lamp for t, _, lamp, _ in seen}
    heard = [(t, phase) for t, phase, _, _ in seen if phase]
    assert heard and heard[0][0] < seen[0][0] + period  # the first message within a period
    for t, phase in heard:
        # the colour the lamp showed at one of the last `period` ticks
        assert phase in {float(lamps[u]) for u in range(max(seen[0][0], t - period + 1), t + 1)}
    assert {phase for _, phase in heard} == {1.0, 2.0, 3.0}
    for _, phase, _, names in seen:
        beacon = [n for n in names if n.startswith("Beacon")]
        assert beacon == ([f"Beacon{COLOURS[LampColor(int(phase))]}"] if phase else [])
        # the camera's colour stimuli start 0.2 m (the robot's centre) before the line
        assert not {"Red", "Yellow", "Green"} & set(names)


def test_far_from_the_line_the_camera_sees_the_colour_and_the_beacon_is_silent() -> None:
    seen = watch("stop-line", 0.5)
    assert all(phase == 0.0 for _, phase, _, _ in seen)
    shown = set()
    for _, _, lamp, names in seen:
        assert not [n for n in names if n.startswith("Beacon")]
        assert COLOURS[lamp] in names
        shown.add(lamp)
    assert shown == set(COLOURS)


def test_a_world_without_a_beacon_never_hears_one() -> None:
    assert load_world("soft-obstacle").config.track.signal.beacon is False
    seen = watch("soft-obstacle", 0.02)
    assert all(phase == 0.0 for _, phase, _, _ in seen)
    assert not any(n.startswith("Beacon") for _, _, _, names in seen for n in names)


def test_a_corridor_world_file_with_a_beacon_hears_it_near_its_stop_line(tmp_path: Path) -> None:
    from core.sim.corridor_world import CorridorWorld

    text = (Path(__file__).parents[3] / "core" / "data" / "worlds" / "u-shape.toml").read_text()
    with_beacon = text.replace(
        "signal = { segment = 1, fraction = 0.5 }",
        "signal = { segment = 1, fraction = 0.5, beacon = true, beacon_range_m = 0.2 }",
    )
    (tmp_path / "beacon.toml").write_text(with_beacon)
    heard = {}
    for name, path in (("with", tmp_path / "beacon.toml"), ("without", None)):
        world = CorridorWorld(load_world(str(path) if path else "u-shape").config)
        world.reset(3, 0)
        geo = world.geometry
        d = geo.directions[1]
        x, y = np.asarray(geo.stopline_point) - d * (0.05 + world.config.robot.length_m / 2)
        frame = world.place(float(x), float(y), math.atan2(d[1], d[0]), None)
        phases = []
        for _ in range(TICKS):
            phases.append(frame.channels[Channel.BEACON_PHASE])
            frame = world.step()
        heard[name] = phases
    assert any(heard["with"]) and not any(heard["without"])
