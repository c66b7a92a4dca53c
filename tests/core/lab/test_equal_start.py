"""Equal starting knowledge: a condition moved to another start, and the grid's arithmetic."""

from __future__ import annotations

import pytest

from core.brain.catalog import load_catalog
from core.errors import UnknownNameError
from core.lab.cells import run_study
from core.lab.equal_start import EqualStartStudy, label, own_start, summarise_equal_start
from core.lab.experiment import LocalBackend, Task, run_task
from core.run.conditions import Start, get_condition, with_start
from core.run.setup import Setup, network_specs

CATALOG = load_catalog()
CAMERA = {s.name for s in CATALOG.stimuli if s.sensor == "camera_obstacle"}
SONAR = {s.name for s in CATALOG.stimuli if s.sensor == "sonar_obstacle"}


def starts_with(condition: str, start: Start) -> dict[str, tuple[str, bool]]:
    """Each stimulus's association (behaviour, locked) the robot starts with."""
    c = Setup(signal="given", start=start).condition(get_condition(condition))
    return {a.stimulus: (a.behaviour, a.locked) for a in network_specs(CATALOG, c)}


@pytest.mark.parametrize(
    ("condition", "start"),
    [("rp", "table1"), ("dp", "table1"), ("dp-rare", "table1"), ("kp", "design")],
)
def test_a_condition_at_its_own_start_runs_exactly_as_it_is(condition: str, start: str) -> None:
    # The grid's own-start cells are the headline's conditions, episode for episode.
    assert own_start(condition) == start
    moved = run_task(Task(condition, 3, 4, setup=Setup(signal="given", start=own_start(condition))))
    plain = run_task(Task(condition, 3, 4, setup=Setup(signal="given")))
    assert moved.ok and plain.ok
    assert moved.episodes == plain.episodes
    assert moved.ltm == plain.ltm


def test_from_kps_design_every_method_has_the_sonar_and_lane_keeping() -> None:
    kp = starts_with("kp", "design")
    for condition in ("rp", "dp", "dp-rare", "qlambda-hybrid"):
        moved = starts_with(condition, "design")
        assert {s: kp[s] for s in SONAR | {"Left", "Middle", "Right"}} == {
            s: moved[s] for s in SONAR | {"Left", "Middle", "Right"}
        }
    # DP keeps what it programmed, locked, on top of the design.
    dp = starts_with("dp", "design")
    assert {s for s in CAMERA if s in dp and dp[s][1]} == {
        f"Obstacle_{lane}_{side}" for lane in "LR" for side in "LMR"
    }


def test_from_table_i_no_method_has_the_sonar_or_lane_keeping() -> None:
    for condition in ("rp", "kp", "qlambda-hybrid", "dp", "dp-rare"):
        moved = starts_with(condition, "table1")
        assert not (SONAR | {"Left", "Middle", "Right"}) & set(moved)


def test_the_papers_dp_split_leaves_the_right_lane_to_learn_and_srlabs_the_middle() -> None:
    programmed = {s for s, (_, locked) in starts_with("dp-rare", "").items() if locked}
    assert programmed & CAMERA == {f"Obstacle_{lane}_{side}" for lane in "LM" for side in "LMR"}
    programmed = {s for s, (_, locked) in starts_with("dp", "").items() if locked}
    assert programmed & CAMERA == {f"Obstacle_{lane}_{side}" for lane in "LR" for side in "LMR"}


def test_a_condition_with_another_knowledge_has_no_start_to_change() -> None:
    with pytest.raises(UnknownNameError, match=r"'expert'.*a start does not replace"):
        with_start(get_condition("expert"), "design")
    with pytest.raises(UnknownNameError, match="unknown start 'later'"):
        Setup(start="later")  # type: ignore[arg-type]


def test_the_headline_difference_is_the_methods_part_plus_the_starts() -> None:
    study = EqualStartStudy(("rp", "kp"), Setup(signal="given"))
    assert [c.label for c in study.cells()] == [
        label("rp", "table1"), label("kp", "table1"), label("rp", "design"), label("kp", "design"),
    ]  # fmt: skip
    results = run_study(study.cells(), [0, 1, 2], 3, 2, LocalBackend(1))
    summary = summarise_equal_start(study, results)
    split = summary["decomposition"]["rp"]
    for measure in ("all", "held-out"):
        headline, method, start = (
            split[k][measure]["mean"] for k in ("headline", "method", "start")
        )
        assert headline == pytest.approx(method + start)
    assert summary["grid"]["rp"]["own_start"] == "table1"
    assert summary["method"]["design"]["rp"] == split["method"]


def test_the_declared_comparisons_are_kp_minus_each_method_from_its_start_holm_adjusted() -> None:
    study = EqualStartStudy(("dp", "rp", "kp"), Setup(signal="given"))
    results = run_study(study.cells(), [0, 1, 2], 3, 2, LocalBackend(1))
    summary = summarise_equal_start(study, results)
    declared = summary["declared"]
    assert [d["label"] for d in declared] == [
        f"kp - {m}, both from kp's design, {t}"
        for m in ("dp", "rp")
        for t in ("training", "held out")
    ]
    method = summary["method"]["design"]
    assert [d["mean"] for d in declared] == [
        method[m][k]["mean"] for m in ("dp", "rp") for k in ("all", "held-out")
    ]
    # Holm over the four: the smallest p times 4, each adjusted p at least its own p.
    ps = sorted(d["p"] for d in declared)
    assert min(d["p_holm"] for d in declared) == pytest.approx(min(1.0, 4 * ps[0]))
    assert all(d["p"] <= d["p_holm"] <= 1.0 for d in declared)
