"""Named networks (the S-R editor's subject) in the database, with their edit history.

Storage only: the editor's rules (built-ins read-only, locks, versions, an edit that
changes nothing makes none) are `core.networks`'. Each method is one transaction that
loads a network's rows, asks the domain for a `Revision` and saves it: a version bumps
`networks.version` and appends the whole network to `network_versions`, so any version can
be read, compared and reverted to.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from contextlib import AbstractContextManager, suppress
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import exc as sa_exc
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from core import networks as domain
from core.errors import UnknownNameError
from core.networks import (
    NAME_PATTERN,
    AssociationChange,
    AssociationExistsError,
    ExpectedVersion,
    Key,
    Network,
    NetworkConflictError,
    NetworkEdit,
    NetworkExistsError,
    NetworkSnapshot,
    NetworkSummary,
    NetworkVersion,
    ReadOnlyNetworkError,
    Revision,
    StaleVersionError,
    StoredNetwork,
    UnknownVersionError,
    Vocabulary,
    changes_between,
    check_name,
    check_pair,
    fingerprint_of,
)
from core.ports import NetworkPair
from server.persistence.db import transaction
from server.persistence.orm import (
    AssociationRow,
    BehaviourRow,
    NetworkRow,
    NetworkVersionRow,
    StimulusRow,
)
from server.persistence.seed import SEEDED_NOTE

__all__ = [
    "FIRST_RECORDED_NOTE",
    "NAME_PATTERN",
    "AssociationChange",
    "AssociationExistsError",
    "ExpectedVersion",
    "NetworkConflictError",
    "NetworkEdit",
    "NetworkExistsError",
    "NetworkSnapshot",
    "NetworkSummary",
    "NetworkVersion",
    "ReadOnlyNetworkError",
    "SqlAlchemyNetworkRepository",
    "StaleVersionError",
    "StoredNetwork",
    "UnknownVersionError",
    "changes_between",
    "check_name",
    "check_pair",
]

FIRST_RECORDED_NOTE = "recorded as found before its first change"


def _utc(value: datetime) -> datetime:
    # SQLite's CURRENT_TIMESTAMP is UTC but comes back without a zone.
    return value.replace(tzinfo=UTC) if value.tzinfo is None else value


def _pair_json(p: NetworkPair) -> dict[str, Any]:
    return {
        "stimulus": p.stimulus,
        "behaviour": p.behaviour,
        "strength": p.strength,
        "source": p.source,
        "locked": p.locked,
    }


def _snapshot(name: str, description: str, state: Mapping[Key, NetworkPair]) -> dict[str, Any]:
    """A network as `network_versions.snapshot` keeps it (the seed's format)."""
    return {
        "name": name,
        "description": description,
        "associations": [_pair_json(state[k]) for k in sorted(state)],
    }


def _from_snapshot(snapshot: Mapping[str, Any]) -> dict[Key, NetworkPair]:
    state = {}
    for a in snapshot.get("associations", ()):
        p = NetworkPair(
            str(a["stimulus"]),
            str(a["behaviour"]),
            float(a["strength"]),
            str(a.get("source", "dp")),
            bool(a.get("locked", False)),
        )
        state[p.stimulus, p.behaviour] = p
    return state


class _Catalogue:
    """The stored stimuli and designed behaviours: ids and catalogue positions by name."""

    def __init__(self, session: Session) -> None:
        self.stimuli: dict[str, tuple[int, int]] = {
            n: (i, p)
            for n, i, p in session.execute(
                select(StimulusRow.name, StimulusRow.id, StimulusRow.position)
            )
        }
        self.behaviours: dict[str, tuple[int, int]] = {
            n: (i, p)
            for n, i, p in session.execute(
                select(BehaviourRow.name, BehaviourRow.id, BehaviourRow.position).where(
                    BehaviourRow.run_id.is_(None)
                )
            )
        }
        self.vocabulary = Vocabulary(
            {n: p for n, (_, p) in self.stimuli.items()},
            {n: p for n, (_, p) in self.behaviours.items()},
        )

    def ids(self, stimulus: str, behaviour: str) -> tuple[int, int]:
        """The row ids of a pair's names, which the domain checked."""
        return self.stimuli[stimulus][0], self.behaviours[behaviour][0]


class SqlAlchemyNetworkRepository:
    """`core.ports.NetworkRepository` in SQL: networks, associations and history, by name.

    Each method is one transaction. Unknown networks, versions and addressed pairs raise
    `UnknownNameError`; invalid input raises `ValueError` or `CatalogError`; conflicts
    (a taken name, a built-in network, an existing pair) raise `NetworkConflictError`
    and a locked association changed without `force` raises `LockedAssociationError`.
    """

    def __init__(self, sessions: Callable[[], Session]) -> None:
        self._sessions = sessions

    def _transaction(self, what: str, *, write: bool) -> AbstractContextManager[Session]:
        return transaction(self._sessions, what, write=write)

    def pairs(self, name: str) -> tuple[NetworkPair, ...]:
        """A network's associations; `UnknownNameError` when there is no such network."""
        with self._transaction(f"reading network {name!r}", write=False) as s:
            row = self._row(s, name)
            return tuple(self._state(s, row.id, ordered_by_id=True).values())

    def summaries(self) -> tuple[NetworkSummary, ...]:
        """Every network without its associations: built-in ones first, then by name."""
        with self._transaction("listing networks", write=False) as s:
            counts = (
                select(AssociationRow.network_id, func.count().label("n"))
                .group_by(AssociationRow.network_id)
                .subquery()
            )
            rows = s.execute(
                select(NetworkRow, func.coalesce(counts.c.n, 0))
                .outerjoin(counts, counts.c.network_id == NetworkRow.id)
                .order_by(NetworkRow.builtin.desc(), NetworkRow.name)
            ).all()
            return tuple(
                NetworkSummary(
                    r.name,
                    r.description,
                    r.builtin,
                    r.version,
                    int(n),
                    _utc(r.created_at),
                    _utc(r.updated_at),
                )
                for r, n in rows
            )

    def get(self, name: str) -> StoredNetwork:
        """A network with its associations."""
        with self._transaction(f"reading network {name!r}", write=False) as s:
            row = self._row(s, name)
            return self._stored(s, row, self._state(s, row.id), _Catalogue(s))

    def create(
        self,
        name: str,
        *,
        description: str = "",
        base: str | None = "innate",
        associations: Iterable[NetworkPair] = (),
        note: str = "",
    ) -> StoredNetwork:
        """A new, editable network: a copy of `base` (None: empty) with `associations` over it.

        Each association replaces any earlier one of its pair (the base's included). The network
        starts at version 1, which its history records.
        """
        check_name(name)
        items = list(associations)
        with self._transaction(f"creating network {name!r}", write=True) as s:
            cat = _Catalogue(s)
            revision = domain.create(
                name,
                lambda n: self._network(s, n),
                cat.vocabulary,
                description=description,
                base=base,
                associations=items,
                note=note,
            )
            return self._insert(s, cat, revision).network

    def delete(self, name: str, *, expected: ExpectedVersion | None = None) -> None:
        """Delete a network and its history (runs started from it keep their own copy)."""
        with self._transaction(f"deleting network {name!r}", write=True) as s:
            row, network = self._load(s, name)
            network.check_writable("deleted", expected)
            s.delete(row)

    def add_association(
        self,
        name: str,
        pair: NetworkPair,
        *,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Add a new association; `AssociationExistsError` if the pair is there already."""
        with self._transaction(f"editing network {name!r}", write=True) as s:
            row, network = self._load(s, name)
            cat = _Catalogue(s)
            revision = network.add(pair, cat.vocabulary, note=note, expected=expected)
            return self._save(s, row, cat, network, revision)

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
        """Set an association (insert or update); None keeps a value (new: 1.0, dp, unlocked).

        Changing a locked association, unlocking it included, needs `force`; a put that
        changes nothing is no change and makes no version.
        """
        with self._transaction(f"editing network {name!r}", write=True) as s:
            row, network = self._load(s, name)
            cat = _Catalogue(s)
            revision = network.put(
                stimulus,
                behaviour,
                cat.vocabulary,
                strength=strength,
                source=source,
                locked=locked,
                force=force,
                note=note,
                expected=expected,
            )
            return self._save(s, row, cat, network, revision)

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
        """Remove an association (a locked one only with `force`); unknown pair: 404's error."""
        with self._transaction(f"editing network {name!r}", write=True) as s:
            row, network = self._load(s, name)
            cat = _Catalogue(s)
            revision = network.remove(
                stimulus, behaviour, cat.vocabulary, force=force, note=note, expected=expected
            )
            return self._save(s, row, cat, network, revision)

    def versions(self, name: str) -> tuple[NetworkVersion, ...]:
        """A network's edit history, oldest first."""
        page, _ = self.versions_page(name, 0, None)
        return page

    def versions_page(
        self, name: str, offset: int = 0, limit: int | None = 100
    ) -> tuple[tuple[NetworkVersion, ...], int]:
        """A page of the history, oldest first, and its length: it reads the page's rows only."""
        with self._transaction(f"reading the history of network {name!r}", write=False) as s:
            row = self._row(s, name)
            self._ensure_history(s, row)
            v = NetworkVersionRow
            total = s.scalar(select(func.count()).select_from(v).where(v.network_id == row.id))
            rows = s.scalars(
                select(v)
                .where(v.network_id == row.id)
                .order_by(v.version)
                .offset(offset)
                .limit(limit)
            )
            page = tuple(
                NetworkVersion(
                    r.version,
                    _utc(r.created_at),
                    r.note,
                    len(r.snapshot.get("associations", ())),
                )
                for r in rows
            )
            return page, int(total or 0)

    def snapshot(self, name: str, version: int) -> NetworkSnapshot:
        """The network as it was at `version`."""
        with self._transaction(f"reading the history of network {name!r}", write=False) as s:
            row = self._row(s, name)
            self._ensure_history(s, row)
            v = self._version_row(s, row, version)
            return NetworkSnapshot(
                row.name,
                v.version,
                _utc(v.created_at),
                v.note,
                str(v.snapshot.get("description", "")),
                _Catalogue(s).vocabulary.order(_from_snapshot(v.snapshot).values()),
            )

    def diff(self, name: str, from_version: int, to_version: int) -> tuple[AssociationChange, ...]:
        """What changed between two versions of a network (either order)."""
        with self._transaction(f"reading the history of network {name!r}", write=False) as s:
            row = self._row(s, name)
            self._ensure_history(s, row)
            before = _from_snapshot(self._version_row(s, row, from_version).snapshot)
            after = _from_snapshot(self._version_row(s, row, to_version).snapshot)
            return changes_between(before, after)

    def revert(
        self,
        name: str,
        version: int,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Make the network what it was at `version`, as a new version.

        Changing or removing a locked association needs `force`, as any edit does.
        """
        with self._transaction(f"reverting network {name!r}", write=True) as s:
            row, network = self._load(s, name)
            cat = _Catalogue(s)

            def history(v: int) -> NetworkSnapshot:
                self._ensure_history(s, row)
                found = self._version_row(s, row, v)
                return NetworkSnapshot(
                    row.name,
                    found.version,
                    _utc(found.created_at),
                    found.note,
                    str(found.snapshot.get("description", row.description)),
                    tuple(_from_snapshot(found.snapshot).values()),
                )

            revision = network.revert(
                version, history, cat.vocabulary, force=force, note=note, expected=expected
            )
            return self._save(s, row, cat, network, revision)

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
        """Store an imported network: a new one, or with `replace` a new version of one.

        Replacing needs an editable network and, to change its locked associations, `force`;
        `expected` applies to the network replaced.
        """
        check_name(name)
        items = list(associations)
        with self._transaction(f"importing network {name!r}", write=True) as s:
            cat = _Catalogue(s)
            found = self._find(s, name, lock=True)
            network = None if found is None else self._aggregate(s, found)
            revision = domain.import_network(
                name,
                network,
                items,
                cat.vocabulary,
                description=description,
                replace=replace,
                force=force,
                note=note,
                expected=expected,
            )
            if found is None or network is None:
                return self._insert(s, cat, revision)
            self._ensure_history(s, found)
            return self._save(s, found, cat, network, revision)

    # --- within a transaction ---------------------------------------------------------

    @staticmethod
    def _find(s: Session, name: str, *, lock: bool = False) -> NetworkRow | None:
        query = select(NetworkRow).where(NetworkRow.name == name)
        # A writer locks the row (PostgreSQL) so concurrent edits take versions in turn;
        # SQLite's writers are serialised by BEGIN IMMEDIATE already.
        return s.scalars(query.with_for_update() if lock else query).first()

    def _row(self, s: Session, name: str, *, lock: bool = False) -> NetworkRow:
        row = self._find(s, name, lock=lock)
        if row is None:
            raise UnknownNameError(f"unknown network {name!r}")
        return row

    def _aggregate(self, s: Session, row: NetworkRow) -> Network:
        """The domain's network of a row, with its stored associations and fingerprint."""
        state = self._state(s, row.id)
        return Network(
            row.name,
            row.description,
            row.builtin,
            row.version,
            tuple(state.values()),
            fingerprint_of(row.id, row.created_at, row.version, row.description, state.values()),
        )

    def _load(self, s: Session, name: str) -> tuple[NetworkRow, Network]:
        """A network to write, its row locked; `UnknownNameError` when there is none."""
        row = self._row(s, name, lock=True)
        return row, self._aggregate(s, row)

    def _network(self, s: Session, name: str) -> Network | None:
        row = self._find(s, name)
        return None if row is None else self._aggregate(s, row)

    @staticmethod
    def _state(
        s: Session, network_id: int, *, ordered_by_id: bool = False
    ) -> dict[Key, NetworkPair]:
        query = (
            select(
                StimulusRow.name,
                BehaviourRow.name,
                AssociationRow.strength,
                AssociationRow.source,
                AssociationRow.locked,
            )
            .join(StimulusRow, StimulusRow.id == AssociationRow.stimulus_id)
            .join(BehaviourRow, BehaviourRow.id == AssociationRow.behaviour_id)
            .where(AssociationRow.network_id == network_id)
        )
        if ordered_by_id:
            query = query.order_by(AssociationRow.id)
        return {
            (st, be): NetworkPair(st, be, x, src, lk) for st, be, x, src, lk in s.execute(query)
        }

    @staticmethod
    def _stored(
        s: Session, row: NetworkRow, state: Mapping[Key, NetworkPair], cat: _Catalogue
    ) -> StoredNetwork:
        s.flush()
        return StoredNetwork(
            row.name,
            row.description,
            row.builtin,
            row.version,
            _utc(row.created_at),
            _utc(row.updated_at),
            cat.vocabulary.order(state.values()),
            row.id,
            fingerprint_of(row.id, row.created_at, row.version, row.description, state.values()),
        )

    @staticmethod
    def _version_row(s: Session, row: NetworkRow, version: int) -> NetworkVersionRow:
        found = s.scalars(
            select(NetworkVersionRow).where(
                NetworkVersionRow.network_id == row.id, NetworkVersionRow.version == version
            )
        ).first()
        if found is None:
            raise UnknownVersionError(
                f"network {row.name!r} has no version {version} (it is at version {row.version})"
            )
        return found

    def _ensure_history(self, s: Session, row: NetworkRow) -> None:
        """Record the current version if the history lacks it (a seed that wrote none)."""
        exists = s.scalar(
            select(NetworkVersionRow.id).where(
                NetworkVersionRow.network_id == row.id, NetworkVersionRow.version == row.version
            )
        )
        if exists is not None:
            return
        note = SEEDED_NOTE if row.builtin and row.version == 1 else FIRST_RECORDED_NOTE
        # A reader racing another reader to record it: the other's row is as good.
        with suppress(sa_exc.IntegrityError), s.begin_nested():
            self._record(s, row, self._state(s, row.id), note)

    @staticmethod
    def _record(s: Session, row: NetworkRow, state: Mapping[Key, NetworkPair], note: str) -> None:
        s.add(
            NetworkVersionRow(
                network_id=row.id,
                version=row.version,
                snapshot=_snapshot(row.name, row.description, state),
                note=note,
            )
        )
        s.flush()

    @staticmethod
    def _write(
        s: Session, network_id: int, cat: _Catalogue, changes: Iterable[AssociationChange]
    ) -> None:
        """Store what changed, changing rows in place (never re-adding)."""
        changes = tuple(changes)
        if not changes:
            return
        rows = {
            (st, be): r
            for r, st, be in s.execute(
                select(AssociationRow, StimulusRow.name, BehaviourRow.name)
                .join(StimulusRow, StimulusRow.id == AssociationRow.stimulus_id)
                .join(BehaviourRow, BehaviourRow.id == AssociationRow.behaviour_id)
                .where(AssociationRow.network_id == network_id)
            )
        }
        for c in changes:
            key = (c.stimulus, c.behaviour)
            if c.after is None:
                s.delete(rows[key])
            elif c.before is None:
                st, be = cat.ids(c.stimulus, c.behaviour)
                s.add(
                    AssociationRow(
                        network_id=network_id,
                        stimulus_id=st,
                        behaviour_id=be,
                        strength=c.after.strength,
                        source=c.after.source,
                        locked=c.after.locked,
                    )
                )
            else:
                r = rows[key]
                r.strength, r.source, r.locked = c.after.strength, c.after.source, c.after.locked
        s.flush()

    def _insert(self, s: Session, cat: _Catalogue, revision: Revision) -> NetworkEdit:
        """Store a new network's first version."""
        network = revision.network
        row = NetworkRow(
            name=network.name,
            description=network.description,
            builtin=False,
            version=network.version,
        )
        s.add(row)
        try:
            s.flush()
        except sa_exc.IntegrityError as e:  # made meanwhile by another connection
            raise NetworkExistsError(f"network {network.name!r} exists already") from e
        self._write(s, row.id, cat, revision.changes)
        self._record(s, row, network.state, revision.note)
        return NetworkEdit(self._stored(s, row, network.state, cat), revision.changes, created=True)

    def _save(
        self, s: Session, row: NetworkRow, cat: _Catalogue, before: Network, revision: Revision
    ) -> NetworkEdit:
        """Store a revision of a network as its next version, unless it makes none."""
        if not revision.versioned:
            return NetworkEdit(self._stored(s, row, before.state, cat), ())
        after = revision.network
        self._ensure_history(s, row)
        self._write(s, row.id, cat, revision.changes)
        row.version = after.version
        row.description = after.description
        self._record(s, row, after.state, revision.note)
        return NetworkEdit(self._stored(s, row, after.state, cat), revision.changes)
