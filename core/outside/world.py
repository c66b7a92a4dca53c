"""An outside world's data: its environment, channels, sensors, behaviours, knowledge, conditions.

An outside world is a folder, ``core/data/outside/<name>/`` (or any folder given by path):

- ``world.toml``: the environment (`adapter`, the Python module of its channels mapping,
  and its `options`), the brain's tick (`dt_s`), the default behaviour, the objectives'
  desires, the episodes' defaults, the declared measure and the world's properties;
- ``sensors.toml``: logical sensors over the world's channel names, in the form of
  ``core/data/sensors.toml``;
- ``behaviours.toml``: behaviours in the form of ``core/data/behaviours.toml``, each with the
  world's `action` it runs (a name of the adapter's `ACTIONS`; a world driven by wheel
  commands, whose `ACTIONS` is empty, runs the behaviour's speed and turn rate);
- ``networks/*.toml``: knowledge sets (innate knowledge and designs);
- ``conditions.toml``: the conditions, in the form of ``core/data/conditions.toml``.

Every error names the file, the entry and the reason.
"""

from __future__ import annotations

import importlib
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

from core.brain.catalog import (
    Catalog,
    data_dir,
    parse_behaviours,
    parse_knowledge,
    parse_sensors,
)
from core.errors import CatalogError, ConditionFileError, ExtraMissingError, UnknownNameError
from core.run.conditions import Condition, parse_condition_file
from core.sim.types import MotorCommand

OUTSIDE_FOLDER = "outside"
"""The shipped outside worlds' folder, in ``core/data/``."""
INSTALL_HINT = "make install-worlds"
"""How to install the srlab[worlds] extra (the outside worlds' environments)."""
MEASURES = ("success", "return")
"""What a world's declared comparison is on: the share of successful episodes, or the
environment's own return per episode."""


class OutsideWorldError(CatalogError):
    """An outside world's data file is wrong (the message names file, entry and reason)."""


@dataclass(frozen=True, slots=True)
class StepResult:
    """What one step of an outside environment gave.

    Attributes:
        channels: the channel values after the step, in the adapter's `CHANNELS` order.
        reward: the environment's own reward for the step.
        outcome: None while the episode goes on, else ``success``, ``collision`` or
            ``timeout``.
    """

    channels: list[float]
    reward: float
    outcome: str | None


class OutsideEnv(Protocol):
    """An outside environment as the adapter's `make` returns it."""

    def reset(self, seed: int) -> list[float]:
        """Start an episode from `seed`; its first channel values."""
        ...

    def step(self, action: str, wheels: MotorCommand) -> StepResult:
        """Run `action` (the running behaviour's) or `wheels` (the brain's wheel command)."""
        ...

    def close(self) -> None:
        """Release the environment."""
        ...


@dataclass(frozen=True, slots=True)
class OutsideWorld:
    """An outside world loaded from its folder.

    Attributes:
        name: the folder's name.
        folder: where its data files are.
        description: one line for people.
        adapter: the module of its channels mapping (`CHANNELS`, `ACTIONS`, `make`).
        options: the adapter's settings (the environment's id, its size...).
        dt_s: the brain's tick, in the units the behaviours' speeds and turn rates use.
        default_behaviour: what runs when nothing is released.
        desires: internal desire per objective (over srlab's defaults).
        episodes: training episodes per seed by default.
        held_out: held-out episodes per seed by default.
        measure: what the declared comparison is on (`MEASURES`).
        reasons: the world's properties with their physical reasons, written before any
            learner ran on it.
        catalog: stimuli, behaviours, sensors and knowledge sets.
        actions: per behaviour id, the world's action it runs ("" for wheel commands).
        conditions: the world's conditions by name, in file order.
    """

    name: str
    folder: Path
    description: str
    adapter: str
    options: Mapping[str, Any]
    dt_s: float
    default_behaviour: str
    desires: Mapping[str, float]
    episodes: int
    held_out: int
    measure: str
    reasons: tuple[str, ...]
    catalog: Catalog
    actions: tuple[str, ...]
    conditions: Mapping[str, Condition] = field(default_factory=dict)

    def module(self) -> ModuleType:
        """The adapter's module (importing the environment's package)."""
        return importlib.import_module(self.adapter)

    def make(self) -> OutsideEnv:
        """A fresh environment (its options with ``folder``, the world's folder, for files).

        Without the environment's package (the srlab[worlds] extra), an `ExtraMissingError`
        saying how to install it.
        """
        try:
            env: OutsideEnv = self.module().make({**self.options, "folder": str(self.folder)})
        except ModuleNotFoundError as e:
            raise ExtraMissingError(
                f"outside world {self.name!r} needs {e.name!r}, of the srlab[worlds] extra: "
                f"run `{INSTALL_HINT}`"
            ) from None
        return env

    def condition(self, name: str) -> Condition:
        """The world's condition called `name`."""
        try:
            return self.conditions[name]
        except KeyError:
            known = ", ".join(self.conditions)
            raise UnknownNameError(
                f"outside world {self.name!r}: unknown condition {name!r} (known: {known})"
            ) from None


def outside_folder() -> Path:
    """The folder of the outside worlds shipped (or in ``SRLAB_DATA_DIR``)."""
    return data_dir() / OUTSIDE_FOLDER


def outside_names() -> tuple[str, ...]:
    """The outside worlds shipped, by name."""
    folder = outside_folder()
    if not folder.is_dir():
        return ()
    return tuple(sorted(p.name for p in folder.iterdir() if (p / "world.toml").is_file()))


def _read(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except OSError as e:
        raise OutsideWorldError(f"{path}: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise OutsideWorldError(f"{path}: {e}") from None


def _adapter_names(adapter: str, where: Path) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The adapter's channel and action names, read without importing its environment.

    The module keeps the names in plain tuples and imports its environment's package
    only in `make`, so a world's data is checked on a machine without the extra.
    """
    try:
        module = importlib.import_module(adapter)
    except ImportError as e:
        raise OutsideWorldError(f"{where}: adapter {adapter!r} cannot be imported: {e}") from None
    channels = getattr(module, "CHANNELS", None)
    actions = getattr(module, "ACTIONS", ())
    if not isinstance(channels, tuple) or not all(isinstance(c, str) for c in channels):
        raise OutsideWorldError(f"{where}: adapter {adapter!r} has no CHANNELS tuple of names")
    if not callable(getattr(module, "make", None)):
        raise OutsideWorldError(f"{where}: adapter {adapter!r} has no make(options)")
    return channels, tuple(actions)


def _with_file(path: Path, e: CatalogError) -> OutsideWorldError:
    return OutsideWorldError(f"{path}: {e}")


def load_outside(name_or_path: str | Path) -> OutsideWorld:
    """An outside world by its shipped name or its folder's path."""
    folder = Path(name_or_path)
    if not (folder / "world.toml").is_file():
        if isinstance(name_or_path, str) and "/" not in name_or_path:
            folder = outside_folder() / name_or_path
        if not (folder / "world.toml").is_file():
            known = ", ".join(outside_names()) or "none"
            raise UnknownNameError(
                f"unknown outside world {str(name_or_path)!r}: neither a shipped one "
                f"(known: {known}) nor a folder with a world.toml"
            )
    where = folder / "world.toml"
    raw = _read(where)
    adapter = raw.get("adapter")
    if not isinstance(adapter, str) or not adapter:
        raise OutsideWorldError(f"{where}: 'adapter' must name the channels mapping's module")
    channels, world_actions = _adapter_names(adapter, where)

    bfile = folder / "behaviours.toml"
    raw_behaviours = _read(bfile).get("behaviour", [])
    try:
        behaviours = parse_behaviours(raw_behaviours)
    except CatalogError as e:
        raise _with_file(bfile, e) from None
    actions: list[str] = []
    for i, b in enumerate(raw_behaviours):
        if b.get("mode", "constant") != "constant":
            raise OutsideWorldError(
                f"{bfile}: behaviour {b['name']!r}: mode must be 'constant' (align and steer "
                "read srlab's own odometry channels)"
            )
        action = b.get("action", "")
        if world_actions and action not in world_actions:
            raise OutsideWorldError(
                f"{bfile}: behaviour {behaviours[i].name!r}: unknown action {action!r} "
                f"(the world's: {', '.join(world_actions)})"
            )
        if not world_actions and action:
            raise OutsideWorldError(
                f"{bfile}: behaviour {behaviours[i].name!r}: this world is driven by wheel "
                "commands (speed_mps, turn_dps): no action to name"
            )
        actions.append(str(action))

    sfile = folder / "sensors.toml"
    try:
        sensors, stimuli = parse_sensors(_read(sfile).get("sensor", []), channels=channels)
    except CatalogError as e:
        raise _with_file(sfile, e) from None

    raw_sets: dict[str, dict[str, Any]] = {}
    files: dict[str, Path] = {}
    for f in sorted((folder / "networks").glob("*.toml")):
        spec = _read(f)
        raw_sets[str(spec.get("name", f.stem))] = spec
        files[str(spec.get("name", f.stem))] = f
    try:
        knowledge = parse_knowledge(raw_sets, stimuli, behaviours)
    except CatalogError as e:
        named = re.match(r"network '([^']+)'", str(e))
        raise _with_file(files.get(named[1] if named else "", folder / "networks"), e) from None
    catalog = Catalog(stimuli, behaviours, sensors, knowledge, "")

    default = str(raw.get("default_behaviour", ""))
    if default not in {b.name for b in behaviours}:
        raise OutsideWorldError(f"{where}: default_behaviour {default!r} is no behaviour")
    dt_s = raw.get("dt_s", 1.0)
    if isinstance(dt_s, bool) or not isinstance(dt_s, int | float) or not dt_s > 0:
        raise OutsideWorldError(f"{where}: dt_s must be a positive number, got {dt_s!r}")
    desires = raw.get("desires", {})
    if not isinstance(desires, dict) or not all(
        isinstance(v, int | float) and math.isfinite(v) for v in desires.values()
    ):
        raise OutsideWorldError(f"{where}: desires must be a table of numbers")
    measure = raw.get("measure", "success")
    if measure not in MEASURES:
        raise OutsideWorldError(f"{where}: measure must be one of {', '.join(MEASURES)}")
    counts = {k: raw.get(k, d) for k, d in (("episodes", 50), ("held_out", 10))}
    for k, v in counts.items():
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise OutsideWorldError(f"{where}: {k} must be a whole number >= 1, got {v!r}")

    cfile = folder / "conditions.toml"
    try:
        text = cfile.read_text(encoding="utf-8")
    except OSError as e:
        raise OutsideWorldError(f"{cfile}: {e.strerror or e}") from None
    try:
        conditions = parse_condition_file(
            text, str(cfile), {}, knowledge.__contains__, {s.name for s in sensors}
        )
    except ConditionFileError as e:
        raise OutsideWorldError(str(e)) from None
    names = {s.name for s in sensors}
    for c in conditions:
        if c.learning and c.agent == "brain" and not names & set(c.learnable_sensors):
            raise OutsideWorldError(
                f"{cfile}: condition {c.name!r}: it learns, but its learnable_sensors "
                f"({', '.join(c.learnable_sensors)}) name none of the world's sensors "
                f"({', '.join(sorted(names))})"
            )
    return OutsideWorld(
        name=folder.name,
        folder=folder,
        description=str(raw.get("description", "")),
        adapter=adapter,
        options=dict(raw.get("options", {})),
        dt_s=float(dt_s),
        default_behaviour=default,
        desires={str(k): float(v) for k, v in desires.items()},
        episodes=counts["episodes"],
        held_out=counts["held_out"],
        measure=str(measure),
        reasons=tuple(str(r) for r in raw.get("reasons", ())),
        catalog=catalog,
        actions=tuple(actions),
        conditions={c.name: c for c in conditions},
    )
