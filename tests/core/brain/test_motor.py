"""The motor module: align, steer and constant primitives and their duration."""

from __future__ import annotations

import math

import pytest
from fakes import channel_list

from core.brain.catalog import Catalog
from core.brain.motor import Motor
from core.sim.channels import Channel
from core.sim.world import MotorCommand

MAX_TURN = math.radians(150)


@pytest.fixture
def motor(catalog: Catalog) -> Motor:
    return Motor(catalog, align_gain=2.0, max_turn_rad_s=MAX_TURN, dt_s=0.1)


def pose(heading: float, heading_error: float) -> list[float]:
    return channel_list({Channel.HEADING_RAD: heading, Channel.HEADING_ERROR_RAD: heading_error})


def test_nothing_running_stands_still(motor: Motor) -> None:
    assert not motor.busy
    assert motor.running == -1
    assert motor.command(pose(0.0, 0.0)) == MotorCommand(0.0, 0.0)


def test_align_holds_the_corridor_heading(motor: Motor, catalog: Catalog) -> None:
    motor.start(catalog.behaviour("goforward3").id, pose(0.1, 0.1))
    cmd = motor.command(pose(0.1, 0.1))
    assert cmd.speed_mps == 0.45
    assert cmd.turn_rad_s == pytest.approx(-0.2)
    assert not motor.busy  # a one-tick primitive


def test_align_turn_is_clipped_to_the_top_rate(motor: Motor, catalog: Catalog) -> None:
    motor.start(catalog.behaviour("goforward1").id, pose(0.0, 0.0))
    assert motor.command(pose(-3.0, -3.0)) == MotorCommand(0.15, MAX_TURN)


def test_steer_turns_towards_a_heading_fixed_at_start(motor: Motor, catalog: Catalog) -> None:
    # On leg 1 (corridor heading pi/2) pointing 0.1 rad right of it.
    corridor = math.pi / 2
    motor.start(catalog.behaviour("leftturn90").id, pose(corridor - 0.1, -0.1))
    assert motor.busy
    assert motor.remaining == 6
    target = corridor + math.pi / 2
    headings = [corridor - 0.1, corridor + 0.4, corridor + 1.2, target - 0.05, target, target]
    commands = []
    for i, heading in enumerate(headings):
        # The heading error keeps changing; the target must not.
        commands.append(motor.command(pose(heading, 0.3 * i)))
        assert motor.remaining == 5 - i
    assert not motor.busy
    assert [c.speed_mps for c in commands] == [0.25] * 6
    assert commands[0].turn_rad_s == MAX_TURN  # 1.67 rad off: clipped
    assert commands[3].turn_rad_s == pytest.approx(0.05 / 0.1)
    assert commands[4].turn_rad_s == pytest.approx(0.0, abs=1e-12)


def test_steer_right_is_clipped_to_its_own_rate(motor: Motor, catalog: Catalog) -> None:
    motor.start(catalog.behaviour("rightturn30").id, pose(0.0, 0.0))
    assert motor.remaining == 2
    assert motor.command(pose(0.0, 0.0)) == MotorCommand(0.25, -MAX_TURN)
    # Past the target (-30 deg) it turns back.
    cmd = motor.command(pose(-math.radians(40), 0.0))
    assert cmd.turn_rad_s == pytest.approx(math.radians(10) / 0.1)


def test_steer_wraps_across_pi(motor: Motor, catalog: Catalog) -> None:
    # On leg 2 (heading pi): a left turn of 15 deg aims at pi + 15 deg, i.e. -165 deg.
    motor.start(catalog.behaviour("leftturn15").id, pose(math.pi, 0.0))
    cmd = motor.command(pose(-math.pi + math.radians(5), 0.0))
    assert cmd.turn_rad_s == pytest.approx(math.radians(10) / 0.1)


@pytest.mark.parametrize(("name", "expected"), [("stop", (0.0, 0.0)), ("back", (-0.2, 0.0))])
def test_constant_primitives_run_as_given(
    motor: Motor, catalog: Catalog, name: str, expected: tuple[float, float]
) -> None:
    b = catalog.behaviour(name)
    motor.start(b.id, pose(0.3, 0.3))
    commands = [motor.command(pose(0.3 * i, 0.1 * i)) for i in range(b.ticks)]
    assert commands == [MotorCommand(*expected)] * b.ticks
    assert not motor.busy


def test_start_replaces_and_stop_abandons(motor: Motor, catalog: Catalog) -> None:
    motor.start(catalog.behaviour("back").id, pose(0.0, 0.0))
    motor.command(pose(0.0, 0.0))
    assert motor.remaining == 4
    motor.start(catalog.behaviour("leftturn45").id, pose(0.0, 0.0))
    assert motor.running == catalog.behaviour("leftturn45").id
    assert motor.remaining == 3
    motor.stop()
    assert not motor.busy
    assert motor.command(pose(0.0, 0.0)) == MotorCommand(0.0, 0.0)
