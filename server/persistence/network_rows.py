"""A stored network's rows in one transaction: found, read as the domain's, written, recorded."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from contextlib import suppress
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import exc as sa_exc
from sqlalchemy import select
from sqlalchemy.orm import Session

from core.errors import UnknownNameError
from core.networks import (
    AssociationChange,
    Key,
    Network,
    NetworkEdit,
    NetworkExistsError,
    Revision,
    StoredNetwork,
    UnknownVersionError,
    Vocabulary,
    fingerprint_of,
)
from core.ports import NetworkPair
from server.persistence.orm import (
    AssociationRow,
    BehaviourRow,
    NetworkRow,
    NetworkVersionRow,
    StimulusRow,
)
from server.persistence.seed import SEEDED_NOTE

FIRST_RECORDED_NOTE = "recorded as found before its first change"


def utc(value: datetime) -> datetime:
    """A stored time with its zone."""
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


def from_snapshot(snapshot: Mapping[str, Any]) -> dict[Key, NetworkPair]:
    """A network's associations by pair, from a `network_versions.snapshot`."""
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


class Catalogue:
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


def find_row(s: Session, name: str, *, lock: bool = False) -> NetworkRow | None:
    """A network's row, None when there is none (locked with `lock`)."""
    query = select(NetworkRow).where(NetworkRow.name == name)
    # A writer locks the row (PostgreSQL) so concurrent edits take versions in turn;
    # SQLite's writers are serialised by BEGIN IMMEDIATE already.
    return s.scalars(query.with_for_update() if lock else query).first()


def network_row(s: Session, name: str, *, lock: bool = False) -> NetworkRow:
    """A network's row (locked with `lock`); `UnknownNameError` when there is none."""
    row = find_row(s, name, lock=lock)
    if row is None:
        raise UnknownNameError(f"unknown network {name!r}")
    return row


def aggregate(s: Session, row: NetworkRow) -> Network:
    """The domain's network of a row, with its stored associations and fingerprint."""
    state = state_of(s, row.id)
    return Network(
        row.name,
        row.description,
        row.builtin,
        row.version,
        tuple(state.values()),
        fingerprint_of(row.id, row.created_at, row.version, row.description, state.values()),
    )


def load(s: Session, name: str) -> tuple[NetworkRow, Network]:
    """A network to write, its row locked; `UnknownNameError` when there is none."""
    row = network_row(s, name, lock=True)
    return row, aggregate(s, row)


def network_or_none(s: Session, name: str) -> Network | None:
    """The domain's network of that name, None when there is none."""
    row = find_row(s, name)
    return None if row is None else aggregate(s, row)


def state_of(s: Session, network_id: int, *, ordered_by_id: bool = False) -> dict[Key, NetworkPair]:
    """A network's associations by pair (in insertion order with `ordered_by_id`)."""
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
    return {(st, be): NetworkPair(st, be, x, src, lk) for st, be, x, src, lk in s.execute(query)}


def stored(
    s: Session, row: NetworkRow, state: Mapping[Key, NetworkPair], cat: Catalogue
) -> StoredNetwork:
    """A network as the port gives it, its associations in catalogue order."""
    s.flush()
    return StoredNetwork(
        row.name,
        row.description,
        row.builtin,
        row.version,
        utc(row.created_at),
        utc(row.updated_at),
        cat.vocabulary.order(state.values()),
        row.id,
        fingerprint_of(row.id, row.created_at, row.version, row.description, state.values()),
    )


def version_row(s: Session, row: NetworkRow, version: int) -> NetworkVersionRow:
    """One version's row of the history; `UnknownVersionError` when there is none."""
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


def ensure_history(s: Session, row: NetworkRow) -> None:
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
        _record(s, row, state_of(s, row.id), note)


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


def _write(
    s: Session, network_id: int, cat: Catalogue, changes: Iterable[AssociationChange]
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


def insert(s: Session, cat: Catalogue, revision: Revision) -> NetworkEdit:
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
    _write(s, row.id, cat, revision.changes)
    _record(s, row, network.state, revision.note)
    return NetworkEdit(stored(s, row, network.state, cat), revision.changes, created=True)


def save(
    s: Session, row: NetworkRow, cat: Catalogue, before: Network, revision: Revision
) -> NetworkEdit:
    """Store a revision of a network as its next version, unless it makes none."""
    if not revision.versioned:
        return NetworkEdit(stored(s, row, before.state, cat), ())
    after = revision.network
    ensure_history(s, row)
    _write(s, row.id, cat, revision.changes)
    row.version = after.version
    row.description = after.description
    _record(s, row, after.state, revision.note)
    return NetworkEdit(stored(s, row, after.state, cat), revision.changes)
