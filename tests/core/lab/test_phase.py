"""Phase diagrams: the star of points, its tasks, and where a difference holds and flips."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.events import Cause, Outcome
from core.lab.experiment import TaskResult, experiment_tasks
from core.lab.phase import Phase, PhasePoint, load_grid, sign_of, summarise_phase
from core.params import ParameterError
from core.run.runner import EpisodeSummary
from core.run.setup import Setup
from core.sim.worlds import PERCEPTION_PRESETS

GIVEN = Setup("soft-obstacle", signal="given").resolved()


def phase(**kwargs: object) -> Phase:
    args: dict[str, object] = {
        "axes": (("echo_range_m", (0.1, 0.3, 0.6)), ("cruise_speed_mps", (0.6,))),
        "conditions": ("kp", "sonar", "rp"),
        "seeds": (0, 1, 2, 3),
        "episodes": 10,
        "setup": GIVEN,
    }
    return Phase(**(args | kwargs))  # type: ignore[arg-type]


def test_a_star_runs_the_base_once_and_each_value_off_it() -> None:
    points = phase().points()
    assert [p.label for p in points] == [
        "base",
        "echo_range_m=0.1",
        "echo_range_m=0.6",
        "cruise_speed_mps=0.6",
    ]
    assert [v for v, _ in phase().axis("echo_range_m")] == [0.1, 0.3, 0.6]
    assert [p.label for _, p in phase().axis("cruise_speed_mps")] == [
        "base",
        "cruise_speed_mps=0.6",
    ]


def test_each_point_is_the_base_world_with_one_setting_moved() -> None:
    plan = phase()
    moved = plan.task(PhasePoint("echo_range_m", 0.6), "kp", 0).setup.world_config()
    base = plan.task(PhasePoint(), "kp", 0).setup.world_config()
    assert moved.track.obstacle.echo_range_m == 0.6
    assert base.track.obstacle.echo_range_m == 0.3
    assert moved.robot == base.robot
    fast = plan.task(PhasePoint("cruise_speed_mps", 0.6), "kp", 0).setup.world_config()
    assert (fast.robot.cruise_speed_mps, fast.track) == (0.6, base.track)


def test_the_base_points_tasks_are_the_experiments() -> None:
    """So the base point reproduces `srlab experiment` on the base world, digit for digit."""
    plan = phase()
    base = [plan.task(PhasePoint(), c, s) for c in ("kp", "sonar") for s in plan.seeds]
    assert base == experiment_tasks(("kp", "sonar"), plan.seeds, 10, GIVEN, tuned=True)


def test_every_point_runs_the_reflexes_and_each_condition_on_the_same_seeds() -> None:
    plan = phase()
    tasks = plan.tasks()
    assert len(tasks) == len(set(tasks)) == 4 * 4 * 4
    for p in plan.points():
        mine = [t for t in tasks if t.setup.world_settings == p.settings]
        assert {(t.condition, t.seed) for t in mine} == {
            (c, s) for c in ("reflexes", "kp", "sonar", "rp") for s in range(4)
        }


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"conditions": ("kp",)}, ValueError, "at least two conditions"),
        ({"conditions": ("kp", "reflexes")}, ValueError, "leave it out"),
        ({"axes": ()}, ParameterError, "declare at least one world parameter"),
        ({"axes": (("echo_range_m", (0.1, 0.1)),)}, ParameterError, "a value is repeated"),
        ({"axes": (("echo_range_m", (4.0,)),)}, ParameterError, "must be in (0, 3], got 4.0"),
    ],
)
def test_a_bad_plan_is_refused(kwargs: dict[str, object], error: type, message: str) -> None:
    with pytest.raises(error, match=message.replace("(", r"\(").replace(")", r"\)")):
        phase(**kwargs)


def test_sign_of_a_difference_is_where_its_interval_lies() -> None:
    assert sign_of({"mean": 0.1, "low": 0.02, "high": 0.2}) == "+"
    assert sign_of({"mean": -0.1, "low": -0.2, "high": -0.01}) == "-"
    assert sign_of({"mean": 0.1, "low": -0.02, "high": 0.2}) == "0"
    assert sign_of(None) == "?"


def episodes(successes: int, n: int = 10) -> tuple[EpisodeSummary, ...]:
    return tuple(
        EpisodeSummary(
            i,
            Outcome.SUCCESS if i < successes else Outcome.FAILURE,
            None if i < successes else Cause.OBSTACLE_COLLISION,
            100,
            0,
        )
        for i in range(n)
    )


def test_a_constructed_flip_is_found_where_it_is_and_the_regions_follow_the_reflexes() -> None:
    """kp leads sonar by 3 episodes in 10 on every seed while the echo is short, and trails it
    by 3 once the reflexes pass by themselves: the flip is between 0.3 and 0.6."""
    plan = phase(axes=(("echo_range_m", (0.1, 0.6)),), conditions=("kp", "sonar"))
    reflexes = {"base": 5, "echo_range_m=0.1": 2, "echo_range_m=0.6": 9}
    lead = {"base": 3, "echo_range_m=0.1": 3, "echo_range_m=0.6": -3}
    results = []
    for p in plan.points():
        for s in plan.seeds:
            jitter = s % 2  # seeds differ, so the intervals have a width
            wins = {
                "reflexes": reflexes[p.label],
                "sonar": 5 + jitter,
                "kp": 5 + jitter + lead[p.label],
            }
            for c, n in wins.items():
                results.append(TaskResult(plan.task(p, c, s), episodes(n), ticks=1000))
    summary = summarise_phase(plan, results)
    (name,) = summary["regions"]
    assert name == "kp - sonar"
    regions = summary["regions"][name]
    assert regions["+"]["points"] == ["base", "echo_range_m=0.1"]
    assert (regions["+"]["reflexes_low"], regions["+"]["reflexes_high"]) == (0.2, 0.5)
    assert regions["-"]["points"] == ["echo_range_m=0.6"]
    assert regions["0"]["points"] == []
    (change,) = summary["axes"]["echo_range_m"]["changes"][name]
    assert (change["from"], change["to"], change["flips"]) == (0.3, 0.6, True)
    assert (change["sign_from"], change["sign_to"]) == ("+", "-")
    assert change["mean_from"] == pytest.approx(0.3)
    assert change["mean_to"] == pytest.approx(-0.3)
    assert summary["tests"] == 3


def test_a_grid_file_declares_each_parameter_with_its_values(tmp_path: Path) -> None:
    path = tmp_path / "grid.toml"
    path.write_text("echo_range_m = [0.1, 0.2]\nobstacle_size_m = [0.35]\n")
    assert load_grid(path) == (("echo_range_m", (0.1, 0.2)), ("obstacle_size_m", (0.35,)))


def test_a_diagram_over_noisy_perception_keeps_the_noise_on_every_point() -> None:
    noisy = Setup("soft-obstacle", signal="given", world_settings=PERCEPTION_PRESETS["noisy"])
    p = phase(setup=noisy.resolved(), axes=(("camera_miss_rate", (0.0, 0.5)),))
    assert p.base_value("camera_miss_rate") == 0.2  # the base is the noisy world
    by_point = {t.setup.world_settings for t in p.tasks()}
    assert by_point == {
        PERCEPTION_PRESETS["noisy"],
        tuple(
            sorted(
                {**dict(PERCEPTION_PRESETS["noisy"]), "perception.camera_miss_rate": 0.0}.items()
            )
        ),
        tuple(
            sorted(
                {**dict(PERCEPTION_PRESETS["noisy"]), "perception.camera_miss_rate": 0.5}.items()
            )
        ),
    }
