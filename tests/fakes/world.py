"""A scripted world that plays back sensor frames without pymunk, and its frames."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core.sim.channels import Channel
from core.sim.track import TrackConfig, TrackGeometry
from core.sim.world import (
    CollisionKind,
    EpisodeLayout,
    LampColor,
    MotorCommand,
    SensorFrame,
    WorldConfig,
)

FloatArray = np.ndarray[Any, np.dtype[np.float64]]

UNSEEN = 99.0

NEUTRAL: Mapping[Channel, float] = {
    **{Channel(i): 3.0 for i in range(8)},
    **{Channel(8 + i): 0.0 for i in range(8)},
    Channel.LATERAL_OFFSET_M: 0.0,
    Channel.HEADING_ERROR_RAD: 0.0,
    Channel.VERTEX_AHEAD_M: 3.6,
    Channel.CORNER_PENDING: 0.0,
    Channel.OBSTACLE_VISIBLE: 0.0,
    Channel.OBSTACLE_DISTANCE_M: UNSEEN,
    Channel.OBSTACLE_LATERAL_M: UNSEEN,
    Channel.LAMP_COLOR: 0.0,
    Channel.STOPLINE_AHEAD_M: UNSEEN,
    Channel.BUMPER: 0.0,
    Channel.LEG: 0.0,
    Channel.PROGRESS_M: 1.2,
    Channel.FRONT_TO_STOPLINE_M: UNSEEN,
    Channel.OBSTACLE_OFFSET_M: UNSEEN,
    Channel.HEADING_RAD: 0.0,
    Channel.OBSTACLE_IMAGE_X: UNSEEN,
}
"""Channels of a robot on the corridor's centre line of leg 0 with nothing in sight."""


def channel_vector(overrides: Mapping[Channel, float] | None = None) -> FloatArray:
    """A full channel vector: `NEUTRAL` with some channels replaced."""
    v = np.zeros(len(Channel), dtype=np.float64)
    for c, x in NEUTRAL.items():
        v[c] = x
    for c, x in (overrides or {}).items():
        v[c] = x
    return v


def channel_list(overrides: Mapping[Channel, float] | None = None) -> list[float]:
    """`channel_vector` as the plain list the brain reads."""
    out: list[float] = channel_vector(overrides).tolist()
    return out


@dataclass(frozen=True, slots=True)
class ScriptedStep:
    """What the world reports after one step: channel overrides and the referee's view."""

    channels: Mapping[Channel, float] = field(default_factory=dict)
    collision: CollisionKind | None = None
    violation: bool = False
    lamp: LampColor = LampColor.NONE


Script = Sequence[ScriptedStep] | Callable[[int], Sequence[ScriptedStep]]
"""Steps of every episode, or a function from the episode's number to its steps."""


class ScriptedWorld:
    """A `World` that plays back scripted sensor frames, step by step.

    Each `reset` restarts the script (or asks it for the episode's steps); once the steps run
    out the last one repeats. Resets and the motor commands the brain applies are recorded.
    """

    def __init__(
        self,
        script: Script = (),
        config: WorldConfig | None = None,
        initial: Mapping[Channel, float] | None = None,
    ) -> None:
        self.config = config or WorldConfig()
        track = self.config.track
        assert isinstance(track, TrackConfig), "a scripted world is on the ring"
        self.geometry = TrackGeometry.build(track)
        self._script = script
        self._initial = dict(initial or {})
        self._steps: Sequence[ScriptedStep] = ()
        self._at = 0
        self._tick = 0
        self.resets: list[tuple[int, int]] = []
        self.commands: list[MotorCommand] = []
        self._layout = EpisodeLayout(None, -1, ((LampColor.GREEN, 1),))

    @property
    def layout(self) -> EpisodeLayout:
        """No obstacle and an always-green lamp: the script says what the robot sees."""
        return self._layout

    def reset(self, seed: int, episode: int) -> SensorFrame:
        """Restart the script for `episode`; the first frame is `initial` over `NEUTRAL`."""
        self.resets.append((seed, episode))
        script = self._script
        self._steps = script(episode) if callable(script) else script
        self._at = 0
        self._tick = 0
        return self._frame(ScriptedStep(self._initial))

    def apply(self, command: MotorCommand) -> None:
        """Record the command; it does not move anything."""
        self.commands.append(command)

    def step(self) -> SensorFrame:
        """The next scripted frame (the last one again once the script is over)."""
        self._tick += 1
        steps = self._steps
        step = steps[min(self._at, len(steps) - 1)] if steps else ScriptedStep()
        self._at += 1
        return self._frame(step)

    def _frame(self, step: ScriptedStep) -> SensorFrame:
        channels = channel_vector(step.channels)
        x, y, _ = self.geometry.start_pose
        return SensorFrame(
            self._tick,
            x,
            y,
            float(channels[Channel.HEADING_RAD]),
            channels,
            step.lamp,
            step.collision,
            step.violation,
        )


def lap_steps(
    geometry: TrackGeometry, step_m: float, extra: Mapping[int, ScriptedStep] | None = None
) -> list[ScriptedStep]:
    """Steps whose progress channel advances `step_m` a step from the start round one lap.

    `extra` replaces the step at some indices (their progress is kept).
    """
    lap = geometry.lap_length_m
    n = int(np.ceil(lap / step_m)) + 1
    steps = []
    for i in range(n):
        p = (geometry.start_progress_m + (i + 1) * step_m) % lap
        base = (extra or {}).get(i, ScriptedStep())
        channels = {**base.channels, Channel.PROGRESS_M: p}
        steps.append(ScriptedStep(channels, base.collision, base.violation, base.lamp))
    return steps
