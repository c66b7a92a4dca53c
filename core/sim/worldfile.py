"""World files: one world per TOML file, a corridor track of any shape (`core.sim.corridor`).

The format is described once, in `SPEC`: the loader checks every key and value against it
and `json_schema` publishes it (docs/schemas/world.schema.json). A bad file is a
`WorldFileError` naming the file, the line, the entry and the reason.

    name = "l-shape"
    description = "one line"
    reasons = "why it is the way it is, in physical terms"
    [track]
    centre = [[0.6, 0.6], [7.4, 0.6], ...]   # lap order; the line closes by itself
    width_m = 1.2
    widths_m = [...]                          # optional: one width per segment
    crossings = [[0, 3]]                      # segments whose centre lines cross
    start = { segment = 0, along_m = 1.2 }
    signal = { segment = 2, fraction = 0.5 }
    [track.obstacle]                          # what every obstacle is (ObstacleConfig)
    echo_range_m = 0.3
    [[track.obstacles]]
    rule = "seeded"                           # or "fixed", "moving"
    [robot]                                   # RobotConfig overrides, as presets have
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from core.errors import CatalogError
from core.sim.corridor import (
    CROSSING_MARGIN_M,
    MAX_TURN_DEG,
    WALL_CLEARANCE_M,
    CorridorConfig,
    CorridorGeometry,
    ObstaclePlacement,
    seeded_area,
    segment_distance,
    segments_meet,
    turn_angle,
)
from core.sim.robot import RobotConfig
from core.sim.track import ObstacleConfig, SignalConfig
from core.sim.types import WorldConfig

if TYPE_CHECKING:
    from core.sim.worlds import WorldPreset

Entry = tuple[str | int, ...]
"""Where a value is in the file: keys and list indices from the top."""


class WorldFileError(CatalogError):
    """A world file that cannot be loaded: the file, the line, the entry and the reason."""


@dataclass(frozen=True, slots=True)
class Field:
    """One key of the format: its JSON Schema and what it means."""

    schema: Mapping[str, Any]
    description: str
    required: bool = False


Table = Mapping[str, "Field | Table | TableList"]


@dataclass(frozen=True, slots=True)
class TableList:
    """A key holding a list of tables (``[[track.obstacles]]``)."""

    table: Table
    description: str


_NUMBER: Mapping[str, Any] = {"type": "number"}
_POSITIVE: Mapping[str, Any] = {"type": "number", "exclusiveMinimum": 0}
_INDEX: Mapping[str, Any] = {"type": "integer", "minimum": 0}
_POINT: Mapping[str, Any] = {
    "type": "array",
    "items": {"type": "number"},
    "minItems": 2,
    "maxItems": 2,
}


def _dataclass_table(
    cls: type, skip: Sequence[str] = (), *, physical: bool = False
) -> dict[str, Field]:
    """The keys of a config dataclass's overrides, typed as its defaults are.

    With `physical`, every number is a size, a range or a duration: not negative.
    """
    out: dict[str, Field] = {}
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        default = getattr(cls(), f.name)
        schema: Mapping[str, Any]
        if isinstance(default, bool):
            schema = {"type": "boolean"}
        elif isinstance(default, int):
            schema = {"type": "integer"}
        elif isinstance(default, float):
            schema = {**_NUMBER, "minimum": 0} if physical else _NUMBER
        else:
            item = {**_NUMBER, "minimum": 0} if physical else _NUMBER
            schema = {"type": "array", "items": item, "minItems": len(default)}
            if len(default) == 2:
                schema = {**schema, "maxItems": 2}
        out[f.name] = Field(schema, f"{cls.__name__}.{f.name}")
    return out


SPEC: Table = {
    "name": Field({"type": "string", "minLength": 1}, "the world's name (default: the file's)"),
    "description": Field({"type": "string"}, "one line for people"),
    "reasons": Field({"type": "string"}, "the physical reasons for the world, written first"),
    "dt_s": Field(_POSITIVE, "the fixed tick, seconds"),
    "max_ticks": Field({"type": "integer", "minimum": 1}, "an episode's time limit in ticks"),
    "robot": _dataclass_table(RobotConfig),
    "track": {
        "centre": Field(
            {"type": "array", "items": _POINT, "minItems": 3},
            "the centre line's vertices [x, y] in metres, in lap order; it closes by itself",
            required=True,
        ),
        "width_m": Field(_POSITIVE, "the corridor's width, wall to wall", required=True),
        "widths_m": Field(
            {"type": "array", "items": _POSITIVE},
            "a width per segment (segment k runs from vertex k to k + 1), for a narrow passage",
        ),
        "crossings": Field(
            {
                "type": "array",
                "items": {"type": "array", "items": _INDEX, "minItems": 2, "maxItems": 2},
            },
            "pairs of segments whose centre lines cross (a figure-8): the walls open there",
        ),
        "start": {
            "segment": Field(_INDEX, "the segment the robot starts on, heading along it"),
            "along_m": Field(_NUMBER, "its distance from the segment's start"),
        },
        "signal": {
            "segment": Field(_INDEX, "the segment with the traffic signal", required=True),
            "fraction": Field(
                {"type": "number", "minimum": 0, "maximum": 1},
                "where the stop line crosses the segment's straight part, 0..1",
                required=True,
            ),
            **_dataclass_table(SignalConfig, skip=("leg", "stopline_fraction"), physical=True),
        },
        "obstacle": _dataclass_table(ObstacleConfig, skip=("enabled",), physical=True),
        "obstacles": TableList(
            {
                "rule": Field(
                    {"enum": ["seeded", "fixed", "moving"]},
                    "seeded: anywhere on the track each episode; fixed: at segment, along_m, "
                    "lateral_m; moving: back and forth on segment between from_fraction and "
                    "to_fraction at speed_mps",
                    required=True,
                ),
                "segment": Field(_INDEX, "the segment it stands or moves on (fixed, moving)"),
                "along_m": Field(_NUMBER, "its distance from the segment's start (fixed)"),
                "lateral_m": Field(_NUMBER, "its offset left of the centre line (fixed, moving)"),
                "from_fraction": Field(
                    {"type": "number", "minimum": 0, "maximum": 1}, "its path's start (moving)"
                ),
                "to_fraction": Field(
                    {"type": "number", "minimum": 0, "maximum": 1}, "its path's end (moving)"
                ),
                "speed_mps": Field(_POSITIVE, "its speed along the path, m/s (moving)"),
            },
            "the obstacles and their placement rules",
        ),
    },
}
"""The world file format."""

_RULE_KEYS = {
    "seeded": {"rule"},
    "fixed": {"rule", "segment", "along_m", "lateral_m"},
    "moving": {"rule", "segment", "lateral_m", "from_fraction", "to_fraction", "speed_mps"},
}
_REQUIRED_BY_RULE = {
    "seeded": set(),
    "fixed": {"segment", "along_m"},
    "moving": {"segment", "from_fraction", "to_fraction", "speed_mps"},
}


def json_schema() -> dict[str, Any]:
    """The JSON Schema of the format (docs/schemas/world.schema.json)."""
    schema = _table_schema(
        SPEC,
        "An srlab world: a corridor track of any shape (a closed centre line with a width), "
        "its signal, its obstacles and the robot's settings (docs/worlds.md).",
    )
    schema["required"] = ["track"]
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "srlab world file",
        **schema,
    }


def _table_schema(table: Table, description: str) -> dict[str, Any]:
    props: dict[str, Any] = {}
    required = []
    for key, spec in table.items():
        if isinstance(spec, Field):
            props[key] = {**spec.schema, "description": spec.description}
            if spec.required:
                required.append(key)
        elif isinstance(spec, TableList):
            props[key] = {"type": "array", "items": _table_schema(spec.table, spec.description)}
            props[key]["description"] = spec.description
        else:
            props[key] = _table_schema(spec, key)
            if any(isinstance(s, Field) and s.required for s in spec.values()):
                required.append(key)
    out: dict[str, Any] = {
        "type": "object",
        "description": description,
        "additionalProperties": False,
        "properties": props,
    }
    if required:
        out["required"] = required
    return out


def entry_name(entry: Entry) -> str:
    """``track.obstacles[1].lateral_m`` for ("track", "obstacles", 1, "lateral_m")."""
    out = ""
    for part in entry:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out or "(top)"


class _Lines:
    """Finds the line a key is on (tomllib reports lines only for syntax errors)."""

    _HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-\" ]+?)\s*\]\]?")
    _KEY = re.compile(r"^\s*\"?([A-Za-z0-9_\-]+)\"?\s*=")

    def __init__(self, text: str) -> None:
        self._at: dict[tuple[str, int, str], int] = {}
        counts: dict[str, int] = {}
        table, index = "", -1
        for n, line in enumerate(text.splitlines(), start=1):
            head = self._HEADER.match(line)
            if head:
                table = head.group(2).replace('"', "").replace(" ", "")
                index = -1
                if head.group(1) == "[[":
                    index = counts[table] = counts.get(table, -1) + 1
                self._at.setdefault((table, index, ""), n)
                continue
            key = self._KEY.match(line)
            if key:
                self._at.setdefault((table, index, key.group(1)), n)

    def of(self, entry: Entry) -> int | None:
        """The line of an entry, or of the nearest table or key holding it."""
        parts = list(entry)
        while parts:
            names = [p for p in parts if isinstance(p, str)]
            index = next((p for p in reversed(parts) if isinstance(p, int)), -1)
            # the entry as a key of its table, as a table itself, or as an inline table's key
            for table, key in ((".".join(names[:-1]), names[-1]), (".".join(names), "")):
                found = self._at.get((table, index, key)) or self._at.get((table, -1, key))
                if found:
                    return found
            parts.pop()
        return None


class _Loader:
    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.lines = _Lines(text)

    def error(self, entry: Entry, reason: str) -> WorldFileError:
        line = self.lines.of(entry)
        where = f"{self.path}:{line}" if line else str(self.path)
        return WorldFileError(f"{where}: {entry_name(entry)}: {reason}")

    def check(self, value: Any, spec: Table, entry: Entry) -> None:
        """Unknown keys, missing required keys and wrong types, by the format's spec."""
        if not isinstance(value, Mapping):
            raise self.error(entry, "a table of settings is needed")
        for key in value:
            if key not in spec:
                known = ", ".join(spec)
                raise self.error((*entry, key), f"unknown key {key!r} (known: {known})")
        for key, sub in spec.items():
            here = (*entry, key)
            if key not in value:
                if isinstance(sub, Field) and sub.required:
                    raise self.error(entry, f"{key!r} is required")
                if isinstance(sub, Mapping) and any(
                    isinstance(s, Field) and s.required for s in sub.values()
                ):
                    raise self.error(entry, f"a [{entry_name(here)}] table is required")
                continue
            if isinstance(sub, Field):
                self.value(value[key], sub.schema, here)
            elif isinstance(sub, TableList):
                if not isinstance(value[key], list):
                    raise self.error(here, "a list of tables is needed")
                for i, item in enumerate(value[key]):
                    self.check(item, sub.table, (*here, i))
            else:
                self.check(value[key], sub, here)

    def value(self, value: Any, schema: Mapping[str, Any], entry: Entry) -> None:
        if "enum" in schema:
            if value not in schema["enum"]:
                raise self.error(
                    entry, f"must be one of {', '.join(schema['enum'])}, got {value!r}"
                )
            return
        kind = schema["type"]
        if kind == "array":
            if not isinstance(value, list):
                raise self.error(entry, f"must be a list, got {value!r}")
            lo, hi = schema.get("minItems", 0), schema.get("maxItems", math.inf)
            if not lo <= len(value) <= hi:
                count = f"{lo}" if lo == hi else f"at least {lo}"
                raise self.error(entry, f"must have {count} items, got {len(value)}")
            for i, item in enumerate(value):
                self.value(item, schema["items"], (*entry, i))
            return
        ok = {
            "string": isinstance(value, str),
            "boolean": isinstance(value, bool),
            "integer": isinstance(value, int) and not isinstance(value, bool),
            "number": isinstance(value, int | float) and not isinstance(value, bool),
        }[kind]
        if not ok:
            raise self.error(entry, f"must be {_A[kind]}, got {value!r}")
        if kind in ("integer", "number"):
            if not math.isfinite(value):
                raise self.error(entry, f"must be finite, got {value!r}")
            if "minimum" in schema and value < schema["minimum"]:
                raise self.error(entry, f"must be at least {schema['minimum']}, got {value!r}")
            if "maximum" in schema and value > schema["maximum"]:
                raise self.error(entry, f"must be at most {schema['maximum']}, got {value!r}")
            if "exclusiveMinimum" in schema and value <= schema["exclusiveMinimum"]:
                raise self.error(
                    entry, f"must be more than {schema['exclusiveMinimum']}, got {value!r}"
                )


_A = {
    "string": "a string",
    "boolean": "true or false",
    "integer": "a whole number",
    "number": "a number",
}


def load_world_file(path: Path, name: str | None = None) -> WorldPreset:
    """The world a file describes; `name` (default: its own, or the file's stem)."""
    from core.sim.worlds import WorldPreset

    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise WorldFileError(f"{path}: cannot read it: {e.strerror or e}") from e
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise WorldFileError(f"{path}: not valid TOML: {e}") from e
    loader = _Loader(path, text)
    loader.check(raw, SPEC, ())
    config = _world_config(loader, raw)
    overrides = {k: v for k, v in raw.items() if k not in ("name", "description", "reasons")}
    return WorldPreset(
        name or str(raw.get("name") or path.stem),
        str(raw.get("description", "")),
        str(raw.get("reasons", "")).strip(),
        config,
        overrides,
    )


def _world_config(loader: _Loader, raw: Mapping[str, Any]) -> WorldConfig:
    from core.sim.worlds import _apply

    track = _corridor(loader, raw["track"])
    robot = RobotConfig()
    if "robot" in raw:
        try:
            robot = _apply(robot, raw["robot"], "robot")
        except CatalogError as e:
            raise loader.error(("robot",), str(e).removeprefix("robot: ")) from e
    extra = {k: raw[k] for k in ("dt_s", "max_ticks") if k in raw}
    return WorldConfig(track=track, robot=robot, **extra)


def _corridor(loader: _Loader, t: Mapping[str, Any]) -> CorridorConfig:
    centre = tuple((float(x), float(y)) for x, y in t["centre"])
    n = len(centre)
    widths = tuple(float(w) for w in t.get("widths_m", [t["width_m"]] * n))
    if len(widths) != n:
        raise loader.error(
            ("track", "widths_m"), f"needs one width per segment ({n}), got {len(widths)}"
        )
    _check_line(loader, centre, widths)
    start = t.get("start", {})
    sig = dict(t["signal"])
    signal_keys = {"leg": sig.pop("segment"), "stopline_fraction": sig.pop("fraction"), **sig}
    signal_keys = {
        k: tuple(float(x) for x in v) if isinstance(v, list) else v for k, v in signal_keys.items()
    }
    try:
        signal = SignalConfig(**signal_keys)
        obstacle = dataclasses.replace(ObstacleConfig(), **t.get("obstacle", {}))
    except (TypeError, ValueError) as e:
        raise loader.error(("track",), str(e)) from e
    config = CorridorConfig(
        centre=centre,
        widths_m=widths,
        crossings=tuple((int(a), int(b)) for a, b in t.get("crossings", [])),
        start_segment=int(start.get("segment", 0)),
        start_along_m=float(start.get("along_m", 1.2)),
        signal=signal,
        obstacle=obstacle,
        obstacles=tuple(_placement(loader, i, o) for i, o in enumerate(t.get("obstacles", []))),
    )
    _check_crossings(loader, config)
    geo = CorridorGeometry.build(config)
    _check_places(loader, config, geo)
    return config


def _check_line(
    loader: _Loader, centre: tuple[tuple[float, float], ...], widths: Sequence[float]
) -> None:
    n = len(centre)
    pts = np.asarray(centre)
    for k in range(n):
        if math.dist(centre[k], centre[(k + 1) % n]) < 1e-6:
            raise loader.error(("track", "centre", k), f"segment {k} has no length")
    for k in range(n):
        d0 = pts[(k + 1) % n] - pts[k]
        d1 = pts[(k + 2) % n] - pts[(k + 1) % n]
        turn = math.degrees(turn_angle(d0 / np.hypot(*d0), d1 / np.hypot(*d1)))
        if abs(turn) > MAX_TURN_DEG:
            raise loader.error(
                ("track", "centre", (k + 1) % n),
                f"the corner at vertex {(k + 1) % n} turns {abs(turn):.0f} degrees "
                f"(at most {MAX_TURN_DEG:.0f})",
            )


def _check_crossings(loader: _Loader, c: CorridorConfig) -> None:
    n = len(c.centre)
    segs = [(c.centre[k], c.centre[(k + 1) % n]) for k in range(n)]
    declared = set()
    for i, (a, b) in enumerate(c.crossings):
        entry: Entry = ("track", "crossings", i)
        if a >= n or b >= n:
            raise loader.error(entry, f"names a segment beyond the last ({n - 1})")
        if a == b or (a - b) % n in (1, n - 1):
            raise loader.error(entry, f"segments {a} and {b} are the same or adjacent")
        at = segments_meet(segs[a], segs[b])
        if at is None:
            raise loader.error(entry, f"segments {a} and {b} do not cross")
        for k, other in ((a, b), (b, a)):
            room = c.widths_m[other] / 2 + CROSSING_MARGIN_M
            if min(math.dist(at, segs[k][0]), math.dist(at, segs[k][1])) < room:
                raise loader.error(
                    entry, f"the crossing is within {room:.2f} m of an end of segment {k}"
                )
        declared.add(frozenset((a, b)))
    for i in range(n):
        for j in range(i + 2, n):
            if (j - i) % n in (1, n - 1) or frozenset((i, j)) in declared:
                continue
            at = segments_meet(segs[i], segs[j])
            if at is not None:
                raise loader.error(
                    ("track", "centre"),
                    f"segments {i} and {j} cross at ({at[0]:.2f}, {at[1]:.2f}) "
                    f"without a declared crossing (add [{i}, {j}] to track.crossings)",
                )
            gap = segment_distance(segs[i], segs[j])
            need = (c.widths_m[i] + c.widths_m[j]) / 2
            if gap < need:
                raise loader.error(
                    ("track", "centre"),
                    f"the corridors of segments {i} and {j} overlap (centre lines {gap:.2f} m "
                    f"apart, {need:.2f} m needed)",
                )


def _placement(loader: _Loader, i: int, o: Mapping[str, Any]) -> ObstaclePlacement:
    entry: Entry = ("track", "obstacles", i)
    rule = o["rule"]
    for key in o:
        if key not in _RULE_KEYS[rule]:
            raise loader.error((*entry, key), f"{key!r} does not apply to a {rule} obstacle")
    for key in _REQUIRED_BY_RULE[rule]:
        if key not in o:
            raise loader.error(entry, f"a {rule} obstacle needs {key!r}")
    return ObstaclePlacement(
        rule=rule,
        segment=int(o.get("segment", 0)),
        along_m=float(o.get("along_m", 0.0)),
        lateral_m=float(o.get("lateral_m", 0.0)),
        from_fraction=float(o.get("from_fraction", 0.0)),
        to_fraction=float(o.get("to_fraction", 1.0)),
        speed_mps=float(o.get("speed_mps", 0.0)),
    )


def _check_places(loader: _Loader, c: CorridorConfig, geo: CorridorGeometry) -> None:
    n = len(c.centre)
    for k in range(n):
        lo, hi = geo.straight_part(k)
        if hi - lo < 0.3:
            raise loader.error(
                ("track", "centre", k),
                f"segment {k} ({geo.leg_lengths_m[k]:.2f} m) is too short for its corners "
                f"(they take {lo + geo.leg_lengths_m[k] - hi:.2f} m of it)",
            )
    if c.start_segment >= n:
        raise loader.error(
            ("track", "start", "segment"), f"no segment {c.start_segment} (0..{n - 1})"
        )
    lo, hi = geo.straight_part(c.start_segment)
    if not lo <= c.start_along_m <= hi:
        raise loader.error(
            ("track", "start", "along_m"),
            f"must be on the segment's straight part, {lo:.2f}..{hi:.2f} m",
        )
    sig = c.signal
    if sig.leg >= n:
        raise loader.error(("track", "signal", "segment"), f"no segment {sig.leg} (0..{n - 1})")
    lo, hi = geo.straight_part(sig.leg)
    need = sig.lamp_beyond_m + 1.0
    stop = geo.along_of(sig.leg, geo.stopline_point)
    if hi - lo < need or stop + sig.lamp_beyond_m > hi:
        raise loader.error(
            ("track", "signal"),
            f"segment {sig.leg} is too short for the signal: its straight part is "
            f"{hi - lo:.2f} m, the stop line and the lamp {sig.lamp_beyond_m:.2f} m beyond it "
            f"need {need:.2f} m and the lamp must stand on it",
        )
    seeded = [i for i, p in enumerate(c.obstacles) if p.rule == "seeded"]
    if seeded and sum(hi - lo for _, lo, hi in seeded_area(geo).spans()) < c.obstacle.size_m:
        raise loader.error(
            ("track", "obstacles", seeded[0]),
            "no room for a seeded obstacle: the corners, the start, the stop line, the "
            "crossings and the other obstacles' keep-outs cover every straight",
        )
    for i, p in enumerate(c.obstacles):
        entry: Entry = ("track", "obstacles", i)
        if p.rule == "seeded":
            continue
        if p.segment >= n:
            raise loader.error((*entry, "segment"), f"no segment {p.segment} (0..{n - 1})")
        length = float(geo.leg_lengths_m[p.segment])
        room = float(geo.widths_m[p.segment]) / 2 - c.obstacle.size_m / 2 - WALL_CLEARANCE_M
        if abs(p.lateral_m) > room:
            raise loader.error(
                (*entry, "lateral_m"),
                f"off the track: {p.lateral_m} m from the centre line of segment {p.segment}, "
                f"at most {room:.2f} m keeps the {c.obstacle.size_m} m obstacle inside its walls",
            )
        if p.rule == "fixed" and not 0.0 <= p.along_m <= length:
            raise loader.error(
                (*entry, "along_m"),
                f"off the track: segment {p.segment} is {length:.2f} m long",
            )
        if p.rule == "moving" and p.from_fraction >= p.to_fraction:
            raise loader.error(
                (*entry, "to_fraction"), "must be more than from_fraction (the path's start)"
            )
