"""Compact episode traces: what the robot sensed and did each tick, for replay.

Format SRT2 also keeps, per tick, what made the behaviour run (its association's source,
exploration, the default or a command) and the stimulus it answered; SRT1 traces, stored
before, read with those unknown (origin "", stimulus -1).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import MISSING, dataclass, fields
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from core.brain.selection import ORIGINS

if TYPE_CHECKING:
    from core.run.simulation import Snapshot

MAGIC = b"SRT2"
_MAGIC_V1 = b"SRT1"
HOWS = ("released", "default", "explored", "continued", "commanded")
Encode = Callable[[Sequence[Any]], Iterable[int]]
"""A column's values (one per tick) as the numbers stored."""
Decode = Callable[[list[Any]], list[Any]]
"""A stored column's numbers as the trace row's values."""


@dataclass(frozen=True, slots=True)
class Column:
    """One column of a stored trace: where it comes from, how it is stored and read.

    `field` names both the `Snapshot` field it packs and the `TraceRow` field it reads
    back into: packing and reading go by name, so the snapshot's field order is free.
    """

    name: str
    """The column's name in the stored layout."""
    dtype: str
    """Its stored type (little-endian numpy)."""
    field: str
    encode: Encode | None = None
    """None: the values are the numbers stored."""
    decode: Decode | None = None
    """None: the numbers stored are the row's values."""


def _indices(names: tuple[str, ...]) -> tuple[Encode, Decode]:
    """A column storing one of `names` as its index."""
    index = {n: i for i, n in enumerate(names)}
    return (lambda v: map(index.__getitem__, v)), (lambda v: [names[i] for i in v])


def _masks(values: Sequence[tuple[int, ...]]) -> Iterable[int]:
    masks = list(map(_MASKS.get, values))  # a run meets few stimulus sets: nearly all known
    return map(_mask, values) if None in masks else cast("list[int]", masks)


COLUMNS: tuple[Column, ...] = (
    Column("tick", "<i4", "tick"),
    Column("x", "<f4", "x"),
    Column("y", "<f4", "y"),
    Column("heading", "<f4", "heading_rad"),
    Column("behaviour", "<i2", "behaviour"),
    Column("how", "<i1", "how", *_indices(HOWS)),
    Column("lamp", "<i1", "lamp"),
    Column("stimuli", "<u8", "stimuli", _masks, lambda v: [_bits(m) for m in v]),
    Column("origin", "<i1", "origin", *_indices(ORIGINS)),
    Column("released_by", "<i1", "released_by"),
)
"""A stored trace's layout (SRT2), in its stored order: the one list packing and reading
follow. Reordering or retyping a column changes what is stored (tests/core/run/test_trace.py
holds traces packed before)."""
_V1_COLUMNS = 8
"""SRT1 traces, stored before, have the first columns only."""
_DTYPE = np.dtype([(c.name, c.dtype) for c in COLUMNS])
_DTYPE_V1 = np.dtype([(c.name, c.dtype) for c in COLUMNS[:_V1_COLUMNS]])
TraceArray = npt.NDArray[np.void]
"""An episode's trace rows, one structured record per tick (SRT2's layout)."""


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


_ROW_FIELDS = tuple(f.name for f in fields(TraceRow))
_ROW_DEFAULTS = {f.name: f.default for f in fields(TraceRow) if f.default is not MISSING}
"""What a row holds that an SRT1 trace does not store."""
assert {c.field for c in COLUMNS} == set(_ROW_FIELDS), "each row field is one column's"


def _places(snapshot: object) -> dict[str, int]:
    """Where each column's field sits in `snapshot` (a NamedTuple): packing goes by name."""
    names: tuple[str, ...] = getattr(snapshot, "_fields", ())
    missing = [c.field for c in COLUMNS if c.field not in names]
    if missing:
        kind = type(snapshot).__name__
        raise ValueError(f"a {kind} has no field {', '.join(missing)} for its trace")
    return {c.field: names.index(c.field) for c in COLUMNS}


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
            values = list(zip(*rows, strict=True))
            place = _places(rows[0])
            for c in COLUMNS:
                column = values[place[c.field]]
                encoded = column if c.encode is None else c.encode(column)
                arr[c.name] = np.fromiter(encoded, c.dtype, n)
        return arr


def trace_records(rows: TraceArray, last: int) -> tuple[tuple[int, int, int], ...]:
    """The STM records of a trace's `last` rows: (tick, stimulus, behaviour), oldest first.

    A tick's record is what STM took for it: the behaviour and the stimulus it answered
    (`released_by`; none for the default behaviour's ticks).
    """
    tail = rows[-last:] if last > 0 else rows[:0]
    return tuple(
        (t, s, b)
        for t, s, b in zip(
            tail["tick"].tolist(),
            tail["released_by"].tolist(),
            tail["behaviour"].tolist(),
            strict=True,
        )
        if s >= 0
    )


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
    columns = COLUMNS if v2 else COLUMNS[:_V1_COLUMNS]
    values: dict[str, list[Any]] = {f: [d] * n for f, d in _ROW_DEFAULTS.items()}
    for c in columns:
        stored = arr[c.name].tolist()
        values[c.field] = stored if c.decode is None else c.decode(stored)
    return [TraceRow(*row) for row in zip(*(values[f] for f in _ROW_FIELDS), strict=True)]


def _bits(mask: int) -> tuple[int, ...]:
    """The indices of the set bits of `mask`, lowest first."""
    out = []
    while mask:
        low = mask & -mask
        out.append(low.bit_length() - 1)
        mask ^= low
    return tuple(out)
