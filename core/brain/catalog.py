"""The catalogue: stimuli, behaviours, logical sensors and knowledge sets, loaded from data."""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from core.errors import CatalogError, UnknownNameError
from core.sim.channels import CHANNELS

Source = Literal["innate", "dp", "learned", "kp", "expert", "designed"]
SOURCES: tuple[Source, ...] = ("innate", "dp", "learned", "kp", "expert", "designed")
Level = Literal["low", "high"]
MotionMode = Literal["align", "steer", "constant"]
MOTION_MODES = ("align", "steer", "constant")
OPS = ("<", "<=", ">", ">=", "==", "!=")


@dataclass(frozen=True, slots=True)
class Behaviour:
    """A motor primitive: a constant wheel command held for `ticks` ticks.

    Attributes:
        id: index in the catalogue.
        name: e.g. ``goforward3`` or ``leftturn30``.
        family: forward, stop, turn, wall, back, or synthesized.
        speed_mps: forward speed while it runs.
        turn_dps: heading rate while it runs, degrees per second, + = left.
        ticks: how many ticks it runs once selected.
        mode: ``align`` (hold the corridor's heading), ``steer`` (turn towards a heading
            `turn_dps * ticks * dt` off the corridor's direction) or ``constant``.
        synthesized: made by knowledge propagation rather than designed.
    """

    id: int
    name: str
    family: str
    speed_mps: float
    turn_dps: float
    ticks: int
    mode: MotionMode = "constant"
    synthesized: bool = False

    def motion_vector(self, dt_s: float) -> tuple[float, float, float]:
        """Displacement (forward, left) in metres and heading change in radians over its run."""
        duration = self.ticks * dt_s
        w = math.radians(self.turn_dps)
        dth = w * duration
        if abs(w) < 1e-12:
            return (self.speed_mps * duration, 0.0, 0.0)
        radius = self.speed_mps / w
        return (radius * math.sin(dth), radius * (1 - math.cos(dth)), dth)


@dataclass(frozen=True, slots=True)
class RuleCondition:
    """One condition of a stimulus rule: ``channel op value``, or ``channel op other``.

    `other` >= 0 compares against another channel instead of the constant (so a designer
    can write "the left sonar reads farther than the right" as data); `value` is then 0.
    """

    channel: int
    op: str
    value: float
    other: int = -1

    def as_data(self) -> list[str | float]:
        """The condition as a data file spells it."""
        return [
            CHANNELS[self.channel],
            self.op,
            CHANNELS[self.other] if self.other >= 0 else self.value,
        ]


@dataclass(frozen=True, slots=True)
class Stimulus:
    """A stimulus a logical sensor emits.

    Attributes:
        id: index in the catalogue.
        name: e.g. ``Corner`` or ``Obstacle_M_R``.
        sensor: the logical sensor that emits it.
        objective: what responses to it are for (KP propagates within an objective).
        level: low- or high-level sensor.
        priority: layer for priority selection and pre-emption; higher wins.
        rule: alternatives (OR) of conjunctions (AND) of channel conditions.
    """

    id: int
    name: str
    sensor: str
    objective: str
    level: Level
    priority: int
    rule: tuple[tuple[RuleCondition, ...], ...]


@dataclass(frozen=True, slots=True)
class LogicalSensorSpec:
    """A logical sensor as declared in data: which physical sensors, processing, stimuli.

    `definition` names the variant of its rules in use when the data file gives it several
    (the camera obstacle sensor's ``paper`` and ``path``), else "".
    """

    name: str
    physical: tuple[str, ...]
    processing: str
    objective: str
    level: Level
    priority: int
    weight: float
    stimuli: tuple[str, ...]
    definition: str = ""


@dataclass(frozen=True, slots=True)
class AssociationSpec:
    """An S-R association in a knowledge set (a network as designed, before any run)."""

    stimulus: str
    behaviour: str
    strength: float = 1.0
    source: Source = "innate"
    locked: bool = False


@dataclass(frozen=True, slots=True)
class KnowledgeSet:
    """A named set of S-R associations: Table I's innate knowledge, DP sets, the expert.

    `sensors` names the sensor definition its camera responses are written for (None: it
    holds none, or they mean the same under every definition).
    """

    name: str
    description: str
    associations: tuple[AssociationSpec, ...]
    sensors: str | None = None


@dataclass(frozen=True, slots=True)
class Catalog:
    """Everything the brain knows by name, indexed for speed."""

    stimuli: tuple[Stimulus, ...]
    behaviours: tuple[Behaviour, ...]
    sensors: tuple[LogicalSensorSpec, ...]
    knowledge: Mapping[str, KnowledgeSet] = field(default_factory=dict)
    definition: str = ""
    """The sensor definition in use (see `SENSOR_DEFINITIONS`; "" for a hand-made one)."""

    def stimulus(self, name: str) -> Stimulus:
        """The stimulus called `name`."""
        for s in self.stimuli:
            if s.name == name:
                return s
        raise UnknownNameError(f"unknown stimulus {name!r}")

    def behaviour(self, name: str) -> Behaviour:
        """The behaviour called `name`."""
        for b in self.behaviours:
            if b.name == name:
                return b
        raise UnknownNameError(f"unknown behaviour {name!r}")

    def knowledge_set(self, name: str) -> KnowledgeSet:
        """The knowledge set called `name`."""
        try:
            return self.knowledge[name]
        except KeyError:
            known = ", ".join(sorted(self.knowledge))
            raise UnknownNameError(f"unknown network {name!r} (known: {known})") from None

    def network_name(self, name: str) -> str:
        """The knowledge set that stands for `name` under this catalogue's definition.

        A set written for one sensor definition has a variant for each other one, named
        ``<name>-<definition>`` (``dp`` and ``dp-path``); without a variant, `name` itself.
        """
        variant = f"{name}-{self.definition}"
        return variant if self.definition and variant in self.knowledge else name

    def stimuli_of_sensor(self, sensor: str) -> tuple[Stimulus, ...]:
        """The stimuli a logical sensor emits."""
        return tuple(s for s in self.stimuli if s.sensor == sensor)

    def with_behaviour(self, behaviour: Behaviour) -> Catalog:
        """A catalogue with one more behaviour (e.g. one synthesised by KP)."""
        if any(b.name == behaviour.name for b in self.behaviours):
            raise CatalogError(f"behaviour {behaviour.name!r} exists already")
        b = Behaviour(
            len(self.behaviours),
            behaviour.name,
            behaviour.family,
            behaviour.speed_mps,
            behaviour.turn_dps,
            behaviour.ticks,
            behaviour.mode,
            behaviour.synthesized,
        )
        return Catalog(
            self.stimuli, (*self.behaviours, b), self.sensors, self.knowledge, self.definition
        )


DATA_DIR_VARIABLE = "SRLAB_DATA_DIR"
"""The environment variable naming a data folder to use instead of the shipped one."""


def data_dir() -> Path:
    """The folder of srlab's data files: ``SRLAB_DATA_DIR`` if set, else the shipped one.

    A lab may keep its own copy of ``core/data`` (its sensors, behaviours, worlds,
    networks, conditions) and point every srlab command and the service at it.
    """
    own = os.environ.get(DATA_DIR_VARIABLE)
    return Path(own) if own else Path(str(resources.files("core") / "data"))


def _read(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise CatalogError(f"{path}: {e}") from e


def _need(d: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in d:
        raise CatalogError(f"{where}: missing {key!r}")
    return d[key]


def _number(value: Any, key: str, where: str) -> float:
    """A finite number from data, or a CatalogError naming the field."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CatalogError(f"{where}: {key} must be a finite number, got {value!r}")
    return float(value)


def _whole(value: Any, key: str, where: str) -> int:
    """A whole number from data, or a CatalogError naming the field."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise CatalogError(f"{where}: {key} must be a whole number, got {value!r}")
    return value


def parse_behaviours(raw: Iterable[Mapping[str, Any]]) -> tuple[Behaviour, ...]:
    """Behaviours from their data-file form."""
    out: list[Behaviour] = []
    for i, b in enumerate(raw):
        where = f"behaviour #{i}"
        ticks = _whole(_need(b, "ticks", where), "ticks", where)
        if ticks < 1:
            raise CatalogError(f"{where}: ticks must be >= 1")
        mode = b.get("mode", "constant")
        if mode not in MOTION_MODES:
            raise CatalogError(f"{where}: mode must be one of {', '.join(MOTION_MODES)}")
        out.append(
            Behaviour(
                id=i,
                name=str(_need(b, "name", where)),
                family=str(b.get("family", "other")),
                speed_mps=_number(_need(b, "speed_mps", where), "speed_mps", where),
                turn_dps=_number(_need(b, "turn_dps", where), "turn_dps", where),
                ticks=ticks,
                mode=mode,
                synthesized=bool(b.get("synthesized", False)),
            )
        )
    names = [b.name for b in out]
    if len(set(names)) != len(names):
        raise CatalogError("behaviour names must be unique")
    return tuple(out)


def _parse_condition(raw: Any, where: str, channels: tuple[str, ...] = CHANNELS) -> RuleCondition:
    if not (isinstance(raw, list | tuple) and len(raw) == 3):
        raise CatalogError(
            f"{where}: a condition is [channel, op, value] or [channel, op, channel], got {raw!r}"
        )
    channel, op, value = raw
    if channel not in channels:
        raise CatalogError(f"{where}: unknown channel {channel!r}")
    if op not in OPS:
        raise CatalogError(f"{where}: unknown operator {op!r} (use one of {' '.join(OPS)})")
    if isinstance(value, str):
        if value not in channels:
            raise CatalogError(f"{where}: unknown channel {value!r} to compare with")
        if value == channel:
            raise CatalogError(f"{where}: {channel!r} compared with itself")
        return RuleCondition(channels.index(channel), op, 0.0, channels.index(value))
    return RuleCondition(channels.index(channel), op, _number(value, "value", where))


def _definition_stimuli(
    s: Mapping[str, Any], name: str, definition: str | None
) -> tuple[list[Any], str]:
    """A sensor's stimuli under `definition`, and that definition's name.

    The name is "" for a sensor with a single set of rules.
    """
    variants = s.get("definitions")
    if variants is None:
        return list(_need(s, "stimuli", f"sensor {name!r}")), ""
    if "stimuli" in s:
        raise CatalogError(f"sensor {name!r}: give 'stimuli' or 'definitions', not both")
    if not isinstance(variants, Mapping) or not variants:
        raise CatalogError(f"sensor {name!r}: 'definitions' must name at least one")
    names = {
        d: [str(_need(st, "name", f"sensor {name!r} definition {d!r}")) for st in v["stimuli"]]
        for d, v in variants.items()
    }
    first = next(iter(names.values()))
    for d, n in names.items():
        if n != first:
            raise CatalogError(
                f"sensor {name!r}: definition {d!r} must emit the same stimuli, in the "
                "same order, as the others (only their rules differ)"
            )
    chosen = definition if definition is not None else next(iter(variants))
    if chosen not in variants:
        known = ", ".join(variants)
        raise UnknownNameError(
            f"unknown sensor definition {chosen!r} for {name!r} (known: {known})"
        )
    return list(variants[chosen]["stimuli"]), chosen


def parse_sensors(
    raw: Iterable[Mapping[str, Any]],
    definition: str | None = None,
    channels: tuple[str, ...] = CHANNELS,
) -> tuple[tuple[LogicalSensorSpec, ...], tuple[Stimulus, ...]]:
    """Logical sensors and the stimuli they declare, from their data-file form.

    A sensor may give several `definitions` of its stimuli's rules (same names, other
    meanings); `definition` picks one (None: each such sensor's first). `channels` names
    the channels the rules may read: srlab's own by default, an outside world's
    (`core.outside`) otherwise.
    """
    sensors: list[LogicalSensorSpec] = []
    stimuli: list[Stimulus] = []
    for i, s in enumerate(raw):
        where = f"sensor #{i}"
        name = str(_need(s, "name", where))
        processing = str(s.get("processing", "rules"))
        if processing != "rules":
            raise CatalogError(f"sensor {name!r}: unknown processing {processing!r}")
        level = s.get("level", "low")
        if level not in ("low", "high"):
            raise CatalogError(f"sensor {name!r}: level must be 'low' or 'high'")
        priority = _whole(s.get("priority", 1), "priority", f"sensor {name!r}")
        weight = _number(s.get("weight", 1.0), "weight", f"sensor {name!r}")
        if not 0.0 <= weight <= 1.0:
            raise CatalogError(f"sensor {name!r}: weight must be in [0, 1]")
        objective = str(_need(s, "objective", f"sensor {name!r}"))
        names: list[str] = []
        declared, chosen = _definition_stimuli(s, name, definition)
        for j, st in enumerate(declared):
            swhere = f"sensor {name!r} stimulus #{j}"
            sname = str(_need(st, "name", swhere))
            alternatives = list(st.get("any", []))
            if "when" in st:
                alternatives.insert(0, st["when"])
            if not alternatives or any(not alt for alt in alternatives):
                raise CatalogError(f"{swhere}: needs a non-empty 'when' or 'any'")
            rule = tuple(
                tuple(_parse_condition(c, f"{swhere} ({sname})", channels) for c in alt)
                for alt in alternatives
            )
            stimuli.append(Stimulus(len(stimuli), sname, name, objective, level, priority, rule))
            names.append(sname)
        sensors.append(
            LogicalSensorSpec(
                name=name,
                physical=tuple(str(p) for p in s.get("physical", ())),
                processing=processing,
                objective=objective,
                level=level,
                priority=priority,
                weight=weight,
                stimuli=tuple(names),
                definition=chosen,
            )
        )
    snames = [s.name for s in stimuli]
    if len(set(snames)) != len(snames):
        raise CatalogError("stimulus names must be unique")
    if len({s.name for s in sensors}) != len(sensors):
        raise CatalogError("logical sensor names must be unique")
    return tuple(sensors), tuple(stimuli)


def parse_knowledge(
    raw: Mapping[str, Mapping[str, Any]],
    stimuli: Iterable[Stimulus],
    behaviours: Iterable[Behaviour],
    known: Mapping[str, KnowledgeSet] | None = None,
) -> dict[str, KnowledgeSet]:
    """Knowledge sets from their data-file form, with `include` resolved.

    A set may include another of `raw` or one of `known` (sets already loaded).
    """
    snames = {s.name for s in stimuli}
    bnames = {b.name for b in behaviours}
    done: dict[str, KnowledgeSet] = {}

    def resolve(name: str, stack: tuple[str, ...]) -> KnowledgeSet:
        if name in done:
            return done[name]
        if name not in raw and known is not None and name in known:
            return known[name]
        if name in stack:
            path = " -> ".join((*stack[stack.index(name) :], name))
            raise CatalogError(f"network {name!r} includes itself: {path}")
        if name not in raw:
            raise UnknownNameError(f"unknown network {name!r}")
        spec = raw[name]
        merged: dict[str, AssociationSpec] = {}
        for inc in spec.get("include", []):
            for a in resolve(str(inc), (*stack, name)).associations:
                merged[f"{a.stimulus}\0{a.behaviour}"] = a
        default_source = spec.get("source", "innate" if name == "innate" else "designed")
        for j, a in enumerate(spec.get("associations", [])):
            where = f"network {name!r} association #{j}"
            st = str(_need(a, "stimulus", where))
            be = str(_need(a, "behaviour", where))
            if st not in snames:
                raise UnknownNameError(f"{where}: unknown stimulus {st!r}")
            if be not in bnames:
                raise UnknownNameError(f"{where}: unknown behaviour {be!r}")
            strength = _number(a.get("strength", 1.0), "strength", where)
            if not 0.0 <= strength <= 1.0:
                raise CatalogError(f"{where}: strength must be in [0, 1]")
            source = a.get("source", default_source)
            if source not in SOURCES:
                raise CatalogError(
                    f"{where}: unknown source {source!r} (use one of {', '.join(SOURCES)})"
                )
            merged[f"{st}\0{be}"] = AssociationSpec(
                st, be, strength, source, bool(a.get("locked", False))
            )
        sensors = spec.get("sensors")
        ks = KnowledgeSet(
            name,
            str(spec.get("description", "")),
            tuple(merged.values()),
            None if sensors is None else str(sensors),
        )
        done[name] = ks
        return ks

    for n in raw:
        resolve(n, ())
    return done


def load_network_file(path: Path, catalog: Catalog) -> KnowledgeSet:
    """A network file's knowledge set (the form of ``core/data/networks/*.toml``).

    It may include the catalogue's sets; its name (``name``, else the file's stem) may not
    be one of theirs. Errors name the file.
    """
    raw = _read(path)
    name = str(raw.get("name", path.stem))
    if name in catalog.knowledge:
        raise CatalogError(
            f"{path}: network {name!r} has the name of a built-in network: name it otherwise"
        )
    try:
        return parse_knowledge({name: raw}, catalog.stimuli, catalog.behaviours, catalog.knowledge)[
            name
        ]
    except CatalogError as e:
        raise type(e)(f"{path}: {e}") from None


def sensor_definitions(path: Path | None = None) -> dict[str, str]:
    """The sensor definitions a data folder offers, default first: name -> description.

    Read once per version of the file (its modification time and size): setting up a run
    asks several times, and parsing the file took a millisecond each time.
    """
    file = (path or data_dir()) / "sensors.toml"
    try:
        st = file.stat()
    except OSError as e:
        raise CatalogError(f"{file}: {e}") from e
    return dict(_sensor_definitions(file, st.st_mtime_ns, st.st_size))


@lru_cache(maxsize=16)
def _sensor_definitions(file: Path, mtime_ns: int, size: int) -> tuple[tuple[str, str], ...]:
    """`sensor_definitions` of one version of `file` (the version is the cache's key)."""
    raw = _read(file)
    out: dict[str, str] = {}
    for s in raw.get("sensor", []):
        for name, v in (s.get("definitions") or {}).items():
            out.setdefault(str(name), str(v.get("description", "")))
    default = raw.get("default_definition")
    if default is not None:
        if default not in out:
            raise CatalogError(f"default_definition {default!r} is not a definition")
        out = {default: out[default], **out}
    return tuple(out.items())


def load_catalog(path: Path | None = None, sensors: str | None = None) -> Catalog:
    """Load the catalogue from a data folder (srlab's own by default).

    `sensors` picks the sensor definition (see `sensor_definitions`); None takes the
    folder's default.
    """
    root = path or data_dir()
    behaviours = parse_behaviours(_read(root / "behaviours.toml").get("behaviour", []))
    raw_sensors = _read(root / "sensors.toml")
    definitions = sensor_definitions(root)
    if sensors is None and definitions:
        sensors = next(iter(definitions))
    elif sensors is not None and sensors not in definitions:
        known = ", ".join(definitions) or "none"
        raise UnknownNameError(f"unknown sensor definition {sensors!r} (known: {known})")
    sensor_specs, stimuli = parse_sensors(raw_sensors.get("sensor", []), sensors)
    raw_sets: dict[str, dict[str, Any]] = {}
    for f in sorted((root / "networks").glob("*.toml")):
        spec = _read(f)
        raw_sets[str(spec.get("name", f.stem))] = spec
    knowledge = parse_knowledge(raw_sets, stimuli, behaviours)
    for ks in knowledge.values():
        if ks.sensors is not None and ks.sensors not in definitions:
            raise CatalogError(f"network {ks.name!r}: unknown sensor definition {ks.sensors!r}")
    return Catalog(stimuli, behaviours, sensor_specs, knowledge, sensors or "")
