"""A Gymnasium environment over the same world and stimuli: `srlab/AmigoTrack-v0`.

Any Gymnasium learner can be compared with the architecture on the same track. The robot
keeps a prior knowledge set as its built-in behaviour (Table I by default); the learner
answers the stimuli of the learnable logical sensors that the prior leaves open, as the
architecture's own exploration does. A step lasts from one such decision to the next (or
to the episode's end), and the only reward is the delayed one of a successful lap.

With ``defer=True`` the learner has one more action, "defer": let the built-in behaviour
answer (what the robot would do without the learner), so that a learner starting from the
prior's knowledge need not override it to find out what it is worth. ``render_mode=
"rgb_array"`` gives a top-down frame of the track (`gymnasium.wrappers.RecordVideo` works).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from core.brain.catalog import Catalog, load_catalog
from core.brain.network import BehaviourNetwork
from core.events import Cause, EpisodeEnded, Outcome
from core.run.conditions import Condition
from core.run.runner import EpisodeSummary
from core.run.simulation import NO_INPUTS, Simulation, TickInputs
from core.sim.corridor_world import CorridorWorld
from core.sim.render import TopDown
from core.sim.world import WorldConfig

ENV_ID = "srlab/AmigoTrack-v0"
MAX_SKIPPED = 100
"""Episodes without a decision `reset` runs before it gives up."""

Observation = npt.NDArray[np.int8]


class AmigoTrackEnv(gym.Env[Observation, np.int64]):
    """The AmigoBot track as a semi-Markov decision process over S-R stimuli.

    Observation: which of the catalogue's stimuli are active (MultiBinary), leaving out
    those of a logical sensor the world lacks the physical sensor for (the stop-line
    beacon's, in a world without one). Action: which of its behaviours to run (Discrete).
    Reward: `success_reward` when a lap is completed, 0 otherwise. `terminated` on success,
    collision or violation; `truncated` on time-out.

    Episodes in which the learner never has to decide (the robot crashed before meeting a
    learnable stimulus) are run inside `reset` and reported in ``info["skipped"]``.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 10}  # noqa: RUF012 - gymnasium's API

    def __init__(
        self,
        prior: str | None = "innate",
        learnable: tuple[str, ...] = ("signal", "camera_obstacle"),
        success_reward: float = 1.0,
        world_config: WorldConfig | None = None,
        catalog: Catalog | None = None,
        extra_networks: tuple[str, ...] = (),
        defer: bool = False,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            modes = ", ".join(self.metadata["render_modes"])
            raise ValueError(f"render_mode {render_mode!r} is not one of: {modes}")
        self.render_mode = render_mode
        self.catalog = catalog or load_catalog()
        for name in extra_networks:
            self.catalog.knowledge_set(name)
        self.extra_networks = extra_networks
        if not learnable:
            raise ValueError("at least one learnable logical sensor is needed")
        for name in learnable:
            if not any(s.name == name for s in self.catalog.sensors):
                raise ValueError(f"unknown logical sensor {name!r}")
        if prior is not None:
            self.catalog.knowledge_set(prior)
        self.prior = prior
        self.learnable_sensors = learnable
        self.success_reward = success_reward
        self.world_config = world_config
        self._learnable = frozenset(s.id for s in self.catalog.stimuli if s.sensor in learnable)
        absent = (world_config or WorldConfig()).absent_physical()
        self.observed = np.array(
            [st.id for st in self.catalog.stimuli if not absent & set(self._physical(st.sensor))],
            dtype=np.intp,
        )
        """The stimuli observed: those of sensors the world has (a world without the stop
        line's beacon leaves the beacon's out, so its observation is as it always was)."""
        self.observation_space = gym.spaces.MultiBinary(len(self.observed))
        self.defer = defer
        self.defer_action = len(self.catalog.behaviours) if defer else -1
        """The "let the built-in behaviour answer" action (-1: there is none)."""
        self.action_space = gym.spaces.Discrete(len(self.catalog.behaviours) + int(defer))
        self._sim: Simulation | None = None
        self._seed = 0
        self._frame: TopDown | None = None

    def _new_simulation(self, seed: int) -> Simulation:
        condition = Condition(
            name="gym",
            description="built-in behaviour for a Gymnasium learner",
            network=self.prior or "innate",
            learnable_sensors=self.learnable_sensors,
            extra_networks=self.extra_networks if self.prior is not None else (),
        )
        network = None if self.prior is not None else BehaviourNetwork(len(self.catalog.stimuli))
        return Simulation(
            condition,
            seed,
            world_config=self.world_config,
            catalog=self.catalog,
            network=network,
        )

    @property
    def simulation(self) -> Simulation:
        """The simulation behind the environment (after the first reset)."""
        if self._sim is None:
            raise gym.error.ResetNeeded("call reset() first")
        return self._sim

    def _physical(self, sensor: str) -> tuple[str, ...]:
        return next((s.physical for s in self.catalog.sensors if s.name == sensor), ())

    def observation(self, active: Sequence[int]) -> Observation:
        """The observation of the stimuli `active` (catalogue ids)."""
        obs = np.zeros(len(self.catalog.stimuli), dtype=np.int8)
        obs[list(active)] = 1
        return obs[self.observed]

    def _observe(self) -> Observation:
        return self.observation(self.simulation.upcoming_stimuli())

    def open_stimulus(self) -> int:
        """The learnable stimulus the learner's next decision answers (-1: no decision)."""
        sim = self.simulation
        if sim.brain.motor.busy:
            return -1
        return sim.brain.selector.open_stimulus(sim.upcoming_stimuli(), self._learnable)

    def _learner_turn(self) -> bool:
        return self.open_stimulus() >= 0

    def _advance(self, first: TickInputs) -> EpisodeEnded | None:
        """Tick until the learner's turn or the episode's end."""
        sim = self.simulation
        inputs = first
        while True:
            result = sim.tick(inputs)
            inputs = NO_INPUTS
            for e in result.events:
                if isinstance(e, EpisodeEnded):
                    return e
            if self._learner_turn():
                return None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Observation, dict[str, Any]]:
        """Start the next episode in which the learner has a decision to make."""
        super().reset(seed=seed)
        if seed is not None or self._sim is None:
            self._seed = seed if seed is not None else int(self.np_random.integers(2**31))
            self._sim = self._new_simulation(self._seed)
        sim = self._sim
        skipped: list[EpisodeSummary] = []
        while True:
            if len(skipped) >= MAX_SKIPPED:
                raise RuntimeError(
                    f"{MAX_SKIPPED} episodes in a row gave the learner no decision: the prior "
                    f"{self.prior!r} answers every stimulus of {self.learnable_sensors}"
                )
            sim.reset()
            if self._learner_turn():
                break
            ended = self._advance(NO_INPUTS)
            if ended is None:
                break
            skipped.append(_summary(ended))
        info = {"episode_index": sim.episode, "skipped": skipped, "stimulus": self.open_stimulus()}
        return self._observe(), info

    def step(
        self, action: np.int64 | int | npt.NDArray[np.integer[Any]]
    ) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        """Run `action` for the open stimulus, then the built-in behaviour until next time.

        The action may be a Python or numpy integer, or a 0-d integer array (what
        stable-baselines3's ``model.predict`` returns).
        """
        a = _action_index(action)
        if a is None or not self.action_space.contains(np.int64(a)):
            raise ValueError(f"action {action!r} is not in {self.action_space}")
        behaviour = -1 if a == self.defer_action else a
        ended = self._advance(TickInputs(behaviour=behaviour))
        obs = self._observe()
        if ended is None:
            return obs, 0.0, False, False, {"stimulus": self.open_stimulus()}
        reward = self.success_reward if ended.outcome is Outcome.SUCCESS else 0.0
        truncated = ended.cause is Cause.TIMEOUT
        return obs, reward, not truncated, truncated, {"episode_summary": _summary(ended)}

    def render(self) -> npt.NDArray[np.uint8] | None:
        """A top-down RGB frame of the track, the robot, the obstacle and the lamp."""
        if self.render_mode != "rgb_array":
            return None
        sim = self.simulation
        if self._frame is None:
            self._frame = TopDown(sim.world.geometry, sim.world.config)
        snap = sim.snapshot
        world = sim.world
        if isinstance(world, CorridorWorld):
            return self._frame.draw(
                (snap.x, snap.y, snap.heading_rad), None, snap.lamp, world.obstacle_centers()
            )
        return self._frame.draw(
            (snap.x, snap.y, snap.heading_rad), world.layout.obstacle_center, snap.lamp
        )


def _action_index(action: object) -> int | None:
    """An action as a Python int, or None when it is no integer at all."""
    if isinstance(action, np.ndarray):
        if action.shape != () or not np.issubdtype(action.dtype, np.integer):
            return None
        return int(action)
    if isinstance(action, bool) or not isinstance(action, int | np.integer):
        return None
    return int(action)


def _summary(e: EpisodeEnded) -> EpisodeSummary:
    return EpisodeSummary(e.episode, e.outcome, e.cause, e.ticks, int(e.outcome is Outcome.SUCCESS))


def register() -> None:
    """Register `srlab/AmigoTrack-v0` with Gymnasium (idempotent)."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="core.learners.envs:AmigoTrackEnv")


register()
