"""The network editor's rules (`core.networks`) on values alone: no database, no fake."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import FrozenInstanceError
from datetime import datetime

import pytest

from core.errors import (
    CatalogError,
    LockedAssociationError,
    RunStateError,
    UnknownNameError,
)
from core.networks import (
    AssociationExistsError,
    ExpectedVersion,
    Network,
    NetworkExistsError,
    NetworkSnapshot,
    ReadOnlyNetworkError,
    StaleVersionError,
    UnknownVersionError,
    Vocabulary,
    changes_between,
    check_name,
    create,
    fingerprint_of,
    import_network,
)
from core.ports import NetworkPair

WORDS = Vocabulary({"Red": 0, "Green": 1, "Corner": 2}, {"stop": 0, "back": 1, "turn": 2})
RED_STOP = NetworkPair("Red", "stop", 0.8, "dp")
CORNER = NetworkPair("Corner", "turn", 1.0, "innate", locked=True)
MINE = Network("mine", "d", False, 3, (RED_STOP, CORNER), fingerprint="v3-x")
BUILTIN = Network("dp", "shipped", True, 1, (RED_STOP,), fingerprint="v1-y")
_T0 = datetime(2024, 1, 1)


def history_of(*networks: Network) -> Callable[[int], NetworkSnapshot]:
    """A network's history as storage gives it to `Network.revert`."""
    found = {
        n.version: NetworkSnapshot(n.name, n.version, _T0, "", n.description, n.associations)
        for n in networks
    }

    def history(version: int) -> NetworkSnapshot:
        if version not in found:
            raise UnknownVersionError(f"no version {version}")
        return found[version]

    return history


# --- versions as values ------------------------------------------------------------------


def test_an_edit_returns_the_next_version_and_leaves_the_network_as_it_was() -> None:
    revision = MINE.put("Red", "stop", WORDS, strength=0.5)

    after = revision.network
    assert (after.name, after.version, after.description, after.builtin) == ("mine", 4, "d", False)
    assert after.state[("Red", "stop")] == NetworkPair("Red", "stop", 0.5, "dp")
    assert after.fingerprint == ""  # storage tags it once stored
    assert revision.versioned and not revision.created and revision.note == "changed Red -> stop"
    assert [(c.before, c.after) for c in revision.changes] == [
        (RED_STOP, after.state[("Red", "stop")])
    ]
    assert MINE.version == 3 and MINE.state[("Red", "stop")] == RED_STOP
    with pytest.raises(FrozenInstanceError):
        MINE.version = 4  # type: ignore[misc]


def test_an_edit_that_changes_nothing_makes_no_version() -> None:
    for revision in (
        MINE.put("Red", "stop", WORDS, strength=0.8),
        MINE.put("Corner", "turn", WORDS, locked=True),  # a lock is no obstacle to no change
        MINE.revise(MINE.state, "same"),
    ):
        assert not revision.versioned and revision.changes == ()
        assert revision.network is MINE
    described = MINE.revise(MINE.state, "renamed", description="other")
    assert described.versioned and described.changes == () and described.network.version == 4


def test_add_remove_and_their_notes() -> None:
    added = MINE.add(NetworkPair("Green", "stop", 1, "dp"), WORDS)
    removed = MINE.remove("Red", "stop", WORDS, note="why")

    assert (
        added.note == "added Green -> stop"
        and added.network.state[("Green", "stop")].strength == 1.0
    )
    assert removed.note == "why" and ("Red", "stop") not in removed.network.state
    assert [(c.before, c.after) for c in removed.changes] == [(RED_STOP, None)]
    with pytest.raises(AssociationExistsError, match="already"):
        MINE.add(RED_STOP, WORDS)
    with pytest.raises(UnknownNameError, match="no association Green -> stop"):
        MINE.remove("Green", "stop", WORDS)


def test_put_adds_a_missing_pair_with_defaults() -> None:
    revision = MINE.put("Green", "back", WORDS, source="expert")

    assert revision.changes[0].after == NetworkPair("Green", "back", 1.0, "expert", False)
    assert revision.note == "added Green -> back"


def test_names_that_address_a_pair_are_lookups_and_names_given_as_data_invalid_input() -> None:
    with pytest.raises(UnknownNameError, match="unknown stimulus 'Blue'"):
        MINE.put("Blue", "stop", WORDS, strength=1.0)
    with pytest.raises(UnknownNameError, match="unknown behaviour 'fly'"):
        MINE.remove("Red", "fly", WORDS)
    with pytest.raises(CatalogError, match=r"^behaviour: unknown behaviour 'fly'") as e:
        MINE.add(NetworkPair("Red", "fly", 1, "dp"), WORDS)
    assert not isinstance(e.value, UnknownNameError)
    with pytest.raises(ValueError, match="strength must be in"):
        MINE.put("Red", "stop", WORDS, strength=2.0)
    with pytest.raises(ValueError, match="source"):
        MINE.put("Red", "stop", WORDS, source="magic")


# --- built-ins, locks, preconditions -------------------------------------------------------


def test_builtin_networks_are_read_only() -> None:
    history = history_of(BUILTIN)
    for what, write in (
        ("edited", lambda: BUILTIN.put("Red", "stop", WORDS, strength=0.1)),
        ("edited", lambda: BUILTIN.add(NetworkPair("Green", "stop", 1, "dp"), WORDS)),
        ("edited", lambda: BUILTIN.remove("Red", "stop", WORDS, force=True)),
        ("edited", lambda: BUILTIN.revert(1, history, WORDS)),
        ("deleted", lambda: BUILTIN.check_writable("deleted")),
        ("replaced", lambda: import_network("dp", BUILTIN, [], WORDS, replace=True)),
    ):
        with pytest.raises(ReadOnlyNetworkError, match="copy it first") as e:
            write()
        assert (e.value.network, e.value.what) == ("dp", what)
        assert f"cannot be {what}" in str(e.value) and "/api/" not in str(e.value)
        assert isinstance(e.value, RunStateError)  # a conflict


def test_the_rules_are_checked_before_the_names() -> None:
    with pytest.raises(ReadOnlyNetworkError):
        BUILTIN.put("Blue", "fly", WORDS, strength=1.0)
    with pytest.raises(StaleVersionError):
        MINE.add(NetworkPair("Blue", "fly", 1, "dp"), WORDS, expected=ExpectedVersion(version=1))


def test_a_locked_association_changes_or_goes_only_when_forced() -> None:
    refused: list[Callable[[], object]] = [
        lambda: MINE.put("Corner", "turn", WORDS, strength=0.3),
        lambda: MINE.put("Corner", "turn", WORDS, locked=False),
        lambda: MINE.remove("Corner", "turn", WORDS),
        lambda: MINE.revise({}, "clear"),
    ]
    for write in refused:
        with pytest.raises(LockedAssociationError, match="force=true"):
            write()
    forced = MINE.put("Corner", "turn", WORDS, locked=False, force=True)
    assert forced.network.state[("Corner", "turn")].locked is False
    assert MINE.remove("Corner", "turn", WORDS, force=True).network.version == 4
    # Locking one is no change of a locked association.
    assert MINE.put("Red", "stop", WORDS, locked=True).network.state[("Red", "stop")].locked


def test_a_stale_version_or_tag_is_refused_before_anything_else() -> None:
    for expected, text in (
        (ExpectedVersion(version=2), "at version 3, not 2"),
        (ExpectedVersion(fingerprints=("v2-old",)), "which no fingerprint expected names"),
    ):
        with pytest.raises(StaleVersionError, match=text) as e:
            MINE.put("Red", "stop", WORDS, strength=0.1, expected=expected)
        assert (e.value.current, e.value.fingerprint) == (3, "v3-x")
        with pytest.raises(StaleVersionError):
            BUILTIN.check_writable("deleted", ExpectedVersion(version=2))  # stale before read-only
    for current in (
        ExpectedVersion(version=3),
        ExpectedVersion(),
        ExpectedVersion(fingerprints=("v1-a", "v3-x")),
        ExpectedVersion(version=3, fingerprints=("v3-x",)),
    ):
        assert MINE.put("Red", "stop", WORDS, strength=0.1, expected=current).versioned


# --- revert, create, import --------------------------------------------------------------


def test_revert_makes_an_old_version_the_next_one() -> None:
    v1 = Network("mine", "first", False, 1, (RED_STOP,))
    now = Network("mine", "now", False, 3, (NetworkPair("Red", "stop", 0.1, "dp"),))
    history = history_of(v1, now)

    revision = now.revert(1, history, WORDS)

    assert revision.network.version == 4 and revision.network.description == "first"
    assert revision.network.associations == (RED_STOP,)
    assert revision.note == "reverted to version 1"
    assert not now.revert(3, history, WORDS).versioned
    with pytest.raises(UnknownVersionError):
        now.revert(9, history, WORDS)


def test_create_copies_a_base_and_overlays_associations() -> None:
    stored = {"dp": BUILTIN, "mine": MINE}
    softer = NetworkPair("Red", "stop", 0.1, "dp")

    revision = create("new", stored.get, WORDS, base="dp", associations=[RED_STOP, softer])

    assert revision.created and revision.versioned and revision.note == "created from dp"
    assert revision.network == Network("new", "", False, 1, (softer,))
    assert create("empty", stored.get, WORDS, base=None).note == "created empty"
    with pytest.raises(NetworkExistsError, match="choose another name"):
        create("mine", stored.get, WORDS)
    with pytest.raises(UnknownNameError, match="unknown base network 'nope'"):
        create("new", stored.get, WORDS, base="nope")
    with pytest.raises(ValueError, match="slug"):
        create("no good", stored.get, WORDS)
    with pytest.raises(CatalogError, match=r"associations\[0\]\.stimulus"):
        create(
            "new", stored.get, WORDS, base=None, associations=[NetworkPair("Blue", "stop", 1, "dp")]
        )


def test_import_makes_a_new_network_or_with_replace_a_new_version() -> None:
    new = import_network("other", None, [RED_STOP], WORDS, description="file")
    assert new.created and new.network == Network("other", "file", False, 1, (RED_STOP,))
    assert new.note == "imported"

    with pytest.raises(NetworkExistsError, match="replace=true"):
        import_network("mine", MINE, [RED_STOP], WORDS)
    with pytest.raises(LockedAssociationError):
        import_network("mine", MINE, [RED_STOP], WORDS, replace=True)
    replaced = import_network("mine", MINE, [RED_STOP], WORDS, replace=True, force=True)
    assert replaced.network.version == 4 and replaced.network.description == ""
    with pytest.raises(StaleVersionError):
        import_network("mine", MINE, [], WORDS, replace=True, expected=ExpectedVersion(version=1))


# --- the small values ----------------------------------------------------------------------


def test_fingerprints_name_the_version_and_digest_identity_and_content() -> None:
    tag = fingerprint_of(1, _T0, 3, "d", [RED_STOP, CORNER])

    assert tag.startswith("v3-") and len(tag) == len("v3-") + 12  # a 12-digit digest
    assert tag == fingerprint_of(1, _T0, 3, "d", [CORNER, RED_STOP])  # order does not matter
    for other in (
        fingerprint_of(2, _T0, 3, "d", [RED_STOP, CORNER]),  # another network with its id
        fingerprint_of(1, "later", 3, "d", [RED_STOP, CORNER]),
        fingerprint_of(1, _T0, 3, "e", [RED_STOP, CORNER]),
        fingerprint_of(1, _T0, 3, "d", [RED_STOP]),
    ):
        assert other != tag


def test_vocabulary_orders_pairs_as_the_catalogue_does() -> None:
    pairs = [NetworkPair("Corner", "stop", 1, "dp"), CORNER, NetworkPair("Red", "back", 1, "dp")]
    ordered = WORDS.order([*pairs, RED_STOP])

    assert [(p.stimulus, p.behaviour) for p in ordered] == [
        ("Red", "stop"),
        ("Red", "back"),
        ("Corner", "stop"),
        ("Corner", "turn"),
    ]


def test_changes_between_sorts_and_classifies() -> None:
    a = {("B", "x"): NetworkPair("B", "x", 1, "dp"), ("A", "y"): NetworkPair("A", "y", 1, "dp")}
    b = {("B", "x"): NetworkPair("B", "x", 0.5, "dp"), ("C", "z"): NetworkPair("C", "z", 1, "dp")}

    got = [(c.stimulus, c.before is None, c.after is None) for c in changes_between(a, b)]

    assert got == [("A", False, True), ("B", False, False), ("C", True, False)]


@pytest.mark.parametrize("name", ["", "a b", "x" * 65, "é", "a/b"])
def test_network_names_are_slugs(name: str) -> None:
    with pytest.raises(ValueError, match="slug"):
        check_name(name)
    assert check_name("my-net_1") == "my-net_1"
