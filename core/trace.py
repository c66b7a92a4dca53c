"""Compact episode traces: what the robot sensed and did each tick, for replay."""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

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
    """Collects an episode's ticks cheaply and packs them at the end."""

    def __init__(self) -> None:
        self._rows: list[tuple[int, float, float, float, int, int, int, int]] = []

    def add(
        self,
        tick: int,
        x: float,
        y: float,
        heading: float,
        behaviour: int,
        how: str,
        lamp: int,
        stimuli: tuple[int, ...],
    ) -> None:
        """Record one tick."""
        mask = 0
        for s in stimuli:
            mask |= 1 << s
        self._rows.append((tick, x, y, heading, behaviour, HOWS.index(how), lamp, mask))

    def __len__(self) -> int:
        return len(self._rows)

    def pack(self) -> bytes:
        """The trace as compressed bytes; the recorder is emptied."""
        arr = np.array(self._rows, dtype=_DTYPE)
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
