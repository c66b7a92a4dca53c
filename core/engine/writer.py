"""Storage kept in step with a run without holding up its ticks: three writer tasks.

- The **acknowledgement task** logs trainers' rewards in arrival order; the log entry is the
  reward's acknowledgement (it never waits for a tick boundary).
- The **learning writer** commits what applied rewards and edits changed, in the order they
  happened (a reward applied before its log entry waits for that entry's id).
- The **episode writer** commits ended episodes with the checkpoint after the last, once
  the rewards applied before that checkpoint are committed.

Every storage call runs on a worker thread through `asyncio.to_thread`, typed, so mypy
checks each call against `core.ports.RunStore`.
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from dataclasses import replace

from core.engine.jobs import (
    CLOSE,
    AckFeed,
    CommandJob,
    EpisodeFeed,
    EpisodeJob,
    RewardAck,
    RewardJob,
    RewardWrite,
    WriteFeed,
    gather,
)
from core.engine.stats import EngineStats
from core.errors import StorageError
from core.ports import Checkpoint, CommandRecord, RewardRecord, RunStatus, RunStore
from core.run.checkpoint import encode

EPISODE_BATCH_S = 0.05
"""How long the episode writer gathers episodes before it commits them together."""
EPISODE_BATCH_MAX = 64
"""The most episodes it commits in one transaction."""

WRITE_BATCH_S = 0.05
"""In fast mode, how long the learning writer gathers rewards before it commits them."""
WRITE_BATCH_MAX = 256
"""The most rewards it commits in one transaction."""


def reward_record(job: RewardJob) -> RewardRecord:
    """A reward as the log keeps it."""
    r = job.reward
    return RewardRecord(
        job.stamp, job.episode, r.value, r.source, r.note, r.uid, r.tick_seen, r.seen_episode,
        r.window, r.records,
    )  # fmt: skip


class RunWriter:
    """A run's writer tasks and the queues that feed them.

    Args:
        run_id: the run written.
        store: where.
        stats: the run's figures (commit and acknowledgement latencies are added here).
        batch: gather a fast run's learning for `WRITE_BATCH_S` before committing it.
        last_external_id: the newest trainer's reward the restored checkpoint holds.
    """

    def __init__(
        self,
        run_id: int,
        store: RunStore,
        stats: EngineStats,
        *,
        batch: bool,
        last_external_id: int = 0,
    ) -> None:
        self.run_id = run_id
        self.store = store
        self.stats = stats
        self._window_s = WRITE_BATCH_S if batch else 0.0
        self._last_external_id = last_external_id
        self.learning: WriteFeed = WriteFeed()
        self.episodes: EpisodeFeed = EpisodeFeed()
        self.acks: AckFeed = AckFeed()
        self.unacked: deque[RewardJob] = deque()
        """Trainers' rewards not acknowledged yet, in arrival order (applied ones too)."""
        self.unlogged: list[CommandJob] = []
        """Edits applied whose log entry is yet to be committed."""

    # --- what the engine hands over ---------------------------------------------------

    def acknowledge(self, job: RewardJob) -> None:
        """Log a trainer's reward as soon as the acknowledgement task gets to it."""
        self.acks.put(job)
        self.unacked.append(job)

    def applied(self, job: CommandJob) -> None:
        """An edit was applied: it is logged in its place among the rewards' learning."""
        self.unlogged.append(job)

    def end_of_ticks(self) -> None:
        """No more episodes or trainers' rewards: those tasks finish what they hold."""
        self.episodes.close()
        self.acks.close()

    def fail_pending(self, error: BaseException) -> None:
        """Answer every waiting reward and edit with a `StorageError` (nothing more is stored)."""
        for job in self.unacked:
            if job.ack is not None and not job.ack.done():
                job.ack.set_exception(StorageError(f"the reward was not stored: {error}"))
        for c in self.unlogged:
            if c.ack is not None and not c.ack.done():
                c.ack.set_exception(StorageError(f"the edit was not stored: {error}"))

    async def set_status(self, status: RunStatus, error: str | None) -> None:
        """Store the run's status."""
        await asyncio.to_thread(self.store.set_status, self.run_id, status, error)

    # --- the learning writer ----------------------------------------------------------

    async def learning_task(self) -> None:
        """Commits what applied rewards and edits changed, in the order they happened.

        What queued up while the last commit ran goes into one transaction; in fast mode,
        where only the episode writer waits for these commits, it also gathers for
        `WRITE_BATCH_S`, so a fast run commits its learning a few times a second instead
        of once a reward.
        """
        closing = False
        while not closing:
            batch, closing = await gather(self.learning, self._window_s, WRITE_BATCH_MAX)
            rewards: list[RewardWrite] = []
            for item in batch:
                if isinstance(item, RewardWrite):
                    rewards.append(item)
                    continue
                await self._commit_rewards(rewards)  # the rewards before it come first
                rewards = []
                await self._log_command(item)
            await self._commit_rewards(rewards)

    async def _commit_rewards(self, writes: list[RewardWrite]) -> None:
        if not writes:
            return
        for i, w in enumerate(writes):
            if w.job.external and w.commit.logged_id is None:
                # Applied before its log entry was written: commit it as that entry.
                await w.job.logged.wait()
                writes[i] = replace(w, commit=replace(w.commit, logged_id=w.job.logged_id))
        ids = await asyncio.to_thread(
            self.store.commit_rewards, self.run_id, tuple(w.commit for w in writes)
        )
        done = time.perf_counter()
        for w, reward_id in zip(writes, ids, strict=True):
            w.job.logged_id = reward_id
            self.stats.reward_commit_s.add(done - w.queued)
            w.job.committed.set()

    async def _log_command(self, job: CommandJob) -> None:
        assert job.update is not None
        c = job.command
        record = CommandRecord(
            job.stamp,
            "edit_association",
            {
                "stimulus": c.stimulus,
                "behaviour": c.behaviour,
                "strength": c.strength,
                "source": c.source,
                "locked": c.locked,
            },
        )
        command_id = await asyncio.to_thread(
            self.store.log_command, self.run_id, record, job.update
        )
        self.unlogged.remove(job)
        if job.ack is not None and not job.ack.done():
            job.ack.set_result(command_id)

    # --- the episode writer -----------------------------------------------------------

    async def episode_task(self) -> None:
        """Commits episodes and checkpoints, each after the rewards applied before it.

        Episodes are nobody's acknowledgement and a lost one is replayed from the log, so
        the writer gathers what arrives within `EPISODE_BATCH_S` and commits it at once:
        in fast mode that is one transaction for many episodes.
        """
        closing = False
        while not closing:
            batch, closing = await gather(self.episodes, EPISODE_BATCH_S, EPISODE_BATCH_MAX)
            if not batch:
                continue
            last = batch[-1]
            if last.after is not None:
                await last.after.committed.wait()
            # Trainer rewards stamped with the next boundary may already be in this state;
            # replay skips those the checkpoint includes. The rewards up to `after` are
            # committed, so the last trainer's one is logged and has its id.
            external = last.external
            if external is not None:
                assert external.logged_id is not None
            last.state["last_external_reward_id"] = (
                self._last_external_id if external is None else external.logged_id
            )
            await asyncio.to_thread(self._end_episodes, batch)

    def _end_episodes(self, batch: list[EpisodeJob]) -> None:
        """Store episodes with the checkpoint after the last (on a worker thread)."""
        last = batch[-1]
        records = tuple(j.stored() for j in batch)
        checkpoint = Checkpoint(last.next_episode, last.tick, encode(last.state))
        self.store.end_episodes(self.run_id, records, checkpoint, last.totals)

    # --- the acknowledgement task -----------------------------------------------------

    async def ack_task(self) -> None:
        """Logs trainers' rewards in arrival order; the log entry is the acknowledgement.

        It never waits for a tick boundary, so acknowledging does not wait for the
        previous reward to be applied.
        """
        while True:
            job = await self.acks.get()
            if job is CLOSE:
                break
            job.logged_id = await asyncio.to_thread(
                self.store.log_reward, self.run_id, reward_record(job)
            )
            job.logged.set()
            self.unacked.remove(job)
            if job.ack is not None and not job.ack.done():
                self.stats.reward_ack_s.add(time.perf_counter() - job.arrived)
                job.ack.set_result(
                    RewardAck(
                        job.logged_id,
                        job.stamp,
                        job.episode,
                        job.reward.value,
                        job.reward.uid,
                        job.reward.tick_seen,
                        job.reward.seen_episode,
                        job.reward.window,
                    )
                )
