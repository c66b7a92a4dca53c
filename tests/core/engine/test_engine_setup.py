"""The engine runs a run in its world preset and sensor definition, and keeps them by name."""

from __future__ import annotations

import asyncio

import pytest
from fakes import InMemoryRunStore

from core.brain.catalog import load_catalog, sensor_definitions
from core.engine import RunEngine
from core.errors import CatalogError, UnknownNameError
from core.ports import Mode, RunSpec, RunStatus
from core.run.conditions import get_condition
from core.run.setup import Setup, default_sensors, network_specs
from core.sim.worlds import default_world, load_world, world_names

OTHER_WORLD = next(n for n in world_names() if n != default_world())
"""A world preset that is not the default."""
OTHER_SENSORS = next(d for d in sensor_definitions() if d != default_sensors())
"""A sensor definition that is not the default."""


def pairs(engine: RunEngine) -> set[tuple[str, str, float, str]]:
    cat = engine.sim.brain.catalog
    return {
        (cat.stimuli[a.stimulus].name, cat.behaviours[a.behaviour].name, a.strength, a.source)
        for a in engine.sim.brain.network
    }


def test_create_stores_the_defaults_by_name() -> None:
    store = InMemoryRunStore(load_catalog())

    engine = RunEngine.create(RunSpec("dp", 1, 1), store)

    stored = store.load_run(engine.run_id).spec
    assert (stored.world, stored.sensors) == (default_world(), default_sensors())
    assert engine.spec == stored
    assert engine.sim.brain.catalog.definition == default_sensors()
    assert engine.sim.world.config == load_world().config


def test_create_runs_in_the_named_world_and_sensor_definition() -> None:
    store = InMemoryRunStore(load_catalog())
    setup = Setup(OTHER_WORLD, OTHER_SENSORS)

    engine = RunEngine.create(RunSpec("dp", 1, 1, world=OTHER_WORLD, sensors=OTHER_SENSORS), store)

    assert store.load_run(engine.run_id).spec.sensors == OTHER_SENSORS
    assert engine.sim.brain.catalog.definition == OTHER_SENSORS
    assert engine.sim.world.config == setup.world_config()
    # The condition's knowledge set in its variant for the definition (dp-<definition>).
    expected = network_specs(setup.catalog(), get_condition("dp"))
    assert pairs(engine) == {(a.stimulus, a.behaviour, a.strength, a.source) for a in expected}
    assert setup.catalog().network_name("dp") in (f"dp-{OTHER_SENSORS}", "dp")


def test_a_named_knowledge_set_is_taken_in_the_definitions_variant() -> None:
    store = InMemoryRunStore(load_catalog())

    engine = RunEngine.create(RunSpec("kp", 1, 1, network="dp", sensors=OTHER_SENSORS), store)

    catalog = load_catalog(sensors=OTHER_SENSORS)
    variant = catalog.knowledge_set(catalog.network_name("dp"))
    assert pairs(engine) == {
        (a.stimulus, a.behaviour, a.strength, a.source) for a in variant.associations
    }


def test_a_restored_run_uses_its_stored_world_and_sensor_definition() -> None:
    store = InMemoryRunStore(load_catalog())
    spec = RunSpec("kp", 4, None, Mode.FAST, world=OTHER_WORLD, sensors=OTHER_SENSORS)
    engine = RunEngine.create(spec, store)
    assert asyncio.run(engine.run(until_tick=300)) is RunStatus.STOPPED

    restored = RunEngine.restore(engine.run_id, store)

    preset = load_world(OTHER_WORLD).config
    assert restored.spec.world == OTHER_WORLD and restored.spec.sensors == OTHER_SENSORS
    assert restored.sim.brain.catalog.definition == OTHER_SENSORS
    assert restored.sim.world.config == preset
    assert restored.sim.world.config.track.obstacle == preset.track.obstacle
    assert pairs(restored) == pairs(engine)
    assert asyncio.run(restored.run(until_tick=400)) is RunStatus.STOPPED
    assert sum(restored.sim.ticks_by_origin.values()) == restored.sim.tick_count == 400


def test_a_catalogue_of_another_definition_is_refused() -> None:
    store = InMemoryRunStore(load_catalog())
    default, other = default_sensors(), OTHER_SENSORS
    with pytest.raises(CatalogError, match=f"sensor definition '{default}', the run '{other}'"):
        RunEngine.create(RunSpec("dp", 1, 1, sensors=other), store, catalog=load_catalog())
    engine = RunEngine.create(RunSpec("dp", 1, 1, sensors=other), store)
    with pytest.raises(CatalogError, match="sensor definition"):
        RunEngine.restore(engine.run_id, store, catalog=load_catalog())


def test_a_spec_naming_no_definition_takes_the_given_catalogues() -> None:
    store = InMemoryRunStore(load_catalog())

    engine = RunEngine.create(
        RunSpec("dp", 1, 1), store, catalog=load_catalog(sensors=OTHER_SENSORS)
    )

    assert store.load_run(engine.run_id).spec.sensors == OTHER_SENSORS
    assert engine.sim.brain.catalog.definition == OTHER_SENSORS


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (RunSpec("dp", 1, world="atlantis"), "unknown world 'atlantis'"),
        (RunSpec("dp", 1, sensors="sixth"), "unknown sensor definition 'sixth'"),
    ],
)
def test_an_unknown_world_or_definition_is_refused_naming_the_known_ones(
    spec: RunSpec, message: str
) -> None:
    store = InMemoryRunStore(load_catalog())
    with pytest.raises(UnknownNameError, match=f"{message} \\(known: "):
        RunEngine.create(spec, store)
    assert store.list_runs() == []
