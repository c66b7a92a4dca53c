"""The reward task, the paper's second thread: each reward applied at its boundary, in order.

It takes the boundary's feed in order: a reward waits until the tick task releases it at
its boundary, then is applied (pop STM, Eq. (1), network insertions, KP) and its learning
handed to the learning writer; an edit the tick task applied is handed on in its place, so
storage commits what changed in the order it happened.
"""

from __future__ import annotations

import time

from core.brain.brain import RewardOutcome
from core.engine.boundary import Boundary
from core.engine.bus import EventBus
from core.engine.jobs import CLOSE, RewardJob, RewardWrite
from core.engine.learning import learning_update
from core.engine.writer import RunWriter, reward_record
from core.ports import RewardCommit
from core.run.simulation import Simulation


class RewardTask:
    """A run's rewards, applied as their boundaries release them; `run` is the task.

    Its books (the last reward applied, the last trainer's, how many this episode) are
    read by the tick task when an episode ends: at a boundary, with every reward due
    there applied and no other released.
    """

    def __init__(
        self, sim: Simulation, boundary: Boundary, writer: RunWriter, bus: EventBus
    ) -> None:
        self.sim = sim
        self.boundary = boundary
        self.writer = writer
        self.bus = bus
        self.last_applied: RewardJob | None = None
        """The last reward applied: an episode's checkpoint is committed after it."""
        self.last_external: RewardJob | None = None
        """The newest trainer's reward applied (its log id may come later)."""
        self.in_episode = 0
        """Rewards applied to the current episode (the tick task zeroes it at a reset)."""

    async def run(self) -> None:
        """The task: until the feed's `CLOSE`, then the learning writer's feed is closed."""
        try:
            while True:
                job = await self.boundary.feed.get()
                if job is CLOSE:
                    break
                if isinstance(job, RewardJob):
                    await self._process(job)
                else:  # an edit, applied by the tick task: stored in its place in order
                    self.writer.learning.put(job)
        finally:
            self.writer.learning.close()

    async def _process(self, job: RewardJob) -> None:
        record = reward_record(job)
        # A trainer's reward is applied at its boundary even if the log is slow to take it
        # (the tick waits for it there); only its commit waits for the log entry.
        await job.release.wait()
        outcome = self._apply(job)
        if job.committed_before:
            job.committed.set()
            return
        commit = RewardCommit(
            record, learning_update(self.sim, outcome), len(outcome.credits), job.logged_id
        )
        self.writer.learning.put(RewardWrite(job, commit, time.perf_counter()))

    def _apply(self, job: RewardJob) -> RewardOutcome:
        self.last_applied = job
        if job.external:
            self.last_external = job
        event, outcome = self.sim.apply_reward(job.reward, job.stamp, job.episode)
        job.applied.set()
        if job.episode == self.sim.episode:
            self.in_episode += 1
        self.bus.publish(event)
        for change in outcome.changes:
            self.bus.publish(change)
        return outcome
