"""What the run store's contract suites share: a run's spec and network, its log's records."""

from __future__ import annotations

from fakes import InspectableRunStore

from core.ports import (
    BehaviourSpec,
    CommandRecord,
    EpisodeRecord,
    Mode,
    NetworkPair,
    RewardRecord,
    RunSpec,
)

NETWORK = (
    NetworkPair("Corner", "leftturn90", 1.0, "innate", locked=True),
    NetworkPair("LeftWall", "leftwallavoid", 1.0, "innate"),
    NetworkPair("Red", "stop", 0.8, "dp"),
)
SPEC = RunSpec(
    condition="dp",
    seed=7,
    episodes=20,
    mode=Mode.REALTIME,
    hz=12.5,
    network="dp",
    params={"eta": 0.2, "epsilon": 0.05},
    world="echo40",
    sensors="path",
)
SLOWER = BehaviourSpec("kp_slow_left", "synthesized", 0.05, 20.0, 3, "constant")


def reward(tick: int, value: float = 1.0, episode: int = 0) -> RewardRecord:
    return RewardRecord(tick=tick, episode=episode, value=value, source="human", note=f"t{tick}")


def edit(tick: int) -> CommandRecord:
    return CommandRecord(tick, "edit_association", {"stimulus": "Red", "behaviour": "stop"})


def episode(n: int, start_tick: int = 0) -> EpisodeRecord:
    return EpisodeRecord(n, "success", None, 100, start_tick, 2, b"\x00trace" + bytes([n]))


def new_run(store: InspectableRunStore) -> int:
    return store.create_run(SPEC, NETWORK)
