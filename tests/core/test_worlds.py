"""World presets: named worlds as data, and whether they pose the paper's problem."""

from __future__ import annotations

import pytest

from core.errors import CatalogError, UnknownNameError
from core.experiment import LocalBackend
from core.sim.world import WorldConfig
from core.worldcheck import world_check
from core.worlds import _apply, default_world, load_world, world_names


def test_every_preset_loads_and_the_default_is_first() -> None:
    names = world_names()
    assert names[0] == default_world()
    assert {"classic", "soft-obstacle"} <= set(names)
    for n in names:
        preset = load_world(n)
        assert preset.name == n
        assert preset.description and preset.reasons, n


def test_classic_is_todays_world_and_soft_obstacle_only_quietens_the_obstacle() -> None:
    assert load_world("classic").config == WorldConfig()
    soft = load_world("soft-obstacle")
    assert soft.overrides == {"track": {"obstacle": {"echo_range_m": 0.3}}}
    assert soft.config.track.obstacle.echo_range_m == 0.3
    assert soft.config.track.obstacle.size_m == WorldConfig().track.obstacle.size_m


def test_an_unknown_world_names_the_known_ones() -> None:
    with pytest.raises(UnknownNameError, match=r"unknown world 'moon'.*classic"):
        load_world("moon")


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"gravity": 1.0}, "unknown setting 'gravity'"),
        ({"robot": 3}, "a table of settings is needed"),
        ({"robot": {"mass_kg": "heavy"}}, "must be a number"),
        ({"max_ticks": 10.5}, "must be a whole number"),
        ({"dt_s": -1.0}, "dt_s and max_ticks must be positive"),
        ({"track": {"obstacle": {"enabled": 1}}}, "must be true or false"),
    ],
)
def test_bad_overrides_are_clear_catalog_errors(overrides: dict[str, object], message: str) -> None:
    with pytest.raises(CatalogError, match=message):
        _apply(WorldConfig(), overrides, "world 'test'")


def test_the_default_world_poses_the_papers_problem_on_a_few_seeds() -> None:
    """(a)-(d) on 4 seeds x 12 episodes, with bounds widened for so few episodes; the full
    figures (20 seeds x 50 episodes) come from `srlab world-check`."""
    results = {r.prop.key: r for r in world_check(default_world(), "path", range(4), 12)}
    assert results["a"].success.mean <= 0.35
    assert 0.25 <= results["b"].success.mean <= 0.90
    assert results["c"].success.mean >= 0.85
    assert results["d"].success.mean <= 0.25
    assert results["c"].success.mean > results["b"].success.mean > results["a"].success.mean


def test_the_classic_world_leaves_the_camera_little_to_add() -> None:
    """Why a new preset was needed: in srlab's first world the sonar reflexes alone pass."""
    results = {
        r.prop.key: r
        for r in world_check("classic", "path", range(3), 10, LocalBackend(1))
        if r.prop.key == "b"
    }
    assert results["b"].success.mean >= 0.9
