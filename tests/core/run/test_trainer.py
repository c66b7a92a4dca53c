"""The reinforcement program (RP): its judgements, and its immediate rewards in a simulation."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.brain.catalog import Catalog, load_catalog
from core.brain.selection import Decision, How
from core.errors import CatalogError, UnknownNameError
from core.events import RewardApplied
from core.run.conditions import get_condition
from core.run.simulation import Simulation
from core.run.trainer import ReinforcementProgram, load_trainer


@pytest.fixture(scope="module")
def cat() -> Catalog:
    return load_catalog()


@pytest.fixture(scope="module")
def rp(cat: Catalog) -> ReinforcementProgram:
    return load_trainer(cat, "rp")


Judged = tuple[float, int, int, int]
"""(reward, tick of the judged response, its stimulus, its behaviour)."""


def decide(cat: Catalog, stimulus: str, behaviour: str, how: How = How.RELEASED) -> Decision:
    return Decision(cat.behaviour(behaviour).id, cat.stimulus(stimulus).id, 1.0, how)


@pytest.mark.parametrize(
    ("stimulus", "behaviour", "expected"),
    [
        ("Red", "stop", 1.0),
        ("Red", "goforward3", -1.0),
        ("Yellow", "stop", 1.0),
        ("Green", "goforward2", 1.0),
        ("Green", "stop", -1.0),
        ("Obstacle_M_M", "rightturn15", 1.0),
        ("Obstacle_M_M", "leftturn30", -1.0),
        ("Obstacle_R_R", "leftturn45", 1.0),
    ],
)
def test_judge_rewards_acceptable_responses_and_penalises_others(
    cat: Catalog, rp: ReinforcementProgram, stimulus: str, behaviour: str, expected: float
) -> None:
    assert rp.judge(decide(cat, stimulus, behaviour)) == expected


@pytest.mark.parametrize("how", [How.EXPLORED, How.DEFAULT, How.COMMANDED])
def test_judge_judges_every_new_response_however_it_was_chosen(
    cat: Catalog, rp: ReinforcementProgram, how: How
) -> None:
    assert rp.judge(decide(cat, "Red", "stop", how)) == 1.0
    assert rp.judge(decide(cat, "Red", "goforward3", how)) == -1.0


def test_judge_says_nothing_about_a_continued_response(
    cat: Catalog, rp: ReinforcementProgram
) -> None:
    assert rp.judge(decide(cat, "Red", "stop", How.CONTINUED)) is None
    assert rp.judge(decide(cat, "Red", "goforward3", How.CONTINUED)) is None


@pytest.mark.parametrize("stimulus", ["SonarObstacleFront", "Corner", "LeftWall", "Collision"])
def test_judge_says_nothing_about_stimuli_it_does_not_know(
    cat: Catalog, rp: ReinforcementProgram, stimulus: str
) -> None:
    assert rp.judge(decide(cat, stimulus, "stop")) is None


def test_judge_says_nothing_without_a_stimulus(cat: Catalog, rp: ReinforcementProgram) -> None:
    assert rp.judge(Decision(cat.behaviour("goforward3").id, -1, 0.3, How.DEFAULT)) is None


def test_load_trainer_reads_the_shipped_program(cat: Catalog, rp: ReinforcementProgram) -> None:
    assert (rp.name, rp.reward, rp.penalty) == ("rp", 1.0, -1.0)
    camera = {s.id for s in cat.stimuli if s.sensor == "camera_obstacle"}
    signal = {s.id for s in cat.stimuli if s.sensor == "signal"}
    assert set(rp.good) == camera | signal


def test_load_trainer_unknown_name_raises(cat: Catalog) -> None:
    with pytest.raises(UnknownNameError, match="nope"):
        load_trainer(cat, "nope")


def test_load_trainer_rejects_a_reward_out_of_range(cat: Catalog, tmp_path: Path) -> None:
    (tmp_path / "trainers").mkdir()
    (tmp_path / "trainers" / "loud.toml").write_text('reward = 2.0\n[good]\nRed = ["stop"]\n')
    with pytest.raises(CatalogError, match=r"\[-1, 1\]"):
        load_trainer(cat, "loud", root=tmp_path)


def test_load_trainer_rejects_unknown_names_in_the_program(cat: Catalog, tmp_path: Path) -> None:
    (tmp_path / "trainers").mkdir()
    (tmp_path / "trainers" / "odd.toml").write_text('[good]\nRed = ["fly"]\n')
    with pytest.raises(UnknownNameError, match="fly"):
        load_trainer(cat, "odd", root=tmp_path)


def test_load_trainer_reports_malformed_toml(cat: Catalog, tmp_path: Path) -> None:
    (tmp_path / "trainers").mkdir()
    (tmp_path / "trainers" / "bad.toml").write_text("reward = = 1\n")
    with pytest.raises(CatalogError, match=r"bad\.toml"):
        load_trainer(cat, "bad", root=tmp_path)


def test_rp_simulation_rewards_judged_responses_on_the_next_tick(cat: Catalog) -> None:
    sim = Simulation(get_condition("rp"), 0, catalog=cat)
    assert sim.trainer is not None
    found: list[RewardApplied] = []
    for _ in range(3):
        sim.reset()
        previous: Judged | None = None
        while True:
            result = sim.tick()
            program = [
                e for e in result.events if isinstance(e, RewardApplied) and e.source == "program"
            ]
            d = sim.brain.last
            judged = sim.trainer.judge(d)
            current = None if judged is None else (judged, sim.tick_count, d.stimulus, d.behaviour)
            done = result.snapshot.done
            # The previous tick's judgement is applied as this tick starts; on an episode's
            # last tick, this tick's own judgement is applied before the episode ends.
            expected = [x for x in (previous, current if done else None) if x is not None]
            assert len(program) == len(expected)
            for event, exp in zip(program, expected, strict=True):
                check_reward(event, exp)
            found.extend(program)
            if done:
                break
            previous = current
    assert found, "the program judged no response in three episodes"
    assert {r.value for r in found} == {1.0, -1.0}


def check_reward(event: RewardApplied, expected: Judged) -> None:
    value, tick, stimulus, behaviour = expected
    assert (event.value, event.note, event.source) == (value, "rp", "program")
    assert event.tick == tick + 1
    newest = event.credits[0]
    assert (newest.tick, newest.stimulus, newest.behaviour) == (tick, stimulus, behaviour)
    assert newest.d_k == 1
    if value > 0:
        assert newest.after == pytest.approx(newest.before + 0.1 * (1 - newest.before))
    else:
        assert newest.after == pytest.approx(newest.before - 0.1 * newest.before)
