"""The behaviour network: locks and designed sources keep learning out."""

from __future__ import annotations

import pytest

from core.brain.catalog import Catalog, Source
from core.brain.network import Association, BehaviourNetwork
from core.errors import LockedAssociationError


def make(*associations: Association) -> BehaviourNetwork:
    return BehaviourNetwork(5, associations)


def test_put_adds_and_replaces_unlocked() -> None:
    net = make()
    net.put(Association(1, 2, 0.4, "learned"))
    net.put(Association(1, 2, 0.9, "dp"))
    assert net.get(1, 2) == Association(1, 2, 0.9, "dp")
    assert len(net) == 1
    assert net.version == 2


def test_put_over_a_locked_association_needs_force() -> None:
    locked = Association(1, 2, 1.0, "dp", locked=True)
    net = make(locked)
    with pytest.raises(LockedAssociationError, match="1->2 is locked"):
        net.put(Association(1, 2, 0.1, "learned"))
    assert net.get(1, 2) == locked
    assert net.version == 0
    net.put(Association(1, 2, 0.1, "dp"), force=True)
    assert net.get(1, 2) == Association(1, 2, 0.1, "dp")


def test_remove_respects_locks() -> None:
    net = make(Association(0, 0, 1.0, "dp", locked=True), Association(0, 1, 0.6, "learned"))
    assert net.remove(0, 1) is True
    assert net.remove(0, 1) is False
    assert net.remove(3, 3) is False
    with pytest.raises(LockedAssociationError):
        net.remove(0, 0)
    assert net.get(0, 0) is not None
    assert net.remove(0, 0, force=True) is True
    assert len(net) == 0


def test_learn_adds_a_new_learned_association() -> None:
    net = make()
    assert net.learn(2, 3, 0.6, "learned") is True
    assert net.get(2, 3) == Association(2, 3, 0.6, "learned")
    assert net.strongest(2) == 0.6
    assert net.learn(2, 3, 0.6, "learned") is False  # nothing changed
    # KP never relabels a pair LTM learning owns (nor the reverse).
    assert net.learn(2, 3, 0.7, "kp") is False
    assert net.get(2, 3) == Association(2, 3, 0.6, "learned")
    assert net.learn(2, 3, 0.7, "learned") is True
    assert net.get(2, 3) == Association(2, 3, 0.7, "learned")
    assert net.version == 2


@pytest.mark.parametrize("source", ["innate", "dp", "expert", "designed"])
def test_learn_never_overwrites_a_designed_association(source: Source) -> None:
    designed = Association(1, 1, 1.0, source)
    net = make(designed)
    assert net.learn(1, 1, 0.55, "learned") is False
    assert net.get(1, 1) == designed
    assert net.version == 0


def test_learn_never_overwrites_a_locked_learned_association() -> None:
    locked = Association(1, 1, 0.9, "learned", locked=True)
    net = make(locked)
    assert net.learn(1, 1, 0.2, "learned") is False
    assert net.get(1, 1) == locked


def test_releasers_strongest_and_iteration() -> None:
    a, b, c = (
        Association(0, 1, 0.3, "learned"),
        Association(0, 2, 0.8, "dp"),
        Association(4, 0, 1.0, "innate"),
    )
    net = make(a, b, c)
    assert set(net.releasers(0)) == {a, b}
    assert list(net.releasers(1)) == []
    assert net.strongest(0) == 0.8
    assert net.strongest(1) == 0.0
    assert set(net) == {a, b, c}


def test_copy_is_independent() -> None:
    net = make(Association(0, 1, 0.3, "learned"))
    twin = net.copy()
    twin.learn(0, 1, 0.9, "learned")
    twin.put(Association(2, 2, 1.0, "dp"))
    assert net.get(0, 1) == Association(0, 1, 0.3, "learned")
    assert net.get(2, 2) is None
    assert len(twin) == 2


def test_from_specs_resolves_names(catalog: Catalog) -> None:
    specs = catalog.knowledge_set("innate").associations
    net = BehaviourNetwork.from_specs(catalog, specs)
    corner = catalog.stimulus("Corner").id
    turn = catalog.behaviour("leftturn90").id
    assert net.get(corner, turn) == Association(corner, turn, 1.0, "innate")
    assert len(net) == len(specs)
