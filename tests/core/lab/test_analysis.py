"""The analysis: horizons, trends, the criterion's null, correctness and paired tables."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest

from core.errors import UnknownNameError
from core.lab.analysis import (
    correctness,
    criterion_null,
    declared_comparisons,
    episodes_to_criterion,
    paired_table,
    parse_pairs,
    trend_per_10,
)
from core.lab.stats import holm


def test_trend_per_10_is_the_least_squares_slope() -> None:
    assert trend_per_10([0, 0, 0, 0]) == pytest.approx(0.0)
    # x = 0..19, y alternating 0, 1: cov = 5, var = 665 (by hand), slope 5 / 665 per episode.
    assert trend_per_10([0, 1] * 10) == pytest.approx(10 * 5 / 665)
    assert trend_per_10([0] * 10 + [1] * 10) > 0.5
    assert math.isnan(trend_per_10([1]))


def test_a_process_that_learns_nothing_reaches_the_criterion_by_chance() -> None:
    """At 90% success, 8 of 10 comes within the first windows; at 10%, almost never."""
    high = criterion_null([[1] * 45 + [0] * 5] * 5)
    low = criterion_null([[1] * 5 + [0] * 45] * 5)
    assert high["median"] is not None and high["median"] <= 15
    assert high["reached_share"] > 0.9
    assert low["median"] is None and low["reached_share"] < 0.05
    assert criterion_null([[1] * 45 + [0] * 5]) == criterion_null([[1] * 45 + [0] * 5])


@dataclass
class Fake:
    """What `correctness` reads of a task result."""

    answers: tuple[tuple[str | None, ...], ...]
    ok: bool = True
    task: object = field(default=None)


def test_correctness_at_checkpoints_and_the_knowledge_criterion() -> None:
    camera = ["Obstacle_M_L", "Obstacle_M_M"]
    correct = {"Obstacle_M_L": frozenset({"rightturn30"}), "Obstacle_M_M": frozenset()}
    seed_a = [(None, None)] * 5 + [("rightturn30", "leftturn30")] * 5  # learns at 6, stays
    seed_b = [("rightturn30", None)] * 3 + [("leftturn15", None)] * 7  # right, then wrong
    out = correctness([Fake(tuple(seed_a)), Fake(tuple(seed_b))], camera, correct)  # type: ignore[list-item]
    at10 = out["checkpoints"]["10"]
    assert at10["Obstacle_M_L"] == {"correct": 0.5, "wrong": 0.5, "none": 0.0}
    assert at10["Obstacle_M_M"] == {"correct": 0.0, "wrong": 0.5, "none": 0.5}
    ml = out["criterion"]["Obstacle_M_L"]
    assert ml["per_seed"] == [6, None]
    assert ml["survival"][:5] == [1.0] * 5 and ml["survival"][5:] == [0.5] * 5
    assert out["criterion"]["Obstacle_M_M"]["per_seed"] == [None, None]  # no correct answer


def test_paired_table_has_every_pair_once_per_horizon() -> None:
    row = {"seeds": 3, "episodes": 10, "seed_ids": [0, 1, 2]}
    summary = {
        "a": {**row, "success_by_seed": [[1] * 10, [1] * 10, [0] * 10]},
        "b": {**row, "success_by_seed": [[0] * 10, [1] * 10, [0] * 10]},
        "c": {**row, "success_by_seed": [[0] * 10, [0] * 10, [0] * 10]},
    }
    table = paired_table(summary)
    assert set(table) == {"a - b", "a - c", "b - c"}
    assert set(table["a - b"]) == {"1-10", "all"}  # 1-50 is longer than the run
    assert table["a - c"]["all"]["mean"] == pytest.approx(2 / 3)
    assert table["a - b"]["all"]["seeds"] == 3


def test_held_out_rates_are_paired_by_training_seed() -> None:
    row = {"seeds": 3, "episodes": 10, "success_by_seed": [[0] * 10] * 3}
    summary = {
        "a": {**row, "seed_ids": [0, 1, 2],
              "evaluation": {"frozen_by_seed": [1.0, 0.5, 0.5],
                             "camera_only_by_seed": [0.0, 0.0, 1.0]}},
        "b": {**row, "seed_ids": [2, 1, 0],  # another order: paired by id, not position
              "evaluation": {"frozen_by_seed": [0.0, 0.5, 0.5],
                             "camera_only_by_seed": [0.0, 0.0, 0.0]}},
        "c": {**row, "seed_ids": [0, 1, 2]},  # no held-out evaluation
    }  # fmt: skip
    table = paired_table(summary)
    assert table["a - b"]["held-out"]["mean"] == pytest.approx((0.5 + 0.0 + 0.5) / 3)
    assert table["a - b"]["camera only"]["mean"] == pytest.approx(1 / 3)
    assert "held-out" not in table["a - c"] and "all" in table["a - c"]


def test_episodes_to_criterion_by_hand() -> None:
    assert episodes_to_criterion([True] * 8 + [False] * 2) == 10
    assert episodes_to_criterion([False] * 5 + [True] * 9) == 13
    assert episodes_to_criterion([True, False] * 10) is None


def test_parse_pairs_reads_condition_names_that_hold_hyphens() -> None:
    got = parse_pairs("kp-sonar, kp-qlambda-hybrid,qlambda-hybrid-kp,,kp-sonar")
    assert got == [("kp", "sonar"), ("kp", "qlambda-hybrid"), ("qlambda-hybrid", "kp")]
    for bad, message in [
        ("kp-bogus", "no way to read it"),
        ("kp", "no way to read it"),
        ("kp-kp", "with itself"),
        (" , ", "no comparison given"),
    ]:
        with pytest.raises(UnknownNameError, match=message):
            parse_pairs(bad)


def _condition(training: list[float], held_out: list[float]) -> dict[str, object]:
    """A condition's summary as `paired` reads it: 10 episodes per seed, and held out."""
    rows = [[1] * round(10 * r) + [0] * (10 - round(10 * r)) for r in training]
    return {
        "seeds": len(rows), "episodes": 10, "seed_ids": list(range(len(rows))),
        "success_by_seed": rows, "evaluation": {"frozen_by_seed": held_out},
    }  # fmt: skip


def test_the_declared_comparisons_are_one_holm_family_on_training_and_held_out() -> None:
    summary = {
        "kp": _condition([0.9, 0.8, 0.9, 0.7, 0.8, 0.9], [1.0, 0.9, 1.0, 0.8, 0.9, 1.0]),
        "sonar": _condition([0.6, 0.7, 0.6, 0.6, 0.7, 0.5], [0.7, 0.6, 0.7, 0.5, 0.6, 0.7]),
        "rp": _condition([0.9, 0.9, 0.8, 0.8, 0.9, 0.8], [1.0, 1.0, 0.9, 0.9, 1.0, 1.0]),
    }
    rows = declared_comparisons(summary)  # the default: dp and qlambda-hybrid did not run
    assert [(r["pair"], r["on"]) for r in rows] == [
        ("kp - sonar", "all"),
        ("kp - sonar", "held-out"),
        ("kp - rp", "all"),
        ("kp - rp", "held-out"),
    ]
    # kp leads sonar on all 6 seeds, both ways: exact sign-flip p = 2 / 2**6, and Holm
    # multiplies the smallest of the 4 tests by 4.
    assert rows[0]["p"] == pytest.approx(2 / 64)
    assert rows[0]["p_holm"] == pytest.approx(4 * 2 / 64)
    assert rows[0]["mean"] == pytest.approx((0.3 + 0.1 + 0.3 + 0.1 + 0.1 + 0.4) / 6)
    assert rows[1]["mean"] == pytest.approx(0.3)
    assert [r["p_holm"] for r in rows] == pytest.approx(holm([r["p"] for r in rows]))
    assert all(r["p_holm"] >= r["p"] for r in rows)
    only = declared_comparisons(summary, [("rp", "sonar")])
    assert [r["pair"] for r in only] == ["rp - sonar", "rp - sonar"]
