"""Conditions and networks as data on the command line: `--condition FILE`, `--network`.

`simulate`, `experiment` and `sweep` take a condition by name (a built-in one, from
``core/data/conditions.toml``) or a condition file (`core.run.conditions.load_conditions`),
and `--network NAME|FILE`: a built-in knowledge set, one made in the S-R editor (read from
the service's database), or a network file. What they name goes into the `Setup`, so every
task carries it to whatever process runs it.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from core.brain.catalog import AssociationSpec, Catalog, KnowledgeSet, load_network_file
from core.errors import UnknownNameError
from core.run.conditions import CONDITIONS, Condition, load_conditions
from core.run.setup import Setup
from server.cli.common import engine_condition

FILE_SUFFIX = ".toml"
"""What tells a file from a name: conditions and networks are named without it."""


def add_network_arguments(parser: argparse.ArgumentParser) -> None:
    """--network and --url (the database of the networks made in the S-R editor)."""
    parser.add_argument(
        "--network",
        metavar="NAME|FILE",
        default="",
        help="start every condition from this network instead of its own: a built-in one "
        "(core/data/networks), one made in the S-R editor (read from --url's database), or "
        "a network file (.toml, in the form of core/data/networks/*.toml)",
    )
    parser.add_argument(
        "--url",
        metavar="URL",
        help="SQLAlchemy URL of the service's database, where the S-R editor's networks "
        "are (default: SRLAB_DATABASE_URL)",
    )


def is_file(text: str) -> bool:
    """Whether a condition or network argument names a file (it ends in .toml)."""
    return text.endswith(FILE_SUFFIX) or f"{FILE_SUFFIX}:" in text


def engine_condition_or_file(text: str) -> str:
    """An argparse type: a condition the engine runs (`engine_condition`), or a file."""
    return text if is_file(text) else engine_condition(text)


def stored_network(name: str, url: str | None, catalog: Catalog) -> KnowledgeSet | None:
    """The network `name` made in the S-R editor, from the database at `url`, if stored.

    None when there is no such network, or no database yet (a SQLite file not made).
    """
    from sqlalchemy.engine import make_url

    from server.persistence import database_url, make_engine, make_sessionmaker
    from server.persistence.networks import SqlAlchemyNetworkRepository

    url = url or database_url()
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        db = parsed.database
        if not db or db == ":memory:" or not Path(db).is_file():
            return None
    engine = make_engine(url)
    try:
        repo = SqlAlchemyNetworkRepository(make_sessionmaker(engine))
        try:
            pairs = repo.pairs(name)
            description = repo.get(name).description
        except UnknownNameError:
            return None
    finally:
        engine.dispose()
    for p in pairs:  # a network stored for another sensor definition, say
        catalog.stimulus(p.stimulus), catalog.behaviour(p.behaviour)
    specs = tuple(
        AssociationSpec(p.stimulus, p.behaviour, p.strength, p.source, p.locked)  # type: ignore[arg-type]
        for p in pairs
    )
    return KnowledgeSet(name, description, specs)


class _Networks:
    """Finds the networks a setup needs that are not shipped: files, then the database."""

    def __init__(self, catalog: Catalog, url: str | None) -> None:
        self.catalog = catalog
        self.url = url
        self.found: dict[str, KnowledgeSet] = {}

    def knows(self, name: str) -> bool:
        if name in self.catalog.knowledge or name in self.found:
            return True
        stored = stored_network(name, self.url, self.catalog)
        if stored is not None:
            self.found[name] = stored
        return stored is not None

    def named(self, text: str) -> str:
        """The name of the network `text` names (a file's is loaded); an error if none."""
        if is_file(text):
            ks = load_network_file(Path(text), self.catalog)
            self.found[ks.name] = ks
            return ks.name
        if not self.knows(text):
            known = ", ".join(sorted(self.catalog.knowledge))
            raise UnknownNameError(
                f"--network {text!r}: no such network, built in (known: {known}) or made in "
                "the S-R editor (the database of --url / SRLAB_DATABASE_URL), nor a file "
                f"(a network file's name ends in {FILE_SUFFIX})"
            )
        return text


def conditions_of(
    texts: Sequence[str], knows: Callable[[str], bool]
) -> tuple[list[str], list[Condition]]:
    """The condition names `texts` give, in order, and the conditions read from files.

    A text is a condition's name, a condition file (all its conditions) or
    ``FILE.toml:NAME`` (one of them). Names a file defines may be used after it.
    """
    names: list[str] = []
    own: dict[str, Condition] = {}
    for text in texts:
        if not is_file(text):
            if text not in CONDITIONS and text not in own:
                known = ", ".join((*CONDITIONS, *own))
                raise UnknownNameError(f"unknown condition {text!r} (known: {known})")
            names.append(text)
            continue
        path, pick = text, ""
        if f"{FILE_SUFFIX}:" in text:
            head, _, pick = text.rpartition(f"{FILE_SUFFIX}:")
            path = head + FILE_SUFFIX
        read = load_conditions(Path(path), {**CONDITIONS, **own}, networks=knows)
        if pick and pick not in {c.name for c in read}:
            raise UnknownNameError(
                f"{path} has no condition {pick!r} (it has {', '.join(c.name for c in read)})"
            )
        for c in read:
            own[c.name] = c
            if not pick or c.name == pick:
                names.append(c.name)
    return list(dict.fromkeys(names)), list(own.values())


def with_conditions(
    setup: Setup, texts: Sequence[str], network: str = "", url: str | None = None
) -> tuple[Setup, list[str]]:
    """`setup` with the conditions `texts` give and `network`, and the conditions' names."""
    networks = _Networks(setup.catalog(), url)
    names, own = conditions_of([t.strip() for t in texts if t.strip()], networks.knows)
    chosen = networks.named(network) if network else ""
    return replace(
        setup, conditions=tuple(own), networks=tuple(networks.found.values()), network=chosen
    ), names
