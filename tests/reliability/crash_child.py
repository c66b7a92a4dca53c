"""A child process for the crash test: an engine run on SQLite while rewards arrive.

Usage: python -m tests.reliability.crash_child DB_URL ACK_FILE SEED

It resumes run 1 if it exists (else creates it), runs it in realtime at a high rate, and
injects a reward every few milliseconds. After each acknowledgement it appends the
reward's id and note to ACK_FILE and fsyncs it: what a client was told is stored. The
parent kills it with SIGKILL at random moments.
"""

from __future__ import annotations

import asyncio
import os
import random
import sys

from core.engine import RunEngine
from core.errors import UnknownRunError
from core.ports import Mode, RunSpec, RunStatus
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker

SPEC = RunSpec("rp", 11, None, Mode.REALTIME, hz=400.0)


async def main(url: str, ack_path: str, seed: int) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(make_engine(url)))
    try:
        run = store.load_run(1)
    except UnknownRunError:
        run = None
    if run is None:
        engine = RunEngine.create(SPEC, store)
    else:
        if run.status is RunStatus.RUNNING:
            store.set_status(1, RunStatus.INTERRUPTED)
        engine = RunEngine.restore(1, store)
    rng = random.Random(seed)
    fd = os.open(ack_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    async def trainer() -> None:
        while engine.status is not RunStatus.RUNNING:
            await asyncio.sleep(0.001)
        sys.stdout.write("running\n")
        sys.stdout.flush()
        n = 0
        while True:
            await asyncio.sleep(rng.uniform(0.0, 0.01))
            n += 1
            note = f"{seed}-{n}"
            ack = await engine.reward(rng.choice([-1.0, -0.5, 0.5, 1.0]), note=note)
            os.write(fd, f"{ack.id} {note}\n".encode())
            os.fsync(fd)

    async with asyncio.TaskGroup() as tg:
        tg.create_task(engine.run())
        tg.create_task(trainer())


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], sys.argv[2], int(sys.argv[3])))
