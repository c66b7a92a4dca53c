"""Writes that several threads ask for at once, done by one of them in one transaction.

Every realtime run writes on worker threads of its own: a trainer's reward is acknowledged
once its log entry is committed, and its learning is committed at the next boundary. With
many trainers those threads queued for SQLite's one write lock, and each committed a
transaction of a row or two. `GroupedWrites` lets the first thread in write what the others
queued while it waited, in one call (`SqlAlchemyRunStore` runs them in one transaction):
each thread still gets its own answer (its result, or the error its own write raised).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

T = TypeVar("T")
R = TypeVar("R")


class _Item(Generic[T, R]):
    __slots__ = ("done", "error", "item", "result")

    def __init__(self, item: T) -> None:
        self.item = item
        self.done = False
        self.result: R | None = None
        self.error: BaseException | None = None


class GroupedWrites(Generic[T, R]):
    """`write` items queued by threads at once, all in one call, by one of the threads.

    Args:
        write_all: writes the items in order; answers each one's result or the exception
            it raised (raising itself fails every item with that exception).
    """

    def __init__(self, write_all: Callable[[Sequence[T]], Sequence[R | BaseException]]) -> None:
        self._write_all = write_all
        self._changed = threading.Condition()
        self._queued: list[_Item[T, R]] = []
        self._writing = False
        self.calls = 0
        """How many times `write_all` was called (each a transaction)."""

    def write(self, item: T) -> R:
        """Write `item`, with what other threads queue meanwhile; its result or its error."""
        mine: _Item[T, R] = _Item(item)
        with self._changed:
            self._queued.append(mine)
            while self._writing and not mine.done:
                self._changed.wait()
            if not mine.done:  # nobody writes: this thread writes what is queued, its own too
                self._writing = True
                batch, self._queued = self._queued, []
        if not mine.done:
            try:
                self._write(batch)
            finally:
                with self._changed:
                    self._writing = False
                    self._changed.notify_all()
        if mine.error is not None:
            raise mine.error
        return mine.result  # type: ignore[return-value]  # set with done, error None

    def _write(self, batch: list[_Item[T, R]]) -> None:
        self.calls += 1
        try:
            results = self._write_all([b.item for b in batch])
        except BaseException as e:
            results = [e] * len(batch)
        for b, result in zip(batch, results, strict=True):
            if isinstance(result, BaseException):
                b.error = result
            else:
                b.result = result
            b.done = True
