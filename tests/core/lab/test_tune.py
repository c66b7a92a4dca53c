"""Tuning: every learner the same budget on tuning seeds, and the tuned file read back."""

from __future__ import annotations

import tomllib

import pytest

from core.errors import CatalogError
from core.lab.tune import GRIDS, TUNING_SEED_BASE, TunedPoint, plan, toml_key, tune, tuned_toml
from core.params import get_parameter, normalise, tuned, tuned_params
from core.run.conditions import CONDITIONS
from core.run.setup import Setup


def test_every_learner_has_a_grid_of_the_same_size() -> None:
    learners = {n for n, c in CONDITIONS.items() if c.learning and not c.interactive}
    assert set(GRIDS) == learners
    sizes = set()
    for name, axes in GRIDS.items():
        size = 1
        for param, values in axes:
            assert get_parameter(param).applies(CONDITIONS[name]), (name, param)
            size *= len(values)
        sizes.add(size)
    assert sizes == {27}


def test_the_plan_gives_every_learner_the_same_number_of_tasks() -> None:
    seeds = list(range(TUNING_SEED_BASE, TUNING_SEED_BASE + 2))
    sweeps = plan(list(GRIDS), seeds, 3, Setup())
    assert {len(s.tasks()) for s in sweeps.values()} == {27 * 2}
    with pytest.raises(CatalogError, match="no tuning grid for innate"):
        plan(["innate"], seeds, 3, Setup())


def test_tune_ranks_points_best_first_and_the_file_reads_back() -> None:
    rows = tune(["kp"], [TUNING_SEED_BASE], 2, Setup(signal="given"))
    points = rows["kp"]
    assert len(points) == 27
    assert [p.success for p in points] == sorted((p.success for p in points), reverse=True)
    text = tuned_toml({"kp": points[0], "qlambda-hybrid": points[0]}, "srlab tune", Setup())
    raw = tomllib.loads(text)
    assert normalise(raw["kp"]) == normalise(points[0].point)
    assert "qlambda-hybrid" in raw


def test_retuning_some_learners_keeps_the_others_sections() -> None:
    first = tuned_toml(
        {"kp": TunedPoint({"eta": 0.3}, 0.8, (0.8,)), "rp": TunedPoint({"eta": 0.05}, 0.9, (0.9,))},
        "srlab tune", Setup(),
    )  # fmt: skip
    again = tuned_toml(
        {"dqn": TunedPoint({"learning_rate": 0.001}, 0.6, (0.6,)),
         "kp": TunedPoint({"eta": 0.5}, 0.85, (0.85,))},
        "srlab tune --conditions dqn,kp", Setup(), previous=first,
    )  # fmt: skip
    raw = tomllib.loads(again)
    assert raw == {"kp": {"eta": 0.5}, "rp": {"eta": 0.05}, "dqn": {"learning_rate": 0.001}}
    assert "# by srlab tune --conditions dqn,kp" in again
    assert again.count("[rp]") == 1 and again.count("[kp]") == 1


def test_the_shipped_tuned_parameters_are_valid_and_only_for_learners() -> None:
    for name, params in tuned().items():
        assert CONDITIONS[name].learning
        assert params == normalise(dict(params))
        assert tuned_params(name) == params
    assert tuned_params("innate") == ()


def test_toml_keys_are_quoted_only_when_they_must_be() -> None:
    assert toml_key("kp") == "kp"
    assert toml_key("insert_threshold") == "insert_threshold"
    assert toml_key("qlambda-hybrid") == "qlambda-hybrid"
    assert toml_key("a b") == '"a b"'
    assert TunedPoint({"eta": 0.1}, 0.5, (0.5,)).success == 0.5
