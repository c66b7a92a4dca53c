"""Noisy perception (`core.sim.perception`): estimates from a camera and odometry that err.

Constructed situations: the robot placed on the first leg, the obstacle ahead of it, and
each noise raised alone, so that what a stimulus is computed from can be compared with the
truth the exact world gives on the same seed.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest

from core.errors import CatalogError, CoreError
from core.sim.channels import Channel
from core.sim.perception import PerceptionConfig
from core.sim.sensing import UNSEEN
from core.sim.types import MotorCommand, SensorFrame
from core.sim.world import PymunkWorld, WorldConfig
from core.sim.worlds import PERCEPTION_PRESETS, load_world, parse_perception, with_settings

BASE = load_world("soft-obstacle").config
FOV_HALF_DEG = BASE.robot.camera_fov_deg / 2
CAMERA = (
    Channel.OBSTACLE_VISIBLE,
    Channel.OBSTACLE_DISTANCE_M,
    Channel.OBSTACLE_LATERAL_M,
    Channel.OBSTACLE_OFFSET_M,
    Channel.OBSTACLE_IMAGE_X,
)


def world(**noise: float) -> PymunkWorld:
    return PymunkWorld(replace(BASE, perception=PerceptionConfig(**noise)))


def facing(w: PymunkWorld, seed: int, episode: int, ahead: float = 1.2) -> SensorFrame:
    """The robot on the first leg's centre line, the obstacle `ahead` m in front of it."""
    geo = w.geometry
    w.reset(seed, episode)
    x, y = geo.point_on_leg(0, 1.5, 0.0)
    obstacle = geo.point_on_leg(0, 1.5 + ahead, 0.0)
    return w.place(x, y, geo.heading_of_leg(0), obstacle)


def errors(channel: Channel, episodes: int = 400, **noise: float) -> np.ndarray:
    """The channel's estimate minus the truth, one placement per episode."""
    exact, noisy = world(), world(**noise)
    out = []
    for e in range(episodes):
        truth = facing(exact, 7, e).channels[channel]
        out.append(facing(noisy, 7, e).channels[channel] - truth)
    return np.asarray(out)


def drive(
    w: PymunkWorld, seed: int, ticks: int, obstacle_ahead: float | None = 3.0
) -> list[SensorFrame]:
    """The robot placed on the first leg and driven straight at 0.3 m/s for `ticks` ticks,
    the obstacle `obstacle_ahead` m in front of it (None: no obstacle)."""
    geo = w.geometry
    w.reset(seed, 0)
    x, y = geo.point_on_leg(0, 1.0, 0.0)
    obstacle = None if obstacle_ahead is None else geo.point_on_leg(0, 1.0 + obstacle_ahead, 0.3)
    frames = [w.place(x, y, geo.heading_of_leg(0), obstacle)]
    for _ in range(ticks):
        w.apply(MotorCommand(0.3, 0.0))
        frames.append(w.step())
    return frames


def test_perception_is_exact_by_default_and_in_every_preset_but_noisy() -> None:
    assert WorldConfig().perception.exact and BASE.perception.exact
    assert PERCEPTION_PRESETS["exact"] == ()
    noisy = with_settings(BASE, PERCEPTION_PRESETS["noisy"]).perception
    assert not noisy.exact and noisy.camera_miss_rate == 0.2


def test_perception_is_named_by_a_preset_its_settings_one_by_one_or_both() -> None:
    noisy = PERCEPTION_PRESETS["noisy"]
    assert parse_perception("noisy") == noisy
    # Settings at 0 are exact and left out: one setup, however it is spelled.
    assert parse_perception("exact") == parse_perception("camera_miss_rate=0") == ()
    assert parse_perception("camera_miss_rate=0.5, odometry_drift_m=0.1") == (
        ("perception.camera_miss_rate", 0.5),
        ("perception.odometry_drift_m", 0.1),
    )
    # In order: a preset sets every setting, a setting after it changes one.
    assert dict(parse_perception("noisy,camera_miss_rate=0.5")) == {
        **dict(noisy),
        "perception.camera_miss_rate": 0.5,
    }
    assert parse_perception("camera_miss_rate=0.5,noisy") == noisy
    assert parse_perception("noisy,exact") == ()


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("blurry", "unknown perception 'blurry'"),
        ("sonar_noise_m=0.1", "unknown perception setting 'sonar_noise_m'"),
        ("camera_miss_rate=2", "camera_miss_rate must be in [0, 1]"),
        ("camera_bearing_sd_deg=wide", "'wide' is not a number"),
    ],
)
def test_an_unknown_or_out_of_bounds_perception_is_refused_naming_it(text: str, says: str) -> None:
    with pytest.raises(CoreError, match=re.escape(says)):
        parse_perception(text)


def test_noise_leaves_every_other_channel_and_the_physics_as_they_were() -> None:
    noise = {"camera_range_sd_m": 0.1, "camera_bearing_sd_deg": 3.0, "camera_miss_rate": 0.2}
    exact, noisy = drive(world(), 4, 60), drive(world(**noise), 4, 60)
    others = [c for c in range(32) if c not in CAMERA]
    for a, b in zip(exact, noisy, strict=True):
        assert (a.x, a.y, a.heading_rad, a.lamp, a.collision) == (
            b.x,
            b.y,
            b.heading_rad,
            b.lamp,
            b.collision,
        )
        assert np.array_equal(a.channels[others], b.channels[others])
    seen = [a for a in exact if a.channels[Channel.OBSTACLE_VISIBLE] > 0]
    assert seen, "the drive must meet the obstacle for the camera to err on it"
    assert any(
        not np.array_equal(a.channels[list(CAMERA)], b.channels[list(CAMERA)])
        for a, b in zip(exact, noisy, strict=True)
    )


def test_the_same_seed_and_episode_give_the_same_noise_and_another_episode_other() -> None:
    noise = {"camera_range_sd_m": 0.2, "camera_bearing_sd_deg": 5.0}
    a, b = facing(world(**noise), 3, 1), facing(world(**noise), 3, 1)
    assert np.array_equal(a.channels, b.channels)
    c = facing(world(**noise), 3, 2)
    assert c.channels[Channel.OBSTACLE_DISTANCE_M] != a.channels[Channel.OBSTACLE_DISTANCE_M]


def test_a_camera_that_misses_every_detection_never_sees_the_obstacle() -> None:
    exact = drive(world(), 4, 60)
    blind = drive(world(camera_miss_rate=1.0), 4, 60)
    assert any(f.channels[Channel.OBSTACLE_VISIBLE] > 0 for f in exact)
    for f in blind:
        assert f.channels[Channel.OBSTACLE_VISIBLE] == 0
        for c in CAMERA[1:]:
            assert f.channels[c] == UNSEEN


def test_missed_detections_are_about_the_rate_asked() -> None:
    missed = errors(Channel.OBSTACLE_VISIBLE, camera_miss_rate=0.3)
    assert set(np.unique(missed)) <= {-1.0, 0.0}
    assert np.mean(missed == -1.0) == pytest.approx(0.3, abs=0.06)


def test_range_errors_have_the_declared_spread_and_no_bias() -> None:
    err = errors(Channel.OBSTACLE_DISTANCE_M, camera_range_sd_m=0.1)
    assert np.std(err) == pytest.approx(0.1, rel=0.12)
    assert abs(np.mean(err)) < 0.02
    assert np.all(errors(Channel.OBSTACLE_IMAGE_X, 20, camera_range_sd_m=0.1) == 0)


def test_bearing_errors_move_the_image_and_the_obstacle_across_the_corridor() -> None:
    image = errors(Channel.OBSTACLE_IMAGE_X, camera_bearing_sd_deg=4.0)
    assert np.std(image) == pytest.approx(4.0 / FOV_HALF_DEG, rel=0.12)
    lateral = errors(Channel.OBSTACLE_LATERAL_M, camera_bearing_sd_deg=4.0)
    # The cross-range error of a bearing: the range (1.2 m) times the bearing error.
    assert np.std(lateral) == pytest.approx(1.2 * math.radians(4.0), rel=0.12)
    assert np.all(errors(Channel.OBSTACLE_DISTANCE_M, 20, camera_bearing_sd_deg=4.0) == 0)


def test_odometry_drift_grows_with_the_distance_travelled() -> None:
    def spread(ticks: int) -> float:
        out = []
        for seed in range(150):
            exact = drive(world(), seed, ticks, None)[-1]
            noisy = drive(world(odometry_drift_m=0.05), seed, ticks, None)[-1]
            lateral = Channel.LATERAL_OFFSET_M
            out.append(noisy.channels[lateral] - exact.channels[lateral])
        return float(np.std(out))

    # 0.3 m/s: 0.6 m after 20 ticks, 2.4 m after 80; a random walk's spread doubles.
    near, far = spread(20), spread(80)
    assert near == pytest.approx(0.05 * math.sqrt(0.6), rel=0.2)
    assert far == pytest.approx(2 * near, rel=0.25)


def test_a_drifted_robot_measures_its_sonars_against_the_map_from_where_it_believes_it_is() -> None:
    exact = drive(world(), 5, 60, None)
    drifted = drive(world(odometry_drift_m=0.05), 5, 60, None)
    lateral = Channel.LATERAL_OFFSET_M
    moved = 0
    for a, b in zip(exact, drifted, strict=True):
        drift = b.channels[lateral] - a.channels[lateral]
        moved += abs(drift) > 0.01
        # What the sonars read is the world's; only what the map predicts moves.
        assert np.array_equal(a.channels[:8], b.channels[:8])
        residual = b.channels[8:16] - a.channels[8:16]
        # Believed `drift` further left: the left wall is predicted nearer by the drift
        # along a sonar's axis (+90 and +44 degrees), the right one farther.
        for sonar, sign in ((0, -1), (1, -1), (4, 1), (5, 1)):
            along = abs(math.sin(math.radians(BASE.robot.sonar_angles_deg[sonar])))
            assert residual[sonar] == pytest.approx(sign * drift / along, abs=1e-9)
    assert moved > 20, "the drive must drift for the residuals to move"


@pytest.mark.parametrize(
    ("setting", "value", "says"),
    [
        ("camera_miss_rate", 1.5, "a probability"),
        ("camera_range_sd_m", -0.1, "0 or more"),
        ("odometry_drift_m", math.inf, "must be finite"),
    ],
)
def test_bad_perception_settings_are_refused_naming_them(
    setting: str, value: float, says: str
) -> None:
    with pytest.raises(CatalogError, match=f"perception.{setting}.*{says}|{says}"):
        with_settings(BASE, ((f"perception.{setting}", value),))
