"""Short runs of each outside world, deterministic by seed, and the CLI end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import worlds_or_skip  # noqa: F401  # before the environments: skips the module without them

from bench.outside import measure
from core.outside.lab import per_seed
from core.outside.run import run_seed
from core.outside.world import load_outside
from server.cli import main

WORLDS = ("minigrid-dynamic", "irsim-corridor")


@pytest.mark.parametrize("name", WORLDS)
def test_a_short_run_is_the_same_on_the_same_seed(name: str) -> None:
    world = load_outside(name)
    kp = world.condition("kp")
    first = run_seed(world, kp, 3, episodes=4, held_out=2)
    again = run_seed(world, kp, 3, episodes=4, held_out=2)
    other = run_seed(world, kp, 4, episodes=4, held_out=2)
    assert first == again
    assert first.episodes != other.episodes
    assert all(e.outcome in ("success", "collision", "timeout") for e in first.episodes)
    assert sum(first.origins.values()) == sum(e.ticks for e in first.episodes)


@pytest.mark.parametrize("name", WORLDS)
def test_the_reflex_does_better_than_innate_knowledge(name: str) -> None:
    # The world's first property, on a few seeds: the low-level reflex is wired to the world.
    world = load_outside(name)
    innate = [run_seed(world, world.condition("innate"), s, 6, 1) for s in range(2)]
    reflex = [run_seed(world, world.condition("reflex"), s, 6, 1) for s in range(2)]
    assert sum(per_seed(reflex, "success")) > sum(per_seed(innate, "success"))


def test_kp_copies_the_reflex_to_the_view() -> None:
    world = load_outside("minigrid-dynamic")
    kp = run_seed(world, world.condition("kp"), 0, episodes=25, held_out=1)
    sonar = run_seed(world, world.condition("sonar"), 0, episodes=25, held_out=1)
    assert kp.origins.get("kp", 0) > 0
    assert "kp" not in sonar.origins
    assert kp.answers["BallNear_M"] in ("left", "right")


def test_the_cli_runs_an_experiment_on_two_seeds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "res"
    argv = ["outside", "experiment", "minigrid-dynamic", "--seeds", "2", "--episodes", "3",
            "--held-out", "2", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    summary = (out / "summary.md").read_text()
    assert summary.splitlines()[0] == f"# `srlab {' '.join(argv)}`"
    assert "| kp - sonar | all |" in summary
    assert "| kp - sonar | held-out |" in summary
    report = json.loads((out / "summary.json").read_text())
    assert report["seeds"] == [0, 1]
    assert [r["on"] for r in report["declared"]] == ["all", "held-out"]
    assert {p["key"] for p in report["properties"]["properties"]} == {"1", "2", "3"}
    assert "kp - sonar" in capsys.readouterr().out


@pytest.mark.parametrize("name", WORLDS)
def test_the_bench_times_the_three_steps(name: str) -> None:
    bare, adapter, brain = measure(load_outside(name), 60)
    assert min(bare, adapter, brain) > 0.0
