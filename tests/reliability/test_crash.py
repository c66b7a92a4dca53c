"""kill -9 at random moments of a stored run under reward traffic, SQLite's way.

A child process runs an engine on a SQLite file while rewards arrive; the parent kills it
with SIGKILL at random points, restarts it (it resumes the run), and in the end checks
the database's integrity, that every acknowledged reward is stored exactly once, and that
the stored LTM equals a replay of the stored rewards. ``SRLAB_CRASH_KILLS`` sets the
number of kills: 20 by default, CI's size (each kill still lands at a random moment of a
running engine that is writing rewards; each costs a new process's start, so 50 took
over 4 minutes of `make test`), 100 in ``make reliability``. ``SRLAB_CRASH_KEEP=FILE``
keeps a copy of the database for a post-mortem.
"""

from __future__ import annotations

import os
import random
import select
import subprocess
import sys
from pathlib import Path

from harness import INTERNAL, check_log, integrity, replay_ltm
from reliability_report import count, record

from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade

ROOT = Path(__file__).resolve().parents[2]
KILLS = int(os.environ.get("SRLAB_CRASH_KILLS", "20"))


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
    log = check_log(rewards, acknowledged)
    replayed_ltm, stored_ltm = replay_ltm(rewards), store.ltm(1)
    replayed = replayed_ltm == stored_ltm
    record(
        "kill -9 of an engine process (SQLite)",
        f"{count(KILLS)} SIGKILLs of a process running a realtime engine (400 Hz) on SQLite, "
        "0-0.4 s after it ticked, while it injected rewards",
        f"{count(log.acknowledged)} rewards acknowledged, {len(log.lost)} lost, "
        f"{len(log.twice)} stored twice; integrity_check ok after every kill; "
        f"LTM {'=' if replayed else '!='} a replay of the {count(log.stored)} logged rewards",
    )
    by_id = {r.id: r for r in rewards}
    for reward_id, note in acknowledged.items():
        assert reward_id in by_id, f"acknowledged reward {reward_id} is not stored"
        assert by_id[reward_id].record.note == note
    notes = [r.record.note for r in rewards if r.record.source not in INTERNAL]
    assert len(notes) == len(set(notes)), "a trainer's reward is stored twice"
    internal = [(r.record.tick, r.record.source) for r in rewards if r.record.source in INTERNAL]
    assert len(internal) == len(set(internal)), "a task or program reward is stored twice"
    assert replayed_ltm == stored_ltm
