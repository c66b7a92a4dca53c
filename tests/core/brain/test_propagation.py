"""Knowledge propagation by hand: RSTM recording, reasoning, RLTM Eq. (1), promotion, synthesis.

A camera stimulus (high level) is perceived at tick 1; the sonar S-R behaviours of the same
objective that fire shortly after are recorded in the camera sensor's RSTM, and a reward
teaches the camera stimulus the vector sum of their motions.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from core.brain.catalog import Behaviour, Catalog, load_catalog
from core.brain.network import Association, BehaviourNetwork
from core.brain.propagation import (
    KnowledgePropagation,
    KpConfig,
    Propagated,
    RstmRecord,
    nearest_primitive,
    resultant_direction,
    steer_angle,
    synthesized_behaviour,
)
from core.brain.selection import Decision, How
from core.events import AssociationDemoted, AssociationPromoted

DT = 0.1
ETA = 0.3
WINDOW = 5


class Harness:
    """A KP module over the shipped catalogue and the "kp" knowledge set, with ids by name."""

    def __init__(self, config: KpConfig) -> None:
        self.catalog: Catalog = load_catalog()
        self.network = BehaviourNetwork.from_specs(
            self.catalog, self.catalog.knowledge_set("kp").associations
        )
        self.added: list[Behaviour] = []
        self.kp = KnowledgePropagation(self.catalog, self.network, config, DT, self.add)

    def add(self, behaviour: Behaviour) -> Behaviour:
        """The brain's callback: append the behaviour to the catalogue, return it with its id."""
        self.catalog = self.catalog.with_behaviour(behaviour)
        added = self.catalog.behaviours[-1]
        self.added.append(added)
        return added

    def s(self, name: str) -> int:
        return self.catalog.stimulus(name).id

    def b(self, name: str) -> int:
        return self.catalog.behaviour(name).id

    def released(self, stimulus: str, behaviour: str, how: How = How.RELEASED) -> Decision:
        return Decision(self.b(behaviour), self.s(stimulus), 1.0, how)

    def approach(self, start: int = 1) -> None:
        """Camera M_M at `start`; sonar front -> rightturn45 (2 ticks later, running one
        more tick), then sonar left -> rightturn30 (4 ticks later)."""
        kp = self.kp
        mm = self.s("Obstacle_M_M")
        front = self.s("SonarObstacleFront")
        left = self.s("SonarObstacleLeft")
        kp.percept(start, [mm], Decision(self.b("goforward3"), mm, 0.3, How.DEFAULT))
        kp.percept(start + 2, [front], self.released("SonarObstacleFront", "rightturn45"))
        kp.percept(
            start + 3,
            [front],
            self.released("SonarObstacleFront", "rightturn45", How.CONTINUED),
        )
        kp.percept(start + 4, [left], self.released("SonarObstacleLeft", "rightturn30"))


def kp_config(
    *,
    synthesize: bool = False,
    snap_tolerance_deg: float = 1.0,
    insert_threshold: float = 0.5,
    rstm_capacity: int = 256,
) -> KpConfig:
    return KpConfig(
        enabled=True,
        window_ticks=WINDOW,
        eta=ETA,
        insert_threshold=insert_threshold,
        synthesize=synthesize,
        snap_tolerance_deg=snap_tolerance_deg,
        rstm_capacity=rstm_capacity,
    )


def heading_sum_deg(turns_deg: list[float]) -> float:
    """The direction of the sum of unit vectors at the given headings, by hand."""
    x = sum(math.cos(math.radians(t)) for t in turns_deg)
    y = sum(math.sin(math.radians(t)) for t in turns_deg)
    return math.degrees(math.atan2(y, x))


# --- RSTM ---------------------------------------------------------------------------------


def test_percept_records_released_low_responses_after_the_high_stimulus() -> None:
    h = Harness(kp_config())
    h.approach(start=1)
    mm = h.s("Obstacle_M_M")
    assert set(h.kp.rstm) == {"camera_obstacle"}
    assert list(h.kp.rstm["camera_obstacle"]) == [
        RstmRecord(3, mm, h.s("SonarObstacleFront"), h.b("rightturn45")),
        RstmRecord(5, mm, h.s("SonarObstacleLeft"), h.b("rightturn30")),
    ]


def test_percept_records_up_to_window_ticks_after_the_high_stimulus() -> None:
    h = Harness(kp_config())
    mm = h.s("Obstacle_M_M")
    kp = h.kp
    kp.percept(1, [mm], Decision(h.b("goforward3"), mm, 0.3, How.DEFAULT))
    kp.percept(1 + WINDOW, [], h.released("SonarObstacleFront", "rightturn45"))
    kp.percept(2 + WINDOW, [], h.released("SonarObstacleLeft", "rightturn30"))
    assert [r.tick for r in kp.rstm["camera_obstacle"]] == [1 + WINDOW]


def test_percept_window_restarts_while_the_high_stimulus_stays_active() -> None:
    h = Harness(kp_config())
    mm = h.s("Obstacle_M_M")
    front = h.s("SonarObstacleFront")
    kp = h.kp
    kp.percept(1, [mm], Decision(h.b("goforward3"), mm, 0.3, How.DEFAULT))
    kp.percept(10, [mm, front], h.released("SonarObstacleFront", "rightturn45"))
    kp.percept(10 + WINDOW, [], h.released("SonarObstacleLeft", "rightturn30"))
    assert [r.tick for r in kp.rstm["camera_obstacle"]] == [10, 10 + WINDOW]


@pytest.mark.parametrize("how", [How.CONTINUED, How.EXPLORED, How.DEFAULT, How.COMMANDED])
def test_percept_ignores_responses_that_were_not_released(how: How) -> None:
    h = Harness(kp_config())
    mm = h.s("Obstacle_M_M")
    h.kp.percept(1, [mm], Decision(h.b("goforward3"), mm, 0.3, How.DEFAULT))
    h.kp.percept(2, [], h.released("SonarObstacleFront", "rightturn45", how))
    assert not h.kp.rstm["camera_obstacle"]


def test_percept_ignores_low_responses_without_a_high_stimulus_first() -> None:
    h = Harness(kp_config())
    front = h.s("SonarObstacleFront")
    h.kp.percept(1, [front], h.released("SonarObstacleFront", "rightturn45"))
    mm = h.s("Obstacle_M_M")
    h.kp.percept(2, [mm], Decision(h.b("goforward3"), mm, 0.3, How.DEFAULT))
    assert not any(h.kp.rstm.values())


def test_percept_ignores_other_objectives_and_high_level_responses() -> None:
    h = Harness(kp_config())
    mm = h.s("Obstacle_M_M")
    red = h.s("Red")
    kp = h.kp
    kp.percept(1, [mm, red], Decision(h.b("goforward3"), mm, 0.3, How.DEFAULT))
    # A wall response (objective avoid_wall) is not an obstacle response.
    kp.percept(2, [], h.released("LeftWall", "leftwallavoid"))
    # A response of the high-level stimulus itself is not a low-level one.
    kp.percept(3, [mm], h.released("Obstacle_M_M", "rightturn45"))
    # The signal has no low-level sensor, so a red lamp is never a KP percept.
    kp.percept(4, [red], h.released("Red", "stop"))
    assert not any(h.kp.rstm.values())


def test_reset_episode_forgets_the_rstm_and_the_high_stimulus() -> None:
    h = Harness(kp_config())
    h.approach()
    h.kp.reset_episode()
    assert not h.kp.rstm["camera_obstacle"]
    h.kp.percept(6, [], h.released("SonarObstacleFront", "rightturn45"))
    assert not h.kp.rstm["camera_obstacle"]


def test_rstm_keeps_only_its_capacity() -> None:
    h = Harness(kp_config(rstm_capacity=2))
    h.approach()
    mm = h.s("Obstacle_M_M")
    h.kp.percept(6, [mm], h.released("SonarObstacleRight", "leftturn30"))
    assert [r.tick for r in h.kp.rstm["camera_obstacle"]] == [5, 6]


# --- reasoning ----------------------------------------------------------------------------


def test_resultant_direction_is_the_vector_sum_of_headings() -> None:
    catalog = load_catalog()
    rt45 = catalog.behaviour("rightturn45")
    rt30 = catalog.behaviour("rightturn30")
    got = resultant_direction([rt45, rt30], DT)
    assert math.degrees(got) == pytest.approx(heading_sum_deg([-45, -30]), abs=1e-9)
    assert math.degrees(got) == pytest.approx(-37.5, abs=1e-9)


def test_opposite_turns_cancel_to_straight_ahead() -> None:
    catalog = load_catalog()
    pair = [catalog.behaviour("rightturn30"), catalog.behaviour("leftturn30")]
    assert resultant_direction(pair, DT) == pytest.approx(0.0, abs=1e-12)


def test_resultant_direction_of_nothing_or_standing_still_is_straight_ahead() -> None:
    catalog = load_catalog()
    assert resultant_direction([], DT) == 0.0
    assert resultant_direction([catalog.behaviour("stop")], DT) == 0.0


def test_steer_angle_of_turns_and_forward_primitives() -> None:
    catalog = load_catalog()
    assert math.degrees(steer_angle(catalog.behaviour("rightturn45"), DT)) == pytest.approx(-45)
    assert math.degrees(steer_angle(catalog.behaviour("leftturn30"), DT)) == pytest.approx(30)
    assert steer_angle(catalog.behaviour("goforward5"), DT) == 0.0


@pytest.mark.parametrize(
    ("angle_deg", "expected"),
    [
        (-19.47, "rightturn15"),
        (-23.0, "rightturn30"),
        (0.0, "goforward3"),
        (5.0, "goforward3"),
        (8.0, "leftturn15"),
        (-95.0, "rightturn90"),
        (52.0, "leftturn45"),
    ],
)
def test_nearest_primitive_snaps_to_the_closest_heading(angle_deg: float, expected: str) -> None:
    catalog = load_catalog()
    got = nearest_primitive(catalog, math.radians(angle_deg), DT)
    assert got.name == expected


def test_nearest_primitive_prefers_the_smaller_turn_on_a_tie() -> None:
    catalog = load_catalog()
    assert nearest_primitive(catalog, math.radians(-7.5), DT).name == "goforward3"
    assert nearest_primitive(catalog, math.radians(22.5), DT).name == "leftturn15"


def test_reasoning_snaps_the_vector_sum_to_the_nearest_primitive() -> None:
    h = Harness(kp_config())
    b, new = h.kp.reasoning([h.b("rightturn45"), h.b("rightturn30")])
    assert (b.name, new) == ("rightturn30", False)  # -37.5 deg: a tie, the smaller turn
    b, new = h.kp.reasoning([h.b("leftturn45"), h.b("leftturn45"), h.b("leftturn90")])
    assert heading_sum_deg([45, 45, 90]) == pytest.approx(59.64, abs=0.01)
    assert (b.name, new) == ("leftturn60", False)
    assert h.added == []


def test_a_single_forward_source_keeps_its_speed() -> None:
    h = Harness(kp_config())
    for name in ("goforward1", "goforward3", "goforward5"):
        assert h.kp.reasoning([h.b(name)])[0].name == name
    b, _ = h.kp.reasoning([h.b("goforward1"), h.b("goforward5")])
    assert b.name == "goforward3"  # the mean speed, 0.45 m/s


# --- RLTM, Eq. (1) with d_k = 1, and promotion ----------------------------------------------


def test_reward_applies_eq1_with_d_equal_1_and_promotes_over_the_threshold() -> None:
    h = Harness(kp_config())
    mm, rt15 = h.s("Obstacle_M_M"), h.b("rightturn30")
    sources = (h.b("rightturn45"), h.b("rightturn30"))
    before_net = len(h.network)

    h.approach(start=1)
    learned, promoted = h.kp.reward(1.0)
    assert learned == [Propagated(mm, rt15, sources, 0.0, ETA, False)]
    assert promoted == []
    assert h.kp.rltm == {(mm, rt15): pytest.approx(ETA)}
    assert not h.kp.rstm["camera_obstacle"], "a reward empties the RSTM"
    assert h.network.get(mm, rt15) is None
    assert len(h.network) == before_net

    h.approach(start=20)
    second = ETA + ETA * (1 - ETA)
    learned, promoted = h.kp.reward(1.0)
    assert learned[0].before == pytest.approx(ETA)
    assert learned[0].after == pytest.approx(second)
    assert second >= 0.5
    assert [(p.stimulus, p.behaviour) for p in promoted] == [(mm, rt15)]
    assert isinstance(promoted[0], AssociationPromoted)
    assert promoted[0].source == "kp"
    assert promoted[0].reliability == pytest.approx(second)
    assoc = h.network.get(mm, rt15)
    assert assoc is not None
    assert (assoc.source, assoc.locked) == ("kp", False)
    assert assoc.strength == pytest.approx(second)

    # A further success strengthens the association without promoting it again.
    h.approach(start=40)
    learned, promoted = h.kp.reward(1.0)
    third = second + ETA * (1 - second)
    assert promoted == []
    assoc = h.network.get(mm, rt15)
    assert assoc is not None
    assert assoc.strength == pytest.approx(third)


def test_negative_reward_lowers_rltm_and_removes_the_kp_association_below_threshold() -> None:
    h = Harness(kp_config())
    mm, rt15 = h.s("Obstacle_M_M"), h.b("rightturn30")
    for start in (1, 20):
        h.approach(start)
        h.kp.reward(1.0)
    v = ETA + ETA * (1 - ETA)
    assert h.network.get(mm, rt15) is not None

    h.approach(start=40)
    learned, promoted = h.kp.reward(-1.0)
    assert learned[0].after == pytest.approx(v - ETA * v)
    assert learned[0].after < 0.5
    assert promoted == [AssociationDemoted(mm, rt15, learned[0].after)]
    assert h.network.get(mm, rt15) is None


def _taught(h: Harness) -> tuple[int, int, float]:
    """M_M -> rightturn30 taught by two successful approaches: (s1, b, its reliability)."""
    for start in (1, 20):
        h.approach(start)
        h.kp.reward(1.0)
    mm, rt30 = h.s("Obstacle_M_M"), h.b("rightturn30")
    assert h.network.get(mm, rt30) is not None
    return mm, rt30, ETA + ETA * (1 - ETA)


def test_a_failed_episode_punishes_the_pair_that_ran_and_demotes_it() -> None:
    h = Harness(kp_config())
    mm, rt30, v = _taught(h)
    # The copy runs for two ticks; the episode then fails before any sonar response fires,
    # so the RSTM holds nothing: only the pair that ran can take the blame.
    ran = Decision(rt30, mm, v, How.RELEASED, "kp")
    h.kp.percept(40, [mm], ran)
    h.kp.percept(41, [mm], ran._replace(how=How.CONTINUED))
    assert not h.kp.rstm["camera_obstacle"]
    learned, changes = h.kp.punish(1.0)
    assert [(p.stimulus, p.behaviour, p.sources) for p in learned] == [(mm, rt30, ())]
    assert learned[0].before == pytest.approx(v)
    assert learned[0].after == pytest.approx(v - ETA * v)
    assert learned[0].after < v
    assert h.kp.rltm[(mm, rt30)] == pytest.approx(v - ETA * v)
    assert changes == [AssociationDemoted(mm, rt30, learned[0].after)]
    assert h.network.get(mm, rt30) is None
    point = h.kp.log[(mm, rt30)].history[-1]
    assert (point.reward, point.before, point.after) == (-1.0, learned[0].before, learned[0].after)


def test_a_failed_episode_punishes_what_the_rstm_would_teach_once_with_what_ran() -> None:
    h = Harness(kp_config())
    mm, rt30, v = _taught(h)
    h.kp.percept(40, [mm], Decision(rt30, mm, v, How.RELEASED, "kp"))
    h.approach(start=41)  # the sonar's responses, which reason to rightturn30 too
    learned, _ = h.kp.punish(0.5)
    assert [(p.stimulus, p.behaviour) for p in learned] == [(mm, rt30)], "punished once"
    assert learned[0].sources == (h.b("rightturn45"), h.b("rightturn30"))
    assert learned[0].after == pytest.approx(v - 0.5 * ETA * v)
    assert not h.kp.rstm["camera_obstacle"], "a punishment empties the RSTM as a reward does"


def test_a_reward_settles_what_ran_before_it() -> None:
    h = Harness(kp_config())
    mm, rt30, v = _taught(h)
    h.kp.percept(40, [mm], Decision(rt30, mm, v, How.RELEASED, "kp"))
    h.kp.reward(1.0)  # the lap's reward credits the run; a later failure does not undo it
    after_reward = h.kp.rltm[(mm, rt30)]
    assert h.kp.punish(1.0) == ([], [])
    assert h.kp.rltm[(mm, rt30)] == after_reward
    h.kp.percept(60, [mm], Decision(rt30, mm, v, How.RELEASED, "kp"))
    h.kp.reset_episode()  # a new episode: what ran in the last one is not blamed now
    assert h.kp.punish(1.0) == ([], [])


def test_failure_penalty_must_be_a_reward_size() -> None:
    with pytest.raises(ValueError, match="failure_penalty"):
        KpConfig(failure_penalty=1.5)
    with pytest.raises(ValueError, match="penalty"):
        Harness(kp_config()).kp.punish(-0.1)


def test_kp_never_overwrites_nor_removes_a_designed_association() -> None:
    h = Harness(kp_config())
    mm, rt15 = h.s("Obstacle_M_M"), h.b("rightturn30")
    h.network.put(Association(mm, rt15, 0.9, "designed"))
    for start, value in ((1, 1.0), (20, 1.0), (40, -1.0)):
        h.approach(start)
        _, promoted = h.kp.reward(value)
        assert promoted == []
        assert h.network.get(mm, rt15) == Association(mm, rt15, 0.9, "designed")
    v = ETA + ETA * (1 - ETA)
    assert h.kp.rltm[(mm, rt15)] == pytest.approx(v - ETA * v)


def test_reward_without_records_learns_nothing() -> None:
    h = Harness(kp_config())
    assert h.kp.reward(1.0) == ([], [])
    assert h.kp.rltm == {}


def test_each_high_stimulus_learns_from_its_own_records() -> None:
    h = Harness(kp_config())
    mm, mr = h.s("Obstacle_M_M"), h.s("Obstacle_M_R")
    kp = h.kp
    kp.percept(1, [mm], Decision(h.b("goforward3"), mm, 0.3, How.DEFAULT))
    kp.percept(2, [], h.released("SonarObstacleFront", "rightturn45"))
    kp.percept(3, [], h.released("SonarObstacleLeft", "rightturn30"))
    kp.percept(4, [mr], Decision(h.b("goforward3"), mr, 0.3, How.DEFAULT))
    kp.percept(5, [], h.released("SonarObstacleRight", "leftturn30"))
    learned, _ = kp.reward(1.0)
    assert [(p.stimulus, p.behaviour, p.sources) for p in learned] == [
        (mm, h.b("rightturn30"), (h.b("rightturn45"), h.b("rightturn30"))),
        (mr, h.b("leftturn30"), (h.b("leftturn30"),)),  # one source propagates as itself
    ]


# --- synthesis ------------------------------------------------------------------------------


def test_synthesize_creates_registers_and_reuses_a_new_behaviour() -> None:
    h = Harness(kp_config(synthesize=True, snap_tolerance_deg=1.0))
    mm = h.s("Obstacle_M_M")
    n = len(h.catalog.behaviours)
    angle = resultant_direction(
        [h.catalog.behaviour(x) for x in ("rightturn45", "rightturn30")], DT
    )

    h.approach(start=1)
    learned, promoted = h.kp.reward(1.0)
    assert len(h.added) == 1
    new = h.added[0]
    assert new.id == n
    assert new.name == f"kp_right{round(abs(math.degrees(angle)))}"
    assert new.name in ("kp_right37", "kp_right38")  # -37.5 deg, to within rounding
    assert (new.mode, new.family, new.synthesized) == ("steer", "synthesized", True)
    assert new.speed_mps == pytest.approx(0.25)
    assert math.degrees(steer_angle(new, DT)) == pytest.approx(math.degrees(angle), abs=1e-6)
    assert abs(new.turn_dps) <= 150.0
    assert learned == [Propagated(mm, n, (h.b("rightturn45"), h.b("rightturn30")), 0.0, ETA, True)]
    assert promoted == []
    assert h.kp.catalog.behaviours[n] == new

    h.approach(start=20)
    learned, promoted = h.kp.reward(1.0)
    assert len(h.added) == 1, "the synthesised behaviour is reused, not made again"
    assert [(p.behaviour, p.synthesized) for p in learned] == [(n, False)]
    assert learned[0].after == pytest.approx(ETA + ETA * (1 - ETA))
    assert promoted == [AssociationPromoted(mm, n, learned[0].after, "kp")]
    assoc = h.network.get(mm, n)
    assert assoc is not None
    assert assoc.source == "kp"


def test_synthesize_keeps_a_primitive_within_the_snap_tolerance() -> None:
    h = Harness(kp_config(synthesize=True, snap_tolerance_deg=1.0))
    b, new = h.kp.reasoning([h.b("rightturn30")])  # exactly its own heading
    assert (b.name, new) == ("rightturn30", False)
    h2 = Harness(kp_config(synthesize=True, snap_tolerance_deg=8.0))
    b, new = h2.kp.reasoning([h2.b("rightturn45"), h2.b("rightturn30")])  # 7.5 deg off
    assert (b.name, new) == ("rightturn30", False)
    assert h.added == h2.added == []


def test_synthesized_behaviour_turns_at_most_150_degrees_per_second() -> None:
    b = synthesized_behaviour(math.radians(37.0), 0.2, DT)
    assert (b.name, b.ticks, b.mode) == ("kp_left37", 3, "steer")
    assert b.turn_dps == pytest.approx(37.0 / 0.3)
    assert math.degrees(steer_angle(b, DT)) == pytest.approx(37.0)
    assert synthesized_behaviour(math.radians(-15.0), 0.2, DT).ticks == 1


# --- properties: reasoning gives back what it was taught ----------------------------------

_PRIMITIVES = [b.name for b in load_catalog().behaviours if b.family in ("forward", "turn")]


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(_PRIMITIVES), n=st.integers(1, 12), synthesize=st.booleans())
def test_n_copies_of_one_primitive_propagate_as_that_primitive(
    name: str, n: int, synthesize: bool
) -> None:
    h = Harness(kp_config(synthesize=synthesize))
    b, new = h.kp.reasoning([h.b(name)] * n)
    assert (b.name, new) == (name, False)
    assert h.added == []


@settings(max_examples=60, deadline=None)
@given(angle=st.floats(-89.0, 89.0), n=st.integers(1, 6))
@example(angle=2.5, n=1)  # its sum's name rounds to kp_left3, its own to kp_left2
def test_a_synthesised_source_propagates_as_itself(angle: float, n: int) -> None:
    h = Harness(kp_config(synthesize=True, snap_tolerance_deg=1.0))
    source = h.add(synthesized_behaviour(math.radians(angle), 0.25, DT))
    h.kp.catalog = h.catalog  # as the brain does when KP synthesises a behaviour
    b, new = h.kp.reasoning([source.id] * n)
    summed = resultant_direction([source] * n, DT)
    nearest = nearest_primitive(h.catalog, summed, DT, 0.25)
    if abs(steer_angle(nearest, DT) - summed) <= math.radians(1.0):
        assert (b.id, new) == (nearest.id, False)  # a primitive within tolerance stands in
    else:
        assert (b.id, new) == (source.id, False)
    assert len(h.added) == 1


@settings(max_examples=60, deadline=None)
@given(names=st.lists(st.sampled_from(_PRIMITIVES), min_size=1, max_size=6))
def test_mirrored_sources_propagate_as_the_mirrored_behaviour(names: list[str]) -> None:
    h = Harness(kp_config())

    def mirror(name: str) -> str:
        if name.startswith("left"):
            return "right" + name[4:]
        if name.startswith("right"):
            return "left" + name[5:]
        return name

    b, _ = h.kp.reasoning([h.b(n) for n in names])
    m, _ = h.kp.reasoning([h.b(mirror(n)) for n in names])
    angle = resultant_direction([h.catalog.behaviour(n) for n in names], DT)
    # Exactly midway between two primitives both sides take the smaller turn, so they
    # mirror too; the mirror of a straight-on result is itself.
    assert m.name == mirror(b.name), (names, math.degrees(angle))
