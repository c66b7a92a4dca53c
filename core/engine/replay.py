"""A resumed run's log after its checkpoint, read in the order the ticks will need it.

A resumed run re-runs the ticks after its checkpoint. Trainers' rewards and edits come
from the log, each at the boundary it was stamped with; the task's and the reinforcement
program's rewards are produced again by the replayed ticks and matched with their log
entries here, so each is stored once, and one whose learning was never committed (the
process died in between) is committed then.
"""

from __future__ import annotations

from collections import deque

from core.commands import INTERNAL_SOURCES, EditAssociation, InjectReward, RewardSource
from core.engine.jobs import RewardJob
from core.ports import StoredReward, StoredRun


class ReplayLog:
    """What a resumed run replays: the log after its checkpoint.

    Args:
        stored: the run as stored.
        skip_upto: the newest trainer's reward the checkpoint's state already holds.
    """

    def __init__(self, stored: StoredRun, skip_upto: int) -> None:
        self._rewards = deque(
            r
            for r in stored.rewards_after
            if r.record.source not in INTERNAL_SOURCES and r.id > skip_upto
        )
        self._internal: dict[tuple[int, str, float], deque[StoredReward]] = {}
        for r in stored.rewards_after:
            if r.record.source in INTERNAL_SOURCES:
                key = (r.record.tick, r.record.source, r.record.value)
                self._internal.setdefault(key, deque()).append(r)
        self._commands = deque(stored.commands_after)
        self.last_tick = max(
            [r.record.tick for r in stored.rewards_after] + [c.record.tick for c in self._commands],
            default=0,
        )
        """The last boundary the log has anything for: replay runs the ticks up to it."""

    def rewards_at(self, boundary: int) -> list[RewardJob]:
        """The trainers' rewards logged for this boundary (or before it), as jobs."""
        jobs: list[RewardJob] = []
        rewards = self._rewards
        while rewards and rewards[0].record.tick <= boundary:
            r = rewards.popleft()
            jobs.append(
                RewardJob(
                    r.record.tick,
                    r.record.episode,
                    InjectReward(
                        r.record.value,
                        note=r.record.note,
                        source=RewardSource(r.record.source),
                        uid=r.record.uid,
                        tick_seen=r.record.tick_seen,
                        seen_episode=r.record.seen_episode,
                        window=r.record.window,
                        records=r.record.records,
                    ),
                    external=True,
                    logged_id=r.id,
                    committed_before=r.applied,
                )
            )
        return jobs

    def edits_at(self, boundary: int) -> list[EditAssociation]:
        """The edits logged for this boundary (or before it)."""
        edits: list[EditAssociation] = []
        commands = self._commands
        while commands and commands[0].record.tick <= boundary:
            p = commands.popleft().record.payload
            strength = p.get("strength")
            edits.append(
                EditAssociation(
                    str(p["stimulus"]),
                    str(p["behaviour"]),
                    None if strength is None else float(strength),
                    str(p.get("source", "dp")),
                    bool(p.get("locked", False)),
                )
            )
        return edits

    def match(self, job: RewardJob) -> None:
        """Mark a reward the replayed ticks produced with its log entry, if it has one."""
        r = job.reward
        logged = self._internal.get((job.stamp, r.source.value, r.value))
        if logged:
            stored = logged.popleft()
            job.logged_id, job.committed_before = stored.id, stored.applied
