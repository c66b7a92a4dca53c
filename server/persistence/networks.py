"""Named networks (the S-R editor's subject) in the database, with their edit history.

Storage only: the editor's rules (built-ins read-only, locks, versions, an edit that
changes nothing makes none) are `core.networks`'. Each method is one transaction that
loads a network's rows, asks the domain for a `Revision` and saves it: a version bumps
`networks.version` and appends the whole network to `network_versions`, so any version can
be read, compared and reverted to. Reading and writing the rows is `network_rows`'.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from core import networks as domain
from core.networks import (
    NAME_PATTERN,
    AssociationChange,
    AssociationExistsError,
    ExpectedVersion,
    NetworkConflictError,
    NetworkEdit,
    NetworkExistsError,
    NetworkSnapshot,
    NetworkSummary,
    NetworkVersion,
    ReadOnlyNetworkError,
    StaleVersionError,
    StoredNetwork,
    UnknownVersionError,
    changes_between,
    check_name,
    check_pair,
)
from core.ports import NetworkPair
from server.persistence.db import transaction
from server.persistence.network_rows import (
    FIRST_RECORDED_NOTE,
    Catalogue,
    aggregate,
    ensure_history,
    find_row,
    from_snapshot,
    insert,
    load,
    network_or_none,
    network_row,
    save,
    state_of,
    stored,
    utc,
    version_row,
)
from server.persistence.orm import AssociationRow, NetworkRow, NetworkVersionRow

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
            row = network_row(s, name)
            return tuple(state_of(s, row.id, ordered_by_id=True).values())

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
                    utc(r.created_at),
                    utc(r.updated_at),
                )
                for r, n in rows
            )

    def get(self, name: str) -> StoredNetwork:
        """A network with its associations."""
        with self._transaction(f"reading network {name!r}", write=False) as s:
            row = network_row(s, name)
            return stored(s, row, state_of(s, row.id), Catalogue(s))

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
            cat = Catalogue(s)
            revision = domain.create(
                name,
                lambda n: network_or_none(s, n),
                cat.vocabulary,
                description=description,
                base=base,
                associations=items,
                note=note,
            )
            return insert(s, cat, revision).network

    def delete(self, name: str, *, expected: ExpectedVersion | None = None) -> None:
        """Delete a network and its history (runs started from it keep their own copy)."""
        with self._transaction(f"deleting network {name!r}", write=True) as s:
            row, network = load(s, name)
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
            row, network = load(s, name)
            cat = Catalogue(s)
            revision = network.add(pair, cat.vocabulary, note=note, expected=expected)
            return save(s, row, cat, network, revision)

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
            row, network = load(s, name)
            cat = Catalogue(s)
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
            return save(s, row, cat, network, revision)

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
            row, network = load(s, name)
            cat = Catalogue(s)
            revision = network.remove(
                stimulus, behaviour, cat.vocabulary, force=force, note=note, expected=expected
            )
            return save(s, row, cat, network, revision)

    def versions(self, name: str) -> tuple[NetworkVersion, ...]:
        """A network's edit history, oldest first."""
        page, _ = self.versions_page(name, 0, None)
        return page

    def versions_page(
        self, name: str, offset: int = 0, limit: int | None = 100
    ) -> tuple[tuple[NetworkVersion, ...], int]:
        """A page of the history, oldest first, and its length: it reads the page's rows only."""
        with self._transaction(f"reading the history of network {name!r}", write=False) as s:
            row = network_row(s, name)
            ensure_history(s, row)
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
                    utc(r.created_at),
                    r.note,
                    len(r.snapshot.get("associations", ())),
                )
                for r in rows
            )
            return page, int(total or 0)

    def snapshot(self, name: str, version: int) -> NetworkSnapshot:
        """The network as it was at `version`."""
        with self._transaction(f"reading the history of network {name!r}", write=False) as s:
            row = network_row(s, name)
            ensure_history(s, row)
            v = version_row(s, row, version)
            return NetworkSnapshot(
                row.name,
                v.version,
                utc(v.created_at),
                v.note,
                str(v.snapshot.get("description", "")),
                Catalogue(s).vocabulary.order(from_snapshot(v.snapshot).values()),
            )

    def diff(self, name: str, from_version: int, to_version: int) -> tuple[AssociationChange, ...]:
        """What changed between two versions of a network (either order)."""
        with self._transaction(f"reading the history of network {name!r}", write=False) as s:
            row = network_row(s, name)
            ensure_history(s, row)
            before = from_snapshot(version_row(s, row, from_version).snapshot)
            after = from_snapshot(version_row(s, row, to_version).snapshot)
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
            row, network = load(s, name)
            cat = Catalogue(s)

            def history(v: int) -> NetworkSnapshot:
                ensure_history(s, row)
                found = version_row(s, row, v)
                return NetworkSnapshot(
                    row.name,
                    found.version,
                    utc(found.created_at),
                    found.note,
                    str(found.snapshot.get("description", row.description)),
                    tuple(from_snapshot(found.snapshot).values()),
                )

            revision = network.revert(
                version, history, cat.vocabulary, force=force, note=note, expected=expected
            )
            return save(s, row, cat, network, revision)

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
            cat = Catalogue(s)
            found = find_row(s, name, lock=True)
            network = None if found is None else aggregate(s, found)
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
                return insert(s, cat, revision)
            ensure_history(s, found)
            return save(s, found, cat, network, revision)
