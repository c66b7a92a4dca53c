"""What a run is set in besides its condition: the world, the sensor definition, the signal.

`Setup` names them; it turns a condition's knowledge-set names into the behaviour network
the robot starts from under that setup, and the world preset into a `WorldConfig`. Every
way of running a condition (headless, an experiment, the engine, the Gymnasium
environment) builds its simulation through here, so they agree.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from typing import Literal

from core.brain.catalog import (
    AssociationSpec,
    Catalog,
    KnowledgeSet,
    load_catalog,
    sensor_definitions,
)
from core.brain.network import BehaviourNetwork
from core.errors import UnknownNameError
from core.run.conditions import CONDITIONS, START_SETS, Condition, Start, with_start
from core.sim.world import WorldConfig
from core.sim.worlds import WorldSettings, default_world, load_world, with_settings

SignalMode = Literal["learned", "given"]
SIGNAL_MODES: tuple[SignalMode, ...] = ("learned", "given")
SIGNAL_SET = "signal"
"""The knowledge set of the signal's correct responses (`--signal given`)."""
SIGNAL_SENSOR = "signal"


def default_sensors() -> str:
    """The sensor definition used when none is named."""
    return next(iter(sensor_definitions()))


@cache
def shared_catalog(sensors: str) -> Catalog:
    """The shipped catalogue under a sensor definition, loaded once per process.

    Never modify it: a brain that synthesises behaviours works on its own copy.
    """
    return load_catalog(sensors=sensors)


@cache
def _catalog_with(sensors: str, networks: tuple[KnowledgeSet, ...]) -> Catalog:
    """The shipped catalogue under a sensor definition, with more knowledge sets."""
    base = shared_catalog(sensors)
    return replace(base, knowledge={**base.knowledge, **{ks.name: ks for ks in networks}})


@dataclass(frozen=True, slots=True)
class Setup:
    """The world, the sensor definition and the signal mode a condition runs in.

    Attributes:
        world: a world preset's name ("" for the default).
        sensors: a sensor definition's name ("" for the default).
        signal: ``learned``, as the condition has it, or ``given``: the signal's correct
            responses added (locked) and the signal taken out of what is learned, so that
            success measures the obstacle alone.
        world_settings: settings changed over the world preset, by dotted path (a phase
            diagram's point, `core.lab.phase`); none by default.
        start: what every condition's robot starts from: its own knowledge ("", the
            default), ``table1`` or ``design`` (kp's; `core.run.conditions.with_start`), so
            that methods are compared from equal starting knowledge.
        conditions: conditions besides the built-in ones, a researcher's from a data file
            (`core.run.conditions.load_conditions`): they travel with every task, so any
            process runs them (`lookup`).
        networks: knowledge sets besides the shipped ones (a network file's, or one made in
            the S-R editor), by name in `catalog`.
        network: a network every condition starts from instead of its own ("" for its
            own): a shipped knowledge set's name or one of `networks`.
    """

    world: str = ""
    sensors: str = ""
    signal: SignalMode = "learned"
    world_settings: WorldSettings = ()
    start: Start = ""
    conditions: tuple[Condition, ...] = ()
    networks: tuple[KnowledgeSet, ...] = ()
    network: str = ""

    def __post_init__(self) -> None:
        if self.signal not in SIGNAL_MODES:
            raise UnknownNameError(
                f"unknown signal mode {self.signal!r} (known: {', '.join(SIGNAL_MODES)})"
            )
        preset = load_world(self.world or None)  # an unknown name fails here, with the known ones
        with_settings(preset.config, self.world_settings)  # and so does a bad setting
        if self.sensors and self.sensors not in sensor_definitions():
            known = ", ".join(sensor_definitions())
            raise UnknownNameError(f"unknown sensor definition {self.sensors!r} (known: {known})")
        if self.start and self.start not in START_SETS:
            known = ", ".join(START_SETS)
            raise UnknownNameError(f"unknown start {self.start!r} (known: {known})")
        if self.start and self.network:
            raise UnknownNameError(
                f"a start ({self.start}) and a network ({self.network}) both say what every "
                "condition starts from: give one"
            )
        if self.network or self.conditions or self.networks:
            knowledge = self.catalog().knowledge
            wanted = [("network", self.network)] if self.network else []
            for c in self.conditions:
                wanted += [
                    (f"condition {c.name!r}: network", n) for n in (c.network, *c.extra_networks)
                ]
            for what, name in wanted:
                if name not in knowledge:
                    known = ", ".join(sorted(knowledge))
                    raise UnknownNameError(f"{what} {name!r} is no network (known: {known})")

    @property
    def world_name(self) -> str:
        """The world preset's name, the default's when none was given."""
        return self.world or default_world()

    @property
    def sensors_name(self) -> str:
        """The sensor definition's name, the default's when none was given."""
        return self.sensors or default_sensors()

    def resolved(self) -> Setup:
        """The same setup with every default named."""
        return replace(self, world=self.world_name, sensors=self.sensors_name)

    def catalog(self) -> Catalog:
        """The shipped catalogue under this setup's sensor definition, with its `networks`.

        Shared, read-only.
        """
        if self.networks:
            return _catalog_with(self.sensors_name, self.networks)
        return shared_catalog(self.sensors_name)

    def lookup(self, name: str) -> Condition:
        """The condition called `name`: one of this setup's `conditions`, else a built-in."""
        for c in self.conditions:
            if c.name == name:
                return c
        if name in CONDITIONS:
            return CONDITIONS[name]
        known = ", ".join((*CONDITIONS, *(c.name for c in self.conditions)))
        raise UnknownNameError(f"unknown condition {name!r} (known: {known})")

    def world_config(self) -> WorldConfig:
        """The world preset's configuration, with the setup's settings changed."""
        return with_settings(load_world(self.world_name).config, self.world_settings)

    def condition(self, condition: Condition) -> Condition:
        """`condition` as it runs in this setup."""
        condition = with_start(condition, self.start)
        if self.network:
            condition = replace(condition, network=self.network)
        if self.signal == "given":
            return replace(
                condition,
                extra_networks=(*condition.extra_networks, SIGNAL_SET),
                learnable_sensors=tuple(
                    s for s in condition.learnable_sensors if s != SIGNAL_SENSOR
                ),
            )
        return condition


def network_specs(catalog: Catalog, condition: Condition) -> tuple[AssociationSpec, ...]:
    """The associations a condition's robot starts with, under the catalogue's definition.

    Its knowledge set (the variant written for the catalogue's sensor definition, if there
    is one), then the extra sets it names; a later set's pair replaces an earlier one's.
    """
    merged: dict[tuple[str, str], AssociationSpec] = {}
    for name in (condition.network, *condition.extra_networks):
        for a in catalog.knowledge_set(catalog.network_name(name)).associations:
            merged[(a.stimulus, a.behaviour)] = a
    return tuple(merged.values())


def condition_network(catalog: Catalog, condition: Condition) -> BehaviourNetwork:
    """The behaviour network a condition's robot starts with (see `network_specs`)."""
    return BehaviourNetwork.from_specs(catalog, network_specs(catalog, condition))
