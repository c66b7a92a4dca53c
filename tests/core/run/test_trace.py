"""Stored traces: packed by name, so they read back the same whatever Snapshot's field order.

`data/trace_srt2.bin` and `data/trace_srt1.bin` were packed by the positional packer this
module's packer replaced, from the snapshots in `data/trace.json` (an episode's first
ticks of `kp`, seed 7, and a few made to cover every how and origin); `rows` there is what
that code read back. Databases and checkpoints hold traces packed so: they must read back
identically, and packing the same snapshots must give the same bytes.
"""

from __future__ import annotations

import json
import zlib
from collections import namedtuple
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from core.brain.selection import How
from core.events import Cause, Outcome
from core.run.simulation import Snapshot
from core.run.trace import MAGIC, TraceRecorder, TraceRow, compress, unpack
from core.sim.types import LampColor

DATA = Path(__file__).parent / "data"
FIXTURE = json.loads((DATA / "trace.json").read_text())


def _snapshot(d: dict[str, Any]) -> Snapshot:
    return Snapshot(
        **{
            **d,
            "stimuli": tuple(d["stimuli"]),
            "how": How(d["how"]),
            "lamp": LampColor(d["lamp"]),
            "outcome": None if d["outcome"] is None else Outcome(d["outcome"]),
            "cause": None if d["cause"] is None else Cause(d["cause"]),
        }
    )


SNAPSHOTS = [_snapshot(d) for d in FIXTURE["snapshots"]]
ROWS = [TraceRow(**{**d, "stimuli": tuple(d["stimuli"])}) for d in FIXTURE["rows"]]


def _packed(snapshots: list[Any]) -> bytes:
    recorder = TraceRecorder()
    for s in snapshots:
        recorder.add(s)
    return compress(recorder.take())


def _raw(blob: bytes) -> bytes:
    return zlib.decompress(blob[len(MAGIC) :])


def test_stored_traces_read_back_as_they_were_packed() -> None:
    assert unpack((DATA / "trace_srt2.bin").read_bytes()) == ROWS
    srt1 = unpack((DATA / "trace_srt1.bin").read_bytes())
    assert srt1 == [replace(r, origin="", released_by=-1) for r in ROWS]


def test_the_same_snapshots_pack_to_the_stored_bytes() -> None:
    stored = (DATA / "trace_srt2.bin").read_bytes()
    packed = _packed(SNAPSHOTS)
    assert packed[: len(MAGIC)] == stored[: len(MAGIC)] == MAGIC
    assert _raw(packed) == _raw(stored)
    assert unpack(packed) == ROWS


def _like_snapshot(fields: list[str]) -> Any:
    """A NamedTuple class like Snapshot, with `fields` (in their order)."""
    return namedtuple("LikeSnapshot", fields)


@pytest.mark.parametrize(
    "order",
    [
        # Fields of one type swapped: a positional packer would store them crossed, silently.
        ["tick", "episode", "episode_tick", "y", "x", *Snapshot._fields[5:]],
        list(reversed(Snapshot._fields)),
    ],
    ids=["swapped", "reversed"],
)
def test_reordering_snapshot_fields_packs_the_same_bytes(order: list[str]) -> None:
    cls = _like_snapshot(order)
    moved = [cls(**s._asdict()) for s in SNAPSHOTS]
    assert _raw(_packed(moved)) == _raw((DATA / "trace_srt2.bin").read_bytes())


def test_a_snapshot_without_a_packed_field_is_refused_loudly() -> None:
    renamed = [("heading" if f == "heading_rad" else f) for f in Snapshot._fields]
    cls = _like_snapshot(renamed)
    moved = [cls(*s) for s in SNAPSHOTS]
    with pytest.raises(ValueError, match="heading_rad"):
        _packed(moved)
