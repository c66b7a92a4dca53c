"""One contract for every `RunStore`: the in-memory fake, SQLite and PostgreSQL."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from contracthelpers import NETWORK, SPEC, edit, episode, new_run, reward
from fakes import InspectableRunStore

from core.errors import StorageError, UnknownNameError, UnknownRunError
from core.ports import (
    Checkpoint,
    LearningUpdate,
    NetworkPair,
    RewardCommit,
    RewardRecord,
    RunSpec,
    RunStatus,
    RunTotals,
)


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
