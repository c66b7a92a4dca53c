"""The placement probe: correct responses computed from the world, in constructed layouts."""

from __future__ import annotations

import numpy as np
import pytest

from core.lab.probe import CORRECT_SHARE, Placement, ProbeResult, _Prober, fingerprint, probe
from core.run.setup import Setup

SETUP = Setup(sensors="path").resolved()


@pytest.fixture(scope="module")
def prober() -> _Prober:
    return _Prober(SETUP.world_config(), SETUP.catalog())


def placement_ahead(prober: _Prober, robot_lateral: float, obstacle_lateral: float) -> Placement:
    """The robot on leg 0 heading along it, the obstacle 1.2 m ahead of the camera."""
    geo = prober.world.geometry
    x, y = geo.point_on_leg(0, 1.5, robot_lateral)
    ahead = 1.2 + prober.world.config.robot.camera_offset_m
    return Placement(x, y, 0.0, geo.point_on_leg(0, 1.5 + ahead, obstacle_lateral))


@pytest.mark.parametrize(
    ("behaviour", "passes"),
    [("goforward3", False), ("leftturn45", True), ("rightturn45", True), ("stop", False)],
)
def test_an_obstacle_dead_ahead_is_passed_by_turning_either_way_not_by_going_on(
    prober: _Prober, behaviour: str, passes: bool
) -> None:
    cat = prober.catalog
    p = placement_ahead(prober, 0.0, 0.0)
    got = prober.passes(p, cat.stimulus("Obstacle_M_M").id, cat.behaviour(behaviour).id)
    assert got is passes


def test_an_obstacle_right_of_the_centre_line_is_passed_on_the_left(prober: _Prober) -> None:
    cat = prober.catalog
    p = placement_ahead(prober, 0.0, -0.1)
    mr = cat.stimulus("Obstacle_M_R").id
    assert prober.passes(p, mr, cat.behaviour("leftturn30").id)
    assert not prober.passes(p, mr, cat.behaviour("goforward3").id)


def test_a_placement_is_kept_only_when_the_camera_reports_its_stimulus(prober: _Prober) -> None:
    cat = prober.catalog
    rng = np.random.default_rng(0)
    mm = cat.stimulus("Obstacle_M_M").id
    kept = [p for p in (prober.draw(mm, "M", rng) for _ in range(300)) if p is not None]
    assert kept
    for p in kept[:5]:
        prober.world.reset(0, 0)
        frame = prober.world.place(p.x, p.y, p.heading_rad, p.obstacle)
        assert mm in prober.detect(frame.channels.tolist())


def test_probe_results_are_deterministic_round_trip_and_name_correct_sets() -> None:
    a = probe(SETUP, k=3, seed=1)
    b = probe(SETUP, k=3, seed=1)
    assert a == b
    assert set(a.stimuli) == {s.name for s in SETUP.catalog().stimuli_of_sensor("camera_obstacle")}
    for s in a.stimuli.values():
        assert s.placements == 3
        assert s.correct == {name for name, share in s.passed.items() if share >= CORRECT_SHARE}
    assert ProbeResult.from_dict(a.as_dict()) == a
    assert fingerprint(SETUP, 3, 1) == fingerprint(SETUP, 3, 1) != fingerprint(SETUP, 4, 1)
    assert fingerprint(Setup(sensors="paper"), 3, 1) != fingerprint(SETUP, 3, 1)
