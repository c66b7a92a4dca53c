"""KP on the signal's objective: the stop-line beacon's responses teach the camera's colours.

The beacon (low level, `obey_signal`) hears the phase only at the stop line; the camera's
signal stimuli (high level, the same objective) see the lamp from 0.8 m. A stop has no
heading, so reasoningKPM gives the stop when the sources stopped at least as often as they
moved; sources without a stop reason as they always did.
"""

from __future__ import annotations

from core.brain.catalog import Catalog, load_catalog
from core.brain.network import BehaviourNetwork
from core.brain.propagation import KnowledgePropagation, KpConfig
from core.brain.selection import Decision, How

DT = 0.1


def harness() -> tuple[Catalog, BehaviourNetwork, KnowledgePropagation]:
    catalog = load_catalog()
    network = BehaviourNetwork.from_specs(catalog, catalog.knowledge_set("beacon").associations)
    config = KpConfig(enabled=True, eta=0.3, insert_threshold=0.5, window_ticks=20)
    kp = KnowledgePropagation(catalog, network, config, DT, lambda b: b)
    return catalog, network, kp


def test_the_beacon_is_a_low_level_sensor_of_the_signals_objective() -> None:
    catalog = load_catalog()
    beacon = {s.name: s for s in catalog.stimuli if s.sensor == "beacon"}
    assert set(beacon) == {"BeaconRed", "BeaconYellow", "BeaconGreen"}
    assert {(s.level, s.objective) for s in beacon.values()} == {("low", "obey_signal")}
    assert catalog.stimulus("Red").objective == "obey_signal"
    assert catalog.stimulus("Red").level == "high"
    # appended after every other sensor's stimuli: no existing stimulus changed its id
    assert min(s.id for s in beacon.values()) == len(catalog.stimuli) - 3


def test_stops_reason_to_the_stop_and_moves_keep_their_sum() -> None:
    catalog, _, kp = harness()
    b = catalog.behaviour
    stop, go = b("stop").id, b("goforward3").id
    assert kp.reasoning([stop]) == (b("stop"), False)
    assert kp.reasoning([stop, stop, go]) == (b("stop"), False)
    assert kp.reasoning([stop, go]) == (b("stop"), False)  # a tie stops
    assert kp.reasoning([stop, go, go]) == (b("goforward3"), False)
    # without a stop among them nothing changes: two right turns of 30 give that turn
    assert kp.reasoning([b("rightturn30").id] * 2) == (b("rightturn30"), False)


def test_a_red_approach_teaches_the_camera_to_stop() -> None:
    """Camera Red at ticks 1-12 (the robot drives in), then the beacon's red at the line
    releases stop tick after tick; a reward teaches Red -> stop, promoted as ``kp``."""
    catalog, network, kp = harness()
    s, b = catalog.stimulus, catalog.behaviour
    red, beacon_red = s("Red").id, s("BeaconRed").id
    middle = s("Middle").id
    for t in range(1, 13):
        kp.percept(t, [red, middle], Decision(b("goforward3").id, middle, 1.0, How.RELEASED))
    for t in range(13, 40):
        kp.percept(t, [beacon_red, middle], Decision(b("stop").id, beacon_red, 1.0, How.RELEASED))
    learned: list[tuple[str, str]] = []
    for _ in range(3):
        for t in range(1, 13):
            kp.percept(t, [red], Decision(b("goforward3").id, middle, 1.0, How.RELEASED))
        kp.percept(13, [beacon_red], Decision(b("stop").id, beacon_red, 1.0, How.RELEASED))
        got, _ = kp.reward(1.0)
        learned += [(catalog.stimuli[p.stimulus].name, catalog.behaviours[p.behaviour].name)
                    for p in got]  # fmt: skip
    assert set(learned) == {("Red", "stop")}
    made = network.get(red, b("stop").id)
    assert made is not None and made.source == "kp"
    # the lane keeping released by Middle is of another objective: never recorded
    assert all(r.low != middle for records in kp.rstm.values() for r in records)


def test_green_at_the_line_teaches_the_camera_to_go() -> None:
    catalog, _, kp = harness()
    s, b = catalog.stimulus, catalog.behaviour
    green, beacon_green = s("Green").id, s("BeaconGreen").id
    kp.percept(1, [green], Decision(b("goforward3").id, s("Middle").id, 1.0, How.RELEASED))
    kp.percept(14, [beacon_green], Decision(b("goforward3").id, beacon_green, 1.0, How.RELEASED))
    got, _ = kp.reward(1.0)
    assert [(p.stimulus, p.behaviour) for p in got] == [(green, b("goforward3").id)]
