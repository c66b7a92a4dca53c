"""Sweeps: the grid, shared tasks, backends giving the same results, and per-value figures."""

from __future__ import annotations

import pytest

from core.errors import UnknownNameError
from core.lab.experiment import LocalBackend, Task, TaskResult, run_task, run_tasks
from core.lab.sweep import Sweep, parse_grid, parse_param, run_sweep, summarise_sweep
from core.params import ParameterError
from core.run.runner import EpisodeSummary


def test_parse_param_reads_name_and_values_in_order() -> None:
    assert parse_param("eta=0.2,0.05,0.1") == ("eta", (0.2, 0.05, 0.1))
    assert parse_param(" kp_window = 10, 30 ") == ("kp_window", (10, 30))
    assert parse_param("synthesize=false,true") == ("synthesize", (False, True))


@pytest.mark.parametrize(
    ("text", "error", "message"),
    [
        ("eta", ParameterError, "--param takes NAME=V1,V2,..., got 'eta'"),
        ("=0.1", ParameterError, "--param takes NAME=V1,V2"),
        ("eta=", ParameterError, "--param eta: no value given"),
        ("eta=abc", ParameterError, "eta: 'abc' is not a number"),
        ("eta=0.1,2", ParameterError, r"eta must be in \[0, 1\], got 2"),
        ("eta=0.1,0.10", ParameterError, "--param eta: a value is repeated"),
        ("speed=1", UnknownNameError, "unknown parameter 'speed'"),
    ],
)
def test_parse_param_refuses_bad_input_clearly(
    text: str, error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        parse_param(text)


def test_parse_grid_refuses_a_parameter_given_twice_and_an_empty_grid() -> None:
    with pytest.raises(ParameterError, match="--param eta is given twice"):
        parse_grid(["eta=0.1", "epsilon=0.1", "eta=0.2"])
    with pytest.raises(ParameterError, match="at least one --param"):
        parse_grid([])


def test_a_parameter_no_condition_uses_is_refused() -> None:
    with pytest.raises(
        ParameterError, match="--param alpha applies to none of the conditions kp, dp"
    ):
        Sweep(parse_grid(["alpha=0.1,0.3"]), ("kp", "dp"), (0,), 1)
    with pytest.raises(UnknownNameError, match="unknown condition 'kq'"):
        Sweep(parse_grid(["eta=0.1"]), ("kq",), (0,), 1)


def test_points_are_the_product_first_parameter_slowest() -> None:
    sweep = Sweep(parse_grid(["eta=0.05,0.2", "epsilon=0.0,0.1,0.3"]), ("kp",), (0,), 1)
    assert sweep.points() == [
        {"eta": e, "epsilon": x} for e in (0.05, 0.2) for x in (0.0, 0.1, 0.3)
    ]


def test_points_differing_only_in_unused_parameters_share_a_task() -> None:
    sweep = Sweep(
        parse_grid(["eta=0.05,0.1,0.2", "epsilon=0.05,0.1"]), ("kp", "qlambda"), (0, 1), 4
    )
    tasks = sweep.tasks()
    assert len(tasks) == 3 * 2 * 2 + 2 * 2
    assert len(set(tasks)) == len(tasks)
    assert Task("qlambda", 1, 4, (("epsilon", 0.05),)) in tasks
    assert sweep.task({"eta": 0.2, "epsilon": 0.1}, "qlambda", 0) == sweep.task(
        {"eta": 0.05, "epsilon": 0.1}, "qlambda", 0
    )
    assert sweep.task({"eta": 0.2, "epsilon": 0.1}, "kp", 0).params == (
        ("epsilon", 0.1),
        ("eta", 0.2),
    )


@pytest.fixture(scope="module")
def small() -> tuple[Sweep, list[TaskResult]]:
    sweep = Sweep(parse_grid(["epsilon=0,1", "eta=0.1,0.5"]), ("kp", "qlambda"), (0, 1), 3)
    return sweep, run_sweep(sweep, LocalBackend(1))


def test_results_come_in_task_order_and_all_succeed(
    small: tuple[Sweep, list[TaskResult]],
) -> None:
    sweep, results = small
    assert [r.task for r in results] == sweep.tasks()
    assert all(r.ok for r in results), [r.error for r in results if not r.ok]


def test_local_processes_give_the_same_results_as_one_process(
    small: tuple[Sweep, list[TaskResult]],
) -> None:
    sweep, serial = small
    parallel = run_sweep(sweep, LocalBackend(2))
    assert parallel == serial


def test_summary_per_point_is_the_experiment_summary_of_its_tasks(
    small: tuple[Sweep, list[TaskResult]],
) -> None:
    sweep, results = small
    summary = summarise_sweep(sweep, results)
    assert [p["params"] for p in summary["points"]] == sweep.points()
    by_task = {r.task: r for r in results}
    for point in summary["points"]:
        for cond in ("kp", "qlambda"):
            s = point["conditions"][cond]
            assert s["seeds"] == 2
            runs = [by_task[sweep.task(point["params"], cond, seed)] for seed in (0, 1)]
            rate = sum(_successes(r.episodes) for r in runs) / (2 * 3)
            assert s["success_rate"]["mean"] == pytest.approx(rate)


def _successes(episodes: tuple[EpisodeSummary, ...]) -> int:
    return sum(e.outcome.value == "success" for e in episodes)


def test_per_value_figures_average_the_other_parameters_then_the_seeds(
    small: tuple[Sweep, list[TaskResult]],
) -> None:
    sweep, results = small
    summary = summarise_sweep(sweep, results)
    by_task = {r.task: r for r in results}
    eps = summary["by_parameter"]["epsilon"]
    assert eps["ignored_by"] == []
    assert [r["value"] for r in eps["conditions"]["kp"]] == [0.0, 1.0]
    seen: list[list[float]] = []
    for i, value in enumerate((0.0, 1.0)):
        per_seed = []
        for seed in (0, 1):
            runs = [
                by_task[sweep.task({"epsilon": value, "eta": eta}, "kp", seed)]
                for eta in (0.1, 0.5)
            ]
            per_seed.append(sum(_successes(r.episodes) / 3 for r in runs) / 2)
        row = eps["conditions"]["kp"][i]
        assert row["success_rate"]["mean"] == pytest.approx(sum(per_seed) / 2)
        assert row["success_rate"]["n"] == 2
        seen.append(per_seed)
    first, second = eps["conditions"]["kp"]
    assert "success_vs_first" not in first
    diffs = [b - a for a, b in zip(*seen, strict=True)]
    assert second["success_vs_first"]["mean"] == pytest.approx(sum(diffs) / 2)
    assert second["success_vs_first"]["n"] == 2
    assert 0.0 <= second["success_vs_first"]["p"] <= 1.0
    eta = summary["by_parameter"]["eta"]
    assert list(eta["conditions"]) == ["kp"]
    assert eta["ignored_by"] == ["qlambda"]


def test_a_failed_task_is_kept_and_left_out_of_the_figures(
    small: tuple[Sweep, list[TaskResult]],
) -> None:
    sweep, _ = small

    def flaky(task: Task) -> TaskResult:
        if task.condition == "kp" and task.seed == 1 and dict(task.params)["epsilon"] == 1:
            raise RuntimeError("sonar unplugged")
        return run_task(task)

    def guarded(task: Task) -> TaskResult:
        try:
            return flaky(task)
        except RuntimeError as e:
            return TaskResult(task, error=f"RuntimeError: {e}")

    results = run_tasks(sweep.tasks(), LocalBackend(1), fn=guarded)
    failed = [r for r in results if not r.ok]
    assert {(r.task.condition, r.task.seed) for r in failed} == {("kp", 1)}
    assert len(failed) == 2  # epsilon=1 with each eta
    summary = summarise_sweep(sweep, results)
    row = summary["by_parameter"]["epsilon"]["conditions"]["kp"][1]
    assert row["success_rate"]["n"] == 1
    assert summary["by_parameter"]["epsilon"]["conditions"]["kp"][0]["success_rate"]["n"] == 2


def test_run_tasks_refuses_repeated_tasks() -> None:
    with pytest.raises(ValueError, match="distinct"):
        run_tasks([Task("innate", 0, 1), Task("innate", 0, 1)], LocalBackend(1))
