"""World files: the format, its load errors (file, line, entry, reason) and its JSON Schema."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from core.sim.corridor import CorridorConfig
from core.sim.worldfile import WorldFileError, json_schema, load_world_file
from core.sim.worlds import load_world, world_names

ROOT = Path(__file__).resolve().parents[3]
WORLDS = ROOT / "core" / "data" / "worlds"

GOOD = """\
name = "square"
description = "a square corridor"
reasons = "a test"

[track]
centre = [[0.6, 0.6], [6.6, 0.6], [6.6, 4.6], [0.6, 4.6]]
width_m = 1.2
start = { segment = 0, along_m = 1.2 }
signal = { segment = 2, fraction = 0.5 }

[track.obstacle]
echo_range_m = 0.3

[[track.obstacles]]
rule = "seeded"

[[track.obstacles]]
rule = "fixed"
segment = 1
along_m = 2.0
lateral_m = 0.2

[[track.obstacles]]
rule = "moving"
segment = 3
from_fraction = 0.3
to_fraction = 0.7
speed_mps = 0.2
lateral_m = -0.3
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "world.toml"
    path.write_text(text)
    return path


def test_a_good_file_loads_with_every_placement_rule(tmp_path: Path) -> None:
    preset = load_world_file(write(tmp_path, GOOD))
    track = preset.config.track
    assert isinstance(track, CorridorConfig)
    assert preset.name == "square"
    assert [p.rule for p in track.obstacles] == ["seeded", "fixed", "moving"]
    assert track.obstacle.echo_range_m == 0.3
    assert track.signal.leg == 2
    assert track.widths_m == (1.2,) * 4


def line_of(text: str, needle: str) -> int:
    return next(n for n, line in enumerate(text.splitlines(), 1) if needle in line)


@pytest.mark.parametrize(
    ("old", "new", "entry", "reason", "line_at"),
    [
        (
            'rule = "seeded"',
            'rule = "seeded"\ncolour = "red"',
            "track.obstacles[0].colour",
            "unknown key 'colour'",
            "colour",
        ),
        (
            "width_m = 1.2",
            "width_m = 1.2\nwidht_m = 1.0",
            "track.widht_m",
            "unknown key 'widht_m'",
            "widht_m",
        ),
        (
            "lateral_m = 0.2",
            "lateral_m = 0.5",
            "track.obstacles[1].lateral_m",
            "off the track",
            "lateral_m = 0.5",
        ),
        (
            "along_m = 2.0",
            "along_m = 9.0",
            "track.obstacles[1].along_m",
            "off the track: segment 1 is 4.00 m long",
            "along_m = 9.0",
        ),
        (
            "signal = { segment = 2, fraction = 0.5 }",
            "signal = { segment = 2, fraction = 0.9 }",
            "track.signal",
            "segment 2 is too short for the signal",
            "signal =",
        ),
        (
            "speed_mps = 0.2",
            "speed_mps = -0.2",
            "track.obstacles[2].speed_mps",
            "must be more than 0",
            "speed_mps",
        ),
        (
            'rule = "seeded"',
            'rule = "seeded"\nspeed_mps = 0.2',
            "track.obstacles[0].speed_mps",
            "does not apply to a seeded obstacle",
            "speed_mps = 0.2",
        ),
        (
            "echo_range_m = 0.3",
            "echo_range_m = 0.3\nsize_m = -0.25",
            "track.obstacle.size_m",
            "must be at least 0, got -0.25",
            "size_m",
        ),
        (
            'rule = "seeded"',
            'rule = "flying"',
            "track.obstacles[0].rule",
            "must be one of seeded, fixed, moving",
            "flying",
        ),
        (
            "from_fraction = 0.3",
            "from_fraction = 0.8",
            "track.obstacles[2].to_fraction",
            "must be more than from_fraction",
            "to_fraction",
        ),
        (
            "width_m = 1.2",
            "width_m = 1.2\nwidths_m = [1.2, 1.2]",
            "track.widths_m",
            "one width per segment (4), got 2",
            "widths_m",
        ),
        (
            "centre = [[0.6, 0.6], [6.6, 0.6], [6.6, 4.6], [0.6, 4.6]]",
            "centre = [[0.6, 0.6], [6.6, 0.6], [6.6, 4.6], [0.6, 4.6], [0.6, 4.6]]",
            "track.centre[3]",
            "segment 3 has no length",
            "centre",
        ),
    ],
)
def test_a_bad_entry_is_named_with_its_file_line_and_reason(
    tmp_path: Path, old: str, new: str, entry: str, reason: str, line_at: str
) -> None:
    assert old in GOOD
    text = GOOD.replace(old, new, 1)
    path = write(tmp_path, text)
    with pytest.raises(WorldFileError) as e:
        load_world_file(path)
    message = str(e.value)
    assert message.startswith(f"{path}:{line_of(text, line_at)}: {entry}: "), message
    assert reason in message


BOWTIE = """\
[track]
centre = [[0.6, 3.1], [6.6, 3.1], [6.6, 7.1], [3.6, 7.1], [3.6, 0.6], [0.6, 0.6]]
width_m = 1.2
signal = { segment = 1, fraction = 0.3 }
"""


def test_an_undeclared_self_crossing_is_an_error_and_a_declared_one_loads(tmp_path: Path) -> None:
    path = write(tmp_path, BOWTIE)
    with pytest.raises(WorldFileError, match=r"segments 0 and 3 cross at \(3\.60, 3\.10\)"):
        load_world_file(path)
    text = BOWTIE.replace("width_m = 1.2", "width_m = 1.2\ncrossings = [[0, 3]]")
    track = load_world_file(write(tmp_path, text)).config.track
    assert isinstance(track, CorridorConfig)
    assert track.crossings == ((0, 3),)


def test_a_crossing_that_is_not_one_or_corridors_that_overlap_are_errors(tmp_path: Path) -> None:
    text = BOWTIE.replace("width_m = 1.2", "width_m = 1.2\ncrossings = [[0, 3], [1, 4]]")
    with pytest.raises(WorldFileError, match=r"crossings\[1\]: segments 1 and 4 do not cross"):
        load_world_file(write(tmp_path, text))
    narrow_u = """\
[track]
centre = [[0.6, 0.6], [6.6, 0.6], [6.6, 1.4], [0.6, 1.4]]
width_m = 1.2
signal = { segment = 0, fraction = 0.5 }
"""
    with pytest.raises(WorldFileError, match=r"too short for its corners|overlap"):
        load_world_file(write(tmp_path, narrow_u))


def test_syntax_errors_and_missing_tables_name_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "[track\ncentre = 1\n")
    with pytest.raises(WorldFileError, match=rf"^{path}: not valid TOML: .*line 1"):
        load_world_file(path)
    path = write(tmp_path, "[track]\ncentre = [[0, 0], [5, 0], [5, 5]]\nwidth_m = 1.0\n")
    with pytest.raises(WorldFileError, match=r"a \[track.signal\] table is required"):
        load_world_file(path)
    with pytest.raises(WorldFileError, match="cannot read it"):
        load_world_file(tmp_path / "missing.toml")


def test_robot_overrides_are_checked_like_a_presets(tmp_path: Path) -> None:
    text = GOOD + "\n[robot]\nmass_kg = 'heavy'\n"
    path = write(tmp_path, text)
    with pytest.raises(WorldFileError) as e:
        load_world_file(path)
    line = line_of(text, "mass_kg")
    assert str(e.value) == f"{path}:{line}: robot.mass_kg: must be a number, got 'heavy'"
    text = GOOD + "\n[robot]\nmass_kg = -1.0\n"
    with pytest.raises(WorldFileError, match=rf"{write(tmp_path, text)}:\d+: robot: .*positive"):
        load_world_file(tmp_path / "world.toml")
    ok = load_world_file(write(tmp_path, GOOD + "\n[robot]\ncruise_speed_mps = 0.4\n"))
    assert ok.config.robot.cruise_speed_mps == 0.4


def test_the_published_schema_is_the_codes_and_accepts_every_preset() -> None:
    published = json.loads((ROOT / "docs" / "schemas" / "world.schema.json").read_text())
    assert published == json_schema(), "run: srlab world schema > docs/schemas/world.schema.json"
    jsonschema.Draft202012Validator.check_schema(published)
    for path in sorted(WORLDS.glob("*.toml")):
        jsonschema.validate(tomllib.loads(path.read_text()), published)
    bad = tomllib.loads(GOOD.replace('rule = "seeded"', 'rule = "seeded"\ncolour = 1', 1))
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, published)


def test_the_world_file_presets_are_listed_and_load_by_name_or_path() -> None:
    names = world_names()
    for name in ("l-shape", "figure-8", "narrow-passage"):
        assert name in names
        preset = load_world(name)
        assert preset.name == name and preset.reasons
        assert isinstance(preset.config.track, CorridorConfig)
    by_path = load_world(str(WORLDS / "figure-8.toml"))
    assert by_path.config == load_world("figure-8").config
