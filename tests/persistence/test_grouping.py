"""Writes queued by threads at once are written together, each thread answered its own."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

import pytest

from server.persistence.grouping import GroupedWrites


class Writer:
    """Records each call's items; the first call waits until `release` is set."""

    def __init__(self) -> None:
        self.batches: list[list[str]] = []
        self.entered = threading.Event()
        self.release = threading.Event()

    def write_all(self, items: Sequence[str]) -> list[str | BaseException]:
        self.batches.append(list(items))
        if len(self.batches) == 1:
            self.entered.set()
            assert self.release.wait(60)  # a bound for a hang, not a speed test
        if "storage fails" in items:
            raise OSError("disk gone")
        return [ValueError(i) if i.startswith("bad") else i.upper() for i in items]


def _in_threads(
    grouped: GroupedWrites[str, str], writer: Writer, later: list[str]
) -> dict[str, object]:
    """`first` written alone while `later` queue behind it; what each thread got."""
    answers: dict[str, object] = {}

    def write(item: str) -> None:
        try:
            answers[item] = grouped.write(item)
        except BaseException as e:
            answers[item] = e

    first = threading.Thread(target=write, args=("first",))
    first.start()
    assert writer.entered.wait(60)
    others = [threading.Thread(target=write, args=(i,)) for i in later]
    for t in others:
        t.start()
    deadline = time.monotonic() + 60  # a bound for a hang, not a speed test
    while True:
        with grouped._changed:
            if len(grouped._queued) == len(later):
                break
        assert time.monotonic() < deadline
        time.sleep(0.001)
    writer.release.set()
    for t in [first, *others]:
        t.join(60)
    return answers


def test_what_queues_during_a_write_is_written_in_one_call_each_answered_its_own() -> None:
    writer = Writer()
    grouped = GroupedWrites(writer.write_all)

    answers = _in_threads(grouped, writer, ["a", "bad b", "c"])

    assert grouped.calls == 2
    assert writer.batches[0] == ["first"]
    assert sorted(writer.batches[1]) == ["a", "bad b", "c"]
    assert (answers["first"], answers["a"], answers["c"]) == ("FIRST", "A", "C")
    assert isinstance(answers["bad b"], ValueError)  # its own error, nobody else's
    assert grouped.write("d") == "D"  # alone: at once


def test_a_write_that_fails_fails_every_item_in_it_and_the_next_write_goes_on() -> None:
    writer = Writer()
    grouped = GroupedWrites(writer.write_all)

    answers = _in_threads(grouped, writer, ["a", "storage fails"])

    assert answers["first"] == "FIRST"
    assert isinstance(answers["a"], OSError) and isinstance(answers["storage fails"], OSError)
    assert grouped.write("e") == "E"
    with pytest.raises(ValueError, match="bad f"):
        grouped.write("bad f")
