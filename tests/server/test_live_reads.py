"""What the service sends the engines' process to run on a live run loads nothing there.

Unpickling a function imports its module. A route's first read of a running run used to
import the route's module, FastAPI with it, on the engines' loop: 170 ms in which no run
ticked (three overruns of a 20 Hz run). The functions now live in `server.live_reads`,
which the engines' process loads at its start (`server.engine_process.preload`).
"""

from __future__ import annotations

import pickle
import subprocess
import sys
from functools import partial
from operator import methodcaller

from bench.liveserver import ROOT
from core.engine import RunEngine
from server.live_reads import Guarded, kp_of_view, latest, run_of_view, set_rate

SENT = (
    run_of_view,  # GET /api/runs/{id}, GET /api/runs
    partial(kp_of_view, 1),  # GET /api/runs/{id}/kp
    Guarded(1, ("running",), RunEngine.pause),  # pause, resume, stop
    Guarded(1, ("running", "paused"), partial(set_rate, 5.0)),  # PUT .../rate
    latest,  # the 3D view's first frame of a run
    methodcaller("set_rate", 5.0),  # the 3D view's rate slider
)
"""What the routes and the viewer pass to `LiveRun.read` and `LiveRun.control`."""

CHILD = """
import pickle, sys
from server.engine_process import preload
preload()
before = set(sys.modules)
for blob in pickle.loads(sys.stdin.buffer.read()):
    pickle.loads(blob)
print(" ".join(sorted(set(sys.modules) - before)) or "-")
print(" ".join(m for m in ("fastapi", "starlette", "viser") if m in sys.modules) or "-")
"""


def test_the_engines_process_has_loaded_what_a_live_read_or_control_unpickles() -> None:
    blobs = pickle.dumps([pickle.dumps(f) for f in SENT])
    done = subprocess.run(
        [sys.executable, "-c", CHILD],
        input=blobs,
        capture_output=True,
        cwd=ROOT,
        check=True,
        timeout=120,
    )
    imported, web = done.stdout.decode().split("\n")[:2]
    assert imported == "-", f"unpickling imported {imported} on the engines' loop"
    assert web == "-", f"the engines' process loaded {web}"
