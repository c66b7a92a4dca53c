"""One contract for every `NetworkRepository`: the in-memory fake, SQLite and PostgreSQL.

The editor's rules are `core.networks`'; each store applies them in one transaction. These
tests hold the stores to the same answers: built-ins read-only, locks, versions, no-op
edits, preconditions, history, import.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from fakes import InMemoryNetworkRepository
from sqlalchemy import Engine, text

from core.brain.catalog import Catalog
from core.errors import CatalogError, LockedAssociationError, UnknownNameError
from core.networks import (
    AssociationExistsError,
    ExpectedVersion,
    NetworkExistsError,
    ReadOnlyNetworkError,
    StaleVersionError,
    UnknownVersionError,
    Vocabulary,
)
from core.ports import NetworkPair, NetworkRepository
from server.persistence import make_sessionmaker
from server.persistence.networks import SqlAlchemyNetworkRepository
from server.persistence.seed import SEEDED_NOTE

RED_STOP = NetworkPair("Red", "stop", 0.8, "dp")
CORNER = ("Corner", "leftturn90")


@pytest.fixture(params=["memory", "sqlite", "postgresql"])
def networks(request: pytest.FixtureRequest, catalog: Catalog) -> NetworkRepository:
    """Each implementation of `NetworkRepository`, seeded with the catalogue's networks."""
    if request.param == "memory":
        return InMemoryNetworkRepository(catalog)
    if request.param == "sqlite":
        engine: Engine = request.getfixturevalue("sqlite_engine")
    else:
        engine = request.getfixturevalue("postgres_engine")
        with engine.begin() as c:  # the module's database: no network an earlier test made
            c.execute(text("DELETE FROM networks WHERE NOT builtin"))
    return SqlAlchemyNetworkRepository(make_sessionmaker(engine))


def keys(pairs: tuple[NetworkPair, ...]) -> list[tuple[str, str]]:
    return [(p.stimulus, p.behaviour) for p in pairs]


def test_the_catalogues_networks_are_built_in_at_version_1(
    networks: NetworkRepository, catalog: Catalog
) -> None:
    summaries = {s.name: s for s in networks.summaries()}

    assert set(summaries) == set(catalog.knowledge)
    for name, s in summaries.items():
        assert s.builtin and s.version == 1
        assert s.association_count == len(catalog.knowledge_set(name).associations)
        assert s.updated_at.tzinfo is not None
    assert [(v.version, v.note) for v in networks.versions("dp")] == [(1, SEEDED_NOTE)]
    dp = catalog.knowledge_set("dp").associations
    assert keys(networks.pairs("dp")) == [(a.stimulus, a.behaviour) for a in dp]


def test_summaries_list_built_in_networks_first_then_by_name(
    networks: NetworkRepository,
) -> None:
    for name in ("zeta", "alpha"):
        networks.create(name)

    listed = [(s.name, s.builtin) for s in networks.summaries()]

    assert [b for _, b in listed] == sorted((b for _, b in listed), reverse=True)
    assert [n for n, b in listed if not b] == ["alpha", "zeta"]


def test_create_copies_the_base_at_version_1(networks: NetworkRepository, catalog: Catalog) -> None:
    made = networks.create("mine", description="a copy", base="dp")

    assert (made.name, made.builtin, made.version, made.description) == ("mine", False, 1, "a copy")
    assert made == networks.get("mine")
    assert made.fingerprint.startswith("v1-") and made.fingerprint != networks.get("dp").fingerprint
    assert made.associations == Vocabulary.of(catalog).order(networks.get("dp").associations)
    assert [(v.version, v.note) for v in networks.versions("mine")] == [(1, "created from dp")]


def test_create_overlays_associations_on_the_base_or_on_nothing(
    networks: NetworkRepository,
) -> None:
    over = NetworkPair(*CORNER, 0.25, "dp", locked=True)
    softer = NetworkPair("Red", "stop", 0.1, "dp")
    made = networks.create("mine", associations=[over, RED_STOP, softer], note="start")
    empty = networks.create("empty", base=None, associations=[RED_STOP])

    got = {(p.stimulus, p.behaviour): p for p in made.associations}
    assert got[CORNER] == over and got["Red", "stop"] == softer and len(got) == 5
    assert empty.associations == (RED_STOP,)
    assert [v.note for v in networks.versions("mine")] == ["start"]
    assert [v.note for v in networks.versions("empty")] == ["created empty"]


def test_create_refusals_store_nothing(networks: NetworkRepository) -> None:
    networks.create("mine")
    for taken in ("mine", "innate"):
        with pytest.raises(NetworkExistsError):
            networks.create(taken)
    for bad in ("", "a b", "x" * 65):
        with pytest.raises(ValueError, match="slug"):
            networks.create(bad)
    with pytest.raises(UnknownNameError, match="base network 'nope'"):
        networks.create("other", base="nope")
    with pytest.raises(CatalogError, match=r"associations\[1\]\.stimulus") as e:
        networks.create("other", associations=[RED_STOP, NetworkPair("Purple", "stop", 1, "dp")])
    assert not isinstance(e.value, UnknownNameError)  # invalid input, not a lookup
    with pytest.raises(ValueError, match="strength"):
        networks.create("other", associations=[NetworkPair("Red", "stop", 1.5, "dp")])
    with pytest.raises(UnknownNameError):
        networks.get("other")


def test_builtin_networks_are_read_only(networks: NetworkRepository) -> None:
    writes: list[Callable[[], object]] = [
        lambda: networks.add_association("dp", NetworkPair("Red", "back", 1.0, "dp")),
        lambda: networks.put_association("dp", "Red", "stop", strength=0.1),
        lambda: networks.remove_association("dp", "Red", "stop", force=True),
        lambda: networks.revert("dp", 1),
        lambda: networks.delete("dp"),
        lambda: networks.import_network("dp", [RED_STOP], replace=True, force=True),
    ]
    for write in writes:
        with pytest.raises(ReadOnlyNetworkError, match="copy it first") as e:
            write()
        assert e.value.network == "dp" and "/api/" not in str(e.value)
    assert networks.get("dp").version == 1 and len(networks.versions("dp")) == 1


def test_add_put_and_remove_make_versions(networks: NetworkRepository) -> None:
    networks.create("mine")
    added = networks.add_association("mine", RED_STOP)
    put = networks.put_association("mine", "Red", "stop", source="expert")
    removed = networks.remove_association("mine", "Red", "stop", note="gone")

    assert [e.network.version for e in (added, put, removed)] == [2, 3, 4]
    assert [(c.before, c.after) for c in added.changes] == [(None, RED_STOP)]
    expert = NetworkPair("Red", "stop", 0.8, "expert")
    assert [(c.before, c.after) for c in put.changes] == [(RED_STOP, expert)]
    assert [(c.before, c.after) for c in removed.changes] == [(expert, None)]
    assert [v.note for v in networks.versions("mine")] == [
        "created from innate",
        "added Red -> stop",
        "changed Red -> stop",
        "gone",
    ]
    assert networks.get("mine") == removed.network


def test_add_and_put_refusals(networks: NetworkRepository) -> None:
    networks.create("mine")
    networks.add_association("mine", RED_STOP)
    with pytest.raises(AssociationExistsError):
        networks.add_association("mine", RED_STOP)
    with pytest.raises(CatalogError, match="behaviour: unknown behaviour 'fly'"):
        networks.add_association("mine", NetworkPair("Red", "fly", 1.0, "dp"))
    with pytest.raises(UnknownNameError, match="stimulus 'Purple'"):
        networks.put_association("mine", "Purple", "stop", strength=1.0)
    with pytest.raises(UnknownNameError, match="no association Green -> stop"):
        networks.remove_association("mine", "Green", "stop")
    with pytest.raises(ValueError, match="strength"):
        networks.put_association("mine", "Red", "stop", strength=float("nan"))
    with pytest.raises(UnknownNameError, match="unknown network 'nope'"):
        networks.add_association("nope", RED_STOP)
    assert networks.get("mine").version == 2


def test_an_edit_that_changes_nothing_makes_no_version(networks: NetworkRepository) -> None:
    made = networks.create("mine")
    same = networks.put_association("mine", *CORNER, strength=1.0)
    reverted = networks.revert("mine", 1)
    imported = networks.import_network("mine", made.associations, replace=True)

    for edit in (same, reverted, imported):
        assert edit.changes == () and edit.network == made
    assert len(networks.versions("mine")) == 1


def test_a_locked_association_changes_only_with_force(networks: NetworkRepository) -> None:
    networks.create("mine")
    networks.put_association("mine", *CORNER, locked=True)
    refusals: list[Callable[[], object]] = [
        lambda: networks.put_association("mine", *CORNER, strength=0.2),
        lambda: networks.put_association("mine", *CORNER, locked=False),
        lambda: networks.remove_association("mine", *CORNER),
        lambda: networks.revert("mine", 1),
    ]
    for refused in refusals:
        with pytest.raises(LockedAssociationError, match="force=true"):
            refused()
    assert networks.get("mine").version == 2
    # Re-setting what it is already is no change, so no lock is in the way.
    assert networks.put_association("mine", *CORNER, strength=1.0).changes == ()

    forced = networks.put_association("mine", *CORNER, strength=0.2, force=True)
    assert forced.changes[0].after == NetworkPair(*CORNER, 0.2, "innate", True)
    assert networks.remove_association("mine", *CORNER, force=True).network.version == 4


def test_preconditions_refuse_a_stale_write_and_change_nothing(
    networks: NetworkRepository,
) -> None:
    v1 = networks.create("mine")
    v2 = networks.put_association("mine", "Red", "stop", strength=0.5).network
    assert v2.fingerprint.startswith("v2-") and v2.fingerprint != v1.fingerprint

    stale = [
        ExpectedVersion(version=1),
        ExpectedVersion(fingerprints=(v1.fingerprint,)),
        ExpectedVersion(version=2, fingerprints=(v1.fingerprint,)),
    ]
    for expected in stale:
        with pytest.raises(StaleVersionError, match="version 2") as e:
            networks.put_association("mine", "Red", "stop", strength=0.9, expected=expected)
        assert (e.value.current, e.value.fingerprint) == (2, v2.fingerprint)
        with pytest.raises(StaleVersionError):
            networks.delete("mine", expected=expected)
    assert networks.get("mine") == v2

    for current in (
        ExpectedVersion(version=2),
        ExpectedVersion(),
        ExpectedVersion(fingerprints=(v2.fingerprint, v1.fingerprint)),
    ):
        edit = networks.put_association("mine", "Red", "stop", strength=0.5, expected=current)
        assert edit.network == v2  # no change, and no refusal
    # The precondition comes first: a stale write to a built-in network is stale.
    with pytest.raises(StaleVersionError):
        networks.put_association("dp", "Red", "stop", strength=0.1, expected=ExpectedVersion(9))


def test_versions_snapshots_and_diff(networks: NetworkRepository) -> None:
    networks.create("mine")
    networks.add_association("mine", RED_STOP)
    networks.put_association("mine", *CORNER, strength=0.4)
    networks.remove_association("mine", "Collision", "back", note="no more backing up")

    assert [(v.version, v.association_count) for v in networks.versions("mine")] == [
        (1, 4),
        (2, 5),
        (3, 5),
        (4, 4),
    ]
    v1, v4 = networks.snapshot("mine", 1), networks.snapshot("mine", 4)
    assert v1.associations == networks.get("innate").associations
    assert v4.associations == networks.get("mine").associations
    assert (v4.note, v4.name, v4.version) == ("no more backing up", "mine", 4)
    changes = {(c.stimulus, c.behaviour): c for c in networks.diff("mine", 1, 4)}
    assert set(changes) == {("Red", "stop"), CORNER, ("Collision", "back")}
    assert changes["Red", "stop"].before is None and changes["Collision", "back"].after is None
    back = {(c.stimulus, c.behaviour): (c.after, c.before) for c in networks.diff("mine", 4, 1)}
    assert back == {k: (c.before, c.after) for k, c in changes.items()}
    assert networks.diff("mine", 2, 2) == ()
    with pytest.raises(UnknownVersionError, match="no version 5"):
        networks.snapshot("mine", 5)
    with pytest.raises(UnknownVersionError):
        networks.diff("mine", 0, 1)


def test_versions_page_reads_a_page_of_the_history_and_counts_it(
    networks: NetworkRepository,
) -> None:
    networks.create("mine")
    for strength in (0.1, 0.2, 0.3, 0.4):
        networks.put_association("mine", *CORNER, strength=strength, note=f"to {strength}")

    page, total = networks.versions_page("mine", offset=1, limit=2)

    assert total == 5
    assert page == networks.versions("mine")[1:3]
    assert [v.note for v in page] == ["to 0.1", "to 0.2"]
    assert networks.versions_page("mine", offset=5, limit=2) == ((), 5)
    with pytest.raises(UnknownNameError):
        networks.versions_page("nothing")


def test_revert_is_a_new_version_with_the_old_description(networks: NetworkRepository) -> None:
    first = networks.create("mine", description="v1")
    networks.add_association("mine", RED_STOP)
    networks.import_network("mine", [RED_STOP], description="v3", replace=True)

    reverted = networks.revert("mine", 1)

    assert reverted.network.version == 4 and reverted.network.description == "v1"
    assert reverted.network.associations == first.associations
    assert networks.versions("mine")[-1].note == "reverted to version 1"
    with pytest.raises(UnknownVersionError):
        networks.revert("mine", 9)


def test_import_creates_replaces_and_refuses(networks: NetworkRepository) -> None:
    made = networks.import_network("mine", [RED_STOP], description="from a file")
    assert made.created and made.network.version == 1
    assert made.network.associations == (RED_STOP,) and made.network.description == "from a file"
    assert [(c.before, c.after) for c in made.changes] == [(None, RED_STOP)]

    with pytest.raises(NetworkExistsError, match="replace"):
        networks.import_network("mine", [])
    locked = NetworkPair(*CORNER, 1.0, "dp", locked=True)
    replaced = networks.import_network("mine", [locked], replace=True, note="v2")
    assert not replaced.created and replaced.network.version == 2
    assert replaced.network.description == ""
    with pytest.raises(LockedAssociationError):
        networks.import_network("mine", [RED_STOP], replace=True)
    stale = ExpectedVersion(version=1)
    with pytest.raises(StaleVersionError):
        networks.import_network("mine", [RED_STOP], replace=True, force=True, expected=stale)
    assert (
        networks.import_network("mine", [RED_STOP], replace=True, force=True).network.version == 3
    )
    assert [v.note for v in networks.versions("mine")] == ["imported", "v2", "imported"]


def test_delete_frees_the_name_for_another_network(networks: NetworkRepository) -> None:
    old = networks.create("mine", base="dp")
    networks.delete("mine")

    with pytest.raises(UnknownNameError):
        networks.get("mine")
    with pytest.raises(UnknownNameError):
        networks.delete("mine")
    new = networks.create("mine")
    assert new.version == 1 and new.fingerprint != old.fingerprint
    assert [v.version for v in networks.versions("mine")] == [1]


def test_pairs_keep_the_order_they_were_stored_in(networks: NetworkRepository) -> None:
    networks.create("mine", base=None, associations=[RED_STOP, NetworkPair(*CORNER, 1, "dp")])
    networks.put_association("mine", "Red", "stop", strength=0.2)
    networks.add_association("mine", NetworkPair("Green", "stop", 1.0, "dp"))

    assert keys(networks.pairs("mine")) == [CORNER, ("Red", "stop"), ("Green", "stop")]
    with pytest.raises(UnknownNameError):
        networks.pairs("nope")
