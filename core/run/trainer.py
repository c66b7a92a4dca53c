"""The reinforcement program (RP) and the simulated teachers that give its rewards.

The program says which responses are acceptable (`ReinforcementProgram`, data in
``core/data/trainers/<name>.toml``); a `Teacher` gives its judgements the way a person at
the keyboard would: with the imperfections the interactive-RL literature simulates
(B-Pref's mistaken and skipping teachers, TAMER's reaction delay, a bias toward positive
reward, fatigue), each a named parameter, seeded from the run's seed. The perfect teacher,
every imperfection 0, is the paper's RP: every judgement given at once with its sign.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from core.brain.catalog import Catalog, data_dir
from core.brain.selection import Decision, How
from core.errors import CatalogError, CoreError, UnknownNameError


@dataclass(frozen=True, slots=True)
class ReinforcementProgram:
    """Judges each new response to the stimuli it knows and says how to reward it.

    Attributes:
        name: the program's name.
        good: acceptable behaviour ids per stimulus id; stimuli not listed are not judged.
        reward: the reward for an acceptable response.
        penalty: the reward for any other response.
    """

    name: str
    good: Mapping[int, frozenset[int]]
    reward: float = 1.0
    penalty: float = -1.0

    def judge(self, decision: Decision) -> float | None:
        """The reward a response earns, or None when the program has nothing to say."""
        if decision.how is How.CONTINUED:
            return None
        good = self.good.get(decision.stimulus)
        if good is None:
            return None
        return self.reward if decision.behaviour in good else self.penalty


def load_trainer(catalog: Catalog, name: str, root: Path | None = None) -> ReinforcementProgram:
    """Load the reinforcement program `name` from the data folder.

    A program written for one sensor definition has a variant for each other one,
    ``<name>-<definition>.toml``; the catalogue's definition picks it.
    """
    folder = (root or data_dir()) / "trainers"
    path = folder / f"{name}-{catalog.definition}.toml"
    if not catalog.definition or not path.is_file():
        path = folder / f"{name}.toml"
    if not path.is_file() or name == TEACHERS_FILE.removesuffix(".toml"):
        raise UnknownNameError(f"unknown reinforcement program {name!r}")
    raw = _read(path)
    good = {
        catalog.stimulus(s).id: frozenset(catalog.behaviour(b).id for b in behaviours)
        for s, behaviours in raw.get("good", {}).items()
    }
    reward = float(raw.get("reward", 1.0))
    penalty = float(raw.get("penalty", -1.0))
    if not (-1.0 <= penalty <= 1.0 and -1.0 <= reward <= 1.0):
        raise CatalogError(f"{path}: reward and penalty must be in [-1, 1]")
    return ReinforcementProgram(name, good, reward, penalty)


def _read(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise CatalogError(f"{path}: {e}") from e


class TeacherError(CoreError):
    """A teacher's imperfections are not acceptable (a name, a value out of range)."""


@dataclass(frozen=True, slots=True)
class Imperfections:
    """How a simulated teacher falls short of a perfect, instant judge. All 0: perfect.

    Attributes:
        mistake: probability that a judgement is given with the wrong sign (B-Pref's
            mistaken teacher).
        skip: probability that a judgement is not given at all.
        delay_s: the mean reaction delay, in seconds: a response judged at tick t is
            rewarded at the boundary `delay` later, where it credits what STM holds then
            (Eq. (1) with ``d_k`` counted to its arrival).
        delay_cv: the spread of the delay, as its coefficient of variation: delays are drawn
            from a gamma distribution with shape ``1 / delay_cv**2`` (0: always `delay_s`;
            the default, 0.7, is about TAMER's gamma of shape 2).
        bias: probability that a penalty the response deserved is given as a reward (a
            lenient teacher's bias toward positive reward).
        fatigue: the share of the feedback rate lost per episode: episode e (from 0) is
            judged at rate ``(1 - fatigue) ** e`` on top of `skip`.
    """

    mistake: float = 0.0
    skip: float = 0.0
    delay_s: float = 0.0
    delay_cv: float = 0.7
    bias: float = 0.0
    fatigue: float = 0.0

    def __post_init__(self) -> None:
        highest = {"delay_s": MAX_DELAY_S, "delay_cv": MAX_DELAY_CV}
        for f in fields(self):
            v, high = getattr(self, f.name), highest.get(f.name, 1.0)
            if not (math.isfinite(v) and 0.0 <= v <= high):
                raise TeacherError(f"teacher {f.name} must be in [0, {high:g}], got {v!r}")

    @property
    def perfect(self) -> bool:
        """Whether every judgement is given, at once, with its sign (the paper's RP)."""
        return not (self.mistake or self.skip or self.delay_s or self.bias or self.fatigue)

    def changed(self) -> dict[str, float]:
        """The imperfections that differ from the perfect teacher's, by name."""
        return {
            f.name: getattr(self, f.name)
            for f in fields(self)
            if getattr(self, f.name) != getattr(PERFECT, f.name)
        }


MAX_DELAY_S = 10.0
MAX_DELAY_CV = 3.0
PERFECT = Imperfections()
"""The paper's reinforcement program: every judgement given, at once, with its sign."""
IMPERFECTIONS = tuple(f.name for f in fields(Imperfections))
"""The imperfections' names, in the order `Imperfections` declares them."""
TEACHERS_FILE = "teachers.toml"
"""The named teachers' presets, in ``core/data/trainers/``."""


@cache
def teacher_presets(root: Path | None = None) -> dict[str, Imperfections]:
    """The named teachers of ``core/data/trainers/teachers.toml``, in file order."""
    path = (root or data_dir()) / "trainers" / TEACHERS_FILE
    out: dict[str, Imperfections] = {}
    for name, values in _read(path).items():
        if not isinstance(values, dict):
            raise CatalogError(f"{path}: [{name}] must be a table of imperfections")
        unknown = set(values) - set(IMPERFECTIONS)
        if unknown:
            raise CatalogError(f"{path}: [{name}] has unknown imperfections {sorted(unknown)}")
        try:
            out[name] = Imperfections(**{k: float(v) for k, v in values.items()})
        except TeacherError as e:
            raise CatalogError(f"{path}: [{name}]: {e}") from e
    return out


def parse_teacher(text: str) -> Imperfections:
    """A teacher from the command line: a preset, ``NAME=VALUE`` pairs, or both.

    ``human``, ``mistake=0.2,delay_s=1`` and ``human,skip=0`` (a preset, then changes)
    all parse; items are separated by commas.
    """
    presets = teacher_presets()
    teacher = PERFECT
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise TeacherError("--teacher: no teacher given")
    for i, item in enumerate(items):
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep:
            if i:
                raise TeacherError(f"--teacher: a preset ({name!r}) must come first")
            if name not in presets:
                raise UnknownNameError(
                    f"unknown teacher {name!r} (presets: {', '.join(presets)}; or give "
                    f"NAME=VALUE with NAME one of {', '.join(IMPERFECTIONS)})"
                )
            teacher = presets[name]
            continue
        if name not in IMPERFECTIONS:
            raise UnknownNameError(
                f"unknown teacher imperfection {name!r} (known: {', '.join(IMPERFECTIONS)})"
            )
        try:
            number = float(value)
        except ValueError:
            raise TeacherError(f"--teacher {name}: {value.strip()!r} is not a number") from None
        teacher = replace(teacher, **{name: number})
    return teacher


@dataclass(frozen=True, slots=True)
class Judgement:
    """A reward a teacher gives for one response.

    Attributes:
        value: the reward, in [-1, 1] (its sign may be wrong: see `note`).
        due: the tick boundary it arrives at: it credits the STM records before it.
        tick: the tick of the response judged.
        note: the program's name, then what was imperfect about it (for the reward log).
    """

    value: float
    due: int
    tick: int
    note: str


class Teacher:
    """A reinforcement program given by a teacher with `imperfections`.

    Its random draws come from a generator of its own, made from the run's seed, so the
    same seed gives the same rewards, and the brain's and the world's draws are untouched.
    Every judgement of an imperfect teacher draws the same five numbers, whatever the
    imperfections' levels, so teachers that differ in one level differ only where that
    level decides (a 20% mistaken teacher errs wherever a 10% one does, and more).
    """

    def __init__(
        self,
        program: ReinforcementProgram,
        imperfections: Imperfections,
        seed: int,
        dt_s: float,
    ) -> None:
        if dt_s <= 0.0:
            raise ValueError("dt_s must be > 0")
        self.program = program
        self.imperfections = imperfections
        self.dt_s = dt_s
        self.rng = np.random.default_rng(np.random.SeedSequence([seed, 0, 5]))
        cv = imperfections.delay_cv
        self._shape = 1.0 / (cv * cv) if cv > 0.0 else 1.0

    @property
    def name(self) -> str:
        """The program's name."""
        return self.program.name

    def judge(self, decision: Decision, tick: int, episode: int) -> Judgement | None:
        """The reward for the response `decision` made at `tick`, or None if none is given."""
        value = self.program.judge(decision)
        if value is None:
            return None
        im = self.imperfections
        if im.perfect:
            return Judgement(value, tick + 1, tick, self.program.name)
        u_skip, u_tired, u_bias, u_mistake = self.rng.random(4)
        spread = float(self.rng.standard_gamma(self._shape)) / self._shape
        if u_skip < im.skip or u_tired >= (1.0 - im.fatigue) ** episode:
            return None
        program = self.program
        notes = [program.name]
        if value == program.penalty and u_bias < im.bias:
            value = program.reward
            notes.append("lenient")
        if u_mistake < im.mistake:
            value = program.penalty if value == program.reward else program.reward
            notes.append("wrong sign")
        delay_s = im.delay_s * (spread if im.delay_cv > 0.0 else 1.0)
        delay = round(delay_s / self.dt_s)
        if delay:
            notes.append(f"judged at tick {tick}, {delay} ticks late")
        return Judgement(value, tick + 1 + delay, tick, ", ".join(notes))
