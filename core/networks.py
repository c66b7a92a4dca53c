"""The network editor's rules: stored S-R networks, their edits and versions, as values.

A stored network (the S-R editor's subject) is an aggregate, `Network`: its associations,
its description and its version. Its rules live here, pure:

- built-in networks (the catalogue's knowledge sets) are read-only: copy one to edit it;
- a locked association changes (or goes) only when the edit is forced;
- a write may expect a version or a fingerprint (`ExpectedVersion`) and is refused when
  the network is no longer at it (`StaleVersionError`);
- every change makes the next version, a `Revision` (a value); an edit that changes
  nothing makes none.

Storage (`server/persistence/networks.py`, `tests/fakes/`) loads a `Network`, asks it
for a `Revision` and saves that, all in one transaction; it implements
`core.ports.NetworkRepository`. Messages here name no request of the API: it adds its own.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from datetime import datetime

from core.brain.catalog import SOURCES, Catalog
from core.errors import (
    CatalogError,
    CoreError,
    LockedAssociationError,
    RunStateError,
    UnknownNameError,
)

NAME_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"
"""A network's name: a slug of letters, digits, - and _, 1 to 64 characters."""
_NAME = re.compile(NAME_PATTERN)
Key = tuple[str, str]
"""An association's (stimulus, behaviour)."""


@dataclass(frozen=True, slots=True)
class NetworkPair:
    """An association of a run's behaviour network, by names."""

    stimulus: str
    behaviour: str
    strength: float
    source: str
    locked: bool = False


# --- errors ------------------------------------------------------------------------------


class NetworkConflictError(RunStateError):
    """A network write that conflicts with what is stored (a kind of RunStateError)."""


class NetworkExistsError(NetworkConflictError):
    """A network of that name exists already."""


class ReadOnlyNetworkError(NetworkConflictError):
    """A write to a built-in network: they are read-only, copy one to edit it.

    `network` and `what` (edited, deleted, replaced) let an adapter say how to copy it.
    """

    def __init__(self, network: str, what: str = "edited", message: str | None = None) -> None:
        super().__init__(
            message
            or f"network {network!r} is built in and cannot be {what}: copy it first and "
            "edit the copy"
        )
        self.network = network
        self.what = what

    def __reduce__(self) -> tuple[type[ReadOnlyNetworkError], tuple[str, str, str]]:
        """Pickled with its fields (the store process sends errors to the service)."""
        return type(self), (self.network, self.what, str(self))


class AssociationExistsError(NetworkConflictError):
    """An association added that the network has already (change it instead)."""


class UnknownVersionError(UnknownNameError):
    """A version a network's history does not have."""


class StaleVersionError(CoreError):
    """A write based on a version of the network that is no longer current.

    `network` is at version `current` (its `fingerprint`); the write expected version
    `expected`, or (`expected` None) one of some fingerprints, none of them current.
    """

    def __init__(
        self, network: str, current: int, fingerprint: str, expected: int | None = None
    ) -> None:
        if expected is not None:
            at = f"version {current}, not {expected}"
        else:
            at = f"version {current} ({fingerprint}), which no fingerprint expected names"
        super().__init__(
            f"network {network!r} is at {at}: another write came first; read it again and "
            "reapply the change"
        )
        self.network = network
        self.current = current
        self.fingerprint = fingerprint
        self.expected = expected

    def __reduce__(self) -> tuple[type[StaleVersionError], tuple[str, int, str, int | None]]:
        """Pickled with its fields (the store process sends errors to the service)."""
        return type(self), (self.network, self.current, self.fingerprint, self.expected)


# --- values ------------------------------------------------------------------------------


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


def fingerprint_of(
    network_id: int,
    created_at: object,
    version: int,
    description: str,
    pairs: Iterable[NetworkPair],
) -> str:
    """The fingerprint of one version of one network: `v<version>-<digest>`.

    The version, and a digest of what makes it this network's version: its identity (its
    id, which SQLite gives a deleted network's to the next one, and its creation time as
    storage keeps it) and its content. A network made again under a deleted one's name
    has other fingerprints, though its versions count from 1 again.
    """
    content = sorted((p.stimulus, p.behaviour, p.strength, p.source, p.locked) for p in pairs)
    identity = [network_id, str(created_at), version, description, content]
    digest = hashlib.sha256(repr(identity).encode()).hexdigest()[:12]
    return f"v{version}-{digest}"


@dataclass(frozen=True, slots=True)
class ExpectedVersion:
    """What a write expects of the network: a version, and/or one of some fingerprints."""

    version: int | None = None
    fingerprints: tuple[str, ...] | None = None
    """The fingerprints any of which may be current (None: any)."""

    def check(self, name: str, version: int, fingerprint: str) -> None:
        """`StaleVersionError` unless the network (at `version`, `fingerprint`) is expected."""
        if self.version is not None and self.version != version:
            raise StaleVersionError(name, version, fingerprint, self.version)
        if self.fingerprints is not None and fingerprint not in self.fingerprints:
            raise StaleVersionError(name, version, fingerprint)


@dataclass(frozen=True, slots=True)
class AssociationChange:
    """What became of one S-R pair: added (no `before`), removed (no `after`) or changed."""

    stimulus: str
    behaviour: str
    before: NetworkPair | None
    after: NetworkPair | None


def changes_between(
    before: Mapping[Key, NetworkPair], after: Mapping[Key, NetworkPair]
) -> tuple[AssociationChange, ...]:
    """The pairs added, removed or changed from `before` to `after`, sorted by name."""
    out = []
    for key in sorted(before.keys() | after.keys()):
        old, new = before.get(key), after.get(key)
        if old != new:
            out.append(AssociationChange(key[0], key[1], old, new))
    return tuple(out)


@dataclass(frozen=True, slots=True)
class Vocabulary:
    """The names an association may use: stimuli and designed behaviours, by catalogue position."""

    stimuli: Mapping[str, int]
    behaviours: Mapping[str, int]

    @classmethod
    def of(cls, catalog: Catalog) -> Vocabulary:
        """The catalogue's stimuli and behaviours at their positions (their ids)."""
        return cls(
            {s.name: s.id for s in catalog.stimuli}, {b.name: b.id for b in catalog.behaviours}
        )

    def require(self, stimulus: str, behaviour: str, where: str | None = None) -> None:
        """Nothing if both names are known.

        Names that address an association (`where` None) raise `UnknownNameError`; names
        given as data (`where`, the field's place) raise `CatalogError`, invalid input.
        """
        for known, kind, name in (
            (self.stimuli, "stimulus", stimulus),
            (self.behaviours, "behaviour", behaviour),
        ):
            if name not in known:
                if where is None:
                    raise UnknownNameError(f"unknown {kind} {name!r}")
                raise CatalogError(f"{where}{kind}: unknown {kind} {name!r}")

    def checked(self, pairs: Iterable[NetworkPair], field: str | None) -> dict[Key, NetworkPair]:
        """Validated pairs by key, a later one of a pair replacing an earlier one.

        `field` names them in errors (None: a single body's).
        """
        out: dict[Key, NetworkPair] = {}
        for i, p in enumerate(pairs):
            where = "" if field is None else f"{field}[{i}]."
            self.require(p.stimulus, p.behaviour, where)
            out.pop((p.stimulus, p.behaviour), None)
            out[p.stimulus, p.behaviour] = check_pair(p, where)
        return out

    def order(self, pairs: Iterable[NetworkPair]) -> tuple[NetworkPair, ...]:
        """`pairs` in catalogue order (stimulus, then behaviour), as the editor's matrix."""
        end = 1 << 30

        def key(p: NetworkPair) -> tuple[int, int, str, str]:
            st = self.stimuli.get(p.stimulus, end)
            be = self.behaviours.get(p.behaviour, end)
            return st, be, p.stimulus, p.behaviour

        return tuple(sorted(pairs, key=key))


# --- the aggregate -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Network:
    """A stored network at one version: the aggregate the editor's rules apply to.

    `fingerprint` is the one storage gave this version (see `fingerprint_of`; "" for a
    version not stored yet). Every edit returns a `Revision`; the network itself never changes.
    """

    name: str
    description: str = ""
    builtin: bool = False
    version: int = 1
    associations: tuple[NetworkPair, ...] = ()
    fingerprint: str = ""

    @property
    def state(self) -> dict[Key, NetworkPair]:
        """The associations by (stimulus, behaviour)."""
        return {(p.stimulus, p.behaviour): p for p in self.associations}

    def check_writable(self, what: str = "edited", expected: ExpectedVersion | None = None) -> None:
        """Refuse a write expecting another version, or one to a built-in network.

        `what` says what the write would do to it: edited, deleted, replaced.
        """
        if expected is not None:
            expected.check(self.name, self.version, self.fingerprint)
        if self.builtin:
            raise ReadOnlyNetworkError(self.name, what)

    def revise(
        self,
        target: Mapping[Key, NetworkPair],
        note: str,
        *,
        force: bool = False,
        description: str | None = None,
        expected: ExpectedVersion | None = None,
        what: str = "edited",
    ) -> Revision:
        """The network with `target` as its associations (and `description`): its next version.

        A revision that changes nothing makes no version (`versioned` False). Changing or
        removing a locked association needs `force`.
        """
        self.check_writable(what, expected)
        description = self.description if description is None else description
        changes = changes_between(self.state, target)
        if not force:
            for c in changes:
                if c.before is not None and c.before.locked:
                    raise LockedAssociationError(
                        f"association {c.stimulus} -> {c.behaviour} of network {self.name!r} "
                        "is locked: repeat with force=true to change or remove it"
                    )
        if not changes and description == self.description:
            return Revision(self, (), note, versioned=False)
        after = Network(
            self.name, description, self.builtin, self.version + 1, tuple(target.values())
        )
        return Revision(after, changes, note)

    def add(
        self,
        pair: NetworkPair,
        vocabulary: Vocabulary,
        *,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> Revision:
        """Add an association the network lacks (`AssociationExistsError` if it has it)."""
        self.check_writable(expected=expected)
        pair = next(iter(vocabulary.checked([pair], None).values()))
        key = (pair.stimulus, pair.behaviour)
        state = self.state
        if key in state:
            raise AssociationExistsError(
                f"network {self.name!r} has {key[0]} -> {key[1]} already: change it with PUT"
            )
        return self.revise({**state, key: pair}, note or f"added {key[0]} -> {key[1]}")

    def put(
        self,
        stimulus: str,
        behaviour: str,
        vocabulary: Vocabulary,
        *,
        strength: float | None = None,
        source: str | None = None,
        locked: bool | None = None,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> Revision:
        """Set an association (insert or update); None keeps a value (new: 1.0, dp, unlocked).

        Changing a locked association, unlocking it included, needs `force`.
        """
        self.check_writable(expected=expected)
        vocabulary.require(stimulus, behaviour)
        state = self.state
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
        return self.revise(target, note or f"{verb} {stimulus} -> {behaviour}", force=force)

    def remove(
        self,
        stimulus: str,
        behaviour: str,
        vocabulary: Vocabulary,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> Revision:
        """Remove an association (a locked one only with `force`)."""
        self.check_writable(expected=expected)
        vocabulary.require(stimulus, behaviour)
        state = self.state
        key = (stimulus, behaviour)
        if key not in state:
            raise UnknownNameError(
                f"network {self.name!r} has no association {stimulus} -> {behaviour}"
            )
        target = {k: v for k, v in state.items() if k != key}
        return self.revise(target, note or f"removed {stimulus} -> {behaviour}", force=force)

    def revert(
        self,
        version: int,
        history: Callable[[int], NetworkSnapshot],
        vocabulary: Vocabulary,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> Revision:
        """Make the network what it was at `version` (from `history`), as a new version."""
        self.check_writable(expected=expected)
        then = history(version)
        target = vocabulary.checked(then.associations, "snapshot.associations")
        return self.revise(
            target,
            note or f"reverted to version {version}",
            force=force,
            description=then.description,
        )


@dataclass(frozen=True, slots=True)
class Revision:
    """What an edit makes of a network: its next version, as a value.

    `network` is the network after the edit; `changes` what changed and `note` what its
    history records. An edit that changes nothing makes no version (`versioned` False,
    `network` the network as it was); a new network's first version is `created`.
    """

    network: Network
    changes: tuple[AssociationChange, ...]
    note: str
    versioned: bool = True
    created: bool = False


def create(
    name: str,
    find: Callable[[str], Network | None],
    vocabulary: Vocabulary,
    *,
    description: str = "",
    base: str | None = "innate",
    associations: Iterable[NetworkPair] = (),
    note: str = "",
) -> Revision:
    """Version 1 of a new, editable network: a copy of `base` (None: empty), edited.

    Each of `associations` replaces any earlier one of its pair (the base's included).
    `find` gives the stored network of a name (None: there is none).
    """
    check_name(name)
    items = list(associations)
    if find(name) is not None:
        raise NetworkExistsError(f"network {name!r} exists already: choose another name")
    state: dict[Key, NetworkPair] = {}
    if base is not None:
        found = find(base)
        if found is None:
            raise UnknownNameError(f"unknown base network {base!r}")
        state = found.state
    state.update(vocabulary.checked(items, "associations"))
    default = f"created from {base}" if base is not None else "created empty"
    return _first(name, description, state, note or default)


def import_network(
    name: str,
    existing: Network | None,
    associations: Iterable[NetworkPair],
    vocabulary: Vocabulary,
    *,
    description: str = "",
    replace: bool = False,
    force: bool = False,
    note: str = "",
    expected: ExpectedVersion | None = None,
) -> Revision:
    """An imported network: a new one, or with `replace` a new version of `existing`.

    `existing` (None: there is none) must be editable to be replaced, and changing its
    locked associations needs `force`; `expected` applies to it.
    """
    check_name(name)
    target = vocabulary.checked(list(associations), "associations")
    if existing is None:
        return _first(name, description, target, note or "imported")
    if not replace:
        raise NetworkExistsError(
            f"network {name!r} exists already: import it under another name, "
            "or replace it (replace=true) to make a new version of it"
        )
    return existing.revise(
        target,
        note or "imported",
        force=force,
        description=description,
        expected=expected,
        what="replaced",
    )


def _first(name: str, description: str, state: Mapping[Key, NetworkPair], note: str) -> Revision:
    network = Network(name, description, False, 1, tuple(state.values()))
    return Revision(network, changes_between({}, state), note, created=True)


# --- what a repository answers -----------------------------------------------------------


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
    fingerprint: str = ""
    """What names this version of this network (see `fingerprint_of`)."""

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
class NetworkEdit:
    """A write's outcome: the network as stored now and what changed (empty: nothing)."""

    network: StoredNetwork
    changes: tuple[AssociationChange, ...]
    created: bool = False
