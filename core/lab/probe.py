"""The placement probe: which responses to each camera obstacle stimulus are correct.

Correctness is computed from the world, not written by hand. For a stimulus S, the probe
places the robot and the obstacle in K placements inside S's definition (drawn at random,
kept when S is what the camera reports), and from each one lets the robot answer S with a
behaviour B: whenever S is active the robot runs B, otherwise it drives straight on
(goforward3, holding the corridor's heading), with no other obstacle knowledge and no wall
reflex. The placement is passed when the robot gets past the obstacle without touching it
or a wall within `PASS_TICKS`. B is a **correct** response to S when it passes at least
`CORRECT_SHARE` of the placements; a stimulus whose best response passes less has no
correct response under its definition (it does not tell the robot enough).

The placements are on leg 0, the straight the robot starts on, away from its corners; the
robot's heading is the corridor's, give or take 8 degrees; the obstacle is 0.6-1.5 m ahead
of the camera, anywhere the world places obstacles across the corridor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.brain.catalog import Catalog
from core.brain.motor import Motor, cruise_scale
from core.brain.sensors import compile_detector
from core.run.setup import Setup
from core.sim.world import WorldConfig, make_world

CAMERA_SENSOR = "camera_obstacle"
PASS_TICKS = 80
"""Ticks a placement has to get past the obstacle (8 s; at the 0.25 m/s of a turn, 2 m)."""
CORRECT_SHARE = 0.75
"""A response passing at least this share of a stimulus's placements is correct."""
CANDIDATE_FAMILIES = ("forward", "turn", "stop")
"""The behaviours the probe tries (the wall-avoid and back reflexes are not responses to a
camera stimulus)."""
LANES = {"L": (0.22, 0.4), "M": (-0.18, 0.18), "R": (-0.4, -0.22)}
"""Robot lateral offsets the probe draws for each lane (the position sensor's thirds, kept
0.2 m from the walls)."""


@dataclass(frozen=True, slots=True)
class Placement:
    """A robot pose and an obstacle centre, on the map."""

    x: float
    y: float
    heading_rad: float
    obstacle: tuple[float, float]


@dataclass(frozen=True, slots=True)
class StimulusProbe:
    """What the probe found for one stimulus: each behaviour's share of placements passed."""

    stimulus: str
    placements: int
    passed: dict[str, float]

    @property
    def correct(self) -> frozenset[str]:
        """The behaviours that pass at least `CORRECT_SHARE` of the placements."""
        return frozenset(b for b, share in self.passed.items() if share >= CORRECT_SHARE)

    @property
    def best(self) -> tuple[str, float]:
        """The behaviour that passes most placements, and its share (ties: first listed)."""
        name = max(self.passed, key=lambda b: self.passed[b])
        return name, self.passed[name]


@dataclass(frozen=True, slots=True)
class ProbeResult:
    """The probe of every camera obstacle stimulus under a world and a sensor definition."""

    world: str
    sensors: str
    k: int
    seed: int
    stimuli: dict[str, StimulusProbe]

    def correct(self) -> dict[str, frozenset[str]]:
        """Stimulus name -> its correct responses."""
        return {s: p.correct for s, p in self.stimuli.items()}

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form (see `from_dict`)."""
        return {
            "world": self.world,
            "sensors": self.sensors,
            "k": self.k,
            "seed": self.seed,
            "pass_ticks": PASS_TICKS,
            "correct_share": CORRECT_SHARE,
            "stimuli": {
                s: {"placements": p.placements, "passed": p.passed, "correct": sorted(p.correct)}
                for s, p in self.stimuli.items()
            },
        }

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> ProbeResult:
        """The result `as_dict` gave."""
        raw = d["stimuli"]
        assert isinstance(raw, dict)
        stimuli = {
            s: StimulusProbe(s, int(v["placements"]), {b: float(x) for b, x in v["passed"].items()})
            for s, v in raw.items()
        }
        return cls(
            str(d["world"]), str(d["sensors"]), int(str(d["k"])), int(str(d["seed"])), stimuli
        )


class _Prober:
    """One world and catalogue, reused for every placement and behaviour."""

    def __init__(self, config: WorldConfig, catalog: Catalog) -> None:
        self.world = make_world(config)
        self.catalog = catalog
        self.detect = compile_detector(catalog)
        robot = config.robot
        cruise = "goforward3"
        self.motor = Motor(
            catalog,
            robot.align_gain,
            robot.max_turn_rad_s,
            config.dt_s,
            cruise_scale(catalog, robot, cruise),
        )
        self.forward = catalog.behaviour(cruise).id
        geo = self.world.geometry
        self.leg_length = float(geo.leg_lengths_m[0])
        self.clear_m = config.track.obstacle.size_m / 2 + robot.length_m / 2

    def draw(self, stimulus: int, lane: str, rng: np.random.Generator) -> Placement | None:
        """A random placement in `lane` (None when `stimulus` is not what it shows)."""
        geo = self.world.geometry
        config = self.world.config
        half = config.track.corridor_width_m / 2
        along = float(rng.uniform(half + 0.6, self.leg_length - half - 2.2))
        lo, hi = LANES[lane]
        lateral = float(rng.uniform(lo, hi))
        heading = float(rng.uniform(-1.0, 1.0)) * math.radians(8.0)
        ahead = float(rng.uniform(0.6, 1.5)) + config.robot.camera_offset_m
        limit = config.track.obstacle.max_lateral_m
        obstacle_lateral = float(rng.uniform(-limit, limit))
        x, y = geo.point_on_leg(0, along, lateral)
        obstacle = geo.point_on_leg(0, along + ahead, obstacle_lateral)
        self.world.reset(0, 0)
        frame = self.world.place(x, y, heading, obstacle)
        camera = [
            s
            for s in self.detect(frame.channels.tolist())
            if self.catalog.stimuli[s].sensor == CAMERA_SENSOR
        ]
        return Placement(x, y, heading, obstacle) if camera == [stimulus] else None

    def passes(self, p: Placement, stimulus: int, behaviour: int) -> bool:
        """Whether answering `stimulus` with `behaviour` gets the robot past the obstacle."""
        world, motor = self.world, self.motor
        world.reset(0, 0)
        frame = world.place(p.x, p.y, p.heading_rad, p.obstacle)
        motor.stop()
        obstacle_x = p.obstacle[0]
        for _ in range(PASS_TICKS):
            channels = frame.channels.tolist()
            if not motor.busy:
                answer = stimulus in self.detect(channels)
                motor.start(behaviour if answer else self.forward, channels)
            world.apply(motor.command(channels))
            frame = world.step()
            if frame.collision is not None:
                return False
            if frame.x > obstacle_x + self.clear_m:
                return True
        return False


def probe(setup: Setup, k: int = 20, seed: int = 0) -> ProbeResult:
    """Probe every camera obstacle stimulus of `setup`'s sensor definition in its world."""
    if k < 1:
        raise ValueError("k must be >= 1")
    setup = setup.resolved()
    catalog = setup.catalog()
    prober = _Prober(setup.world_config(), catalog)
    candidates = [b for b in catalog.behaviours if b.family in CANDIDATE_FAMILIES]
    out: dict[str, StimulusProbe] = {}
    for st in catalog.stimuli_of_sensor(CAMERA_SENSOR):
        rng = np.random.default_rng(np.random.SeedSequence([seed, st.id, 17]))
        lane = st.name.split("_")[1]
        placements: list[Placement] = []
        for _ in range(2000 * k):
            p = prober.draw(st.id, lane, rng)
            if p is not None:
                placements.append(p)
                if len(placements) == k:
                    break
        if not placements:
            out[st.name] = StimulusProbe(st.name, 0, {b.name: 0.0 for b in candidates})
            continue
        passed = {
            b.name: sum(prober.passes(p, st.id, b.id) for p in placements) / len(placements)
            for b in candidates
        }
        out[st.name] = StimulusProbe(st.name, len(placements), passed)
    return ProbeResult(setup.world_name, setup.sensors_name, k, seed, out)


def fingerprint(setup: Setup, k: int, seed: int) -> str:
    """What a probe's result depends on, as a short hash (a cache key)."""
    import hashlib

    setup = setup.resolved()
    catalog = setup.catalog()
    parts = [
        repr(setup.world_config()),
        repr([s for s in catalog.stimuli if s.sensor == CAMERA_SENSOR]),
        repr([s for s in catalog.stimuli if s.sensor == "position"]),
        repr(catalog.behaviours),
        repr((k, seed, PASS_TICKS, CORRECT_SHARE, CANDIDATE_FAMILIES, LANES, PROBE_VERSION)),
    ]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]


PROBE_VERSION = 1
"""Bumped whenever the probe's procedure changes, so cached results are not reused."""
