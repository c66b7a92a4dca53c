"""The motor module: turns the running behaviour into a wheel command each tick."""

from __future__ import annotations

import math

from core.brain.catalog import Behaviour, Catalog
from core.sim.channels import Channel
from core.sim.robot import RobotConfig
from core.sim.types import MotorCommand

_HEADING_ERROR = int(Channel.HEADING_ERROR_RAD)
_HEADING = int(Channel.HEADING_RAD)
_ALIGN, _STEER, _CONSTANT = 0, 1, 2
_TWO_PI = 2 * math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % _TWO_PI - math.pi


def cruise_scale(catalog: Catalog, robot: RobotConfig, cruise: str = "goforward3") -> float:
    """The factor on the forward primitives' speeds that runs `cruise` at the robot's cruise.

    1.0 (exactly) when the robot cruises at the catalogue's speed of `cruise`.
    """
    nominal = catalog.behaviour(cruise).speed_mps
    if nominal <= 0.0:
        raise ValueError(f"the cruise behaviour {cruise!r} does not move forward")
    return robot.cruise_speed_mps / nominal


class Motor:
    """Runs one motor primitive at a time for its duration.

    ``align`` primitives hold the corridor's heading with a proportional controller on the
    odometry's heading error; ``steer`` primitives turn towards a heading fixed when they
    start (the corridor's direction plus their angle); ``constant`` ones run as given. The
    forward primitives' speeds are the catalogue's times `forward_scale` (see
    `cruise_scale`).
    """

    def __init__(
        self,
        catalog: Catalog,
        align_gain: float,
        max_turn_rad_s: float,
        dt_s: float,
        forward_scale: float = 1.0,
    ) -> None:
        self._dt = dt_s
        self._gain = align_gain
        self._max_turn = max_turn_rad_s
        self._forward_scale = forward_scale
        self._speed: list[float] = []
        self._rate: list[float] = []
        self._angle: list[float] = []
        self._mode: list[int] = []
        self._ticks: list[int] = []
        for b in catalog.behaviours:
            self.add_behaviour(b)
        self.running = -1
        self.remaining = 0
        self._target = 0.0

    def add_behaviour(self, b: Behaviour) -> None:
        """Make a behaviour runnable (the catalogue's, or one synthesised later)."""
        rate = math.radians(b.turn_dps)
        forward = b.family == "forward" and not b.synthesized
        self._speed.append(b.speed_mps * self._forward_scale if forward else b.speed_mps)
        self._rate.append(rate)
        self._angle.append(rate * b.ticks * self._dt)
        self._mode.append({"align": _ALIGN, "steer": _STEER}.get(b.mode, _CONSTANT))
        self._ticks.append(b.ticks)

    @property
    def busy(self) -> bool:
        """Whether a multi-tick primitive is still running."""
        return self.remaining > 0

    def start(self, behaviour: int, channels: list[float]) -> None:
        """Begin running a behaviour (replacing whatever ran)."""
        self.running = behaviour
        self.remaining = self._ticks[behaviour]
        if self._mode[behaviour] == _STEER:
            corridor = channels[_HEADING] - channels[_HEADING_ERROR]
            self._target = corridor + self._angle[behaviour]

    def stop(self) -> None:
        """Abandon the running primitive."""
        self.running = -1
        self.remaining = 0

    def command(self, channels: list[float]) -> MotorCommand:
        """This tick's wheel command; counts one tick of the running primitive."""
        b = self.running
        if b < 0:
            return MotorCommand(0.0, 0.0)
        self.remaining -= 1
        mode = self._mode[b]
        if mode == _ALIGN:
            turn = -self._gain * channels[_HEADING_ERROR]
            lim = self._max_turn
        elif mode == _STEER:
            turn = _wrap(self._target - channels[_HEADING]) / self._dt
            lim = abs(self._rate[b])
        else:
            return MotorCommand(self._speed[b], self._rate[b])
        return MotorCommand(self._speed[b], lim if turn > lim else max(turn, -lim))
