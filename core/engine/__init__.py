"""The engine: the paper's two threads as two asyncio tasks around one simulation.

A reader can hold its parts one at a time:

- `engine`: `RunEngine`, a run's lifecycle and the calls the outside makes.
- `build`: a new run's simulation (stored first) or a stored one's, from its checkpoint.
- `tick_task`: `TickTask`, the paper's first thread: ticks with their boundaries, and
  episodes.
- `reward_task`: `RewardTask`, the paper's second thread: rewards applied at their
  boundaries.
- `boundary`: `Boundary`, the one hand-over between those two tasks (a reward is applied
  at the tick boundary it was stamped with, and the tick after waits for it).
- `pacing`: the tick task's one loop and its policies (fast, realtime, replay), the
  controls the outside sets, the realtime tick rate's bounds, the `Pacer` clock, exact
  sleeps.
- `jobs`: what the tasks hand each other (`RewardJob`, `CommandJob`, `EpisodeJob`) on typed
  queues.
- `writer`: `RunWriter`, the acknowledgement task, the learning writer and the episode
  writer; every storage call typed against `core.ports.RunStore`.
- `learning`: the brain's changes as storage records.
- `replay`: a resumed run's log after its checkpoint.
- `bus`: subscriptions, bounded queues that never hold up a tick.
- `stats`: pacing and storage figures.
- `view`: `RunView`, what the service reads of a live run.
"""

from core.engine.bus import (
    COMPETITORS,
    Competition,
    EventBus,
    StatusChanged,
    Subscription,
    SubscriptionClosed,
    TickPublished,
)
from core.engine.engine import RunEngine
from core.engine.jobs import RewardAck
from core.engine.pacing import (
    FAST_YIELD_TICKS,
    HZ_MAX,
    HZ_MIN,
    MonotonicPacer,
    Pacer,
    Wake,
    check_hz,
    sleep_until,
)
from core.engine.stats import EngineStats
from core.engine.view import RunView
from core.engine.writer import EPISODE_BATCH_MAX, EPISODE_BATCH_S, WRITE_BATCH_MAX, WRITE_BATCH_S

__all__ = [
    "COMPETITORS",
    "EPISODE_BATCH_MAX",
    "EPISODE_BATCH_S",
    "FAST_YIELD_TICKS",
    "HZ_MAX",
    "HZ_MIN",
    "WRITE_BATCH_MAX",
    "WRITE_BATCH_S",
    "Competition",
    "EngineStats",
    "EventBus",
    "MonotonicPacer",
    "Pacer",
    "RewardAck",
    "RunEngine",
    "RunView",
    "StatusChanged",
    "Subscription",
    "SubscriptionClosed",
    "TickPublished",
    "Wake",
    "check_hz",
    "sleep_until",
]
