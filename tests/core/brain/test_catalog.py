"""The catalogue: parsing data files and rejecting malformed ones with clear errors."""

from __future__ import annotations

import math
import re
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest
from fakes import channel_list

from core.brain.catalog import (
    Behaviour,
    Catalog,
    data_dir,
    load_catalog,
    parse_behaviours,
    parse_knowledge,
    parse_sensors,
    sensor_definitions,
)
from core.brain.sensors import compile_detector
from core.errors import CatalogError, UnknownNameError
from core.run.conditions import get_condition


def sensor(*conditions: Any, **extra: Any) -> dict[str, Any]:
    """One logical sensor with one stimulus whose rule is `conditions`."""
    return {
        "name": "probe",
        "objective": "test",
        "stimuli": [{"name": "Probe", "when": list(conditions)}],
        **extra,
    }


def network(*associations: Mapping[str, Any], **extra: Any) -> dict[str, Any]:
    """A network's data-file form."""
    return {"associations": list(associations), **extra}


def test_shipped_catalogue_loads(catalog: Catalog) -> None:
    assert len(catalog.behaviours) == 21  # Table III
    assert len(catalog.stimuli) == 25  # 22, and the stop-line beacon's 3
    assert {"innate", "expert"} <= set(catalog.knowledge)
    assert [s.id for s in catalog.stimuli] == list(range(len(catalog.stimuli)))
    assert [b.id for b in catalog.behaviours] == list(range(len(catalog.behaviours)))
    innate = {(a.stimulus, a.behaviour) for a in catalog.knowledge_set("innate").associations}
    assert innate == {
        ("Corner", "leftturn90"),
        ("LeftWall", "leftwallavoid"),
        ("RightWall", "rightwallavoid"),
        ("Collision", "back"),
    }
    # The expert answers every signal and camera obstacle stimulus.
    answered = {a.stimulus for a in catalog.knowledge_set("expert").associations}
    for sensor_name in ("signal", "camera_obstacle"):
        assert {s.name for s in catalog.stimuli_of_sensor(sensor_name)} <= answered


@pytest.mark.parametrize(
    ("condition", "message"),
    [
        (["sonar_9", "<", 0.1], "unknown channel 'sonar_9'"),
        (["bumper", "=>", 0.5], "unknown operator '=>'"),
        (["bumper", ">", "half"], "unknown channel 'half' to compare with"),
        (["bumper", ">", True], "value must be a finite number, got True"),
        (["bumper", ">"], "a condition is [channel, op, value]"),
        ("bumper > 0.5", "a condition is [channel, op, value]"),
    ],
)
def test_malformed_rule_raises_catalog_error(condition: Any, message: str) -> None:
    with pytest.raises(CatalogError) as e:
        parse_sensors([sensor(condition)])
    assert message in str(e.value)
    assert "sensor 'probe' stimulus #0 (Probe)" in str(e.value)


def test_stimulus_without_conditions_raises_catalog_error() -> None:
    with pytest.raises(CatalogError, match="needs a non-empty 'when' or 'any'"):
        parse_sensors([sensor()])
    with pytest.raises(CatalogError, match="needs a non-empty 'when' or 'any'"):
        parse_sensors([{"name": "p", "objective": "o", "stimuli": [{"name": "P", "any": [[]]}]}])


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ({"processing": "neural"}, "unknown processing 'neural'"),
        ({"level": "middle"}, "level must be 'low' or 'high'"),
        ({"weight": 1.5}, "weight must be in [0, 1]"),
    ],
)
def test_malformed_sensor_raises_catalog_error(extra: Mapping[str, Any], message: str) -> None:
    with pytest.raises(CatalogError) as e:
        parse_sensors([sensor(["bumper", ">", 0.5], **extra)])
    assert message in str(e.value)


def test_sensor_without_objective_raises_catalog_error() -> None:
    raw = sensor(["bumper", ">", 0.5])
    del raw["objective"]
    with pytest.raises(CatalogError, match="sensor 'probe': missing 'objective'"):
        parse_sensors([raw])


def test_duplicate_stimulus_names_raise_catalog_error() -> None:
    raw = [sensor(["bumper", ">", 0.5]), {**sensor(["bumper", ">", 0.2]), "name": "other"}]
    with pytest.raises(CatalogError, match="stimulus names must be unique"):
        parse_sensors(raw)


def test_rules_compile_to_or_of_ands() -> None:
    raw = {
        "name": "probe",
        "objective": "test",
        "stimuli": [
            {
                "name": "Probe",
                "when": [["sonar_0", "<", 1.0], ["sonar_1", "<", 1.0]],
                "any": [[["bumper", "==", 1]]],
            }
        ],
    }
    sensors, stimuli = parse_sensors([raw])
    detect = compile_detector(Catalog(stimuli, (), sensors))
    assert detect([2.0, 2.0] + [0.0] * 29) == []
    assert detect([0.5, 2.0] + [0.0] * 29) == []
    assert detect([0.5, 0.5] + [0.0] * 29) == [0]
    values = [2.0] * 31
    values[25] = 1.0
    assert detect(values) == [0]


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_rule_value_is_rejected_or_works(value: float) -> None:
    # TOML accepts `inf` and `nan`; either the parser refuses them with a CatalogError or the
    # compiled detector evaluates them. Today it raises NameError on the first tick.
    try:
        sensors, stimuli = parse_sensors([sensor(["sonar_0", "<", value])])
    except CatalogError:
        return
    detect = compile_detector(Catalog(stimuli, (), sensors))
    assert detect(channel_list()) == ([0] if value == math.inf else [])


def behaviour(**fields: Any) -> dict[str, Any]:
    return {"name": "b", "speed_mps": 0.1, "turn_dps": 0.0, "ticks": 1, **fields}


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (behaviour(ticks=0), "behaviour #0: ticks must be >= 1"),
        (behaviour(mode="hover"), "behaviour #0: mode must be one of align, steer, constant"),
        ({"name": "b", "turn_dps": 0.0, "ticks": 1}, "behaviour #0: missing 'speed_mps'"),
    ],
)
def test_malformed_behaviour_raises_catalog_error(raw: Mapping[str, Any], message: str) -> None:
    with pytest.raises(CatalogError) as e:
        parse_behaviours([raw])
    assert message in str(e.value)


@pytest.mark.parametrize("field", ["ticks", "speed_mps", "turn_dps"])
def test_behaviour_with_a_non_number_raises_catalog_error(field: str) -> None:
    with pytest.raises(CatalogError, match=field):
        parse_behaviours([behaviour(**{field: "fast"})])


@pytest.mark.parametrize("field", ["priority", "weight"])
def test_sensor_with_a_non_number_raises_catalog_error(field: str) -> None:
    with pytest.raises(CatalogError, match=field):
        parse_sensors([sensor(["bumper", ">", 0.5], **{field: "high"})])


def test_knowledge_with_a_non_number_strength_raises_catalog_error(catalog: Catalog) -> None:
    raw = {"a": network({"stimulus": "Red", "behaviour": "stop", "strength": "strong"})}
    with pytest.raises(CatalogError, match="strength"):
        parse_knowledge(raw, catalog.stimuli, catalog.behaviours)


def test_knowledge_with_an_unknown_source_raises_catalog_error(catalog: Catalog) -> None:
    # A typo would turn a learnable association into one learning never touches.
    raw = {"a": network({"stimulus": "Red", "behaviour": "stop", "source": "lerned"})}
    with pytest.raises(CatalogError, match="lerned"):
        parse_knowledge(raw, catalog.stimuli, catalog.behaviours)


def test_duplicate_behaviour_names_raise_catalog_error() -> None:
    with pytest.raises(CatalogError, match="behaviour names must be unique"):
        parse_behaviours([behaviour(), behaviour()])


def test_behaviour_motion_vector() -> None:
    straight = Behaviour(0, "f", "forward", 0.5, 0.0, 4)
    assert straight.motion_vector(0.1) == pytest.approx((0.2, 0.0, 0.0))
    # A quarter circle of radius v / w.
    w = 90.0
    arc = Behaviour(1, "l", "turn", math.radians(w), w, 10, "steer")
    assert arc.motion_vector(0.1) == pytest.approx((1.0, 1.0, math.pi / 2))


def test_with_behaviour_appends_and_rejects_duplicates(catalog: Catalog) -> None:
    new = catalog.with_behaviour(Behaviour(99, "spin", "synthesized", 0.0, 90.0, 2, "constant"))
    assert new.behaviour("spin").id == len(catalog.behaviours)
    assert len(catalog.behaviours) == 21
    with pytest.raises(CatalogError, match="'spin' exists already"):
        new.with_behaviour(Behaviour(0, "spin", "x", 0.0, 0.0, 1))


def test_knowledge_with_unknown_stimulus_raises_unknown_name(catalog: Catalog) -> None:
    raw = {"bad": network({"stimulus": "Purple", "behaviour": "stop"})}
    with pytest.raises(UnknownNameError, match="unknown stimulus 'Purple'"):
        parse_knowledge(raw, catalog.stimuli, catalog.behaviours)


def test_knowledge_with_unknown_behaviour_raises_unknown_name(catalog: Catalog) -> None:
    raw = {"bad": network({"stimulus": "Red", "behaviour": "fly"})}
    with pytest.raises(UnknownNameError, match="association #0: unknown behaviour 'fly'"):
        parse_knowledge(raw, catalog.stimuli, catalog.behaviours)


def test_knowledge_including_an_unknown_network_raises_unknown_name(catalog: Catalog) -> None:
    raw = {"a": network(include=["ghost"])}
    with pytest.raises(UnknownNameError, match="unknown network 'ghost'"):
        parse_knowledge(raw, catalog.stimuli, catalog.behaviours)


@pytest.mark.parametrize(
    "raw",
    [
        {"a": {"include": ["a"]}},
        {"a": {"include": ["b"]}, "b": {"include": ["a"]}},
        {"a": {"include": ["b"]}, "b": {"include": ["c"]}, "c": {"include": ["a"]}},
    ],
)
def test_include_cycles_raise_catalog_error(
    catalog: Catalog, raw: Mapping[str, Mapping[str, Any]]
) -> None:
    with pytest.raises(CatalogError, match="includes itself"):
        parse_knowledge(raw, catalog.stimuli, catalog.behaviours)


def test_knowledge_strength_out_of_range_raises_catalog_error(catalog: Catalog) -> None:
    raw = {"a": network({"stimulus": "Red", "behaviour": "stop", "strength": 1.2})}
    with pytest.raises(CatalogError, match="strength must be in"):
        parse_knowledge(raw, catalog.stimuli, catalog.behaviours)


def test_include_merges_and_later_associations_override(catalog: Catalog) -> None:
    raw = {
        "base": network(
            {"stimulus": "Red", "behaviour": "stop", "strength": 0.5},
            {"stimulus": "Corner", "behaviour": "leftturn90"},
        ),
        "top": network(
            {"stimulus": "Red", "behaviour": "stop", "strength": 0.9, "locked": True},
            include=["base"],
            source="dp",
        ),
    }
    sets = parse_knowledge(raw, catalog.stimuli, catalog.behaviours)
    top = {(a.stimulus, a.behaviour): a for a in sets["top"].associations}
    assert top[("Red", "stop")].strength == 0.9
    assert top[("Red", "stop")].locked
    assert top[("Red", "stop")].source == "dp"
    assert top[("Corner", "leftturn90")].source == "designed"
    assert {a.strength for a in sets["base"].associations} == {0.5, 1.0}


def test_lookups_of_unknown_names_raise_unknown_name(catalog: Catalog) -> None:
    with pytest.raises(UnknownNameError, match="unknown stimulus 'Blue'"):
        catalog.stimulus("Blue")
    with pytest.raises(UnknownNameError, match="unknown behaviour 'jump'"):
        catalog.behaviour("jump")
    with pytest.raises(UnknownNameError, match=r"unknown network 'novice' \(known: .*expert"):
        catalog.knowledge_set("novice")
    with pytest.raises(UnknownNameError, match="unknown condition 'lazy'"):
        get_condition("lazy")


def copy_data(tmp_path: Path) -> Path:
    root = tmp_path / "data"
    shutil.copytree(data_dir(), root)
    return root


def test_load_catalog_from_a_copy_of_the_data(tmp_path: Path, catalog: Catalog) -> None:
    copied = load_catalog(copy_data(tmp_path))
    assert copied.stimuli == catalog.stimuli
    assert copied.behaviours == catalog.behaviours
    assert dict(copied.knowledge) == dict(catalog.knowledge)


def test_load_catalog_reports_the_file_of_a_toml_error(tmp_path: Path) -> None:
    root = copy_data(tmp_path)
    (root / "sensors.toml").write_text("[[sensor]\nname = \n", encoding="utf-8")
    with pytest.raises(CatalogError, match=r"sensors\.toml"):
        load_catalog(root)


def test_load_catalog_reports_a_missing_file(tmp_path: Path) -> None:
    root = copy_data(tmp_path)
    (root / "behaviours.toml").unlink()
    with pytest.raises(CatalogError, match=r"behaviours\.toml"):
        load_catalog(root)


def test_load_catalog_rejects_a_network_file_with_an_unknown_behaviour(tmp_path: Path) -> None:
    root = copy_data(tmp_path)
    (root / "networks" / "bad.toml").write_text(
        'name = "bad"\nassociations = [{ stimulus = "Red", behaviour = "moonwalk" }]\n',
        encoding="utf-8",
    )
    with pytest.raises(UnknownNameError, match="network 'bad' association #0"):
        load_catalog(root)


def test_sensor_definitions_are_read_again_when_the_file_changes_and_answered_as_a_copy(
    tmp_path: Path,
) -> None:
    root = copy_data(tmp_path)
    answer = sensor_definitions(root)
    assert list(answer) == ["path", "paper"]
    answer.clear()  # the caller's own copy: the next answer is whole
    assert list(sensor_definitions(root)) == ["path", "paper"]
    file = root / "sensors.toml"
    file.write_text(
        file.read_text(encoding="utf-8").replace(
            'default_definition = "path"', 'default_definition = "paper"'
        ),
        encoding="utf-8",
    )
    assert list(sensor_definitions(root)) == ["paper", "path"]
    file.unlink()
    with pytest.raises(CatalogError, match=r"sensors\.toml"):
        sensor_definitions(root)


def test_the_behaviours_file_says_what_its_data_are() -> None:
    """The header's figures for the turns and the cruise speeds are the rows' own."""
    text = (data_dir() / "behaviours.toml").read_text()
    turns = re.search(r"Turns are arcs at ([\d.]+) m/s turning at ([\d.]+) deg/s", text)
    cruise = re.search(r"five cruise speeds ([\d., and]+) m/s", text.replace("\n# ", " "))
    assert turns is not None and cruise is not None
    catalog = load_catalog()
    turning = [b for b in catalog.behaviours if b.family == "turn"]
    assert turning
    assert {b.speed_mps for b in turning} == {float(turns[1])}
    assert {abs(b.turn_dps) for b in turning} == {float(turns[2])}
    forward = sorted(b.speed_mps for b in catalog.behaviours if b.family == "forward")
    assert forward == [float(v) for v in re.findall(r"[\d.]+\d", cruise[1])]
