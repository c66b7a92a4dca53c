"""What the reliability tests share: reward traffic over HTTP and checks of the stored log."""

from __future__ import annotations

import random
import sqlite3
import threading
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from core.brain.catalog import load_catalog
from core.commands import InjectReward, RewardSource
from core.events import RewardDue
from core.ports import StoredReward
from core.run.conditions import get_condition
from core.run.simulation import Simulation

INTERNAL = ("task", "program")
"""Reward sources the run itself produces (the rest are trainers')."""


class RewardTraffic:
    """Threads that post trainer rewards to a run and remember what was acknowledged.

    Every reward has a unique note (`prefix`, thread, sequence number), so the stored log
    shows whether one was stored twice. A request that fails (the server died, the run
    ended) counts by its kind and the thread goes on until `stop`.
    """

    def __init__(
        self,
        url: str,
        run_id: int,
        prefix: str,
        *,
        threads: int = 2,
        pause_s: float = 0.01,
        headers: dict[str, str] | None = None,
        seed: int = 0,
        timeout_s: float = 15.0,
    ) -> None:
        self.url = url
        self.run_id = run_id
        self.prefix = prefix
        self.pause_s = pause_s
        self.headers = headers or {}
        self.timeout_s = timeout_s
        self.acked: dict[int, str] = {}
        """Reward id -> note, for every 202."""
        self.outcomes: Counter[str] = Counter()
        """Status codes and error kinds of every request."""
        self.details: dict[str, str] = {}
        """One response body or error message per outcome."""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._post, args=(i, seed * 1000 + i), daemon=True)
            for i in range(threads)
        ]

    def start(self) -> RewardTraffic:
        """Start posting."""
        for t in self._threads:
            t.start()
        return self

    def stop(self) -> None:
        """Stop posting and wait for the threads."""
        self._stop.set()
        for t in self._threads:
            t.join(self.timeout_s + 5)
            assert not t.is_alive(), "a reward request hung"

    @property
    def sent(self) -> int:
        """Requests made so far."""
        return sum(self.outcomes.values())

    def _post(self, thread: int, seed: int) -> None:
        rng = random.Random(seed)
        n = 0
        with httpx.Client(base_url=self.url, timeout=self.timeout_s, headers=self.headers) as c:
            while not self._stop.is_set():
                n += 1
                note = f"{self.prefix}-{thread}-{n}"
                value = rng.choice([-1.0, -0.5, 0.5, 1.0])
                try:
                    r = c.post(
                        f"/api/runs/{self.run_id}/rewards", json={"value": value, "note": note}
                    )
                except httpx.TimeoutException as e:
                    self._count("timeout", repr(e))
                    continue
                except httpx.HTTPError as e:
                    self._count(type(e).__name__, str(e))
                    self._stop.wait(0.05)
                    continue
                self._count(str(r.status_code), r.text[:300])
                if r.status_code == 202:
                    with self._lock:
                        self.acked[int(r.json()["id"])] = note
                elif r.status_code != 429:
                    self._stop.wait(0.02)  # the run is not running (yet): do not spin
                self._stop.wait(rng.uniform(0.0, self.pause_s))

    def _count(self, outcome: str, detail: str) -> None:
        with self._lock:
            self.outcomes[outcome] += 1
            self.details.setdefault(outcome, detail)


@dataclass
class LogCheck:
    """What the stored reward log says about the acknowledged rewards."""

    stored: int
    trainer: int
    acknowledged: int
    lost: list[int] = field(default_factory=list)
    """Acknowledged rewards missing from the log, or stored with another note."""
    twice: list[str] = field(default_factory=list)
    """Notes (trainers') or (tick, source) pairs (the run's own) stored more than once."""
    unapplied: int = 0
    """Logged rewards whose learning was never committed."""

    @property
    def held(self) -> bool:
        """Nothing acknowledged lost, nothing stored twice."""
        return not self.lost and not self.twice


def check_log(rewards: list[StoredReward], acked: dict[int, str]) -> LogCheck:
    """Compare the stored log with what clients were told."""
    by_id = {r.id: r for r in rewards}
    lost = [i for i, note in acked.items() if i not in by_id or by_id[i].record.note != note]
    trainers = [r.record.note for r in rewards if r.record.source not in INTERNAL]
    own = [f"{r.record.tick}/{r.record.source}" for r in rewards if r.record.source in INTERNAL]
    twice = [k for k, n in Counter(trainers + own).items() if n > 1]
    return LogCheck(
        stored=len(rewards),
        trainer=len(trainers),
        acknowledged=len(acked),
        lost=lost,
        twice=twice,
        unapplied=sum(not r.applied for r in rewards),
    )


def integrity(path: Path) -> str:
    """SQLite's own verdict on a database file."""
    with sqlite3.connect(path) as db:
        return str(db.execute("PRAGMA integrity_check").fetchone()[0])


def replay_ltm(
    rewards: list[StoredReward], condition: str = "rp", seed: int = 11
) -> dict[tuple[str, str], float]:
    """LTM after replaying the log headless, in the order the rewards apply, up to the
    last applied one.

    Trainers' rewards are applied at the boundaries they were stamped with; the run's own
    are produced again by the replayed ticks and matched with their log entries. As in the
    engine, a boundary applies the run's own rewards first, then the trainers'; an
    episode's own rewards apply before it ends and trainers' stamped after its last tick
    after the reset. Learning is committed in the order it happened, so the applied
    rewards come first in that order (not always in the log's: a trainer's reward gets
    its id when it arrives, the run's own when its learning is committed, so one that
    arrived between an own reward's application and its commit has the smaller id and is
    applied after it; a crash between the two commits leaves it unapplied behind an
    applied one). Equal to the stored LTM only if every reward was applied exactly once,
    in that order.

    The simulation defers its rewards, as the engine's does, so that the replay can stop
    right after the last applied reward: a run stopped between a boundary and its tick has
    applied the boundary's rewards but not run the tick, and when that tick would have
    ended an episode, a simulation applying its own rewards would apply the episode's
    last ones in the same `tick()` call, which the run never did.
    """
    catalog = load_catalog()
    applied_total = sum(r.applied for r in rewards)
    trainers: dict[int, list[StoredReward]] = {}
    own_logged: dict[tuple[int, str, float], deque[StoredReward]] = {}
    for r in rewards:
        if r.record.source in INTERNAL:
            key = (r.record.tick, r.record.source, r.record.value)
            own_logged.setdefault(key, deque()).append(r)
        else:
            trainers.setdefault(r.record.tick, []).append(r)
    sim = Simulation(get_condition(condition), seed, catalog=catalog, defer_rewards=True)
    count = 0
    stopped = False  # at the first reward, in the order they apply, that was not applied

    def apply(due: list[tuple[RewardDue, StoredReward | None]]) -> None:
        nonlocal count, stopped
        for e, stored in due:
            if stopped or count == applied_total:
                return
            if stored is None or not stored.applied:
                stopped = True
                return
            reward = InjectReward(e.value, note=e.note, source=RewardSource(e.source))
            sim.apply_reward(reward, e.tick, e.episode)
            count += 1

    def logged(own: list[RewardDue]) -> list[tuple[RewardDue, StoredReward | None]]:
        """The run's own rewards with their log entries (None: never committed)."""
        matched: list[tuple[RewardDue, StoredReward | None]] = []
        for e in own:
            entries = own_logged.get((e.tick, str(e.source), e.value))
            matched.append((e, entries.popleft() if entries else None))
        return matched

    own: list[RewardDue] = []
    sim.reset()
    while not stopped and count < applied_total:
        boundary = sim.tick_count + 1
        apply(logged(own))
        apply(
            [
                (
                    RewardDue(
                        boundary, sim.episode, r.record.value, r.record.source, r.record.note
                    ),
                    r,
                )
                for r in trainers.get(boundary, [])
            ]
        )
        if stopped or count == applied_total:
            break
        result = sim.tick()
        own = [e for e in result.events if isinstance(e, RewardDue)]
        if result.snapshot.done:
            apply(logged(own))
            own = []
            if not stopped and count < applied_total:
                sim.reset()
    assert count == applied_total, (
        f"an unapplied reward precedes an applied one in the order they apply "
        f"({count} applied before it, {applied_total} applied in all)"
    )
    return {
        (catalog.stimuli[s].name, catalog.behaviours[b].name): v
        for (s, b), v in sim.brain.ltm.items()
    }


def rss_kib(pid: int) -> tuple[int, int]:
    """A process's resident memory now and at its peak (VmRSS, VmHWM), in KiB."""
    fields = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            fields[key] = int(value.split()[0])
    return fields["VmRSS"], fields["VmHWM"]
