"""The experimental conditions: which knowledge the robot starts with and how it learns.

They are data: the built-in ones in ``core/data/conditions.toml``, a researcher's own in a
file of the same form (`load_conditions`), each table a `Condition`.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable, Collection
from dataclasses import dataclass, fields, replace
from functools import cache
from pathlib import Path
from typing import Any, Literal, NoReturn

from core.brain.brain import BrainConfig, LearningConfig
from core.brain.catalog import Catalog, data_dir, load_catalog
from core.brain.propagation import KpConfig
from core.brain.selection import SelectionConfig
from core.errors import ConditionFileError, UnknownNameError
from core.run.trainer import (
    IMPERFECTIONS,
    PERFECT,
    TEACHERS_FILE,
    Imperfections,
    TeacherError,
)


@dataclass(frozen=True, slots=True)
class Condition:
    """One condition of the paper's comparison.

    Attributes:
        name: its name on the command line.
        description: one line for people.
        network: the knowledge set the behaviour network starts from.
        learning: whether rewards update LTM and the network.
        epsilon: exploration rate of the learnable stimuli.
        success_reward: the delayed reward a successful lap gives (None: none).
        learnable_sensors: the logical sensors whose stimuli are explored and learned.
        trainer: the reinforcement program that rewards responses at once (None: none).
        teacher: how the program's judgements are given (`core.run.trainer.Imperfections`): the
            perfect teacher, at once and always right, unless set (the teacher_*
            parameters, `srlab experiment --teacher`).
        kp: whether knowledge propagation runs.
        agent: ``brain`` (the paper's architecture), ``qlambda`` (the tabular baseline), or
            ``dqn`` / ``ppo`` (stable-baselines3's, the ``srlab[baselines]`` extra).
        extra_networks: knowledge sets added on top of `network` (the signal's responses
            when they are given, see `core.run.setup.Setup`).
        hybrid: for an outside learner (``agent`` other than ``brain``): it may defer to the
            built-in behaviour, starts by deferring, and explores per encounter, so the
            designed reflexes it starts from are kept until it has learned better.
        interactive: meant for a person giving rewards at the keyboard (the runs API):
            not one of the experiments' conditions, so never tuned or compared.
        kp_failure_penalty: with `kp`, the punishment a failed episode gives KP's RLTM
            (`core.brain.propagation.KpConfig.failure_penalty`; 0: none).
        epsilon_half_life: for Q(lambda), episodes over which `epsilon` halves
            (`core.learners.qlambda.epsilon_at`; 0: it stays constant).
    """

    name: str
    description: str
    network: str
    learning: bool = False
    epsilon: float = 0.0
    success_reward: float | None = None
    learnable_sensors: tuple[str, ...] = ("signal", "camera_obstacle")
    trainer: str | None = None
    teacher: Imperfections = PERFECT
    kp: bool = False
    agent: str = "brain"
    extra_networks: tuple[str, ...] = ()
    hybrid: bool = False
    interactive: bool = False
    kp_failure_penalty: float = 0.0
    epsilon_half_life: float = 0.0

    def brain_config(self, eta: float = 0.1, synthesize: bool = False) -> BrainConfig:
        """The brain parameters of this condition."""
        return BrainConfig(
            selection=SelectionConfig(epsilon=self.epsilon if self.learning else 0.0),
            learning=LearningConfig(
                enabled=self.learning, eta=eta, learnable_sensors=self.learnable_sensors
            ),
            kp=KpConfig(
                enabled=self.kp,
                eta=eta,
                synthesize=synthesize,
                failure_penalty=self.kp_failure_penalty,
            ),
        )


CONDITIONS_FILE = "conditions.toml"
"""The built-in conditions' data file, in ``core/data/``."""
AGENTS = ("brain", "qlambda", "dqn", "ppo")
"""What may learn in a condition: the paper's architecture, or a baseline."""
_STRING = ((str,), "a string")
_FLAG = ((bool,), "true or false")
_NUMBER = ((int, float), "a number")
_LIST = ((list,), "a list of names")
_TYPES: dict[str, tuple[tuple[type, ...], str]] = {
    "name": _STRING,
    "description": _STRING,
    "based_on": _STRING,
    "network": _STRING,
    "learning": _FLAG,
    "epsilon": _NUMBER,
    "success_reward": _NUMBER,
    "learnable_sensors": _LIST,
    "trainer": _STRING,
    "teacher": ((dict,), "a table of imperfections"),
    "kp": _FLAG,
    "agent": _STRING,
    "extra_networks": _LIST,
    "hybrid": _FLAG,
    "interactive": _FLAG,
    "kp_failure_penalty": _NUMBER,
    "epsilon_half_life": _NUMBER,
}
"""Every key a condition's table may hold: the TOML types it takes, in words."""


def _line_of(text: str, index: int, key: str | None) -> int | None:
    """The line of the `index`-th ``[[condition]]`` table (its `key`'s, if found there)."""
    lines = text.splitlines()
    heads = [i for i, line in enumerate(lines) if line.strip() == "[[condition]]"]
    if index >= len(heads):
        return None
    first = heads[index]
    last = heads[index + 1] if index + 1 < len(heads) else len(lines)
    if key is not None:
        pattern = re.compile(rf"^\s*{re.escape(key)}\s*=")
        for i in range(first, last):
            if pattern.match(lines[i]):
                return i + 1
    return first + 1


def _condition_of(
    entry: dict[str, Any],
    known: dict[str, Condition],
    fail: Callable[[str, str | None], NoReturn],
    networks: Callable[[str], bool] | None,
    sensors: Collection[str] | None = None,
) -> Condition:
    """One table's condition (`fail(reason, key)` raises, naming where)."""
    for key, value in entry.items():
        if key not in _TYPES:
            fail(f"unknown key {key!r} (known: {', '.join(_TYPES)})", key)
        kinds, words = _TYPES[key]
        if not isinstance(value, kinds) or (bool not in kinds and isinstance(value, bool)):
            fail(f"{key} must be {words}, got {value!r}", key)
    name = entry.get("name")
    if not name:
        fail("a condition needs a name", None)
    base = entry.get("based_on")
    values: dict[str, Any] = {}
    if base is not None:
        if base not in known:
            fail(f"based_on {base!r} names no condition (known: {', '.join(known)})", "based_on")
        values = {f.name: getattr(known[base], f.name) for f in fields(Condition)}
    elif "network" not in entry:
        fail("a condition needs a network (or based_on, to take another's)", None)
    values |= {k: v for k, v in entry.items() if k != "based_on"}
    values.setdefault("description", "")
    for key in ("learnable_sensors", "extra_networks"):
        if key in values:
            items = values[key]
            if not all(isinstance(v, str) for v in items):
                fail(f"{key} must be a list of names", key)
            values[key] = tuple(items)
    if "teacher" in entry:
        unknown = set(entry["teacher"]) - set(IMPERFECTIONS)
        if unknown:
            fail(f"teacher: unknown imperfections {sorted(unknown)} (known: "
                 f"{', '.join(IMPERFECTIONS)})", "teacher")  # fmt: skip
        try:
            values["teacher"] = Imperfections(**{k: float(v) for k, v in entry["teacher"].items()})
        except (TeacherError, TypeError, ValueError) as e:
            fail(f"teacher: {e}", "teacher")
    epsilon = float(values.get("epsilon", 0.0))
    if not 0.0 <= epsilon <= 1.0:
        fail(f"epsilon must be in [0, 1], got {epsilon!r}", "epsilon")
    reward = values.get("success_reward")
    if reward is not None and not -1.0 <= reward <= 1.0:
        fail(f"success_reward must be in [-1, 1], got {reward!r}", "success_reward")
    for key in ("kp_failure_penalty", "epsilon_half_life"):
        if float(values.get(key, 0.0)) < 0.0:
            fail(f"{key} must be 0 or more, got {values[key]!r}", key)
    if values.get("agent", "brain") not in AGENTS:
        fail(f"agent must be one of {', '.join(AGENTS)}, got {values['agent']!r}", "agent")
    for key in ("epsilon", "success_reward", "kp_failure_penalty", "epsilon_half_life"):
        if values.get(key) is not None:
            values[key] = float(values[key])
    if networks is None:  # the built-in ones: their names are checked by the tests
        return Condition(**values)
    for key in ("network", "extra_networks"):
        items = values.get(key, ())
        for n in (items,) if isinstance(items, str) else items:
            if key in entry and not networks(n):
                fail(f"{key}: {n!r} is no network (built in, a file, or the S-R editor's)", key)
    if sensors is None:
        sensors = {s.name for s in _default_catalog().sensors}
    for n in values.get("learnable_sensors", ()):
        if n not in sensors:
            fail(f"learnable_sensors: unknown sensor {n!r} (known: {', '.join(sorted(sensors))})",
                 "learnable_sensors")  # fmt: skip
    trainer = values.get("trainer")
    if trainer is not None and trainer not in trainer_names():
        fail(f"trainer: unknown reinforcement program {trainer!r} (known: "
             f"{', '.join(trainer_names())})", "trainer")  # fmt: skip
    return Condition(**values)


def condition_definition(condition: Condition) -> dict[str, Any]:
    """A condition as its data file's table holds it (every field, the teacher's changes)."""
    out: dict[str, Any] = {}
    for f in fields(Condition):
        value = getattr(condition, f.name)
        if f.name == "teacher":
            value = condition.teacher.changed()
        elif isinstance(value, tuple):
            value = list(value)
        out[f.name] = value
    return out


def parse_condition_file(
    text: str,
    where: str,
    known: dict[str, Condition] | None = None,
    networks: Callable[[str], bool] | None = None,
    sensors: Collection[str] | None = None,
) -> tuple[Condition, ...]:
    """The conditions of a data file's text (``[[condition]]`` tables), in file order.

    `known` are the conditions a table may be `based_on` (and may not be named as), besides
    the file's earlier ones; `networks` says whether a network name is known (None: the
    names, and the sensors and trainer, are not checked, as for the built-in file);
    `sensors` the logical sensors `learnable_sensors` may name (None: srlab's own). A bad
    file raises `ConditionFileError` naming `where` (the file), the entry, its line and the
    reason.
    """
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConditionFileError(f"{where}: {e}") from None
    unknown = set(raw) - {"condition"}
    if unknown:
        raise ConditionFileError(
            f"{where}: unknown table or key {sorted(unknown)[0]!r}: a condition file holds "
            "[[condition]] tables"
        )
    entries = raw.get("condition", [])
    if not isinstance(entries, list) or not entries:
        raise ConditionFileError(f"{where}: no [[condition]] table")
    so_far = dict(known or {})
    out: list[Condition] = []
    for i, entry in enumerate(entries):
        label = f"condition {entry.get('name')!r}" if entry.get("name") else f"condition #{i + 1}"

        def fail(reason: str, key: str | None, i: int = i, label: str = label) -> NoReturn:
            line = _line_of(text, i, key)
            at = f" (line {line})" if line is not None else ""
            raise ConditionFileError(f"{where}: {label}{at}: {reason}")

        condition = _condition_of(entry, so_far, fail, networks, sensors)
        if condition.name in so_far:
            what = "a built-in condition" if known and condition.name in known else "an earlier one"
            fail(f"the name {condition.name!r} is taken by {what}: name it otherwise", "name")
        so_far[condition.name] = condition
        out.append(condition)
    return tuple(out)


def load_conditions(
    path: Path,
    known: dict[str, Condition] | None = None,
    networks: Callable[[str], bool] | None = None,
) -> tuple[Condition, ...]:
    """The conditions of a data file (`parse_condition_file`); built-ins are `known` by default."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ConditionFileError(f"{path}: {e.strerror or e}") from None
    known = CONDITIONS if known is None else known
    return parse_condition_file(text, str(path), known, networks or _shipped_network)


@cache
def _default_catalog() -> Catalog:
    return load_catalog()


def _shipped_network(name: str) -> bool:
    return name in _default_catalog().knowledge


def trainer_names() -> tuple[str, ...]:
    """The reinforcement programs a condition may name (``core/data/trainers/``)."""
    folder = data_dir() / "trainers"
    teachers = TEACHERS_FILE.removesuffix(".toml")
    return tuple(sorted(
        {f.stem for f in folder.glob("*.toml") if f.stem != teachers and "-" not in f.stem}
    ))  # fmt: skip


CONDITIONS: dict[str, Condition] = {
    c.name: c
    for c in parse_condition_file(
        (data_dir() / CONDITIONS_FILE).read_text(encoding="utf-8"),
        str(data_dir() / CONDITIONS_FILE),
    )
}
"""The built-in conditions (``core/data/conditions.toml``), by name, in file order."""


Start = Literal["", "table1", "design"]
"""What a condition's robot starts from: its own start (""), Table I, or kp's design."""
STARTS: tuple[Start, ...] = ("table1", "design")
START_SETS: dict[str, str] = {"table1": "innate", "design": "kp"}
"""The knowledge set of each start: Table I, or kp's design (Table I, lane keeping, sonar)."""
PROGRAMMED_ON_TABLE_I = ("dp", "dp-rare")
"""Knowledge sets that program responses on top of Table I (the S-R editor's)."""


def with_start(condition: Condition, start: Start) -> Condition:
    """`condition` with its robot starting from `start` instead of its own knowledge.

    A condition starting from Table I or kp's design starts from the other when told; a
    DP condition keeps its programmed responses and puts them on top of the start. A
    condition whose knowledge is neither (the expert's, `unaware`'s) has no start to change.
    """
    if not start:
        return condition
    if start not in START_SETS:
        raise UnknownNameError(f"unknown start {start!r} (known: {', '.join(START_SETS)})")
    base = START_SETS[start]
    if condition.network in START_SETS.values():
        return replace(condition, network=base)
    if condition.network in PROGRAMMED_ON_TABLE_I:
        if base == START_SETS["table1"]:
            return condition
        extra = (condition.network, *condition.extra_networks)
        return replace(condition, network=base, extra_networks=extra)
    raise UnknownNameError(
        f"condition {condition.name!r} starts from {condition.network!r}, which a start "
        f"does not replace (a start replaces Table I and kp's design)"
    )


DEEP_AGENTS = ("dqn", "ppo")
"""The agents of the deep baselines (`core.learners.baselines`), which need the optional extra."""


def get_condition(name: str) -> Condition:
    """The condition called `name`."""
    try:
        return CONDITIONS[name]
    except KeyError:
        known = ", ".join(CONDITIONS)
        raise UnknownNameError(f"unknown condition {name!r} (known: {known})") from None
