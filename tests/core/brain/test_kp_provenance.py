"""KP provenance by hand: what a propagated association was made from, and when it ran.

Camera M_M is perceived at tick 1; sonar front releases rightturn45 at tick 3 and sonar
left rightturn30 at tick 5 (both recorded in the camera sensor's RSTM). A reward reasons
over them: the record keeps both sources, their vector sum and the primitive it snapped to
(or the one synthesised), and the pair's RLTM history; once promoted, the ticks where the
``kp`` association ran.
"""

from __future__ import annotations

import math

import pytest

from core.brain.catalog import Behaviour, Catalog, load_catalog
from core.brain.network import BehaviourNetwork
from core.brain.propagation import (
    KnowledgePropagation,
    KpConfig,
    RltmPoint,
    RstmRecord,
    steer_angle,
)
from core.brain.selection import Decision, How

DT = 0.1
ETA = 0.3


class Kp:
    """A KP module over the shipped catalogue and the "kp" knowledge set, ids by name."""

    def __init__(self, synthesize: bool = False) -> None:
        self.catalog: Catalog = load_catalog()
        self.network = BehaviourNetwork.from_specs(
            self.catalog, self.catalog.knowledge_set("kp").associations
        )
        config = KpConfig(enabled=True, window_ticks=5, eta=ETA, synthesize=synthesize)
        self.kp = KnowledgePropagation(self.catalog, self.network, config, DT, self.add)

    def add(self, behaviour: Behaviour) -> Behaviour:
        self.catalog = self.catalog.with_behaviour(behaviour)
        return self.catalog.behaviours[-1]

    def s(self, name: str) -> int:
        return self.catalog.stimulus(name).id

    def b(self, name: str) -> int:
        return self.catalog.behaviour(name).id

    def approach(self, start: int) -> None:
        mm = self.s("Obstacle_M_M")
        front, left = self.s("SonarObstacleFront"), self.s("SonarObstacleLeft")
        kp = self.kp
        kp.percept(start, [mm], Decision(self.b("goforward3"), mm, 0.3, How.DEFAULT))
        kp.percept(start + 2, [front], Decision(self.b("rightturn45"), front, 1.0, How.RELEASED))
        kp.percept(start + 4, [left], Decision(self.b("rightturn30"), left, 1.0, How.RELEASED))


def test_two_sonar_responses_propagate_with_sources_sum_and_snapped_primitive() -> None:
    k = Kp()
    mm = k.s("Obstacle_M_M")
    rt45, rt30 = k.b("rightturn45"), k.b("rightturn30")
    k.approach(start=1)

    learned, _ = k.kp.reward(1.0)

    assert len(learned) == 1
    p = learned[0].provenance
    assert p is not None
    assert p.stimulus == mm
    assert p.sources == (
        RstmRecord(3, mm, k.s("SonarObstacleFront"), rt45),
        RstmRecord(5, mm, k.s("SonarObstacleLeft"), rt30),
    )
    a45 = steer_angle(k.catalog.behaviours[rt45], DT)
    a30 = steer_angle(k.catalog.behaviours[rt30], DT)
    assert math.degrees(a45) == pytest.approx(-45.0)
    assert math.degrees(a30) == pytest.approx(-30.0)
    assert p.sum_x == pytest.approx(math.cos(a45) + math.cos(a30))
    assert p.sum_y == pytest.approx(math.sin(a45) + math.sin(a30))
    assert math.degrees(p.angle_rad) == pytest.approx(-37.5)
    assert (p.nearest, p.behaviour, p.resolution) == (rt30, rt30, "snapped")
    assert math.degrees(p.nearest_angle_rad) == pytest.approx(-30.0)
    assert p.after_tick == 5

    log = k.kp.log[(mm, rt30)]
    assert list(log.provenances) == [p]
    assert list(log.history) == [RltmPoint(5, 1.0, 0.0, learned[0].after)]
    assert learned[0].after == pytest.approx(ETA)


def test_synthesised_behaviour_is_named_in_the_provenance() -> None:
    k = Kp(synthesize=True)
    k.approach(start=1)
    learned, _ = k.kp.reward(1.0)
    p = learned[0].provenance
    assert p is not None and p.resolution == "synthesized"
    assert p.nearest == k.b("rightturn30") and p.behaviour != p.nearest
    assert k.kp.catalog.behaviours[p.behaviour].synthesized

    k.approach(start=20)
    again, _ = k.kp.reward(1.0)
    assert again[0].provenance is not None
    assert again[0].provenance.resolution == "reused"
    assert again[0].behaviour == p.behaviour


def test_rltm_history_grows_per_reward_and_runs_are_kept_as_tick_spans() -> None:
    k = Kp()
    mm, rt30 = k.s("Obstacle_M_M"), k.b("rightturn30")
    k.approach(start=1)
    k.kp.reward(1.0)
    k.approach(start=20)
    _, promoted = k.kp.reward(1.0)
    assert [(c.stimulus, c.behaviour) for c in promoted] == [(mm, rt30)]
    log = k.kp.log[(mm, rt30)]
    assert [(h.after_tick, h.before) for h in log.history] == [(5, 0.0), (24, pytest.approx(ETA))]
    assert log.reasoned == 2

    # The promoted association releases rightturn30 for M_M at 40 and runs on to 42.
    kp_run = Decision(rt30, mm, 0.5, How.RELEASED, "kp")
    k.kp.percept(40, [mm], kp_run)
    for t in (41, 42):
        k.kp.percept(t, [], Decision(rt30, mm, 0.5, How.CONTINUED, "kp"))
    k.kp.percept(43, [mm], kp_run)  # released again at once: the same stretch
    k.kp.percept(44, [], Decision(k.b("goforward3"), -1, 0.0, How.DEFAULT))
    k.kp.percept(50, [mm], kp_run)
    assert list(log.runs) == [(40, 43), (50, 50)]
    assert log.ran_ticks == 5


def test_the_same_inputs_give_the_same_provenance() -> None:
    def run() -> list[object]:
        k = Kp(synthesize=True)
        out: list[object] = []
        for start in (1, 20, 40):
            k.approach(start)
            learned, _ = k.kp.reward(1.0 if start != 20 else -0.5)
            out.extend(p.provenance for p in learned)
        return out

    assert run() == run()
