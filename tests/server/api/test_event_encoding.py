"""The live stream's tick payload: the competition the console draws against the threshold."""

from __future__ import annotations

from core.brain.catalog import Catalog
from core.engine import COMPETITORS, Competition, TickPublished
from core.run.conditions import get_condition
from core.run.simulation import Simulation
from server.api.routes.events import competition, encode


def test_red_releases_stop_above_the_threshold_in_the_expert_network(catalog: Catalog) -> None:
    sim = Simulation(get_condition("expert"), seed=1, catalog=catalog)
    red = catalog.stimulus("Red").id
    middle = catalog.stimulus("Middle").id
    result = competition(Competition.of(sim.brain.selector, (middle, red)), catalog)
    assert result["threshold"] == sim.brain.selector.config.threshold
    values = result["values"]
    assert values[0]["behaviour"] == "stop" and values[0]["stimulus"] == "Red"
    assert values[0]["value"] >= result["threshold"]
    assert [v["value"] for v in values] == sorted((v["value"] for v in values), reverse=True)
    assert {v["stimulus"] for v in values} <= {"Red", "Middle"}


def test_no_stimuli_means_no_competitors(catalog: Catalog) -> None:
    sim = Simulation(get_condition("innate"), seed=1, catalog=catalog)
    assert competition(Competition.of(sim.brain.selector, ()), catalog)["values"] == []


def test_a_tick_event_carries_the_competition_when_the_engine_took_it(
    catalog: Catalog,
) -> None:
    sim = Simulation(get_condition("expert"), seed=3, catalog=catalog)
    sim.reset()
    snapshot = sim.tick().snapshot
    event = TickPublished(1, snapshot)
    plain = encode(event, catalog)
    taken = Competition.of(sim.brain.selector, snapshot.stimuli)
    rich = encode(TickPublished(1, snapshot, competition=taken), catalog)
    assert plain is not None and rich is not None
    assert "competition" not in plain[1]
    assert rich[0] == "tick" and len(rich[1]["competition"]["values"]) <= COMPETITORS
    assert rich[1]["stimuli"] == [catalog.stimuli[i].name for i in snapshot.stimuli]


def test_a_tick_event_says_what_made_its_behaviour_run(catalog: Catalog) -> None:
    sim = Simulation(get_condition("expert"), seed=3, catalog=catalog)
    sim.reset()
    snapshots = [sim.tick().snapshot for _ in range(60)]
    encoded = [encode(TickPublished(1, s), catalog) for s in snapshots]
    for snap, e in zip(snapshots, encoded, strict=True):
        assert e is not None
        data = e[1]
        assert data["origin"] == snap.origin
        expected = catalog.stimuli[snap.released_by].name if snap.released_by >= 0 else None
        assert data["released_by"] == expected
    released = [e[1] for e in encoded if e is not None and e[1]["how"] == "released"]
    assert released and all(d["released_by"] in d["stimuli"] for d in released)
    assert {d["origin"] for d in released} <= {"innate", "designed", "expert", "dp"}
