"""What the reflexes would teach: copies reasoned from the RSTM, scored against the probe."""

from __future__ import annotations

import pytest

from core.lab.copies import Copy, copy_report, reflex_copies
from core.run.setup import Setup


def test_copies_are_camera_stimuli_reasoned_from_sonar_responses_and_reproducible() -> None:
    setup = Setup(signal="given")
    copies = reflex_copies(setup, seed=0, episodes=4)
    assert copies, "the reflexes meet the obstacle in four episodes"
    camera = {s.name for s in setup.catalog().stimuli_of_sensor("camera_obstacle")}
    sonar_answers = {"rightturn30", "rightturn45", "leftturn30"}  # kp's design, Fig. 13
    for c in copies:
        assert c.stimulus in camera
        assert c.sources >= 1
        assert 0 <= c.episode < 4
    # One sonar response, or n copies of one, propagates as itself.
    assert {c.behaviour for c in copies if c.sources == 1} <= sonar_answers
    assert reflex_copies(setup, seed=0, episodes=4) == copies


def test_the_report_scores_copies_per_seed_and_among_rewarded_episodes() -> None:
    correct = {"Obstacle_M_L": frozenset({"rightturn30"}), "Obstacle_M_R": frozenset()}
    seed_a = [
        Copy(0, "Obstacle_M_L", "rightturn30", 2, True),
        Copy(1, "Obstacle_M_L", "leftturn30", 1, False),
    ]
    seed_b = [
        Copy(0, "Obstacle_M_R", "leftturn30", 1, True),
        Copy(2, "Obstacle_M_L", "rightturn30", 1, False),
    ]
    report = copy_report([seed_a, seed_b, []], correct)
    assert report.correct.n == 2, "a seed without a copy says nothing"
    assert report.correct.mean == pytest.approx((0.5 + 0.5) / 2)
    assert report.correct_rewarded.mean == pytest.approx((1.0 + 0.0) / 2)
    assert report.by_stimulus["Obstacle_M_L"][:4] == (3, 2, 1, 1)
    assert report.by_stimulus["Obstacle_M_L"][4] == {"rightturn30": 2, "leftturn30": 1}
    assert report.by_stimulus["Obstacle_M_R"][:4] == (1, 0, 1, 0)


def test_the_beacon_teaches_the_cameras_colours_what_the_signal_says() -> None:
    """In `stop-line` the beacon's reflexes would teach the camera's colour stimuli: stop on
    red and yellow, go on green (a copy can be wrong where the lamp changes at the line)."""
    got = reflex_copies(Setup("stop-line", signal="learned"), 1, 8, "beacon-reflexes")
    assert {c.stimulus for c in got} <= {"Red", "Yellow", "Green"}
    assert {c.stimulus for c in got} >= {"Red", "Green"}
    right = {"Red": "stop", "Yellow": "stop", "Green": "goforward3"}
    assert sum(c.behaviour == right[c.stimulus] for c in got) >= 0.8 * len(got)
