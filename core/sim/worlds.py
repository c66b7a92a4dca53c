"""World presets: named worlds as data, every dimension a parameter.

A preset in `core/data/worlds.toml` is a set of overrides of `WorldConfig`'s defaults (the
rectangular ring), nested as the dataclasses are (``[world.robot]``,
``[world.track.obstacle]`` ...), with the physical reasons for them written beside them. A
preset in `core/data/worlds/NAME.toml` is a world file (`core.sim.worldfile`): a corridor
track of any shape. `srlab world-check --world NAME` measures whether a preset poses the
paper's problem, on properties of the world alone (no learning). `WORLD_PARAMETERS` names
the settings a phase diagram varies around a preset (`srlab phase`, `core.lab.phase`).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from core.brain.catalog import data_dir
from core.errors import CatalogError, UnknownNameError
from core.params import Parameter
from core.run.conditions import Condition
from core.sim.robotfile import ROBOT_PREFIX, RobotFile, RobotFileError, load_robot_file, robot_of
from core.sim.world import WorldConfig


@dataclass(frozen=True, slots=True)
class WorldPreset:
    """A named world.

    Attributes:
        name: its name on the command line and in the runs API.
        description: one line for people.
        reasons: why it differs from the defaults, in physical terms.
        config: the world itself.
        overrides: the settings that differ from `WorldConfig()`, as the data file gives them.
    """

    name: str
    description: str
    reasons: str
    config: WorldConfig
    overrides: Mapping[str, Any]


def _apply(base: Any, overrides: Mapping[str, Any], where: str) -> Any:
    """`base` (a dataclass) with `overrides` set, recursing into nested dataclasses."""
    fields = {f.name: f for f in dataclasses.fields(base)}
    changes: dict[str, Any] = {}
    for key, value in overrides.items():
        if key not in fields:
            known = ", ".join(fields)
            raise CatalogError(f"{where}: unknown setting {key!r} (known: {known})")
        current = getattr(base, key)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, Mapping):
                raise CatalogError(f"{where}.{key}: a table of settings is needed")
            changes[key] = _apply(current, value, f"{where}.{key}")
            continue
        changes[key] = _value(current, value, f"{where}.{key}")
    try:
        return dataclasses.replace(base, **changes)
    except (TypeError, ValueError) as e:
        raise CatalogError(f"{where}: {e}") from e


def _value(current: Any, value: Any, where: str) -> Any:
    """`value` in the type of the default it replaces."""
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise CatalogError(f"{where} must be true or false, got {value!r}")
        return value
    if isinstance(current, int | float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CatalogError(f"{where} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise CatalogError(f"{where} must be finite, got {value!r}")
        if isinstance(current, int) and value != int(value):
            raise CatalogError(f"{where} must be a whole number, got {value!r}")
        return type(current)(value)
    if isinstance(current, tuple):
        if not isinstance(value, list):
            raise CatalogError(f"{where} must be a list, got {value!r}")
        if current and all(isinstance(x, int | float) for x in current):
            return tuple(_value(float(current[0]), x, where) for x in value)
        return tuple(value)
    return value


WorldSettings = tuple[tuple[str, float], ...]
"""Settings over a preset by dotted path (``("track.obstacle.echo_range_m", 0.4)``), sorted."""


def with_settings(config: WorldConfig, settings: WorldSettings) -> WorldConfig:
    """`config` with each dotted-path setting of `settings` changed.

    A path that names no setting, or a value the setting cannot take, is a CatalogError
    naming it.
    """
    nested: dict[str, Any] = {}
    for path, value in settings:
        *tables, key = path.split(".")
        at = nested
        for t in tables:
            at = at.setdefault(t, {})
            if not isinstance(at, dict):
                raise CatalogError(f"world setting {path!r}: {t!r} is a setting, not a table")
        at[key] = value
    return _apply(config, nested, "world") if nested else config


@cache
def _raw() -> dict[str, dict[str, Any]]:
    path = data_dir() / "worlds.toml"
    try:
        with path.open("rb") as f:
            raw = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise CatalogError(f"{path}: {e}") from e
    out: dict[str, dict[str, Any]] = {}
    for i, w in enumerate(raw.get("world", [])):
        name = w.get("name")
        if not isinstance(name, str) or not name:
            raise CatalogError(f"{path}: world #{i} needs a name")
        if name in out:
            raise CatalogError(f"{path}: world {name!r} is defined twice")
        out[name] = w
    if raw.get("default") not in out:
        raise CatalogError(f"{path}: 'default' must name one of the worlds")
    out[""] = {"name": raw["default"]}
    return out


@cache
def _files() -> dict[str, Path]:
    """The world files of `core/data/worlds/`, by name (the file's stem)."""
    found = sorted((data_dir() / "worlds").glob("*.toml"))
    clash = [p.stem for p in found if p.stem in _raw()]
    if clash:
        raise CatalogError(f"{data_dir() / 'worlds'}: {clash[0]!r} is also in worlds.toml")
    return {p.stem: p for p in found}


def world_names() -> tuple[str, ...]:
    """The presets' names, the default first, then worlds.toml's, then the world files'."""
    raw = _raw()
    default = raw[""]["name"]
    return (default, *(n for n in raw if n and n != default), *_files())


def default_world() -> str:
    """The preset a run uses when none is named."""
    return str(_raw()[""]["name"])


@cache
def load_world(name: str | None = None) -> WorldPreset:
    """The preset called `name` (None: the default), or the world file at path `name`.

    A name ending in ``.toml`` is a path (`core.sim.worldfile`); a bad file is a
    `WorldFileError` naming the file, the line, the entry and the reason.
    """
    raw = _raw()
    name = name or default_world()
    robot = robot_of(name)
    if robot is not None:
        try:
            return robot_preset(load_robot_file(robot), name)
        except RobotFileError as e:
            raise UnknownNameError(str(e)) from None
    if name in _files() or name.endswith(".toml"):
        from core.sim.worldfile import load_world_file

        path = _files().get(name) or Path(name)
        return load_world_file(path, name if name in _files() else None)
    spec = raw.get(name) if name else None
    if spec is None:
        known = ", ".join(world_names())
        raise UnknownNameError(f"unknown world {name!r} (known: {known})")
    overrides = {k: v for k, v in spec.items() if k not in ("name", "description", "reasons")}
    config = _apply(WorldConfig(), overrides, f"world {name!r}")
    return WorldPreset(
        name,
        str(spec.get("description", "")),
        str(spec.get("reasons", "")).strip(),
        config,
        overrides,
    )


def robot_preset(robot: RobotFile, name: str = "") -> WorldPreset:
    """The world a robot (`core.sim.robotfile`) runs in: its map's preset at its rate.

    The map's track, with the robot's tick (dt = 1 / hz) and episode time limit; named
    `name` (``ros2:ROBOT`` by default).
    """
    preset = load_world(robot.world)
    config = dataclasses.replace(preset.config, dt_s=1.0 / robot.hz, max_ticks=robot.max_ticks)
    description = f"the robot {robot.name} through ROS 2, on the map of {preset.name}"
    return WorldPreset(
        name or f"{ROBOT_PREFIX}{robot.name}", description, preset.reasons, config, {}
    )


def _every(_: Condition) -> bool:
    return True


@dataclass(frozen=True, slots=True)
class WorldParameter:
    """A named world setting a phase diagram may vary (`core.lab.phase`).

    Attributes:
        parameter: its name, physical meaning, kind and allowed values.
        path: the `WorldConfig` setting it changes, as a dotted path.
        unit: its unit, for people.
    """

    parameter: Parameter
    path: str
    unit: str

    @property
    def name(self) -> str:
        """Its name on the command line and in reports."""
        return self.parameter.name


def _world(
    name: str, path: str, unit: str, low: float, high: float, meaning: str, *, zero: bool = False
) -> WorldParameter:
    """A world parameter in (`low`, `high`], or [`low`, `high`] with `zero` (a noise's 0)."""
    return WorldParameter(
        Parameter(name, meaning, "float", low, high, zero, _every, "every condition"), path, unit
    )


WORLD_PARAMETERS: dict[str, WorldParameter] = {
    p.name: p
    for p in (
        _world(
            "echo_range_m", "track.obstacle.echo_range_m", "m", 0.0, 3.0,
            "how far away the sonars hear the obstacle's echo: a soft obstacle's weak echo "
            "only near, a hard carton's as far as the sonars reach (3 m)",
        ),
        _world(
            "obstacle_size_m", "track.obstacle.size_m", "m", 0.0, 0.6,
            "the side of the square obstacle (the robot is 0.33 m x 0.28 m, the corridor 1.2 m)",
        ),
        _world(
            "camera_range_m", "track.obstacle.sight_range_m", "m", 0.0, 3.0,
            "how far away the camera makes the obstacle out (the camera stimuli start at "
            "1.5 m; the lamp is still seen from the camera's 3 m)",
        ),
        _world(
            "cruise_speed_mps", "robot.cruise_speed_mps", "m/s", 0.0, 0.75,
            "the robot's cruise (goforward3) speed; the other forward speeds scale with it, "
            "turns keep theirs",
        ),
        _world(
            "camera_range_sd_m", "perception.camera_range_sd_m", "m", 0.0, 1.0,
            "standard deviation of the camera's range error on each detection of the obstacle",
            zero=True,
        ),
        _world(
            "camera_bearing_sd_deg", "perception.camera_bearing_sd_deg", "deg", 0.0, 30.0,
            "standard deviation of the camera's bearing error on each detection (the obstacle "
            "across the corridor moves by the range times it)",
            zero=True,
        ),
        _world(
            "camera_miss_rate", "perception.camera_miss_rate", "", 0.0, 1.0,
            "the chance that a tick's detection of the obstacle is missed",
            zero=True,
        ),
        _world(
            "odometry_drift_m", "perception.odometry_drift_m", "m", 0.0, 0.5,
            "standard deviation of the robot's lateral position error after 1 m travelled "
            "(a random walk with the distance)",
            zero=True,
        ),
    )
}  # fmt: skip

PERCEPTION_PRESETS: dict[str, WorldSettings] = {
    "exact": (),
    "noisy": (
        ("perception.camera_bearing_sd_deg", 3.0),
        ("perception.camera_miss_rate", 0.2),
        ("perception.camera_range_sd_m", 0.1),
        ("perception.odometry_drift_m", 0.03),
    ),
}
"""Named perception settings (`--perception`): ``exact``, the default, senses the truth;
``noisy`` is a cheap camera and wheel odometry: 10 cm of range error and 3 degrees of
bearing error a detection, one detection in five missed, 3 cm of lateral drift after 1 m
(`core.sim.perception`)."""


PERCEPTION_PREFIX = "perception."
"""The world settings of `PerceptionConfig`: what `--perception` may set one by one."""


def perception_parameters() -> list[str]:
    """The world parameters that set perception (`PerceptionConfig`), by name."""
    return [n for n, w in WORLD_PARAMETERS.items() if w.path.startswith(PERCEPTION_PREFIX)]


def parse_perception(text: str) -> WorldSettings:
    """``noisy``, ``camera_miss_rate=0.5`` or both (``noisy,odometry_drift_m=0.1``).

    Comma-separated, in order: a preset's name (`PERCEPTION_PRESETS`), which sets every
    perception setting, or a perception parameter's ``NAME=VALUE`` (`WORLD_PARAMETERS`,
    checked against its bounds), which sets one. Returns the settings sorted, those at 0
    left out (0 is exact), so that ``exact`` and ``camera_miss_rate=0`` are one setup.
    """
    settings: dict[str, float] = {}
    for item in (i.strip() for i in text.split(",")):
        name, is_setting, value = item.partition("=")
        if not is_setting:
            if item not in PERCEPTION_PRESETS:
                known = ", ".join(PERCEPTION_PRESETS)
                raise UnknownNameError(
                    f"unknown perception {item!r}: a preset ({known}) or NAME=VALUE"
                )
            # A preset sets every perception setting: those it leaves out are exact.
            settings = dict(PERCEPTION_PRESETS[item])
            continue
        name = name.strip()
        if name not in perception_parameters():
            known = ", ".join(perception_parameters())
            raise UnknownNameError(f"unknown perception setting {name!r} (known: {known})")
        p = WORLD_PARAMETERS[name]
        settings[p.path] = float(p.parameter.parse(value))
    return tuple(sorted((k, v) for k, v in settings.items() if v != 0))


def merge_settings(base: WorldSettings, over: WorldSettings) -> WorldSettings:
    """`base`'s settings with `over`'s added, `over` winning where both set one; sorted."""
    return tuple(sorted({**dict(base), **dict(over)}.items()))


def get_world_parameter(name: str) -> WorldParameter:
    """The world parameter called `name`."""
    try:
        return WORLD_PARAMETERS[name]
    except KeyError:
        known = ", ".join(WORLD_PARAMETERS)
        raise UnknownNameError(f"unknown world parameter {name!r} (known: {known})") from None
