"""The one hand-over between the tick task and the reward task: the tick boundary.

Every reward is stamped with the boundary it applies at: a trainer's with the next one
(the one after the boundary being settled, if one is), the task's and the program's with
the boundary after the tick that produced them. The tick task settles a boundary by
releasing the rewards due there and waiting until the reward task has applied them, in
stamp order; only then does it apply that boundary's edits and run the next tick. So a
reward credits exactly the STM records of the ticks before its boundary, whatever the
timing, and a run replays from its seed and its log.

The tick task owns `due`, `held` and `settling`; the reward task sees a job only through
the feed, and applies it only once it is released.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator

from core.engine.jobs import CommandJob, RewardFeed, RewardJob


class Boundary:
    """Rewards stamped, waiting for their boundary, and the feed to the reward task."""

    def __init__(self) -> None:
        self.due: deque[RewardJob] = deque()
        """Rewards queued for the reward task, in stamp order."""
        self.held: list[RewardJob] = []
        """Trainers' rewards stamped past the boundary being settled, until its tick ran."""
        self.settling = 0
        """The boundary being settled (0: none)."""
        self.feed = RewardFeed()
        """To the reward task: rewards in stamp order, and applied edits in their place."""

    def stamp(self, next_boundary: int) -> int:
        """The boundary a trainer's reward arriving now applies at.

        The next one, unless that is being settled: then the one after, so a stream of
        rewards can never hold a boundary open.
        """
        return self.settling + 1 if self.settling >= next_boundary else next_boundary

    def add(self, job: RewardJob, next_boundary: int) -> None:
        """Queue a reward; one stamped past the next boundary is held until that tick ran.

        Held, the rewards that tick produces for its boundary come first there, as they do
        when the log is replayed.
        """
        if job.stamp > next_boundary:
            self.held.append(job)
        else:
            self.queue(job)

    def queue(self, job: RewardJob) -> None:
        """Hand a reward to the reward task, due at its stamp."""
        self.due.append(job)
        self.feed.put(job)

    def applied(self, job: CommandJob) -> None:
        """Hand an applied edit to the reward task, which stores it in its place."""
        self.feed.put(job)

    def release_held(self) -> None:
        """The tick after the settled boundary ran: held rewards are due now."""
        for job in self.held:
            self.queue(job)
        self.held.clear()

    def release(self, boundary: int) -> None:
        """Release the rewards due up to `boundary` without waiting: a paused run's.

        The reward task applies them in stamp order; the tick task's `settle` of that
        boundary, when the run goes on, finds them applied.
        """
        for job in self.due:
            if job.stamp > boundary:
                break
            job.release.set()

    async def settle(self, boundary: int, *, internal_only: bool, limit: float) -> None:
        """Apply, in order, every reward stamped up to `limit`, each waiting for the last.

        `internal_only` stops at the first trainer's reward (an episode's own rewards
        apply before it ends; a trainer's arriving then applies after the reset).
        """
        due = self.due
        self.settling = boundary
        try:
            # Released together, the rewards are applied back to back (the reward task
            # takes them in stamp order, each after the last), so the learning writer finds
            # them all queued and commits them in one transaction instead of the second
            # waiting for the first's commit.
            released = 0
            for job in due:
                if job.stamp > limit or (internal_only and job.external):
                    break
                job.release.set()
                released += 1
            for _ in range(released):
                await due[0].applied.wait()
                due.popleft()
        finally:
            self.settling = 0

    def waiting(self) -> Iterator[RewardJob]:
        """Every reward not applied yet (due or held)."""
        yield from self.due
        yield from self.held

    def close(self) -> None:
        """No more rewards: the reward task finishes what it was handed, then returns."""
        self.feed.close()
