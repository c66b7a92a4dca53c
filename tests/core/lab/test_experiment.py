"""Experiments: determinism across processes, failed tasks, and the summary statistics."""

from __future__ import annotations

import functools
import math
import os
import signal
from pathlib import Path
from typing import Any

import pytest

import core.lab.experiment
from core.errors import UnknownNameError
from core.events import Outcome
from core.lab.experiment import (
    WORKER_DIED,
    LocalBackend,
    Task,
    TaskResult,
    episodes_to_criterion,
    expected_cost,
    experiment_tasks,
    mean_ci,
    parse_conditions,
    run_experiment,
    run_task,
    run_tasks,
    summarise,
    t_quantile_975,
)
from core.run.conditions import Condition
from core.run.runner import RunSummary
from core.run.runner import run as real_run
from core.run.setup import Setup


@pytest.fixture(scope="module")
def serial() -> list[TaskResult]:
    return run_experiment(["kp", "rp"], [0, 1], 4, jobs=1)


def test_results_are_the_same_whatever_the_number_of_jobs(serial: list[TaskResult]) -> None:
    parallel = run_experiment(["kp", "rp"], [0, 1], 4, jobs=2)
    assert [r.task for r in parallel] == [r.task for r in serial]
    for a, b in zip(serial, parallel, strict=True):
        assert a.ok and b.ok, (a.error, b.error)
        assert a.episodes == b.episodes
        assert a.ticks == b.ticks
        assert a.ltm == b.ltm
        assert a.rltm == b.rltm


def test_results_come_in_condition_then_seed_order(serial: list[TaskResult]) -> None:
    setup = Setup().resolved()  # the defaults, named, so results say where they ran
    assert setup.world and setup.sensors
    assert [r.task for r in serial] == [
        Task("kp", 0, 4, setup=setup),
        Task("kp", 1, 4, setup=setup),
        Task("rp", 0, 4, setup=setup),
        Task("rp", 1, 4, setup=setup),
    ]
    for r in serial:
        assert [e.episode for e in r.episodes] == [0, 1, 2, 3]
        assert r.ticks == sum(e.ticks for e in r.episodes)


def test_reliabilities_are_camera_pairs_in_0_1(serial: list[TaskResult]) -> None:
    for r in serial:
        for k, v in (r.ltm | r.rltm).items():
            stimulus, behaviour = k.split("/", 1)
            assert stimulus.startswith("Obstacle_"), k
            assert behaviour
            assert 0.0 < v <= 1.0
        if r.task.condition == "rp":
            assert r.rltm == {}, "only KP has an RLTM"


def test_on_result_sees_every_task(serial: list[TaskResult]) -> None:
    seen: list[TaskResult] = []
    results = run_experiment(["kp", "rp"], [0, 1], 4, jobs=1, on_result=seen.append)
    assert seen == results == serial


def test_a_failing_task_is_returned_with_its_error_and_the_others_survive(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def run(condition: Condition, seed: int, episodes: int, **kw: Any) -> RunSummary:
        if condition.name == "rp" and seed == 1:
            raise RuntimeError("the robot fell off the table")
        return real_run(condition, seed, episodes, **kw)

    monkeypatch.setattr(core.lab.experiment, "run", run)
    results = run_experiment(["kp", "rp"], [0, 1], 2, jobs=1)
    failed = [r for r in results if not r.ok]
    assert [(r.task.condition, r.task.seed) for r in failed] == [("rp", 1)]
    error = failed[0].error
    assert error is not None
    assert error.startswith("RuntimeError: the robot fell off the table")
    assert "Traceback" in error
    assert failed[0].episodes == ()
    for r in results:
        if r.ok:
            assert len(r.episodes) == 2
    summary = summarise(results, ["kp", "rp"])
    assert summary["kp"]["seeds"] == 2
    assert summary["rp"]["seeds"] == 1


def kill_worker(task: Task, doomed: Task, once: Path | None = None) -> TaskResult:
    """`run_task`, except that `doomed` kills its worker process (every time, or the first)."""
    if task == doomed and (once is None or not once.exists()):
        if once is not None:
            once.touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return run_task(task)


TASKS = [Task(c, s, 2) for c in ("kp", "rp") for s in range(4)]


def test_a_task_that_kills_its_worker_fails_alone_and_the_others_survive() -> None:
    doomed = Task("rp", 1, 2)
    results = run_tasks(TASKS, LocalBackend(2), fn=functools.partial(kill_worker, doomed=doomed))
    assert [r.task for r in results] == TASKS
    assert [r.task for r in results if not r.ok] == [doomed]
    assert results[TASKS.index(doomed)].error == WORKER_DIED
    serial = {r.task: r for r in run_tasks([t for t in TASKS if t != doomed], LocalBackend(1))}
    for r in results:
        if r.task != doomed:
            assert r == serial[r.task]


def test_a_worker_killed_once_costs_nothing(tmp_path: Path) -> None:
    """A worker killed from outside (the OOM killer, a user): its tasks are simply run again."""
    fn = functools.partial(kill_worker, doomed=TASKS[2], once=tmp_path / "killed")
    results = run_tasks(TASKS, LocalBackend(2), fn=fn)
    assert (tmp_path / "killed").exists()
    assert all(r.ok for r in results)
    assert results == run_tasks(TASKS, LocalBackend(1))


def test_run_task_reports_an_unknown_condition_as_an_error() -> None:
    r = run_task(Task("nope", 0, 1))
    assert not r.ok
    assert r.error is not None
    assert r.error.startswith("UnknownNameError")


def test_summarise_a_condition_whose_every_task_failed() -> None:
    results = [TaskResult(Task("kp", 0, 3), error="boom")]
    assert summarise(results, ["kp"]) == {"kp": {"seeds": 0}}


def test_summarise_figures_match_the_episodes(serial: list[TaskResult]) -> None:
    summary = summarise(serial, ["kp", "rp"])
    for name in ("kp", "rp"):
        s = summary[name]
        rs = [r for r in serial if r.task.condition == name]
        rates = [sum(e.outcome is Outcome.SUCCESS for e in r.episodes) / 4 for r in rs]
        assert s["seeds"] == 2
        assert s["episodes"] == 4
        assert s["success_rate"] == mean_ci(rates)
        assert s["success_by_seed"] == [
            [int(e.outcome is Outcome.SUCCESS) for e in r.episodes] for r in rs
        ]
        assert s["success_curve"] == pytest.approx(
            [sum(col) / 2 for col in zip(*s["success_by_seed"], strict=True)]
        )
        assert s["ticks"] == sum(r.ticks for r in rs)
        assert s["episodes_to_criterion"]["per_seed"] == [None, None]  # 4 < the window
        assert s["learns_camera"] is True
    assert summary["kp"]["camera_memory"] == "rltm"
    assert summary["rp"]["camera_memory"] == "ltm"


@pytest.mark.parametrize("jobs", [0, -1])
def test_run_experiment_rejects_bad_jobs(jobs: int) -> None:
    with pytest.raises(ValueError, match="jobs"):
        run_experiment(["kp"], [0], 1, jobs=jobs)


def test_run_experiment_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="episodes"):
        run_experiment(["kp"], [0], 0)
    with pytest.raises(ValueError, match="seed"):
        run_experiment(["kp"], [], 1)
    with pytest.raises(UnknownNameError, match="bogus"):
        run_experiment(["kp", "bogus"], [0], 1)


# --- episodes to criterion ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("successes", "expected"),
    [
        ([1] * 10, 10),
        ([1] * 30, 10),
        ([0] * 20, None),
        ([], None),
        ([1] * 9, None),
        ([0] * 5 + [1] * 10, 13),  # episodes 4..13 hold 8 successes
        ([1, 1, 0, 1, 1, 1, 1, 0, 1, 1], 10),  # 8 of 10 at once
        ([1, 1, 0, 1, 1, 0, 1, 0, 1, 1], None),  # 7 of 10
        # 5 of 10 while alternating; episodes 20..29 hold 1, 0, 1, 0 then six successes
        ([0, 0, 0] + [1, 0] * 10 + [1] * 8, 29),
    ],
)
def test_episodes_to_criterion(successes: list[int], expected: int | None) -> None:
    assert episodes_to_criterion([bool(s) for s in successes]) == expected


def test_episodes_to_criterion_other_window_and_rate() -> None:
    assert episodes_to_criterion([False, True, True], window=2, rate=1.0) == 3
    assert episodes_to_criterion([True, False, True], window=2, rate=0.5) == 2
    assert episodes_to_criterion([False, True, False], window=3, rate=0.5) is None


# --- statistics -----------------------------------------------------------------------------


def test_mean_ci_by_hand() -> None:
    values = [0.2, 0.4, 0.9]
    mean = 1.5 / 3
    sd = math.sqrt(((0.2 - mean) ** 2 + (0.4 - mean) ** 2 + (0.9 - mean) ** 2) / 2)
    got = mean_ci(values)
    assert got["n"] == 3
    assert got["mean"] == pytest.approx(0.5)
    assert got["ci95"] == pytest.approx(4.303 * sd / math.sqrt(3), rel=1e-4)
    assert got["ci95"] == pytest.approx(0.8957, abs=1e-4)
    # The interval is that t interval, clipped to the values' range.
    assert (got["low"], got["high"]) == pytest.approx((0.2, 0.9))
    narrow = [0.3, 0.4, 0.5, 0.6, 0.4, 0.5, 0.45, 0.55]
    inner = mean_ci(narrow)
    assert (inner["low"], inner["high"]) == pytest.approx(
        (inner["mean"] - inner["ci95"], inner["mean"] + inner["ci95"])
    )


def test_mean_ci_of_equal_values_has_no_width() -> None:
    assert mean_ci([0.5] * 4) == {"mean": 0.5, "ci95": 0.0, "low": 0.5, "high": 0.5, "n": 4}


def test_mean_ci_carries_an_interval_inside_the_values() -> None:
    got = mean_ci([0.2, 0.4, 0.9, 0.5])
    assert 0.2 <= got["low"] < got["mean"] < got["high"] <= 0.9


def test_mean_ci_of_one_or_no_value_has_no_interval() -> None:
    one = mean_ci([0.7])
    assert (one["mean"], one["n"]) == (0.7, 1)
    assert math.isnan(one["ci95"])
    none = mean_ci([])
    assert none["n"] == 0
    assert math.isnan(none["mean"])
    assert math.isnan(none["ci95"])


def test_t_quantile_975() -> None:
    assert t_quantile_975(1) == pytest.approx(12.706, abs=1e-3)
    assert t_quantile_975(19) == pytest.approx(2.093, abs=1e-3)
    assert t_quantile_975(30) == pytest.approx(2.042, abs=1e-3)
    assert t_quantile_975(39) == pytest.approx(2.023, abs=1e-3)  # 40 seeds: not 1.96
    assert math.isnan(t_quantile_975(0))


# --- parse_conditions -----------------------------------------------------------------------


def test_parse_conditions_keeps_order_and_drops_repeats_and_blanks() -> None:
    assert parse_conditions("kp, rp,,kp ,innate") == ["kp", "rp", "innate"]


@pytest.mark.parametrize("text", ["", " ", ",,", " , "])
def test_parse_conditions_rejects_empty_input(text: str) -> None:
    with pytest.raises(UnknownNameError, match="no condition"):
        parse_conditions(text)


def test_parse_conditions_rejects_unknown_names() -> None:
    with pytest.raises(UnknownNameError, match=r"'bogus'.*known: innate"):
        parse_conditions("kp,bogus")


def test_paired_against_pairs_seeds_and_a_condition_against_itself_is_zero() -> None:
    summary = {
        "kp": {"seeds": 3, "seed_ids": [0, 1, 2], "success_by_seed": [[1, 0], [1, 1], [0, 0]]},
        "same": {"seeds": 3, "seed_ids": [2, 0, 1], "success_by_seed": [[0, 0], [1, 0], [1, 1]]},
        "better": {
            "seeds": 3, "seed_ids": [0, 1, 2], "success_by_seed": [[1, 1], [1, 1], [1, 0]],
        },
    }  # fmt: skip
    out = core.lab.experiment.paired_against(summary, "kp")
    assert out["same"]["mean"] == 0.0 and out["same"]["p"] == 1.0  # the same seeds, reordered
    # better - kp per seed: +0.5, 0, +0.5.
    assert out["better"]["mean"] == pytest.approx(1 / 3)
    first = core.lab.experiment.paired_against(summary, "kp", horizon=1)
    assert first["better"]["mean"] == pytest.approx(1 / 3)  # 0, 0, +1 over episode 1
    assert core.lab.experiment.paired_against(summary, "nobody") == {}


def test_the_new_conditions_with_evaluation_are_the_same_whatever_the_jobs() -> None:
    args = (["sonar", "qlambda-hybrid"], [0, 1], 3)
    serial = run_experiment(*args, jobs=1, eval_episodes=2, tuned=True)
    parallel = run_experiment(*args, jobs=2, eval_episodes=2, tuned=True)
    assert [r.task for r in serial] == [r.task for r in parallel]
    for a, b in zip(serial, parallel, strict=True):
        assert a.ok and b.ok, (a.error, b.error)
        assert (a.episodes, a.evaluation, a.transfer, a.answers) == (
            b.episodes, b.evaluation, b.transfer, b.answers,
        )  # fmt: skip
        assert len(a.evaluation) == len(a.transfer) == 2


def test_the_pool_is_given_the_longest_tasks_first() -> None:
    setup = Setup().resolved()
    brain, learner = Task("kp", 0, 10, setup=setup), Task("qlambda", 0, 10, setup=setup)
    assert expected_cost(learner) > expected_cost(brain)
    assert expected_cost(Task("kp", 0, 10, setup=setup, eval_episodes=5)) == 20
    assert expected_cost(Task("dqn", 0, 10, setup=setup)) > expected_cost(learner)


def test_experiment_tasks_are_in_condition_then_seed_order() -> None:
    tasks = experiment_tasks(["kp", "rp"], [3, 1], 5, Setup(), eval_episodes=2, tuned=True)
    assert [(t.condition, t.seed) for t in tasks] == [("kp", 3), ("kp", 1), ("rp", 3), ("rp", 1)]
    assert all(t.eval_episodes == 2 and t.setup == Setup().resolved() for t in tasks)
