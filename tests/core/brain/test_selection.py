"""Behaviour selection: competition, max, priority, exploration and the default."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pytest

from core.brain.catalog import Catalog
from core.brain.network import Association, BehaviourNetwork
from core.brain.perception import Perception
from core.brain.selection import (
    DEFAULT_DESIRES,
    Decision,
    How,
    SelectionConfig,
    Selector,
    Strategy,
)

FLAT = dict.fromkeys(DEFAULT_DESIRES, 1.0)
"""Every desire at 1, so a releaser's value is its association's strength."""


class Names:
    """Stimulus and behaviour ids by name."""

    def __init__(self, catalog: Catalog) -> None:
        self.catalog = catalog

    def s(self, name: str) -> int:
        return self.catalog.stimulus(name).id

    def b(self, name: str) -> int:
        return self.catalog.behaviour(name).id

    def a(self, stimulus: str, behaviour: str, strength: float) -> Association:
        return Association(self.s(stimulus), self.b(behaviour), strength, "designed")


@pytest.fixture
def n(catalog: Catalog) -> Names:
    return Names(catalog)


def selector(
    catalog: Catalog,
    associations: Iterable[Association] = (),
    *,
    strategy: Strategy = Strategy.COMPETITION,
    epsilon: float = 0.0,
    learnable: Iterable[str] = (),
    seed: int = 0,
) -> Selector:
    network = BehaviourNetwork(len(catalog.stimuli), associations)
    config = SelectionConfig(strategy=strategy, epsilon=epsilon, desires=FLAT)
    ids = frozenset(catalog.stimulus(s).id for s in learnable)
    return Selector(catalog, network, Perception(catalog), config, ids, np.random.default_rng(seed))


def test_nothing_active_runs_the_default(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, [n.a("Corner", "leftturn90", 1.0)])
    assert sel.select([], -1) == Decision(n.b("goforward3"), -1, FLAT["keep_moving"], How.DEFAULT)


def test_default_answers_the_most_salient_learnable_stimulus(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, learnable=["Red", "Obstacle_M_M"])
    d = sel.select([n.s("Middle"), n.s("Red")], -1)
    assert (d.behaviour, d.stimulus, d.how) == (n.b("goforward3"), n.s("Red"), How.DEFAULT)
    assert d.origin == "default"


def test_default_is_never_credited_to_a_stimulus_that_is_not_learnable(
    catalog: Catalog, n: Names
) -> None:
    """The keep-moving default is nobody's response: the position layer is never credited
    with it (Middle -> goforward3 would otherwise be rewarded on every successful lap)."""
    sel = selector(catalog, learnable=["Red"])
    d = sel.select([n.s("Middle")], -1)
    assert (d.behaviour, d.stimulus, d.how) == (n.b("goforward3"), -1, How.DEFAULT)
    d = sel.select([n.s("Middle"), n.s("Obstacle_M_M")], -1)
    assert d.stimulus == -1


def test_a_released_decision_names_its_association_source(catalog: Catalog, n: Names) -> None:
    network = [Association(n.s("Red"), n.b("stop"), 0.7, "kp")]
    d = selector(catalog, network).select([n.s("Red")], -1)
    assert (d.behaviour, d.how, d.origin) == (n.b("stop"), How.RELEASED, "kp")


def test_competition_respects_the_threshold(catalog: Catalog, n: Names) -> None:
    threshold = SelectionConfig().threshold
    weak = selector(catalog, [n.a("Red", "stop", threshold - 0.01)])
    assert weak.select([n.s("Red")], -1).how is How.DEFAULT
    enough = selector(catalog, [n.a("Red", "stop", threshold)])
    d = enough.select([n.s("Red")], -1)
    assert (d.behaviour, d.stimulus, d.how) == (n.b("stop"), n.s("Red"), How.RELEASED)
    assert d.value == pytest.approx(threshold)


def test_competition_strongest_wins(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, [n.a("Red", "stop", 0.6), n.a("Middle", "goforward2", 0.9)])
    d = sel.select([n.s("Middle"), n.s("Red")], -1)
    assert (d.behaviour, d.how) == (n.b("goforward2"), How.RELEASED)


def test_competition_hysteresis_keeps_the_incumbent_against_a_close_rival(
    catalog: Catalog, n: Names
) -> None:
    h = SelectionConfig().hysteresis
    active = [n.s("Obstacle_M_M"), n.s("Red")]  # the same layer
    close = selector(catalog, [n.a("Red", "stop", 0.6), n.a("Obstacle_M_M", "back", 0.6 + h / 2)])
    assert close.select(active, -1).behaviour == n.b("back")
    assert close.select(active, n.b("stop")).behaviour == n.b("stop")
    far = selector(catalog, [n.a("Red", "stop", 0.6), n.a("Obstacle_M_M", "back", 0.6 + 2 * h)])
    assert far.select(active, n.b("stop")).behaviour == n.b("back")


def test_competition_hysteresis_never_holds_against_a_higher_layer(
    catalog: Catalog, n: Names
) -> None:
    h = SelectionConfig().hysteresis
    sel = selector(catalog, [n.a("Middle", "goforward3", 0.6), n.a("Red", "stop", 0.6 + h / 2)])
    assert sel.select([n.s("Middle"), n.s("Red")], n.b("goforward3")).behaviour == n.b("stop")


def test_competition_incumbent_below_threshold_gets_no_bonus(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, [n.a("Red", "stop", 0.2), n.a("Red", "back", 0.24)])
    assert sel.select([n.s("Red")], n.b("stop")).how is How.DEFAULT


def test_max_ignores_the_threshold(catalog: Catalog, n: Names) -> None:
    associations = [n.a("Red", "stop", 0.1), n.a("Middle", "goforward1", 0.05)]
    assert selector(catalog, associations).select([n.s("Red")], -1).how is How.DEFAULT
    sel = selector(catalog, associations, strategy=Strategy.MAX)
    d = sel.select([n.s("Middle"), n.s("Red")], -1)
    assert (d.behaviour, d.stimulus, d.how) == (n.b("stop"), n.s("Red"), How.RELEASED)


def test_max_has_no_hysteresis(catalog: Catalog, n: Names) -> None:
    sel = selector(
        catalog, [n.a("Red", "stop", 0.6), n.a("Red", "back", 0.61)], strategy=Strategy.MAX
    )
    assert sel.select([n.s("Red")], n.b("stop")).behaviour == n.b("back")


def test_priority_picks_the_highest_layer(catalog: Catalog, n: Names) -> None:
    associations = [
        n.a("Middle", "goforward5", 0.9),
        n.a("Red", "stop", 0.5),
        n.a("Collision", "back", 0.1),
    ]
    active = [n.s("Middle"), n.s("Red"), n.s("Collision")]
    d = selector(catalog, associations, strategy=Strategy.PRIORITY).select(active, -1)
    assert (d.behaviour, d.stimulus) == (n.b("back"), n.s("Collision"))
    d = selector(catalog, associations).select(active, -1)
    assert d.behaviour == n.b("goforward5")
    d = selector(catalog, associations, strategy=Strategy.PRIORITY).select(active[:2], -1)
    assert d.behaviour == n.b("stop")


def test_ties_go_to_the_higher_layer_then_the_lower_behaviour_id(
    catalog: Catalog, n: Names
) -> None:
    sel = selector(catalog, [n.a("Middle", "goforward1", 0.7), n.a("Red", "stop", 0.7)])
    assert sel.select([n.s("Middle"), n.s("Red")], -1).behaviour == n.b("stop")
    sel = selector(catalog, [n.a("Red", "stop", 0.7), n.a("Red", "goforward1", 0.7)])
    assert sel.select([n.s("Red")], -1).behaviour == min(n.b("stop"), n.b("goforward1"))


def test_perception_weight_scales_values(catalog: Catalog, n: Names) -> None:
    # The sonar obstacle sensor's recognition filter weighs 0.9.
    sel = selector(catalog, [n.a("SonarObstacleFront", "rightturn45", 1.0)])
    d = sel.select([n.s("SonarObstacleFront")], -1)
    weight = next(s.weight for s in catalog.sensors if s.name == "sonar_obstacle")
    assert d.value == pytest.approx(weight)


def test_exploration_tries_a_random_behaviour_for_an_unknown_learnable_stimulus(
    catalog: Catalog, n: Names
) -> None:
    sel = selector(catalog, epsilon=1.0, learnable=["Red"])
    d = sel.select([n.s("Middle"), n.s("Red")], -1)
    assert d.how is How.EXPLORED
    assert d.stimulus == n.s("Red")
    assert 0 <= d.behaviour < len(catalog.behaviours)


def test_exploration_also_tries_over_a_weak_association(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, [n.a("Red", "stop", 0.5)], epsilon=1.0, learnable=["Red"])
    assert sel.select([n.s("Red")], -1).how is How.EXPLORED


def test_exploration_skips_a_confident_stimulus(catalog: Catalog, n: Names) -> None:
    confident = SelectionConfig().confident
    sel = selector(catalog, [n.a("Red", "stop", confident)], epsilon=1.0, learnable=["Red"])
    d = sel.select([n.s("Red")], -1)
    assert (d.behaviour, d.how) == (n.b("stop"), How.RELEASED)


def test_exploration_skips_stimuli_that_are_not_learnable(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, epsilon=1.0, learnable=["Red"])
    for active in ([n.s("Middle")], [n.s("Corner")], [n.s("Green")], []):
        assert sel.select(active, -1).how is How.DEFAULT


def test_exploration_never_overrides_a_higher_priority_reflex(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, [n.a("Collision", "back", 1.0)], epsilon=1.0, learnable=["Red"])
    for _ in range(50):
        d = sel.select([n.s("Red"), n.s("Collision")], -1)
        assert (d.behaviour, d.stimulus, d.how) == (n.b("back"), n.s("Collision"), How.RELEASED)


def test_exploration_may_override_a_lower_layer_response(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, [n.a("Middle", "goforward3", 1.0)], epsilon=1.0, learnable=["Red"])
    d = sel.select([n.s("Middle"), n.s("Red")], -1)
    assert (d.stimulus, d.how) == (n.s("Red"), How.EXPLORED)


def test_epsilon_zero_never_explores(catalog: Catalog, n: Names) -> None:
    learnable = [s.name for s in catalog.stimuli]
    sel = selector(catalog, epsilon=0.0, learnable=learnable)
    rng = np.random.default_rng(1)
    for _ in range(500):
        active = sorted(rng.choice(len(catalog.stimuli), size=3, replace=False).tolist())
        assert sel.select(active, -1).how is not How.EXPLORED


def test_exploration_rate_follows_epsilon_per_encounter(catalog: Catalog, n: Names) -> None:
    sel = selector(catalog, epsilon=0.3, learnable=["Red"], seed=4)
    tried = []
    for _ in range(400):
        tried.append(sel.select([n.s("Red")], -1))
        sel.select([n.s("Middle")], -1)  # the encounter ends
    explored = [d for d in tried if d.how is How.EXPLORED]
    assert 0.2 < len(explored) / len(tried) < 0.4
    assert len({d.behaviour for d in explored}) > 10


def test_exploration_is_reproducible_from_the_seed(catalog: Catalog, n: Names) -> None:
    def run(seed: int) -> list[Decision]:
        sel = selector(catalog, epsilon=0.5, learnable=["Red", "Obstacle_M_M"], seed=seed)
        out = []
        for i in range(200):
            out.append(sel.select([n.s("Red")] if i % 3 else [n.s("Obstacle_M_M")], -1))
        return out

    assert run(7) == run(7)
    assert run(7) != run(8)
