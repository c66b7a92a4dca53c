"""The run store's contract, its reward log: logged, applied, recorded and committed in batches.

Every implementation passes it (`store` in tests/conftest.py): memory, SQLite, PostgreSQL.
"""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime, timedelta
from functools import partial

import pytest
from contracthelpers import NETWORK, SLOWER, edit, new_run, reward
from fakes import InspectableRunStore

from core.errors import CatalogError, StorageError, UnknownNameError, UnknownRunError
from core.ports import (
    BehaviourSpec,
    LearningUpdate,
    NetworkPair,
    RewardCommit,
    RewardRecord,
)
from server.persistence import SqlAlchemyRunStore
from server.persistence.sqlalchemy_repo import GroupedWrite


def test_log_reward_returns_increasing_ids_in_log_order(store: InspectableRunStore) -> None:
    a, b = new_run(store), new_run(store)

    ids = [
        store.log_reward(a, reward(10)),
        store.log_reward(b, reward(11)),
        store.log_reward(a, reward(5, -1.0)),
    ]

    assert ids == sorted(ids) and len(set(ids)) == 3
    assert [(r.id, r.record, r.applied, r.credited) for r in store.rewards(a)] == [
        (ids[0], reward(10), False, 0),
        (ids[2], reward(5, -1.0), False, 0),
    ]
    assert [r.id for r in store.rewards(b)] == [ids[1]]


def test_rewards_logged_together_are_each_answered_their_own(
    store: InspectableRunStore,
) -> None:
    """Rewards several runs' threads log at once share a transaction (SQL stores): a
    reward of a missing run or with text no database stores is refused alone."""
    if not isinstance(store, SqlAlchemyRunStore):
        pytest.skip("the memory store writes no transactions")
    a, b = new_run(store), new_run(store)
    unstorable = replace(reward(12), note="a\x00b")

    def logs(*rewards: tuple[int, RewardRecord]) -> list[GroupedWrite]:
        return [("logging", partial(store._log_reward, *r)) for r in rewards]

    answers = store._write_together(logs((a, reward(10)), (999_999, reward(11)), (b, unstorable)))
    again = store._write_together(logs((b, reward(13)), (a, reward(14))))

    assert isinstance(answers[1], UnknownRunError) and isinstance(answers[2], ValueError)
    assert [r.id for r in store.rewards(a)] == [answers[0], again[1]]
    assert [(r.id, r.record) for r in store.rewards(b)] == [(again[0], reward(13))]
    assert store.log_reward(b, reward(15)) > max(i for i in again if isinstance(i, int))


def test_apply_reward_marks_it_applied_and_stores_ltm_and_rltm(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    first = store.log_reward(run_id, reward(10))
    second = store.log_reward(run_id, reward(20))

    store.apply_reward(
        run_id,
        first,
        LearningUpdate(
            ltm={("Red", "stop"): 0.6, ("Green", "goforward3"): 0.55},
            rltm={("Obstacle_M_M", "leftturn45"): 0.7},
        ),
        credited=3,
    )

    rewards = store.rewards(run_id)
    assert [(r.id, r.applied, r.credited) for r in rewards] == [
        (first, True, 3),
        (second, False, 0),
    ]
    assert store.ltm(run_id) == {("Red", "stop"): 0.6, ("Green", "goforward3"): 0.55}
    assert store.rltm(run_id) == {("Obstacle_M_M", "leftturn45"): 0.7}


def test_apply_reward_overwrites_reliabilities_it_touches(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    first = store.log_reward(run_id, reward(1))
    second = store.log_reward(run_id, reward(2))
    store.apply_reward(
        run_id, first, LearningUpdate(ltm={("Red", "stop"): 0.6, ("Left", "rightturn15"): 0.5}), 1
    )

    store.apply_reward(run_id, second, LearningUpdate(ltm={("Red", "stop"): 0.65625}), 1)

    assert store.ltm(run_id) == {("Red", "stop"): 0.65625, ("Left", "rightturn15"): 0.5}


def test_apply_reward_upserts_and_removes_network_pairs(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    reward_id = store.log_reward(run_id, reward(3))

    store.apply_reward(
        run_id,
        reward_id,
        LearningUpdate(
            network_upserts=(
                NetworkPair("Red", "stop", 0.9, "learned", locked=True),
                NetworkPair("Obstacle_M_M", "leftturn45", 0.5, "kp"),
            ),
            network_removals=(("LeftWall", "leftwallavoid"), ("Yellow", "stop")),
        ),
        credited=1,
    )

    assert store.network(run_id) == (
        NETWORK[0],
        NetworkPair("Red", "stop", 0.9, "learned", locked=True),
        NetworkPair("Obstacle_M_M", "leftturn45", 0.5, "kp"),
    )


def test_apply_reward_stores_synthesised_behaviours_it_names(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    other = new_run(store)
    reward_id = store.log_reward(run_id, reward(3))

    store.apply_reward(
        run_id,
        reward_id,
        LearningUpdate(
            ltm={("Obstacle_L_M", SLOWER.name): 0.5},
            rltm={("Obstacle_L_M", SLOWER.name): 0.5},
            network_upserts=(NetworkPair("Obstacle_L_M", SLOWER.name, 0.5, "kp"),),
            behaviours_added=(SLOWER,),
        ),
        credited=1,
    )

    assert store.behaviours(run_id) == (SLOWER,)
    assert store.network(run_id)[-1].behaviour == SLOWER.name
    assert store.ltm(run_id) == {("Obstacle_L_M", SLOWER.name): 0.5}
    assert store.behaviours(other) == ()
    with pytest.raises(UnknownNameError):
        store.log_command(other, edit(4), LearningUpdate(ltm={("Red", SLOWER.name): 0.5}))


def test_apply_reward_adding_a_behaviour_again_updates_it(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    first = store.log_reward(run_id, reward(1))
    second = store.log_reward(run_id, reward(2))
    faster = BehaviourSpec(SLOWER.name, "synthesized", 0.1, 20.0, 3, "constant")
    store.apply_reward(run_id, first, LearningUpdate(behaviours_added=(SLOWER,)), 0)

    store.apply_reward(run_id, second, LearningUpdate(behaviours_added=(faster,)), 0)

    assert store.behaviours(run_id) == (faster,)


def test_apply_reward_rejects_a_synthesised_name_of_the_catalogue(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    reward_id = store.log_reward(run_id, reward(1))
    clash = BehaviourSpec("stop", "synthesized", 0.0, 0.0, 1, "constant")

    with pytest.raises(CatalogError):
        store.apply_reward(run_id, reward_id, LearningUpdate(behaviours_added=(clash,)), 0)

    assert store.behaviours(run_id) == ()


def test_apply_reward_with_an_unknown_name_changes_nothing(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    reward_id = store.log_reward(run_id, reward(1))
    update = LearningUpdate(
        ltm={("Red", "stop"): 0.6},
        network_upserts=(NetworkPair("Red", "teleport", 1.0, "learned"),),
        behaviours_added=(SLOWER,),
    )

    with pytest.raises(UnknownNameError):
        store.apply_reward(run_id, reward_id, update, 1)

    assert store.ltm(run_id) == {}
    assert store.network(run_id) == NETWORK
    assert store.behaviours(run_id) == ()
    assert not store.rewards(run_id)[0].applied


def test_apply_reward_of_an_unknown_reward_raises_storage_error(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    other = new_run(store)
    others_reward = store.log_reward(other, reward(1))

    with pytest.raises(StorageError):
        store.apply_reward(run_id, others_reward + 1000, LearningUpdate(), 0)
    with pytest.raises(StorageError):
        store.apply_reward(run_id, others_reward, LearningUpdate(ltm={("Red", "stop"): 1.0}), 0)

    assert not store.rewards(other)[0].applied
    assert store.ltm(run_id) == {}


def test_record_reward_logs_it_applied_with_its_learning(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    first = store.log_reward(run_id, reward(3))
    second = store.record_reward(
        run_id, reward(5, value=0.5), LearningUpdate(ltm={("Red", "stop"): 0.05}), credited=2
    )

    assert second > first
    assert [(r.id, r.record.tick, r.applied, r.credited) for r in store.rewards(run_id)] == [
        (first, 3, False, 0),
        (second, 5, True, 2),
    ]
    assert store.ltm(run_id) == {("Red", "stop"): 0.05}


def test_record_reward_with_an_unknown_name_stores_nothing(store: InspectableRunStore) -> None:
    run_id = new_run(store)

    with pytest.raises(UnknownNameError):
        store.record_reward(
            run_id, reward(1), LearningUpdate(ltm={("Red", "teleport"): 0.1}), credited=1
        )

    assert store.rewards(run_id) == []
    assert store.ltm(run_id) == {}


def test_commit_rewards_applies_and_records_them_in_order(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    trainers = store.log_reward(run_id, reward(3))
    made = NetworkPair("Red", SLOWER.name, 0.4, "kp")

    ids = store.commit_rewards(
        run_id,
        (
            RewardCommit(reward(3), LearningUpdate(ltm={("Red", "stop"): 0.1}), 2, trainers),
            RewardCommit(
                reward(5, value=0.5),
                LearningUpdate(ltm={("Red", "stop"): 0.2}, behaviours_added=(SLOWER,)),
                1,
            ),
            # A later reward names the behaviour an earlier one in the batch added.
            RewardCommit(
                reward(8),
                LearningUpdate(rltm={("Red", SLOWER.name): 0.4}, network_upserts=(made,)),
                3,
            ),
        ),
    )

    assert ids[0] == trainers and trainers < ids[1] < ids[2]
    assert [(r.id, r.record.tick, r.applied, r.credited) for r in store.rewards(run_id)] == [
        (trainers, 3, True, 2),
        (ids[1], 5, True, 1),
        (ids[2], 8, True, 3),
    ]
    assert store.ltm(run_id) == {("Red", "stop"): 0.2}
    assert store.rltm(run_id) == {("Red", SLOWER.name): 0.4}
    assert store.behaviours(run_id) == (SLOWER,)
    assert made in store.network(run_id)
    assert store.commit_rewards(run_id, ()) == ()


def test_a_batch_leaves_storage_as_committing_each_reward_in_turn(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    logged = [store.log_reward(run_id, reward(t)) for t in (2, 3, 4)]
    strong = NetworkPair("Red", "stop", 0.6, "learned")
    again = NetworkPair("Red", "stop", 0.7, "learned")
    other = NetworkPair("Green", "stop", 0.5, "learned")
    updates = (
        LearningUpdate(ltm={("Red", "stop"): 0.3}, network_upserts=(strong, other)),
        LearningUpdate(ltm={("Red", "stop"): 0.1}, network_removals=(("Red", "stop"),)),
        LearningUpdate(ltm={("Green", "stop"): 0.4}, network_upserts=(again,)),
        LearningUpdate(network_removals=(("Green", "stop"),)),
    )

    ids = store.commit_rewards(
        run_id,
        (
            RewardCommit(reward(2), updates[0], 1, logged[0]),
            RewardCommit(reward(3), updates[1], 2, logged[1]),
            RewardCommit(reward(3), updates[2], 3),
            RewardCommit(reward(4), updates[3], 4, logged[2]),
        ),
    )

    assert ids[:2] == tuple(logged[:2]) and ids[3] == logged[2] and ids[2] > logged[2]
    assert [(r.id, r.applied, r.credited) for r in store.rewards(run_id)] == [
        (logged[0], True, 1),
        (logged[1], True, 2),
        (logged[2], True, 4),
        (ids[2], True, 3),
    ]
    assert store.ltm(run_id) == {("Red", "stop"): 0.1, ("Green", "stop"): 0.4}
    assert again in store.network(run_id)
    assert all((p.stimulus, p.behaviour) != ("Green", "stop") for p in store.network(run_id))


def test_a_batch_naming_a_reward_the_log_lacks_stores_nothing(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    logged = [store.log_reward(run_id, reward(t)) for t in (2, 3)]

    with pytest.raises(StorageError, match=f"no reward {logged[1] + 100}"):
        store.commit_rewards(
            run_id,
            (
                RewardCommit(reward(2), LearningUpdate(ltm={("Red", "stop"): 0.2}), 1, logged[0]),
                RewardCommit(reward(3), LearningUpdate(), 1, logged[1] + 100),
                RewardCommit(reward(3), LearningUpdate(), 1, logged[1]),
            ),
        )

    assert [(r.id, r.applied) for r in store.rewards(run_id)] == [
        (logged[0], False),
        (logged[1], False),
    ]
    assert store.ltm(run_id) == {}


def test_commit_rewards_is_all_or_nothing(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    trainers = store.log_reward(run_id, reward(3))
    bad = LearningUpdate(ltm={("Red", "teleport"): 0.1})

    with pytest.raises(UnknownNameError):
        store.commit_rewards(
            run_id,
            (
                RewardCommit(reward(3), LearningUpdate(ltm={("Red", "stop"): 0.1}), 1, trainers),
                RewardCommit(reward(4), LearningUpdate(ltm={("Red", "stop"): 0.3}), 1),
                RewardCommit(reward(5), bad, 1),
            ),
        )

    assert [(r.id, r.applied) for r in store.rewards(run_id)] == [(trainers, False)]
    assert store.ltm(run_id) == {}
    with pytest.raises(UnknownRunError):
        store.commit_rewards(run_id + 1000, (RewardCommit(reward(1), LearningUpdate(), 0),))


def test_the_reward_log_pages_say_when_each_reward_was_logged(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    before = datetime.now(UTC).replace(microsecond=0)  # SQLite keeps whole seconds
    ids = [store.log_reward(run_id, reward(t)) for t in (3, 4)]
    after = datetime.now(UTC)

    page, count = store.rewards_page(run_id)

    assert count == 2 and [r.id for r in page] == ids
    for r in page:
        assert r.at is not None and r.at.tzinfo is not None
        assert before <= r.at <= after + timedelta(seconds=1)


def test_the_log_keeps_a_reward_s_seen_tick_and_window(store: InspectableRunStore) -> None:
    """Logged on arrival (a trainer's) or recorded applied in a batch, on every store."""
    run_id = new_run(store)
    seen = replace(
        reward(30), tick_seen=25, seen_episode=1, window=(-15, 23), records=((20, 1, 2), (21, 1, 3))
    )
    plain = reward(31)
    logged = store.log_reward(run_id, seen)
    (recorded,) = store.commit_rewards(
        run_id, (RewardCommit(replace(seen, tick=32, uid="b"), LearningUpdate(), 4),)
    )
    store.log_reward(run_id, plain)

    assert [r.record for r in store.rewards(run_id)] == [
        seen,
        replace(seen, tick=32, uid="b"),
        plain,
    ]
    page, _ = store.rewards_page(run_id)
    assert [(r.id, r.record.tick_seen, r.record.window) for r in page] == [
        (logged, 25, (-15, 23)),
        (recorded, 25, (-15, 23)),
        (page[2].id, None, None),
    ]
