"""The channels mappings on constructed observations (no environment needed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.outside import irsim as irs
from core.outside import minigrid as mg


def _view(cells: dict[tuple[int, int], int]) -> np.ndarray:
    image = np.zeros((7, 7, 3), dtype=np.uint8)
    image[:, :, 0] = mg.EMPTY
    for (x, y), kind in cells.items():
        image[x, y, 0] = kind
    return image


def _named(values: list[float]) -> dict[str, float]:
    return dict(zip(mg.CHANNELS, values, strict=True))


def test_an_empty_view_sees_nothing() -> None:
    c = _named(mg.channels_of(_view({})))
    assert c["front_ball"] == c["front_wall"] == 0.0
    assert c["left_free"] == c["right_free"] == 1.0
    assert c["ball_ahead_cells"] == c["ball_left_cells"] == c["ball_right_cells"] == mg.NONE
    assert c["goal_visible"] == 0.0


def test_the_cell_ahead_is_the_agents_column_one_row_up() -> None:
    c = _named(mg.channels_of(_view({(3, 5): mg.BALL, (2, 6): mg.WALL})))
    assert c["front_ball"] == 1.0
    assert c["ball_ahead_cells"] == 1.0
    assert c["left_free"] == 0.0
    assert c["right_free"] == 1.0


def test_farther_balls_count_rows_ahead_in_each_column() -> None:
    c = _named(mg.channels_of(_view({(3, 3): mg.BALL, (2, 4): mg.BALL, (4, 1): mg.BALL})))
    assert c["front_ball"] == 0.0
    assert (c["ball_ahead_cells"], c["ball_left_cells"], c["ball_right_cells"]) == (3, 2, 5)


def test_the_goal_is_placed_relative_to_the_agent() -> None:
    c = _named(mg.channels_of(_view({(1, 6): mg.GOAL, (3, 5): mg.WALL})))
    assert c["front_wall"] == 1.0
    assert (c["goal_visible"], c["goal_ahead_cells"], c["goal_side_cells"]) == (1.0, 0.0, 2.0)


def test_lidar_sectors_take_the_shortest_range() -> None:
    # 19 beams over the half-plane ahead, 10 degrees apart, from -90 (right) to +90.
    ranges = [4.0] * 19
    ranges[9] = 1.5  # straight ahead
    ranges[13] = 0.5  # 40 degrees left
    ranges[4] = 0.8  # 50 degrees right
    front, left, right = irs.lidar_channels(ranges, -math.pi / 2, math.pi / 18)
    assert (front, left, right) == (1.5, 0.5, 0.8)


def test_the_detector_reports_the_nearest_seen_obstacle() -> None:
    gap, bearing = irs.seen_channels((0.0, 0.0, 0.0), [(3.0, 0.0, 0.3), (1.0, 1.0, 0.3)], 0.2)
    assert gap == pytest.approx(math.sqrt(2) - 0.5)
    assert bearing == pytest.approx(45.0)
    assert irs.seen_channels((0.0, 0.0, 0.0), [], 0.2) == [irs.NONE, irs.NONE]


def test_the_goal_bearing_is_relative_to_the_heading() -> None:
    d, bearing = irs.goal_channels((1.0, 1.0, math.pi / 2), (2.0, 1.0))
    assert d == pytest.approx(1.0)
    assert bearing == pytest.approx(-90.0)
