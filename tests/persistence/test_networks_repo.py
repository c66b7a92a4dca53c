"""`SqlAlchemyNetworkRepository` on a migrated SQLite file: edits, locks, history, import."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from sqlalchemy import Engine, delete, select
from sqlalchemy.orm import Session

from core.brain.catalog import Catalog
from core.errors import (
    CatalogError,
    LockedAssociationError,
    RunStateError,
    UnknownNameError,
)
from core.ports import NetworkPair
from server.persistence import make_sessionmaker
from server.persistence.networks import (
    FIRST_RECORDED_NOTE,
    AssociationExistsError,
    NetworkConflictError,
    NetworkExistsError,
    ReadOnlyNetworkError,
    SqlAlchemyNetworkRepository,
    UnknownVersionError,
    changes_between,
)
from server.persistence.orm import AssociationRow, NetworkRow, NetworkVersionRow
from server.persistence.seed import SEEDED_NOTE

RED_STOP = NetworkPair("Red", "stop", 0.8, "dp")


@pytest.fixture
def repo(sqlite_engine: Engine) -> SqlAlchemyNetworkRepository:
    return SqlAlchemyNetworkRepository(make_sessionmaker(sqlite_engine))


def keys(pairs: tuple[NetworkPair, ...]) -> set[tuple[str, str]]:
    return {(p.stimulus, p.behaviour) for p in pairs}


def test_conflicts_are_answered_as_run_state_errors() -> None:
    # The service maps RunStateError to 409 and UnknownNameError to 404.
    for kind in (NetworkExistsError, ReadOnlyNetworkError, AssociationExistsError):
        assert issubclass(kind, NetworkConflictError) and issubclass(kind, RunStateError)
    assert issubclass(UnknownVersionError, UnknownNameError)


def test_summaries_list_the_seeded_networks(
    repo: SqlAlchemyNetworkRepository, catalog: Catalog
) -> None:
    summaries = {s.name: s for s in repo.summaries()}

    assert set(summaries) == set(catalog.knowledge)
    assert {"innate", "dp", "kp", "expert", "dp-paper", "expert-paper"} <= set(summaries)
    for name, s in summaries.items():
        assert s.builtin and s.version == 1
        assert s.association_count == len(catalog.knowledge_set(name).associations)
        assert s.updated_at.tzinfo is not None


def test_create_copies_the_base_and_records_version_1(
    repo: SqlAlchemyNetworkRepository, catalog: Catalog
) -> None:
    made = repo.create("mine", description="a copy", base="dp")

    assert (made.name, made.builtin, made.version, made.description) == ("mine", False, 1, "a copy")
    assert made.associations == repo.get("mine").associations
    assert keys(made.associations) == keys(repo.get("dp").associations)
    history = repo.versions("mine")
    assert [(v.version, v.note) for v in history] == [(1, "created from dp")]
    assert [s.name for s in repo.summaries()][-1] == "mine"


def test_create_overlays_associations_on_the_base_or_on_nothing(
    repo: SqlAlchemyNetworkRepository,
) -> None:
    over = NetworkPair("Corner", "leftturn90", 0.25, "dp", locked=True)
    made = repo.create("mine", associations=[over, RED_STOP], note="start")
    empty = repo.create("empty", base=None, associations=[RED_STOP])

    got = {(p.stimulus, p.behaviour): p for p in made.associations}
    assert got["Corner", "leftturn90"] == over and got["Red", "stop"] == RED_STOP
    assert len(made.associations) == 5
    assert empty.associations == (RED_STOP,)
    assert repo.versions("mine")[0].note == "start"
    assert repo.versions("empty")[0].note == "created empty"


def test_create_refusals(repo: SqlAlchemyNetworkRepository) -> None:
    repo.create("mine")
    with pytest.raises(NetworkExistsError):
        repo.create("mine")
    with pytest.raises(NetworkExistsError):
        repo.create("innate")
    for bad in ("", "a b", "x" * 65, "é"):
        with pytest.raises(ValueError, match="slug"):
            repo.create(bad)
    with pytest.raises(UnknownNameError, match="base network 'nope'"):
        repo.create("other", base="nope")


def test_names_given_as_data_are_invalid_input_not_lookups(
    repo: SqlAlchemyNetworkRepository,
) -> None:
    with pytest.raises(CatalogError, match=r"associations\[1\]\.stimulus") as e:
        repo.create("mine", associations=[RED_STOP, NetworkPair("Purple", "stop", 1.0, "dp")])
    assert not isinstance(e.value, UnknownNameError)  # a 422, not a 404
    with pytest.raises(ValueError, match="strength"):
        repo.create("mine", associations=[NetworkPair("Red", "stop", 1.5, "dp")])
    with pytest.raises(ValueError, match="source"):
        repo.create("mine", associations=[NetworkPair("Red", "stop", 1.0, "magic")])
    with pytest.raises(UnknownNameError):
        repo.get("mine")  # nothing half-made


def test_a_later_association_of_a_pair_replaces_an_earlier_one(
    repo: SqlAlchemyNetworkRepository,
) -> None:
    softer = NetworkPair("Red", "stop", 0.1, "dp")
    made = repo.create("mine", base=None, associations=[RED_STOP, softer])
    assert made.associations == (softer,)


def test_builtin_networks_are_read_only(repo: SqlAlchemyNetworkRepository) -> None:
    writes: list[Callable[[], object]] = [
        lambda: repo.add_association("dp", NetworkPair("Red", "back", 1.0, "dp")),
        lambda: repo.put_association("dp", "Red", "stop", strength=0.1),
        lambda: repo.remove_association("dp", "Red", "stop"),
        lambda: repo.revert("dp", 1),
        lambda: repo.delete("dp"),
        lambda: repo.import_network("dp", [RED_STOP], replace=True),
    ]
    for write in writes:
        with pytest.raises(ReadOnlyNetworkError, match="copy it first"):
            write()
    assert repo.get("dp").version == 1 and len(repo.versions("dp")) == 1


def test_add_association(repo: SqlAlchemyNetworkRepository) -> None:
    repo.create("mine")
    edit = repo.add_association("mine", RED_STOP)

    assert edit.network.version == 2
    assert [(c.stimulus, c.behaviour, c.before, c.after) for c in edit.changes] == [
        ("Red", "stop", None, RED_STOP)
    ]
    with pytest.raises(AssociationExistsError, match="PUT"):
        repo.add_association("mine", RED_STOP)
    with pytest.raises(CatalogError, match="behaviour: unknown behaviour 'fly'"):
        repo.add_association("mine", NetworkPair("Red", "fly", 1.0, "dp"))
    with pytest.raises(UnknownNameError):
        repo.add_association("nope", RED_STOP)


def test_put_inserts_then_updates_keeping_what_it_is_not_given(
    repo: SqlAlchemyNetworkRepository,
) -> None:
    repo.create("mine")
    added = repo.put_association("mine", "Red", "stop", strength=0.5)
    changed = repo.put_association("mine", "Red", "stop", source="expert")

    assert added.changes[0].after == NetworkPair("Red", "stop", 0.5, "dp", False)
    assert changed.changes[0].after == NetworkPair("Red", "stop", 0.5, "expert", False)
    assert changed.network.version == 3
    assert [v.note for v in repo.versions("mine")][1:] == [
        "added Red -> stop",
        "changed Red -> stop",
    ]


def test_put_that_changes_nothing_makes_no_version(repo: SqlAlchemyNetworkRepository) -> None:
    repo.create("mine")
    edit = repo.put_association("mine", "Corner", "leftturn90", strength=1.0)

    assert edit.changes == () and edit.network.version == 1
    assert len(repo.versions("mine")) == 1


def test_put_and_remove_unknown_names_are_lookups(repo: SqlAlchemyNetworkRepository) -> None:
    repo.create("mine")
    with pytest.raises(UnknownNameError, match="stimulus 'Purple'"):
        repo.put_association("mine", "Purple", "stop", strength=1.0)
    with pytest.raises(UnknownNameError, match="behaviour 'fly'"):
        repo.remove_association("mine", "Red", "fly")
    with pytest.raises(UnknownNameError, match="no association Red -> stop"):
        repo.remove_association("mine", "Red", "stop")
    with pytest.raises(ValueError, match="strength"):
        repo.put_association("mine", "Red", "stop", strength=float("nan"))


def test_a_locked_association_changes_only_with_force(repo: SqlAlchemyNetworkRepository) -> None:
    repo.create("mine")
    repo.put_association("mine", "Corner", "leftturn90", locked=True)

    with pytest.raises(LockedAssociationError, match="force=true"):
        repo.put_association("mine", "Corner", "leftturn90", strength=0.2)
    with pytest.raises(LockedAssociationError):
        repo.put_association("mine", "Corner", "leftturn90", locked=False)
    with pytest.raises(LockedAssociationError):
        repo.remove_association("mine", "Corner", "leftturn90")
    assert repo.get("mine").version == 2

    forced = repo.put_association("mine", "Corner", "leftturn90", strength=0.2, force=True)
    assert forced.changes[0].after == NetworkPair("Corner", "leftturn90", 0.2, "innate", True)
    repo.put_association("mine", "Corner", "leftturn90", locked=False, force=True)
    repo.put_association("mine", "Corner", "leftturn90", strength=0.3)
    repo.put_association("mine", "Corner", "leftturn90", locked=True)
    assert repo.remove_association("mine", "Corner", "leftturn90", force=True).network.version == 7


def test_versions_snapshots_and_diff(repo: SqlAlchemyNetworkRepository) -> None:
    repo.create("mine")
    repo.add_association("mine", RED_STOP)
    repo.put_association("mine", "Corner", "leftturn90", strength=0.4)
    repo.remove_association("mine", "Collision", "back", note="no more backing up")

    assert [(v.version, v.association_count) for v in repo.versions("mine")] == [
        (1, 4),
        (2, 5),
        (3, 5),
        (4, 4),
    ]
    v1, v4 = repo.snapshot("mine", 1), repo.snapshot("mine", 4)
    assert v1.associations == repo.get("innate").associations
    assert v4.associations == repo.get("mine").associations and v4.note == "no more backing up"
    changes = {(c.stimulus, c.behaviour): c for c in repo.diff("mine", 1, 4)}
    assert set(changes) == {("Red", "stop"), ("Corner", "leftturn90"), ("Collision", "back")}
    assert changes["Red", "stop"].before is None
    assert changes["Collision", "back"].after is None
    corner = changes["Corner", "leftturn90"]
    assert corner.before is not None and corner.after is not None
    assert (corner.before.strength, corner.after.strength) == (1.0, 0.4)
    assert repo.diff("mine", 2, 2) == ()
    with pytest.raises(UnknownVersionError, match="no version 5"):
        repo.snapshot("mine", 5)
    with pytest.raises(UnknownVersionError):
        repo.diff("mine", 0, 1)


def test_revert_is_a_new_version_and_respects_locks(repo: SqlAlchemyNetworkRepository) -> None:
    first = repo.create("mine", description="v1")
    repo.add_association("mine", RED_STOP)
    repo.put_association("mine", "Corner", "leftturn90", strength=0.1, locked=True)

    with pytest.raises(LockedAssociationError):
        repo.revert("mine", 1)
    reverted = repo.revert("mine", 1, force=True)

    assert reverted.network.version == 4 and reverted.network.associations == first.associations
    assert {(c.stimulus, c.behaviour) for c in reverted.changes} == {
        ("Red", "stop"),
        ("Corner", "leftturn90"),
    }
    assert repo.versions("mine")[-1].note == "reverted to version 1"
    assert repo.revert("mine", 4).changes == ()  # already there: no new version
    assert repo.get("mine").version == 4
    with pytest.raises(UnknownVersionError):
        repo.revert("mine", 9)


def test_history_records_a_version_the_seed_did_not_write(
    repo: SqlAlchemyNetworkRepository, sqlite_engine: Engine
) -> None:
    repo.create("mine")
    with Session(sqlite_engine) as s, s.begin():
        s.execute(delete(NetworkVersionRow))

    assert [(v.version, v.note) for v in repo.versions("innate")] == [(1, SEEDED_NOTE)]
    edit = repo.put_association("mine", "Red", "stop", strength=0.5)
    assert edit.network.version == 2
    assert [(v.version, v.note) for v in repo.versions("mine")] == [
        (1, FIRST_RECORDED_NOTE),
        (2, "added Red -> stop"),
    ]
    assert repo.snapshot("mine", 1).associations == repo.get("innate").associations


def test_import_creates_replaces_and_refuses(repo: SqlAlchemyNetworkRepository) -> None:
    made = repo.import_network("mine", [RED_STOP], description="from a file")
    assert made.created and made.network.version == 1
    assert made.network.associations == (RED_STOP,)
    assert repo.versions("mine")[0].note == "imported"

    with pytest.raises(NetworkExistsError, match="replace"):
        repo.import_network("mine", [])
    locked = NetworkPair("Corner", "leftturn90", 1.0, "dp", locked=True)
    replaced = repo.import_network("mine", [locked], replace=True, note="v2")
    assert not replaced.created and replaced.network.version == 2
    assert replaced.network.description == ""
    assert repo.versions("mine")[-1].note == "v2"
    with pytest.raises(LockedAssociationError):
        repo.import_network("mine", [RED_STOP], replace=True)
    assert repo.import_network("mine", [RED_STOP], replace=True, force=True).network.version == 3
    with pytest.raises(ValueError, match="slug"):
        repo.import_network("no good", [])
    with pytest.raises(CatalogError, match=r"associations\[0\]\.stimulus"):
        repo.import_network("other", [NetworkPair("X", "stop", 1.0, "dp")])


def test_delete_removes_the_network_with_its_rows(
    repo: SqlAlchemyNetworkRepository, sqlite_engine: Engine
) -> None:
    repo.create("mine")
    repo.add_association("mine", RED_STOP)
    with Session(sqlite_engine) as s:
        network_id = s.scalar(select(NetworkRow.id).where(NetworkRow.name == "mine"))

    repo.delete("mine")

    with pytest.raises(UnknownNameError):
        repo.get("mine")
    with pytest.raises(UnknownNameError):
        repo.delete("mine")
    with Session(sqlite_engine) as s:
        for table in (AssociationRow, NetworkVersionRow):
            left = s.scalars(select(table).where(table.network_id == network_id)).all()
            assert left == []
    repo.create("mine")  # the name is free again
    assert repo.versions("mine")[0].version == 1


def test_pairs_are_in_insertion_order(repo: SqlAlchemyNetworkRepository, catalog: Catalog) -> None:
    expected = [(a.stimulus, a.behaviour) for a in catalog.knowledge_set("dp").associations]
    assert [(p.stimulus, p.behaviour) for p in repo.pairs("dp")] == expected
    with pytest.raises(UnknownNameError):
        repo.pairs("nope")


def test_changes_between_sorts_and_classifies() -> None:
    a = {("B", "x"): NetworkPair("B", "x", 1.0, "dp"), ("A", "y"): NetworkPair("A", "y", 1.0, "dp")}
    b = {("B", "x"): NetworkPair("B", "x", 0.5, "dp"), ("C", "z"): NetworkPair("C", "z", 1.0, "dp")}

    got = [(c.stimulus, c.before is None, c.after is None) for c in changes_between(a, b)]

    assert got == [("A", False, True), ("B", False, False), ("C", True, False)]
