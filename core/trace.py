"""Compact episode traces: what the robot sensed and did each tick, for replay."""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from core.simulation import Snapshot

MAGIC = b"SRT1"
_DTYPE = np.dtype(
    [
        ("tick", "<i4"),
        ("x", "<f4"),
        ("y", "<f4"),
        ("heading", "<f4"),
        ("behaviour", "<i2"),
        ("how", "<i1"),
        ("lamp", "<i1"),
        ("stimuli", "<u8"),
    ]
)
HOWS = ("released", "default", "explored", "continued", "commanded")
_HOW_INDEX = {h: i for i, h in enumerate(HOWS)}


@dataclass(frozen=True, slots=True)
class TraceRow:
    """One tick of a stored trace."""

    tick: int
    x: float
    y: float
    heading_rad: float
    behaviour: int
    how: str
    lamp: int
    stimuli: tuple[int, ...]


class TraceRecorder:
    """Collects an episode's snapshots cheaply and packs them at the end."""

    def __init__(self) -> None:
        self._rows: list[Snapshot] = []

    def add(self, snapshot: Snapshot) -> None:
        """Record one tick (snapshots are immutable, so keeping them is enough)."""
        self._rows.append(snapshot)

    def __len__(self) -> int:
        return len(self._rows)

    def pack(self) -> bytes:
        """The trace as compressed bytes; the recorder is emptied."""
        rows = []
        for s in self._rows:
            mask = 0
            for i in s.stimuli:
                mask |= 1 << i
            rows.append(
                (s.tick, s.x, s.y, s.heading_rad, s.behaviour, _HOW_INDEX[s.how.value],
                 int(s.lamp), mask)
            )  # fmt: skip
        arr = np.array(rows, dtype=_DTYPE)
        self._rows = []
        return MAGIC + zlib.compress(arr.tobytes(), 1)


def unpack(blob: bytes) -> list[TraceRow]:
    """The rows of a packed trace."""
    if not blob.startswith(MAGIC):
        raise ValueError("not an srlab trace")
    arr = np.frombuffer(zlib.decompress(blob[len(MAGIC) :]), dtype=_DTYPE)
    rows = []
    for r in arr:
        mask = int(r["stimuli"])
        rows.append(
            TraceRow(
                int(r["tick"]),
                float(r["x"]),
                float(r["y"]),
                float(r["heading"]),
                int(r["behaviour"]),
                HOWS[int(r["how"])],
                int(r["lamp"]),
                tuple(i for i in range(64) if mask >> i & 1),
            )
        )
    return rows
