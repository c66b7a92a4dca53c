"""kill -9 at random moments of a stored run under reward traffic, SQLite's way.

A child process runs an engine on a SQLite file while rewards arrive; the parent kills it
with SIGKILL at random points, restarts it (it resumes the run), and in the end checks
the database's integrity, that every acknowledged reward is stored exactly once, and that
the stored LTM equals a replay of the stored rewards. ``SRLAB_CRASH_KILLS`` sets the
number of kills (50 by default; ``make reliability`` runs more); ``SRLAB_CRASH_KEEP=FILE``
keeps a copy of the database for a post-mortem.
"""

from __future__ import annotations

import os
import random
import select
import sqlite3
import subprocess
import sys
from pathlib import Path

from core.brain.catalog import load_catalog
from core.commands import InjectReward
from core.conditions import get_condition
from core.events import RewardApplied
from core.ports import StoredReward
from core.simulation import Simulation, TickInputs
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade

ROOT = Path(__file__).resolve().parents[2]
KILLS = int(os.environ.get("SRLAB_CRASH_KILLS", "50"))
INTERNAL = ("task", "program")


def start_child(url: str, acks: Path, n: int) -> subprocess.Popen[bytes]:
    child = subprocess.Popen(
        [sys.executable, "-m", "tests.reliability.crash_child", url, str(acks), str(n)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert child.stdout is not None
    ready, _, _ = select.select([child.stdout], [], [], 60)
    line = child.stdout.readline() if ready else b""
    if line.strip() != b"running":
        child.kill()
        _, err = child.communicate()
        raise AssertionError(f"the child did not start: {line!r} {err.decode()[-2000:]}")
    return child


def integrity(path: Path) -> str:
    with sqlite3.connect(path) as db:
        return str(db.execute("PRAGMA integrity_check").fetchone()[0])


def replay_ltm(rewards: list[StoredReward]) -> dict[tuple[str, str], float]:
    """LTM after replaying the log headless up to the last applied reward."""
    catalog = load_catalog()
    applied = [r.applied for r in rewards]
    last = max((i for i, a in enumerate(applied) if a), default=-1)
    # Rewards are applied in log order, so the applied ones are a prefix of the log.
    assert all(applied[: last + 1]), "an unapplied reward precedes an applied one"
    target = last + 1
    external = [r for r in rewards if r.record.source not in INTERNAL]
    sim = Simulation(get_condition("rp"), 11, catalog=catalog)
    count = 0
    sim.reset()
    while count < target:
        boundary = sim.tick_count + 1
        now = tuple(
            InjectReward(r.record.value, r.record.note, r.record.source)
            for r in external
            if r.record.tick == boundary
        )
        result = sim.tick(TickInputs(rewards=now))
        for e in result.events:
            if isinstance(e, RewardApplied):
                count += 1
                if count == target:
                    break
        if result.snapshot.done and count < target:
            sim.reset()
    names = catalog
    return {
        (names.stimuli[s].name, names.behaviours[b].name): v for (s, b), v in sim.brain.ltm.items()
    }


def test_kill_9_loses_nothing_acknowledged_and_applies_every_reward_once(
    tmp_path: Path,
) -> None:
    path = tmp_path / "crash.db"
    url = f"sqlite:///{path}"
    upgrade(url)
    acks = tmp_path / "acks.txt"
    rng = random.Random(2026)
    for n in range(KILLS):
        child = start_child(url, acks, n)
        try:
            select.select([], [], [], rng.uniform(0.0, 0.4))
        finally:
            child.kill()
            child.communicate()
        assert integrity(path) == "ok", f"after kill {n + 1}"

    store = SqlAlchemyRunStore(make_sessionmaker(make_engine(url)))
    rewards = store.rewards(1)
    if os.environ.get("SRLAB_CRASH_KEEP"):
        import shutil

        shutil.copy(path, os.environ["SRLAB_CRASH_KEEP"])
    acknowledged: dict[int, str] = {}
    for line in acks.read_text().splitlines():
        logged_id, note = line.split()
        acknowledged[int(logged_id)] = note
    assert len(acknowledged) >= KILLS, "the children acknowledged rewards"
    by_id = {r.id: r for r in rewards}
    for reward_id, note in acknowledged.items():
        assert reward_id in by_id, f"acknowledged reward {reward_id} is not stored"
        assert by_id[reward_id].record.note == note
    notes = [r.record.note for r in rewards if r.record.source not in INTERNAL]
    assert len(notes) == len(set(notes)), "a trainer's reward is stored twice"
    internal = [(r.record.tick, r.record.source) for r in rewards if r.record.source in INTERNAL]
    assert len(internal) == len(set(internal)), "a task or program reward is stored twice"
    assert replay_ltm(rewards) == store.ltm(1)
