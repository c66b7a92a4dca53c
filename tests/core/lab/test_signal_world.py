"""The `stop-line` world poses the signal's problem (its world-check properties, in small).

The full check is `srlab world-check --world stop-line` on 20 seeds
(`docs/results/signal-kp/world-check/`); here, on a few seeds, the same ordering: no signal
knowledge obeys least, the beacon's reflexes more but not always, the expert's camera
responses always.
"""

from __future__ import annotations

from core.lab.worldcheck import PROPERTIES, SIGNAL_PROPERTIES, properties_for, world_check


def test_a_world_with_a_beacon_is_checked_on_the_signal() -> None:
    assert properties_for("stop-line") == SIGNAL_PROPERTIES
    assert properties_for("soft-obstacle") == PROPERTIES
    assert {p.condition for p in SIGNAL_PROPERTIES} == {"reflexes", "beacon-reflexes", "expert"}
    assert not any(p.signal_given for p in SIGNAL_PROPERTIES)


def test_the_beacon_obeys_more_than_nothing_and_less_than_the_camera() -> None:
    got = {r.prop.key: r for r in world_check("stop-line", seeds=range(4), episodes=20)}
    none, beacon, expert = (got[k].success.mean for k in "abc")
    assert none < beacon < expert
    assert expert >= 0.95 and beacon < 0.95
    assert set(got["a"].failures) == {"signal_violation"}
