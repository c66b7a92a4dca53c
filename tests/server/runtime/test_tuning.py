"""Process tuning (`server.runtime.tuning`): short scheduler slices, and nothing else moved.

Each case runs in a fresh interpreter, so the test process keeps its own slices (and a
slice it may have asked for, which children inherit, is first set back to the default). The cases
need Linux 6.12 or later (EEVDF's slice requests) and skip elsewhere; whether the kernel
reports slices is read with the system call itself, not with the code under test.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from server.runtime.tuning import SHORT_SLICE_NS, slice_ns

reported = slice_ns()
pytestmark = pytest.mark.skipif(
    not reported, reason="the kernel reports no scheduler slice (Linux 6.12 or later does)"
)


def _in_fresh_interpreter(code: str) -> dict[str, object]:
    """Run `code` in a new interpreter; it prints one JSON object, returned here."""
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
        cwd=Path(__file__).resolve().parents[3],  # the repository, where `server` is
    )
    result = json.loads(done.stdout)
    assert isinstance(result, dict)
    return result


def test_every_thread_and_every_later_one_asks_for_short_slices_at_its_own_nice() -> None:
    result = _in_fresh_interpreter(
        """
import json, os, threading
from server.runtime.tuning import ask_short_slices, slice_ns
ask_short_slices(0)  # the kernel's default slice again
os.nice(5)
before = slice_ns()
ready, leave = threading.Event(), threading.Event()
early = {}
def wait():
    early["tid"] = threading.get_native_id()
    ready.set()
    leave.wait()
t = threading.Thread(target=wait)
t.start()
ready.wait()
asked = ask_short_slices()
early_slice = slice_ns(early["tid"])
leave.set()
t.join()
later = []
t = threading.Thread(target=lambda: later.append(slice_ns()))
t.start()
t.join()
print(json.dumps({"before": before, "asked": asked, "main": slice_ns(),
    "early": early_slice, "later": later[0], "nice": os.getpriority(os.PRIO_PROCESS, 0)}))
"""
    )
    assert result["before"] != SHORT_SLICE_NS, "the kernel's default slice before"
    assert result["asked"] is True
    assert result["main"] == SHORT_SLICE_NS
    assert result["early"] == SHORT_SLICE_NS, "a thread that ran before the call"
    assert result["later"] == SHORT_SLICE_NS, "a thread made after inherits it"
    assert result["nice"] == 5, "the nice value stays what it was"


def test_a_policy_someone_chose_is_kept() -> None:
    result = _in_fresh_interpreter(
        """
import json, os
from server.runtime.tuning import ask_short_slices, slice_ns
os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
before = slice_ns()
asked = ask_short_slices()
print(json.dumps({"asked": asked, "before": before, "after": slice_ns(),
    "batch": os.sched_getscheduler(0) == os.SCHED_BATCH}))
"""
    )
    assert result["asked"] is False
    assert result["after"] == result["before"]
    assert result["batch"] is True


def test_the_slice_bench_measures_each_side_in_a_process_of_its_own() -> None:
    """`bench.slices` runs its two sides in fresh processes beside its spinners."""
    from bench.busy import busy
    from bench.slices import _measured

    with busy(1):
        default = _measured(False, 5, 0.0001, 0.001)
        short = _measured(True, 5, 0.0001, 0.001)
    assert len(default) == len(short) == 5
    assert min(default + short) >= 0.0, "a sleep never ends before it is due"
