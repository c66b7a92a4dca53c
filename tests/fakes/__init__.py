"""Test doubles: in-memory stores, a scripted world and a manual clock.

- `world`: `ScriptedWorld`, which plays back sensor frames without pymunk, and the frames.
- `runs`: `InMemoryRunStore`, the run store (`core.ports.RunStore`) in memory.
- `networks`: `InMemoryNetworkRepository`, stored networks and their versions in memory.
- `pacing`: `ManualPacer`, a realtime engine's clock that moves only when told.
"""

from fakes.networks import SEEDED_NOTE, InMemoryNetworkRepository
from fakes.pacing import ManualPacer
from fakes.runs import InMemoryRunStore, InspectableRunStore
from fakes.world import UNSEEN, ScriptedStep, ScriptedWorld, channel_list, channel_vector, lap_steps

__all__ = [
    "SEEDED_NOTE",
    "UNSEEN",
    "InMemoryNetworkRepository",
    "InMemoryRunStore",
    "InspectableRunStore",
    "ManualPacer",
    "ScriptedStep",
    "ScriptedWorld",
    "channel_list",
    "channel_vector",
    "lap_steps",
]
