"""Named networks (the S-R editor's subject) in the database, with their edit history.

Every change is one transaction that bumps `networks.version` and appends the whole
network to `network_versions`, so any version can be read, compared and reverted to.
Built-in networks (the catalogue's innate, dp, kp and expert) are read-only: copy one to
edit it. A locked association changes only when the caller forces it.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Callable, Iterable, Mapping
from contextlib import AbstractContextManager, suppress
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import exc as sa_exc
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from core.brain.catalog import SOURCES
from core.errors import (
    CatalogError,
    CoreError,
    LockedAssociationError,
    RunStateError,
    UnknownNameError,
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

NAME_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"
"""A network's name: a slug of letters, digits, - and _, 1 to 64 characters."""
_NAME = re.compile(NAME_PATTERN)
FIRST_RECORDED_NOTE = "recorded as found before its first change"
_Key = tuple[str, str]


class NetworkConflictError(RunStateError):
    """A network write that conflicts with what is stored (answered 409, as RunStateError)."""


class NetworkExistsError(NetworkConflictError):
    """A network of that name exists already."""


class ReadOnlyNetworkError(NetworkConflictError):
    """A write to a built-in network: they are read-only, copy one to edit it."""


class AssociationExistsError(NetworkConflictError):
    """An association added that the network has already (change it instead)."""


class UnknownVersionError(UnknownNameError):
    """A version a network's history does not have."""


class StaleVersionError(CoreError):
    """A write based on a version of the network that is no longer current (HTTP 412)."""

    def __init__(self, message: str, current: int, etag: str) -> None:
        super().__init__(message)
        self.current = current
        self.etag = etag


def etag_of(row: NetworkRow, state: Mapping[_Key, NetworkPair]) -> str:
    """The entity tag of one version of one network, as HTTP's `ETag`.

    The version, and a digest of what makes it this network's version: its row (SQLite
    gives a deleted network's id to the next one), its creation time and its content.
    """
    content = sorted(
        (p.stimulus, p.behaviour, p.strength, p.source, p.locked) for p in state.values()
    )
    identity = [row.id, str(row.created_at), row.version, row.description, content]
    digest = hashlib.sha256(repr(identity).encode()).hexdigest()[:12]
    return f'"v{row.version}-{digest}"'


@dataclass(frozen=True, slots=True)
class Precondition:
    """What a write expects of the network: a version, or one of some entity tags."""

    version: int | None = None
    etags: tuple[str, ...] | None = None
    """From If-Match: the tags any of which may be current ("*": any)."""

    def check(self, name: str, version: int, tag: str) -> None:
        """`StaleVersionError` unless the network (at `version`, tagged `tag`) is expected."""
        if self.version is not None and self.version != version:
            raise StaleVersionError(
                f"network {name!r} is at version {version}, not {self.version}: another "
                "write came first; read it again (GET) and reapply the change",
                version,
                tag,
            )
        if self.etags is not None and "*" not in self.etags and tag not in self.etags:
            raise StaleVersionError(
                f"network {name!r} is at version {version} ({tag}), which If-Match does not "
                "name: another write came first; read it again (GET) and reapply the change",
                version,
                tag,
            )


@dataclass(frozen=True, slots=True)
class NetworkSummary:
    """A stored network without its associations."""

    name: str
    description: str
    builtin: bool
    version: int
    association_count: int
    created_at: datetime
    updated_at: datetime


@dataclass(frozen=True, slots=True)
class StoredNetwork:
    """A stored network with its associations, in catalogue order."""

    name: str
    description: str
    builtin: bool
    version: int
    created_at: datetime
    updated_at: datetime
    associations: tuple[NetworkPair, ...]
    id: int = 0
    """Its row's id (SQLite may give a deleted network's id to a new one)."""
    etag: str = ""
    """The entity tag of this version of this network (HTTP `ETag`, see `etag_of`)."""

    @property
    def summary(self) -> NetworkSummary:
        """The network without its associations."""
        return NetworkSummary(
            self.name,
            self.description,
            self.builtin,
            self.version,
            len(self.associations),
            self.created_at,
            self.updated_at,
        )


@dataclass(frozen=True, slots=True)
class NetworkVersion:
    """One entry of a network's edit history."""

    version: int
    created_at: datetime
    note: str
    association_count: int


@dataclass(frozen=True, slots=True)
class NetworkSnapshot:
    """A network as it was at one version."""

    name: str
    version: int
    created_at: datetime
    note: str
    description: str
    associations: tuple[NetworkPair, ...]


@dataclass(frozen=True, slots=True)
class AssociationChange:
    """What became of one S-R pair: added (no `before`), removed (no `after`) or changed."""

    stimulus: str
    behaviour: str
    before: NetworkPair | None
    after: NetworkPair | None


@dataclass(frozen=True, slots=True)
class NetworkEdit:
    """A write's outcome: the network as stored now and what changed (empty: nothing)."""

    network: StoredNetwork
    changes: tuple[AssociationChange, ...]
    created: bool = False


def check_name(name: str) -> str:
    """`name` if it is a valid network name, else `ValueError`."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(
            f"network name {name!r} is not a slug: use 1-64 letters, digits, '-' and '_'"
        )
    return name


def check_pair(pair: NetworkPair, where: str = "") -> NetworkPair:
    """`pair` if its values are valid (strength, source, lock), else `ValueError`."""
    s = pair.strength
    if isinstance(s, bool) or not isinstance(s, int | float) or not math.isfinite(s):
        raise ValueError(f"{where}strength must be a finite number, got {s!r}")
    if not 0.0 <= s <= 1.0:
        raise ValueError(f"{where}strength must be in [0, 1], got {s!r}")
    if pair.source not in SOURCES:
        raise ValueError(f"{where}source must be one of {', '.join(SOURCES)}, got {pair.source!r}")
    if not isinstance(pair.locked, bool):
        raise ValueError(f"{where}locked must be true or false, got {pair.locked!r}")
    return NetworkPair(pair.stimulus, pair.behaviour, float(s), pair.source, pair.locked)


def changes_between(
    before: Mapping[_Key, NetworkPair], after: Mapping[_Key, NetworkPair]
) -> tuple[AssociationChange, ...]:
    """The pairs added, removed or changed from `before` to `after`, sorted by name."""
    out = []
    for key in sorted(before.keys() | after.keys()):
        old, new = before.get(key), after.get(key)
        if old != new:
            out.append(AssociationChange(key[0], key[1], old, new))
    return tuple(out)


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


def _snapshot(name: str, description: str, state: Mapping[_Key, NetworkPair]) -> dict[str, Any]:
    """A network as `network_versions.snapshot` keeps it (the seed's format)."""
    return {
        "name": name,
        "description": description,
        "associations": [_pair_json(state[k]) for k in sorted(state)],
    }


def _from_snapshot(snapshot: Mapping[str, Any]) -> dict[_Key, NetworkPair]:
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

    def ids(self, stimulus: str, behaviour: str, where: str | None = None) -> tuple[int, int]:
        """The ids of a pair's names.

        Names that address an association (`where` None) raise `UnknownNameError`; names
        given as data (`where`, the field's place) raise `CatalogError`, invalid input.
        """
        st = self.stimuli.get(stimulus)
        be = self.behaviours.get(behaviour)
        for found, kind, name in ((st, "stimulus", stimulus), (be, "behaviour", behaviour)):
            if found is None:
                if where is None:
                    raise UnknownNameError(f"unknown {kind} {name!r}")
                raise CatalogError(f"{where}{kind}: unknown {kind} {name!r}")
        assert st is not None and be is not None
        return st[0], be[0]

    def order(self, pairs: Iterable[NetworkPair]) -> tuple[NetworkPair, ...]:
        """`pairs` in catalogue order (stimulus, then behaviour), as the editor's matrix."""
        end = (1 << 30, 0)

        def key(p: NetworkPair) -> tuple[int, int, str, str]:
            st = self.stimuli.get(p.stimulus, end)[1]
            be = self.behaviours.get(p.behaviour, end)[1]
            return st, be, p.stimulus, p.behaviour

        return tuple(sorted(pairs, key=key))


class SqlAlchemyNetworkRepository:
    """Stored networks, their associations and edit history, by name.

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
            if self._find(s, name) is not None:
                raise NetworkExistsError(f"network {name!r} exists already: choose another name")
            cat = _Catalogue(s)
            state: dict[_Key, NetworkPair] = {}
            if base is not None:
                base_row = self._find(s, base)
                if base_row is None:
                    raise UnknownNameError(f"unknown base network {base!r}")
                state = self._state(s, base_row.id)
            state.update(self._checked(cat, items, "associations"))
            row = NetworkRow(name=name, description=description, builtin=False, version=1)
            s.add(row)
            try:
                s.flush()
            except sa_exc.IntegrityError as e:  # made meanwhile by another connection
                raise NetworkExistsError(f"network {name!r} exists already") from e
            self._write(s, row.id, cat, {}, state)
            default = f"created from {base}" if base is not None else "created empty"
            self._record(s, row, state, note or default)
            return self._stored(s, row, state, cat)

    def delete(self, name: str, *, expected: Precondition | None = None) -> None:
        """Delete a network and its history (runs started from it keep their own copy)."""
        with self._transaction(f"deleting network {name!r}", write=True) as s:
            row = self._writable(s, name, "deleted", expected)
            s.delete(row)

    def add_association(
        self,
        name: str,
        pair: NetworkPair,
        *,
        note: str = "",
        expected: Precondition | None = None,
    ) -> NetworkEdit:
        """Add a new association; `AssociationExistsError` if the pair is there already."""
        with self._transaction(f"editing network {name!r}", write=True) as s:
            row = self._writable(s, name, expected=expected)
            cat = _Catalogue(s)
            pair = next(iter(self._checked(cat, [pair], None).values()))
            state = self._state(s, row.id)
            key = (pair.stimulus, pair.behaviour)
            if key in state:
                raise AssociationExistsError(
                    f"network {name!r} has {key[0]} -> {key[1]} already: change it with PUT"
                )
            target = {**state, key: pair}
            return self._commit(s, row, cat, state, target, note or f"added {key[0]} -> {key[1]}")

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
        expected: Precondition | None = None,
    ) -> NetworkEdit:
        """Set an association (insert or update); None keeps a value (new: 1.0, dp, unlocked).

        Changing a locked association, unlocking it included, needs `force`; a put that
        changes nothing is no change and makes no version.
        """
        with self._transaction(f"editing network {name!r}", write=True) as s:
            row = self._writable(s, name, expected=expected)
            cat = _Catalogue(s)
            cat.ids(stimulus, behaviour)
            state = self._state(s, row.id)
            key = (stimulus, behaviour)
            old = state.get(key) or NetworkPair(stimulus, behaviour, 1.0, "dp", False)
            new = NetworkPair(
                stimulus,
                behaviour,
                old.strength if strength is None else strength,
                old.source if source is None else source,
                old.locked if locked is None else locked,
            )
            target = {**state, key: check_pair(new)}
            verb = "changed" if key in state else "added"
            default = f"{verb} {stimulus} -> {behaviour}"
            return self._commit(s, row, cat, state, target, note or default, force=force)

    def remove_association(
        self,
        name: str,
        stimulus: str,
        behaviour: str,
        *,
        force: bool = False,
        note: str = "",
        expected: Precondition | None = None,
    ) -> NetworkEdit:
        """Remove an association (a locked one only with `force`); unknown pair: 404's error."""
        with self._transaction(f"editing network {name!r}", write=True) as s:
            row = self._writable(s, name, expected=expected)
            cat = _Catalogue(s)
            cat.ids(stimulus, behaviour)
            state = self._state(s, row.id)
            key = (stimulus, behaviour)
            if key not in state:
                raise UnknownNameError(
                    f"network {name!r} has no association {stimulus} -> {behaviour}"
                )
            target = {k: v for k, v in state.items() if k != key}
            default = f"removed {stimulus} -> {behaviour}"
            return self._commit(s, row, cat, state, target, note or default, force=force)

    def versions(self, name: str) -> tuple[NetworkVersion, ...]:
        """A network's edit history, oldest first."""
        with self._transaction(f"reading the history of network {name!r}", write=False) as s:
            row = self._row(s, name)
            self._ensure_history(s, row)
            rows = s.scalars(
                select(NetworkVersionRow)
                .where(NetworkVersionRow.network_id == row.id)
                .order_by(NetworkVersionRow.version)
            )
            return tuple(
                NetworkVersion(
                    v.version,
                    _utc(v.created_at),
                    v.note,
                    len(v.snapshot.get("associations", ())),
                )
                for v in rows
            )

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
                _Catalogue(s).order(_from_snapshot(v.snapshot).values()),
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
        expected: Precondition | None = None,
    ) -> NetworkEdit:
        """Make the network what it was at `version`, as a new version.

        Changing or removing a locked association needs `force`, as any edit does.
        """
        with self._transaction(f"reverting network {name!r}", write=True) as s:
            row = self._writable(s, name, expected=expected)
            self._ensure_history(s, row)
            snapshot = self._version_row(s, row, version).snapshot
            cat = _Catalogue(s)
            target = self._checked(cat, _from_snapshot(snapshot).values(), "snapshot.associations")
            state = self._state(s, row.id)
            return self._commit(
                s,
                row,
                cat,
                state,
                target,
                note or f"reverted to version {version}",
                force=force,
                description=str(snapshot.get("description", row.description)),
            )

    def import_network(
        self,
        name: str,
        associations: Iterable[NetworkPair],
        *,
        description: str = "",
        replace: bool = False,
        force: bool = False,
        note: str = "",
        expected: Precondition | None = None,
    ) -> NetworkEdit:
        """Store an imported network: a new one, or with `replace` a new version of one.

        Replacing needs an editable network and, to change its locked associations, `force`;
        `expected` applies to the network replaced.
        """
        check_name(name)
        items = list(associations)
        with self._transaction(f"importing network {name!r}", write=True) as s:
            cat = _Catalogue(s)
            target = self._checked(cat, items, "associations")
            row = self._find(s, name)
            if row is None:
                row = NetworkRow(name=name, description=description, builtin=False, version=1)
                s.add(row)
                try:
                    s.flush()
                except sa_exc.IntegrityError as e:
                    raise NetworkExistsError(f"network {name!r} exists already") from e
                self._write(s, row.id, cat, {}, target)
                self._record(s, row, target, note or "imported")
                return NetworkEdit(
                    self._stored(s, row, target, cat), changes_between({}, target), created=True
                )
            if not replace:
                raise NetworkExistsError(
                    f"network {name!r} exists already: import it under another name, "
                    "or replace it (replace=true) to make a new version of it"
                )
            row = self._writable(s, name, "replaced", expected)
            self._ensure_history(s, row)
            state = self._state(s, row.id)
            return self._commit(
                s,
                row,
                cat,
                state,
                target,
                note or "imported",
                force=force,
                description=description,
            )

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

    def _writable(
        self, s: Session, name: str, what: str = "edited", expected: Precondition | None = None
    ) -> NetworkRow:
        row = self._row(s, name, lock=True)
        if expected is not None:
            expected.check(name, row.version, etag_of(row, self._state(s, row.id)))
        if row.builtin:
            raise ReadOnlyNetworkError(
                f"network {name!r} is built in and cannot be {what}: copy it first with "
                f'POST /api/networks {{"name": "my-{name}", "base": "{name}"}} and edit the copy'
            )
        return row

    @staticmethod
    def _state(
        s: Session, network_id: int, *, ordered_by_id: bool = False
    ) -> dict[_Key, NetworkPair]:
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
    def _checked(
        cat: _Catalogue, pairs: Iterable[NetworkPair], field: str | None
    ) -> dict[_Key, NetworkPair]:
        """Validated pairs by key, a later one of a pair replacing an earlier one.

        `field` names them in errors (None: a single body's).
        """
        out: dict[_Key, NetworkPair] = {}
        for i, p in enumerate(pairs):
            where = "" if field is None else f"{field}[{i}]."
            cat.ids(p.stimulus, p.behaviour, where)
            out.pop((p.stimulus, p.behaviour), None)
            out[p.stimulus, p.behaviour] = check_pair(p, where)
        return out

    @staticmethod
    def _stored(
        s: Session, row: NetworkRow, state: Mapping[_Key, NetworkPair], cat: _Catalogue
    ) -> StoredNetwork:
        s.flush()
        return StoredNetwork(
            row.name,
            row.description,
            row.builtin,
            row.version,
            _utc(row.created_at),
            _utc(row.updated_at),
            cat.order(state.values()),
            row.id,
            etag_of(row, state),
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
    def _record(s: Session, row: NetworkRow, state: Mapping[_Key, NetworkPair], note: str) -> None:
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
        s: Session,
        network_id: int,
        cat: _Catalogue,
        state: Mapping[_Key, NetworkPair],
        target: Mapping[_Key, NetworkPair],
    ) -> tuple[AssociationChange, ...]:
        """Make the stored associations `target`, changing rows in place (never re-adding)."""
        changes = changes_between(state, target)
        if not changes:
            return changes
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
        return changes

    def _commit(
        self,
        s: Session,
        row: NetworkRow,
        cat: _Catalogue,
        state: Mapping[_Key, NetworkPair],
        target: Mapping[_Key, NetworkPair],
        note: str,
        *,
        force: bool = False,
        description: str | None = None,
    ) -> NetworkEdit:
        """Store `target` as the network's next version, unless it changes nothing."""
        description = row.description if description is None else description
        changes = changes_between(state, target)
        if not force:
            for c in changes:
                if c.before is not None and c.before.locked:
                    raise LockedAssociationError(
                        f"association {c.stimulus} -> {c.behaviour} of network {row.name!r} "
                        "is locked: repeat with force=true to change or remove it"
                    )
        if not changes and description == row.description:
            return NetworkEdit(self._stored(s, row, state, cat), ())
        self._ensure_history(s, row)
        self._write(s, row.id, cat, state, target)
        row.version += 1
        row.description = description
        self._record(s, row, target, note)
        return NetworkEdit(self._stored(s, row, target, cat), changes)
