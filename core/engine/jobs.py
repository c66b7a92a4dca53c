"""What the engine's tasks hand each other: a reward, an edit, an episode, a write.

A trainer's reward is a `RewardJob` from the moment it arrives: the tick task releases it
at its boundary, the reward task applies it, the acknowledgement task logs it and the
learning writer commits what it changed, each setting the job's events as it goes. The
feeds between the tasks are typed queues: each carries its jobs, then `CLOSE`.
"""

from __future__ import annotations

import asyncio
import enum
from dataclasses import dataclass, field, replace
from typing import Any, Final, Generic, TypeVar

from core.commands import EditAssociation, InjectReward
from core.ports import EpisodeRecord, LearningUpdate, RewardCommit, RunTotals
from core.run.trace import TraceArray, compress


@dataclass(frozen=True, slots=True)
class RewardAck:
    """What a trainer's reward was stored as."""

    id: int
    tick: int
    episode: int
    value: float
    uid: str = ""
    """The reward's id from its arrival (its log `id` is the database's)."""
    tick_seen: int | None = None
    seen_episode: int | None = None
    window: tuple[int, int] | None = None
    """The first and last tick it could credit (with a seen tick)."""


@dataclass(eq=False)
class RewardJob:
    """A reward on its way through the engine, stamped with the boundary it applies at."""

    stamp: int
    episode: int
    reward: InjectReward
    external: bool
    """A trainer's reward (logged on arrival), not the task's or the program's."""
    release: asyncio.Event = field(default_factory=asyncio.Event)
    """Set by the tick task at the job's boundary: only then is it applied."""
    applied: asyncio.Event = field(default_factory=asyncio.Event)
    committed: asyncio.Event = field(default_factory=asyncio.Event)
    ack: asyncio.Future[RewardAck] | None = None
    arrived: float = 0.0
    logged_id: int | None = None
    logged: asyncio.Event = field(default_factory=asyncio.Event)
    """Set once the reward is in the log (external rewards are logged by the ack task)."""
    committed_before: bool = False
    """Its learning is already in storage (a replayed reward applied before a crash)."""


@dataclass(eq=False)
class CommandJob:
    """An edit of the network, applied by the tick task at its boundary."""

    stamp: int
    command: EditAssociation
    ack: asyncio.Future[int] | None = None
    update: LearningUpdate | None = None
    """What the edit changed, once applied: the writer logs it with the command."""


@dataclass(eq=False)
class EpisodeJob:
    """An ended episode with the learning state after it, for the episode writer."""

    record: EpisodeRecord
    next_episode: int
    tick: int
    state: dict[str, Any]
    """The learning state after the episode: encoded only if it is a batch's last."""
    totals: RunTotals
    after: RewardJob | None
    """The last reward applied before the checkpoint: it is committed first."""
    external: RewardJob | None
    """The last trainer's reward applied before the checkpoint: once `after` is committed
    it is in the log, and its id tells a replay which logged rewards the state holds."""
    trace: TraceArray | None = None
    """The episode's trace rows, compressed into the record by `stored` on the writer's
    thread (zlib runs there without the GIL, beside the ticks); None: `record` has it."""

    def stored(self) -> EpisodeRecord:
        """The record as stored, its trace compressed."""
        if self.trace is None:
            return self.record
        return replace(self.record, trace=compress(self.trace))


@dataclass(frozen=True, slots=True)
class RewardWrite:
    """An applied reward's learning, handed to the learning writer."""

    job: RewardJob
    commit: RewardCommit
    queued: float
    """perf_counter() when it was handed to the writer."""


class Close(enum.Enum):
    """The last item a queue carries: its reader finishes what it has and returns."""

    CLOSE = enum.auto()


CLOSE: Final = Close.CLOSE

_T = TypeVar("_T")


class Feed(Generic[_T]):
    """A queue from one task to another that ends: `close` puts its last item."""

    def __init__(self) -> None:
        self._queue: asyncio.Queue[_T | Close] = asyncio.Queue()

    def put(self, item: _T) -> None:
        """Queue an item (never blocks: the queue is unbounded)."""
        self._queue.put_nowait(item)

    def close(self) -> None:
        """Queue `CLOSE`: the reader finishes what is queued before it, then returns."""
        self._queue.put_nowait(CLOSE)

    async def get(self) -> _T | Close:
        """The next item, waiting for one."""
        return await self._queue.get()

    def get_nowait(self) -> _T | Close:
        """The next item; `asyncio.QueueEmpty` if there is none."""
        return self._queue.get_nowait()

    def empty(self) -> bool:
        """Whether nothing is queued."""
        return self._queue.empty()


RewardFeed = Feed[RewardJob | CommandJob]
"""Tick task -> reward task: rewards to apply and applied edits, in boundary order."""
WriteFeed = Feed[RewardWrite | CommandJob]
"""Reward task -> learning writer: what to commit, in the order it happened."""
EpisodeFeed = Feed[EpisodeJob]
"""Tick task -> episode writer."""
AckFeed = Feed[RewardJob]
"""A trainer's reward -> the acknowledgement task, on arrival."""


async def gather(feed: Feed[_T], window_s: float, limit: int) -> tuple[list[_T], bool]:
    """The next item of `feed` and those arriving within `window_s` after it.

    At most `limit` items; the flag says whether `CLOSE` came (it ends the gathering and
    is not returned).
    """
    item = await feed.get()
    deadline = asyncio.get_running_loop().time() + window_s
    batch: list[_T] = []
    while True:
        if item is CLOSE:
            return batch, True
        batch.append(item)
        if len(batch) >= limit:
            return batch, False
        if not feed.empty():
            item = feed.get_nowait()
            continue
        if window_s <= 0:
            return batch, False
        try:
            # asyncio.timeout, not wait_for: 3.11's wait_for can swallow the cancellation
            # of a task group whose other task failed.
            async with asyncio.timeout_at(deadline):
                item = await feed.get()
        except TimeoutError:
            return batch, False
