"""`InMemoryNetworkRepository`: stored networks in memory, with their versions."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np

from core import networks as rules
from core.brain.catalog import Catalog
from core.errors import UnknownNameError
from core.networks import (
    AssociationChange,
    ExpectedVersion,
    Network,
    NetworkEdit,
    NetworkSnapshot,
    NetworkSummary,
    NetworkVersion,
    Revision,
    StoredNetwork,
    UnknownVersionError,
    Vocabulary,
    changes_between,
    fingerprint_of,
)
from core.ports import (
    NetworkPair,
)

FloatArray = np.ndarray[Any, np.dtype[np.float64]]

SEEDED_NOTE = "seeded from the catalogue"
"""The note of a built-in network's first version (as `server.persistence.seed` writes it)."""


@dataclass(frozen=True, slots=True)
class _MemoryVersion:
    """One entry of a network's history in `InMemoryNetworkRepository`."""

    version: int
    created_at: datetime
    note: str
    description: str
    state: Mapping[tuple[str, str], NetworkPair]
    """The associations by key, sorted (as the SQL store's snapshot keeps them)."""


@dataclass(slots=True)
class _MemoryNetwork:
    """One network's rows in `InMemoryNetworkRepository`."""

    id: int
    name: str
    description: str
    builtin: bool
    version: int
    created_at: datetime
    updated_at: datetime
    rows: dict[tuple[str, str], NetworkPair]
    """The associations in the order they were stored (a change keeps a pair's place)."""
    history: dict[int, _MemoryVersion] = field(default_factory=dict)

    def record(self, note: str, at: datetime) -> None:
        state = {k: self.rows[k] for k in sorted(self.rows)}
        self.history[self.version] = _MemoryVersion(self.version, at, note, self.description, state)


class InMemoryNetworkRepository:
    """A `NetworkRepository` in memory, seeded with the catalogue's knowledge sets (built in).

    Like the SQL store it loads a `core.networks.Network`, asks it for a `Revision` and
    stores that; the shared contract suite in `tests/persistence` holds both to the same
    answers. Every write is all or nothing (the domain decides before anything changes),
    ids are never reused and times come from `clock` (UTC now by default).
    """

    def __init__(self, catalog: Catalog, clock: Callable[[], datetime] | None = None) -> None:
        self._vocabulary = Vocabulary.of(catalog)
        self._clock = clock or (lambda: datetime.now(UTC))
        self._networks: dict[str, _MemoryNetwork] = {}
        self._next_id = 1
        self._lock = threading.RLock()
        now = self._clock()
        for ks in catalog.knowledge.values():
            rows = {
                (a.stimulus, a.behaviour): NetworkPair(
                    a.stimulus, a.behaviour, a.strength, a.source, a.locked
                )
                for a in ks.associations
            }
            stored = self._add(ks.name, ks.description, rows, now, builtin=True)
            stored.record(SEEDED_NOTE, now)

    def _add(
        self,
        name: str,
        description: str,
        rows: dict[tuple[str, str], NetworkPair],
        at: datetime,
        *,
        builtin: bool = False,
    ) -> _MemoryNetwork:
        stored = _MemoryNetwork(self._next_id, name, description, builtin, 1, at, at, rows)
        self._next_id += 1
        self._networks[name] = stored
        return stored

    def _get(self, name: str) -> _MemoryNetwork:
        try:
            return self._networks[name]
        except KeyError:
            raise UnknownNameError(f"unknown network {name!r}") from None

    def _find(self, name: str) -> Network | None:
        stored = self._networks.get(name)
        return None if stored is None else self._aggregate(stored)

    @staticmethod
    def _fingerprint(n: _MemoryNetwork) -> str:
        return fingerprint_of(n.id, n.created_at, n.version, n.description, n.rows.values())

    def _aggregate(self, n: _MemoryNetwork) -> Network:
        pairs = tuple(n.rows.values())
        return Network(n.name, n.description, n.builtin, n.version, pairs, self._fingerprint(n))

    def _stored(self, n: _MemoryNetwork) -> StoredNetwork:
        return StoredNetwork(
            n.name,
            n.description,
            n.builtin,
            n.version,
            n.created_at,
            n.updated_at,
            self._vocabulary.order(n.rows.values()),
            n.id,
            self._fingerprint(n),
        )

    def _version(self, n: _MemoryNetwork, version: int) -> _MemoryVersion:
        try:
            return n.history[version]
        except KeyError:
            raise UnknownVersionError(
                f"network {n.name!r} has no version {version} (it is at version {n.version})"
            ) from None

    def _insert(self, revision: Revision) -> NetworkEdit:
        network, now = revision.network, self._clock()
        rows = {(c.stimulus, c.behaviour): c.after for c in revision.changes if c.after}
        stored = self._add(network.name, network.description, rows, now)
        stored.record(revision.note, now)
        return NetworkEdit(self._stored(stored), revision.changes, created=True)

    def _save(self, n: _MemoryNetwork, revision: Revision) -> NetworkEdit:
        if not revision.versioned:
            return NetworkEdit(self._stored(n), ())
        for c in revision.changes:
            key = (c.stimulus, c.behaviour)
            if c.after is None:
                del n.rows[key]
            else:
                n.rows[key] = c.after
        n.version = revision.network.version
        n.description = revision.network.description
        n.updated_at = self._clock()
        n.record(revision.note, n.updated_at)
        return NetworkEdit(self._stored(n), revision.changes)

    def summaries(self) -> tuple[NetworkSummary, ...]:
        """Every network without its associations: built-in ones first, then by name."""
        with self._lock:
            ordered = sorted(self._networks.values(), key=lambda n: (not n.builtin, n.name))
            return tuple(self._stored(n).summary for n in ordered)

    def get(self, name: str) -> StoredNetwork:
        """A network with its associations, in catalogue order."""
        with self._lock:
            return self._stored(self._get(name))

    def pairs(self, name: str) -> tuple[NetworkPair, ...]:
        """A network's associations in the order they were stored."""
        with self._lock:
            return tuple(self._get(name).rows.values())

    def create(
        self,
        name: str,
        *,
        description: str = "",
        base: str | None = "innate",
        associations: Iterable[NetworkPair] = (),
        note: str = "",
    ) -> StoredNetwork:
        """A new, editable network at version 1: `base` (None: empty) with `associations`."""
        with self._lock:
            revision = rules.create(
                name,
                self._find,
                self._vocabulary,
                description=description,
                base=base,
                associations=associations,
                note=note,
            )
            return self._insert(revision).network

    def delete(self, name: str, *, expected: ExpectedVersion | None = None) -> None:
        """Delete an editable network and its history."""
        with self._lock:
            self._aggregate(self._get(name)).check_writable("deleted", expected)
            del self._networks[name]

    def add_association(
        self,
        name: str,
        pair: NetworkPair,
        *,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Add an association the network lacks."""
        with self._lock:
            n = self._get(name)
            revision = self._aggregate(n).add(pair, self._vocabulary, note=note, expected=expected)
            return self._save(n, revision)

    def put_association(
        self,
        name: str,
        stimulus: str,
        behaviour: str,
        *,
        strength: float | None = None,
        source: str | None = None,
        locked: bool | None = None,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Set an association (insert or update); None keeps a value."""
        with self._lock:
            n = self._get(name)
            revision = self._aggregate(n).put(
                stimulus,
                behaviour,
                self._vocabulary,
                strength=strength,
                source=source,
                locked=locked,
                force=force,
                note=note,
                expected=expected,
            )
            return self._save(n, revision)

    def remove_association(
        self,
        name: str,
        stimulus: str,
        behaviour: str,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Remove an association."""
        with self._lock:
            n = self._get(name)
            revision = self._aggregate(n).remove(
                stimulus, behaviour, self._vocabulary, force=force, note=note, expected=expected
            )
            return self._save(n, revision)

    def versions(self, name: str) -> tuple[NetworkVersion, ...]:
        """A network's edit history, oldest first."""
        with self._lock:
            n = self._get(name)
            return tuple(
                NetworkVersion(v.version, v.created_at, v.note, len(v.state))
                for _, v in sorted(n.history.items())
            )

    def versions_page(
        self, name: str, offset: int = 0, limit: int = 100
    ) -> tuple[tuple[NetworkVersion, ...], int]:
        """A page of `versions`, and their number."""
        every = self.versions(name)
        return every[offset : offset + limit], len(every)

    def snapshot(self, name: str, version: int) -> NetworkSnapshot:
        """The network as it was at `version`."""
        with self._lock:
            n = self._get(name)
            v = self._version(n, version)
            pairs = self._vocabulary.order(v.state.values())
            return NetworkSnapshot(n.name, v.version, v.created_at, v.note, v.description, pairs)

    def diff(self, name: str, from_version: int, to_version: int) -> tuple[AssociationChange, ...]:
        """What changed between two versions of a network (either order)."""
        with self._lock:
            n = self._get(name)
            before = self._version(n, from_version).state
            return changes_between(before, self._version(n, to_version).state)

    def revert(
        self,
        name: str,
        version: int,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Make the network what it was at `version`, as a new version."""
        with self._lock:
            n = self._get(name)

            def history(v: int) -> NetworkSnapshot:
                found = self._version(n, v)
                pairs = tuple(found.state.values())
                return NetworkSnapshot(
                    n.name, v, found.created_at, found.note, found.description, pairs
                )

            revision = self._aggregate(n).revert(
                version, history, self._vocabulary, force=force, note=note, expected=expected
            )
            return self._save(n, revision)

    def import_network(
        self,
        name: str,
        associations: Iterable[NetworkPair],
        *,
        description: str = "",
        replace: bool = False,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Store an imported network: a new one, or with `replace` a new version of one."""
        with self._lock:
            n = self._networks.get(name)
            revision = rules.import_network(
                name,
                None if n is None else self._aggregate(n),
                associations,
                self._vocabulary,
                description=description,
                replace=replace,
                force=force,
                note=note,
                expected=expected,
            )
            return self._insert(revision) if n is None else self._save(n, revision)
