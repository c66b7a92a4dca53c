"""The reinforcement program (RP): an artificial trainer that gives immediate rewards."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from core.brain.catalog import Catalog, data_dir
from core.brain.selection import Decision, How
from core.errors import CatalogError, UnknownNameError


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
    if not path.is_file():
        raise UnknownNameError(f"unknown reinforcement program {name!r}")
    try:
        with path.open("rb") as f:
            raw = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise CatalogError(f"{path}: {e}") from e
    good = {
        catalog.stimulus(s).id: frozenset(catalog.behaviour(b).id for b in behaviours)
        for s, behaviours in raw.get("good", {}).items()
    }
    reward = float(raw.get("reward", 1.0))
    penalty = float(raw.get("penalty", -1.0))
    if not (-1.0 <= penalty <= 1.0 and -1.0 <= reward <= 1.0):
        raise CatalogError(f"{path}: reward and penalty must be in [-1, 1]")
    return ReinforcementProgram(name, good, reward, penalty)
