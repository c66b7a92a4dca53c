"""Compact episode traces: what the robot sensed and did each tick, for replay.

Format SRT2 also keeps, per tick, what made the behaviour run (its association's source,
exploration, the default or a command) and the stimulus it answered; SRT1 traces, stored
before, read with those unknown (origin "", stimulus -1).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from core.brain.selection import ORIGINS

if TYPE_CHECKING:
    from core.simulation import Snapshot

MAGIC = b"SRT2"
_MAGIC_V1 = b"SRT1"
_FIELDS_V1 = [
    ("tick", "<i4"),
    ("x", "<f4"),
    ("y", "<f4"),
    ("heading", "<f4"),
    ("behaviour", "<i2"),
    ("how", "<i1"),
    ("lamp", "<i1"),
    ("stimuli", "<u8"),
]
_DTYPE_V1 = np.dtype(_FIELDS_V1)
_DTYPE = np.dtype([*_FIELDS_V1, ("origin", "<i1"), ("released_by", "<i1")])
TraceArray = npt.NDArray[np.void]
"""An episode's trace rows, one structured record per tick (SRT2's layout)."""
HOWS = ("released", "default", "explored", "continued", "commanded")
_HOW_INDEX = {h: i for i, h in enumerate(HOWS)}
_ORIGIN_INDEX = {o: i for i, o in enumerate(ORIGINS)}


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
    origin: str = ""
    """What made the behaviour run (`core.brain.selection.ORIGINS`; "" in an SRT1 trace)."""
    released_by: int = -1
    """The stimulus the behaviour answered (-1: none, or unknown in an SRT1 trace)."""


class TraceRecorder:
    """Collects an episode's snapshots cheaply and gives them as rows at the end.

    `compress` packs the rows `take` gives (the engine's writer does, off the tick task).
    """

    def __init__(self) -> None:
        self._rows: list[Snapshot] = []
        self.add: Callable[[Snapshot], None] = self._rows.append
        """Record one tick (snapshots are immutable, so keeping them is enough): the list's
        own `append`, so a tick pays no Python call for it."""

    def __len__(self) -> int:
        return len(self._rows)

    def take(self) -> TraceArray:
        """The trace's rows as one array, uncompressed (`compress` packs it); emptied."""
        rows = self._rows.copy()
        self._rows.clear()  # the same list: `add` appends to it
        n = len(rows)
        arr: TraceArray = np.empty(n, dtype=_DTYPE)
        if rows:
            # Column by column, each converted straight to its type (`np.fromiter`): numpy
            # fills a structured array from a list per field several times faster than
            # from a tuple per row, and faster still without guessing each column's type.
            # This runs on the tick task: a few per cent of a fast run's time.
            _, tick, _, x, y, heading, stimuli, behaviour, how, lamp, *_, origin, by = zip(
                *rows, strict=True
            )
            arr["tick"] = np.fromiter(tick, np.int32, n)
            arr["x"] = np.fromiter(x, np.float32, n)
            arr["y"] = np.fromiter(y, np.float32, n)
            arr["heading"] = np.fromiter(heading, np.float32, n)
            arr["behaviour"] = np.fromiter(behaviour, np.int16, n)
            arr["how"] = np.fromiter(map(_HOW_INDEX.__getitem__, how), np.int8, n)
            arr["lamp"] = np.fromiter(lamp, np.int8, n)
            masks = list(map(_MASKS.get, stimuli))  # a run meets few sets: nearly all known
            arr["stimuli"] = masks if None not in masks else list(map(_mask, stimuli))
            arr["origin"] = np.fromiter(map(_ORIGIN_INDEX.__getitem__, origin), np.int8, n)
            arr["released_by"] = np.fromiter(by, np.int8, n)
        return arr


def compress(rows: TraceArray) -> bytes:
    """A trace's rows (`TraceRecorder.take`) as stored.

    zlib lets go of the GIL while it compresses, so on a writer's thread this runs beside
    the ticks, on another core: about a third of packing an episode's trace.
    """
    return MAGIC + zlib.compress(rows.tobytes(), 1)


_MASKS: dict[tuple[int, ...], int] = {}
"""Bit masks of the stimulus sets seen (a run meets few: the ticks' sets repeat)."""
_MASKS_MAX = 65536


def _mask(stimuli: tuple[int, ...]) -> int:
    """The stimuli as a bit mask."""
    mask = _MASKS.get(stimuli)
    if mask is None:
        mask = 0
        for i in stimuli:
            mask |= 1 << i
        if len(_MASKS) < _MASKS_MAX:
            _MASKS[stimuli] = mask
    return mask


def unpack(blob: bytes) -> list[TraceRow]:
    """The rows of a packed trace (SRT2, or SRT1 as stored before)."""
    if blob.startswith(MAGIC):
        dtype, v2 = _DTYPE, True
    elif blob.startswith(_MAGIC_V1):
        dtype, v2 = _DTYPE_V1, False
    else:
        raise ValueError("not an srlab trace")
    arr = np.frombuffer(zlib.decompress(blob[len(MAGIC) :]), dtype=dtype)
    # Whole columns as Python lists: indexing numpy's structured rows one field at a time
    # cost about 50 us a row, most of a stored episode's read.
    n = len(arr)
    origins = [ORIGINS[o] for o in arr["origin"].tolist()] if v2 else [""] * n
    released = arr["released_by"].tolist() if v2 else [-1] * n
    return [
        TraceRow(tick, x, y, heading, behaviour, HOWS[how], lamp, _bits(mask), origin, by)
        for tick, x, y, heading, behaviour, how, lamp, mask, origin, by in zip(
            arr["tick"].tolist(),
            arr["x"].tolist(),
            arr["y"].tolist(),
            arr["heading"].tolist(),
            arr["behaviour"].tolist(),
            arr["how"].tolist(),
            arr["lamp"].tolist(),
            arr["stimuli"].tolist(),
            origins,
            released,
            strict=True,
        )
    ]


def _bits(mask: int) -> tuple[int, ...]:
    """The indices of the set bits of `mask`, lowest first."""
    out = []
    while mask:
        low = mask & -mask
        out.append(low.bit_length() - 1)
        mask ^= low
    return tuple(out)
