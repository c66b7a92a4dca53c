"""One contract for every `RunStore`: the in-memory fake, SQLite and PostgreSQL."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from fakes import InspectableRunStore

from core.errors import CatalogError, StorageError, UnknownNameError, UnknownRunError
from core.ports import (
    BehaviourSpec,
    Checkpoint,
    CommandRecord,
    EpisodeRecord,
    LearningUpdate,
    Mode,
    NetworkPair,
    RewardCommit,
    RewardRecord,
    RunSpec,
    RunStatus,
    RunTotals,
)

NETWORK = (
    NetworkPair("Corner", "leftturn90", 1.0, "innate", locked=True),
    NetworkPair("LeftWall", "leftwallavoid", 1.0, "innate"),
    NetworkPair("Red", "stop", 0.8, "dp"),
)
SPEC = RunSpec(
    condition="dp",
    seed=7,
    episodes=20,
    mode=Mode.REALTIME,
    hz=12.5,
    network="dp",
    params={"eta": 0.2, "epsilon": 0.05},
    world="echo40",
    sensors="path",
)
SLOWER = BehaviourSpec("kp_slow_left", "synthesized", 0.05, 20.0, 3, "constant")


def reward(tick: int, value: float = 1.0, episode: int = 0) -> RewardRecord:
    return RewardRecord(tick=tick, episode=episode, value=value, source="human", note=f"t{tick}")


def edit(tick: int) -> CommandRecord:
    return CommandRecord(tick, "edit_association", {"stimulus": "Red", "behaviour": "stop"})


def episode(n: int, start_tick: int = 0) -> EpisodeRecord:
    return EpisodeRecord(n, "success", None, 100, start_tick, 2, b"\x00trace" + bytes([n]))


def new_run(store: InspectableRunStore) -> int:
    return store.create_run(SPEC, NETWORK)


def test_create_run_stores_spec_network_and_created_status(store: InspectableRunStore) -> None:
    run_id = new_run(store)

    run = store.load_run(run_id)
    assert run.id == run_id
    assert run.spec == SPEC
    assert run.status is RunStatus.CREATED
    assert run.error is None
    assert run.totals == RunTotals(0, 0, 0)
    assert run.checkpoint is None
    assert run.rewards_after == () and run.commands_after == ()
    assert store.network(run_id) == NETWORK
    assert store.ltm(run_id) == {} and store.rltm(run_id) == {}
    assert store.episodes(run_id) == [] and store.rewards(run_id) == []


def test_create_run_with_defaults_and_no_network(store: InspectableRunStore) -> None:
    spec = RunSpec("innate", seed=2**40)

    run_id = store.create_run(spec, ())

    assert store.load_run(run_id).spec == spec
    assert store.network(run_id) == ()


def test_create_run_params_come_back_as_json(store: InspectableRunStore) -> None:
    spec = RunSpec("kp", 1, params={"sensors": ("signal", "camera"), "nested": {"a": 1}})

    run_id = store.create_run(spec, ())

    assert store.load_run(run_id).spec.params == {
        "sensors": ["signal", "camera"],
        "nested": {"a": 1},
    }


def test_create_run_ids_increase_and_list_runs_is_by_id(store: InspectableRunStore) -> None:
    ids = [new_run(store) for _ in range(3)]

    assert ids == sorted(ids) and len(set(ids)) == 3
    assert [r.id for r in store.list_runs()] == ids
    assert all(r.spec == SPEC for r in store.list_runs())


def test_create_run_with_an_unknown_name_raises_and_stores_nothing(
    store: InspectableRunStore,
) -> None:
    with pytest.raises(UnknownNameError):
        store.create_run(SPEC, (NetworkPair("Nowhere", "stop", 1.0, "dp"),))

    assert store.list_runs() == []


@pytest.mark.parametrize(
    "status", [RunStatus.RUNNING, RunStatus.PAUSED, RunStatus.FINISHED, RunStatus.STOPPED]
)
def test_set_status_changes_status(store: InspectableRunStore, status: RunStatus) -> None:
    run_id = new_run(store)

    store.set_status(run_id, status)

    assert store.load_run(run_id).status is status


def test_set_status_stores_and_clears_the_error(store: InspectableRunStore) -> None:
    run_id = new_run(store)

    store.set_status(run_id, RunStatus.FAILED, "disk full")
    failed = store.load_run(run_id)
    store.set_status(run_id, RunStatus.INTERRUPTED)

    assert (failed.status, failed.error) == (RunStatus.FAILED, "disk full")
    assert store.load_run(run_id).error is None


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


def test_log_command_stores_command_and_its_update(store: InspectableRunStore) -> None:
    run_id = new_run(store)

    first = store.log_command(
        run_id,
        edit(5),
        LearningUpdate(network_upserts=(NetworkPair("Red", "stop", 0.3, "designed", True),)),
    )
    second = store.log_command(
        run_id, edit(6), LearningUpdate(network_removals=(("Corner", "leftturn90"),))
    )

    assert first < second
    assert [(c.id, c.record) for c in store.commands(run_id)] == [
        (first, edit(5)),
        (second, edit(6)),
    ]
    assert store.network(run_id) == (
        NETWORK[1],
        NetworkPair("Red", "stop", 0.3, "designed", True),
    )


def test_end_episode_stores_episode_checkpoint_and_totals(store: InspectableRunStore) -> None:
    run_id = new_run(store)

    store.end_episode(run_id, episode(0), Checkpoint(0, 100, b"state-0"), RunTotals(1, 1, 100))
    store.end_episode(run_id, episode(1, 100), Checkpoint(1, 250, b"state-1"), RunTotals(2, 1, 250))

    run = store.load_run(run_id)
    assert run.checkpoint == Checkpoint(1, 250, b"state-1")
    assert run.totals == RunTotals(2, 1, 250)
    assert store.episodes(run_id) == [episode(0), episode(1, 100)]


def test_end_episode_twice_for_one_episode_raises_and_keeps_the_first(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    store.end_episode(run_id, episode(0), Checkpoint(0, 100, b"first"), RunTotals(1, 1, 100))

    with pytest.raises(StorageError):
        store.end_episode(run_id, episode(0), Checkpoint(0, 120, b"again"), RunTotals(9, 9, 9))

    run = store.load_run(run_id)
    assert run.checkpoint == Checkpoint(0, 100, b"first")
    assert run.totals == RunTotals(1, 1, 100)
    assert store.episodes(run_id) == [episode(0)]


def test_load_run_without_checkpoint_returns_the_whole_log(store: InspectableRunStore) -> None:
    run_id = new_run(store)
    r1 = store.log_reward(run_id, reward(30))
    c1 = store.log_command(run_id, edit(10), LearningUpdate())
    r2 = store.log_reward(run_id, reward(20))
    store.apply_reward(run_id, r2, LearningUpdate(), 2)

    run = store.load_run(run_id)

    assert [(r.id, r.applied) for r in run.rewards_after] == [(r1, False), (r2, True)]
    assert [c.id for c in run.commands_after] == [c1]


def test_load_run_returns_only_rewards_and_commands_after_the_checkpoint(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    store.log_reward(run_id, reward(50))
    at_checkpoint = store.log_reward(run_id, reward(100))
    store.log_command(run_id, edit(99), LearningUpdate())
    store.end_episode(run_id, episode(0), Checkpoint(0, 100, b"s"), RunTotals(1, 0, 100))
    after = [store.log_reward(run_id, reward(t)) for t in (101, 150)]
    command = store.log_command(run_id, edit(101), LearningUpdate())

    run = store.load_run(run_id)

    assert [r.id for r in run.rewards_after] == after
    assert at_checkpoint not in {r.id for r in run.rewards_after}
    assert [(c.id, c.record) for c in run.commands_after] == [(command, edit(101))]
    assert len(store.rewards(run_id)) == 4


def test_runs_keep_their_learning_apart(store: InspectableRunStore) -> None:
    a, b = new_run(store), new_run(store)
    ra = store.log_reward(a, reward(1))

    store.apply_reward(
        a,
        ra,
        LearningUpdate(ltm={("Red", "stop"): 0.9}, network_removals=(("Red", "stop"),)),
        1,
    )

    assert store.ltm(b) == {} and store.network(b) == NETWORK
    assert store.ltm(a) == {("Red", "stop"): 0.9}


def test_the_service_reads_page_and_summarise_what_is_stored(
    store: InspectableRunStore,
) -> None:
    run_id = new_run(store)
    ids = [store.log_reward(run_id, reward(t)) for t in (10, 20, 30)]
    for n in range(3):
        store.end_episode(
            run_id, episode(n, 100 * n), Checkpoint(n, 100 * n + 50, b"s"), RunTotals(n + 1, 1, 50)
        )
    store.set_status(run_id, RunStatus.RUNNING)
    other = new_run(store)

    summary = store.run_summary(run_id)
    assert (summary.id, summary.status, summary.totals) == (
        run_id,
        RunStatus.RUNNING,
        RunTotals(3, 1, 50),
    )
    assert summary.checkpoint is None and summary.rewards_after == () == summary.commands_after
    page, total = store.run_summaries(offset=1, limit=5)
    assert total == 2 and [r.id for r in page] == [other]
    rewards, count = store.rewards_page(run_id, offset=1, limit=1)
    assert count == 3 and [r.id for r in rewards] == ids[1:2]
    assert store.episode(run_id, 1) == episode(1, 100)
    assert store.episode(run_id, 7) is None
    assert [e.episode for e in store.episode_summaries(run_id)] == [0, 1, 2]
    assert all(e.trace == b"" for e in store.episode_summaries(run_id))
    episodes, many = store.episode_summaries_page(run_id, offset=2, limit=10)
    assert many == 3 and [(e.episode, e.trace) for e in episodes] == [(2, b"")]

    assert store.interrupt_active() == 1
    assert store.run_summary(run_id).status is RunStatus.INTERRUPTED
    assert store.run_summary(other).status is RunStatus.CREATED


UNSTORABLE = {"nul": "a\x00b", "high surrogate": "\ud800", "low surrogate": "note \udfff"}
"""Text no supported database stores (PostgreSQL's text holds no NUL; a surrogate alone is
not UTF-8): every store refuses it the same way, before writing anything."""
STORABLE = (
    "tab\t newline\n \x01\x1f\x7f \ud7ff\ue000\ufffd\uffff \U0001f600\U0010ffff é中 '\"; -- \\ %s ?"
)
"""Every other kind of character, those next to the refused ones included."""


def noted(note: str, tick: int = 5) -> RewardRecord:
    return RewardRecord(tick=tick, episode=0, value=1.0, source="trainer", note=note)


@pytest.mark.parametrize("text", UNSTORABLE.values(), ids=UNSTORABLE.keys())
def test_text_no_database_stores_is_refused_and_changes_nothing(
    store: InspectableRunStore, text: str
) -> None:
    run_id = new_run(store)
    kept = store.log_reward(run_id, reward(1))
    learned = LearningUpdate(ltm={("Red", "stop"): 0.5})
    writes: list[Callable[[], object]] = [
        lambda: store.log_reward(run_id, noted(text)),
        lambda: store.record_reward(run_id, noted(text), learned, 1),
        lambda: store.commit_rewards(run_id, (RewardCommit(noted(text), learned, 1),)),
        lambda: store.set_status(run_id, RunStatus.FAILED, text),
    ]

    for write in writes:
        with pytest.raises(ValueError, match="cannot be stored"):
            write()

    assert [r.id for r in store.rewards(run_id)] == [kept]
    assert store.ltm(run_id) == {}
    run = store.load_run(run_id)
    assert (run.status, run.error) == (RunStatus.CREATED, None)
    later = store.log_reward(run_id, reward(2))  # the store goes on as before
    assert [r.id for r in store.rewards(run_id)] == [kept, later]


def test_any_other_text_is_stored_and_read_back_exactly(store: InspectableRunStore) -> None:
    run_id = new_run(store)

    logged = store.log_reward(run_id, noted(STORABLE))
    recorded = store.record_reward(run_id, noted(STORABLE[::-1], 6), LearningUpdate(), 0)
    store.set_status(run_id, RunStatus.FAILED, STORABLE)

    notes = {r.id: r.record.note for r in store.rewards(run_id)}
    assert notes == {logged: STORABLE, recorded: STORABLE[::-1]}
    assert store.load_run(run_id).error == STORABLE


UNKNOWN = 987_654
CALLS: dict[str, Callable[[InspectableRunStore], object]] = {
    "load_run": lambda s: s.load_run(UNKNOWN),
    "set_status": lambda s: s.set_status(UNKNOWN, RunStatus.RUNNING),
    "log_reward": lambda s: s.log_reward(UNKNOWN, reward(1)),
    "apply_reward": lambda s: s.apply_reward(UNKNOWN, 1, LearningUpdate(), 0),
    "log_command": lambda s: s.log_command(UNKNOWN, edit(1), LearningUpdate()),
    "end_episode": lambda s: s.end_episode(
        UNKNOWN, episode(0), Checkpoint(0, 1, b""), RunTotals(1, 0, 1)
    ),
    "ltm": lambda s: s.ltm(UNKNOWN),
    "record_reward": lambda s: s.record_reward(UNKNOWN, reward(1), LearningUpdate(), 0),
    "rltm": lambda s: s.rltm(UNKNOWN),
    "network": lambda s: s.network(UNKNOWN),
    "behaviours": lambda s: s.behaviours(UNKNOWN),
    "rewards": lambda s: s.rewards(UNKNOWN),
    "commands": lambda s: s.commands(UNKNOWN),
    "episodes": lambda s: s.episodes(UNKNOWN),
    "run_summary": lambda s: s.run_summary(UNKNOWN),
    "rewards_page": lambda s: s.rewards_page(UNKNOWN),
    "episode": lambda s: s.episode(UNKNOWN, 0),
    "episode_summaries": lambda s: s.episode_summaries(UNKNOWN),
    "episode_summaries_page": lambda s: s.episode_summaries_page(UNKNOWN),
}


@pytest.mark.parametrize("call", CALLS.values(), ids=CALLS.keys())
def test_an_unknown_run_raises_unknown_run_error(
    store: InspectableRunStore, call: Callable[[InspectableRunStore], object]
) -> None:
    new_run(store)

    with pytest.raises(UnknownRunError):
        call(store)
