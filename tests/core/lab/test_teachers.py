"""Simulated teachers: a reinforcement program's judgements given late, wrong, or not at all."""

from __future__ import annotations

import asyncio
from dataclasses import replace
from pathlib import Path

import pytest
from fakes import InMemoryRunStore

from core.brain.catalog import Catalog, load_catalog
from core.brain.selection import Decision, How
from core.engine import RunEngine
from core.errors import CatalogError, UnknownNameError
from core.events import RewardApplied, RewardDue
from core.params import configure, teacher_params
from core.ports import Mode, RunSpec, RunStatus
from core.run.checkpoint import decode, encode, export_state, restore_simulation
from core.run.conditions import Condition, get_condition
from core.run.runner import run
from core.run.simulation import Simulation
from core.run.trainer import (
    IMPERFECTIONS,
    PERFECT,
    Imperfections,
    Teacher,
    TeacherError,
    load_trainer,
    parse_teacher,
    teacher_presets,
)

CATALOG: Catalog = load_catalog()
DT_S = 0.1  # the default world's tick


def rp_with(**imperfections: float) -> Condition:
    return replace(get_condition("rp"), teacher=Imperfections(**imperfections))


def program_rewards(sim: Simulation, episodes: int) -> list[RewardApplied]:
    """Every reward the program gave over `episodes` episodes, in the order applied."""
    out: list[RewardApplied] = []
    for _ in range(episodes):
        sim.reset()
        while True:
            result = sim.tick()
            out += [
                e for e in result.events if isinstance(e, RewardApplied) and e.source == "program"
            ]
            if result.snapshot.done:
                break
    return out


def test_a_delayed_teachers_reward_credits_the_records_before_its_arrival() -> None:
    # A fixed delay of 0.5 s is 5 ticks: a response judged at tick t is rewarded at the
    # boundary before tick t + 6, and credits every STM record made before that boundary.
    sim = Simulation(rp_with(delay_s=0.5, delay_cv=0.0), 3, catalog=CATALOG)
    firsts = 0
    for _ in range(4):
        sim.reset()
        arrived_before = 0  # the boundary of the episode's last program reward so far
        ends = []
        while True:
            result = sim.tick()
            for e in result.events:
                if not (isinstance(e, RewardApplied) and e.source == "program"):
                    continue
                judged = int(e.note.split("judged at tick ")[1].split(",")[0])
                assert e.note.endswith("5 ticks late")
                if result.snapshot.done and e.tick < judged + 6:
                    ends.append(e)  # still on its way at the episode's end: it arrives there
                    assert e.tick == sim.tick_count + 1
                else:
                    assert e.tick == judged + 6
                # It credits by its arrival: every record before it that no earlier reward
                # took, each with d_k counted to the arrival, not to the judged tick.
                assert all(arrived_before <= c.tick < e.tick for c in e.credits)
                assert all(c.d_k == e.tick - c.tick for c in e.credits)
                if arrived_before == 0 and e.credits:
                    # The episode's first reward: the judged record and the 5 after it.
                    newest = [c.tick for c in e.credits][:6]
                    assert newest == list(range(e.tick - 1, judged - 1, -1))
                    firsts += 1
                arrived_before = e.tick
            if result.snapshot.done:
                break
    assert firsts >= 3


def test_a_delayed_reward_is_due_at_its_arrival_when_the_engine_applies_it() -> None:
    # With the engine's reward task applying rewards, the simulation hands each on as due
    # at the boundary it arrives at, in the tick before it, as an instant one.
    sim = Simulation(rp_with(delay_s=0.5, delay_cv=0.0), 3, catalog=CATALOG, defer_rewards=True)
    sim.reset()
    dues: list[tuple[int, RewardDue]] = []
    while not sim.snapshot.done:
        result = sim.tick()
        dues += [(sim.tick_count, e) for e in result.events if isinstance(e, RewardDue)]
    program = [(t, e) for t, e in dues if e.source == "program"]
    assert len(program) >= 5
    for tick, e in program:
        judged = int(e.note.split("judged at tick ")[1].split(",")[0])
        assert e.tick == tick + 1
        # On its way when the episode ended: it arrives at the end, before the delay is up.
        assert e.tick == judged + 6 or (tick == sim.tick_count and e.tick < judged + 6)


def test_a_mistaken_teachers_wrong_sign_is_in_the_reward_log_with_its_source() -> None:
    sim = Simulation(rp_with(mistake=1.0), 5, catalog=CATALOG)
    assert sim.trainer is not None
    program = sim.trainer
    seen = 0
    for _ in range(3):
        sim.reset()
        deserved: float | None = None
        while True:
            result = sim.tick()
            applied = [
                e for e in result.events if isinstance(e, RewardApplied) and e.source == "program"
            ]
            if deserved is not None:  # the last tick's judgement, applied as this one starts
                assert applied[0].value == -deserved
                assert applied[0].note == "rp, wrong sign"
                seen += 1
            deserved = program.judge(sim.brain.last)
            if result.snapshot.done:
                break
    assert seen > 20


def test_the_engine_logs_a_simulated_teachers_rewards_as_they_arrive() -> None:
    # The same teacher in a run of the engine: its log holds each reward with its source,
    # its note and the boundary it arrived at, and learning ends as in the headless loop.
    condition = rp_with(mistake=0.3, delay_s=1.0)
    spec = RunSpec("rp", 2, 3, Mode.FAST)
    store = InMemoryRunStore(CATALOG)
    sim = Simulation(condition, 2, catalog=CATALOG, defer_rewards=True)
    run_id = store.create_run(spec, ())
    engine = RunEngine(run_id, spec, store, sim)
    assert asyncio.run(engine.run()) is RunStatus.FINISHED
    plain = run(condition, 2, 3, catalog=CATALOG)
    assert engine.sim.brain.ltm.as_dict() == plain.ltm
    log = [r.record for r in store.rewards(run_id) if r.record.source == "program"]
    assert any("wrong sign" in r.note for r in log)
    assert all(r.note.startswith("rp") for r in log)
    late = [r for r in log if "ticks late" in r.note]
    assert late
    for r in late:
        judged = int(r.note.split("judged at tick ")[1].split(",")[0])
        late_by = int(r.note.split(", ")[-1].split(" ")[0])
        assert judged < r.tick <= judged + 1 + late_by


@pytest.mark.parametrize(
    "teacher",
    [
        Imperfections(mistake=0.3),
        Imperfections(skip=0.5),
        Imperfections(delay_s=1.0),
        Imperfections(bias=0.5),
        Imperfections(fatigue=0.3),
        teacher_presets()["human"],
    ],
)
def test_imperfections_are_reproducible_per_seed(teacher: Imperfections) -> None:
    def rewards(seed: int, teacher: Imperfections = teacher) -> list[tuple[int, float, str]]:
        sim = Simulation(replace(get_condition("rp"), teacher=teacher), seed, catalog=CATALOG)
        return [(e.tick, e.value, e.note) for e in program_rewards(sim, 3)]

    assert rewards(7) == rewards(7)
    assert rewards(7) != rewards(7, PERFECT)  # the imperfection acted
    assert rewards(7) != rewards(8)


def test_a_teacher_that_skips_everything_gives_no_reward_but_the_tasks() -> None:
    sim = Simulation(rp_with(skip=1.0), 1, catalog=CATALOG)
    assert program_rewards(sim, 3) == []


def test_a_tired_teacher_gives_fewer_judgements_each_episode() -> None:
    sim = Simulation(rp_with(fatigue=1.0), 1, catalog=CATALOG)
    per_episode = [len(program_rewards(sim, 1)) for _ in range(3)]
    assert per_episode[0] > 0 and per_episode[1:] == [0, 0]


def test_a_lenient_teacher_never_punishes_and_says_so() -> None:
    lenient = program_rewards(Simulation(rp_with(bias=1.0), 2, catalog=CATALOG), 3)
    assert {e.value for e in lenient} == {1.0}
    assert any(e.note == "rp, lenient" for e in lenient)


def test_the_delays_follow_their_distribution() -> None:
    program = load_trainer(CATALOG, "rp")
    red, stop = CATALOG.stimulus("Red").id, CATALOG.behaviour("stop").id
    decision = Decision(stop, red, 1.0, How.RELEASED)
    teacher = Teacher(program, Imperfections(delay_s=1.0), 0, DT_S)
    late = []
    for tick in range(4000):
        j = teacher.judge(decision, tick, 0)
        assert j is not None and j.tick == tick
        late.append(j.due - tick - 1)
    mean = sum(late) / len(late)
    assert 9.5 < mean < 10.5  # 1 s of 0.1 s ticks
    assert min(late) < 3 and max(late) > 25  # spread: a gamma of shape about 2
    fixed = Teacher(program, Imperfections(delay_s=1.0, delay_cv=0.0), 0, DT_S)
    judged = [fixed.judge(decision, t, 0) for t in range(50)]
    assert {j.due - j.tick for j in judged if j is not None} == {11}


def test_a_checkpoint_carries_the_teachers_draws() -> None:
    condition = rp_with(mistake=0.3, skip=0.3)
    sim = Simulation(condition, 6, catalog=CATALOG)
    run(condition, 6, 2, catalog=CATALOG, simulation=sim)
    state = decode(encode(export_state(sim)))
    went_on = program_rewards(sim, 2)
    restored = restore_simulation(condition, 6, state, CATALOG)
    assert program_rewards(restored, 2) == went_on


def test_the_teacher_parameters_set_the_conditions_teacher() -> None:
    rp = get_condition("rp")
    condition, _ = configure(rp, {"teacher_mistake": 0.2, "teacher_delay_s": 1.5, "eta": 0.3})
    assert condition.teacher == Imperfections(mistake=0.2, delay_s=1.5)
    assert configure(rp)[0].teacher == PERFECT
    assert teacher_params(Imperfections(skip=0.5, delay_cv=0.0)) == {
        "teacher_skip": 0.5,
        "teacher_delay_cv": 0.0,
    }
    assert teacher_params(PERFECT) == {}


def test_presets_and_changes_parse_from_the_command_line() -> None:
    presets = teacher_presets()
    assert presets["perfect"] == PERFECT and PERFECT.perfect
    assert not any(t.perfect for n, t in presets.items() if n != "perfect")
    assert parse_teacher("human,skip=0") == replace(presets["human"], skip=0.0)
    assert parse_teacher("mistake=0.2, delay_s=1") == Imperfections(mistake=0.2, delay_s=1.0)
    with pytest.raises(UnknownNameError, match=r"unknown teacher 'nope'.*human"):
        parse_teacher("nope")
    with pytest.raises(UnknownNameError, match=r"'anger'.*" + ", ".join(IMPERFECTIONS)):
        parse_teacher("anger=1")
    with pytest.raises(TeacherError, match=r"mistake must be in \[0, 1\]"):
        parse_teacher("mistake=2")
    with pytest.raises(TeacherError, match="'x' is not a number"):
        parse_teacher("skip=x")
    with pytest.raises(TeacherError, match="must come first"):
        parse_teacher("skip=0.1,human")


def test_the_presets_file_is_not_a_reinforcement_program(tmp_path: Path) -> None:
    with pytest.raises(UnknownNameError, match="teachers"):
        load_trainer(CATALOG, "teachers")
    (tmp_path / "trainers").mkdir()
    (tmp_path / "trainers" / "teachers.toml").write_text("[odd]\nanger = 1\n")
    with pytest.raises(CatalogError, match="unknown imperfections"):
        teacher_presets(tmp_path)
