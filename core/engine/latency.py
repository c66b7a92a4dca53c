"""Latency statistics kept as they come: a fixed set of log-spaced buckets.

A run keeps the lateness of every tick and the delay of every reward it acknowledges. Keeping
the samples and sorting them to read a percentile makes every read slower the older the run
(200,000 samples took 200 ms, on the event loop that paces the ticks). `LatencyHistogram`
counts each sample in one of a fixed number of buckets instead, 16 per doubling from 1 us:
adding is O(1), and reading a percentile walks the buckets, whatever the run's age: down
from the highest one holding a sample, so a p99 (each published state reads two) looks at
the few buckets of the slowest samples, not at every one below them. A percentile is the
upper edge of its bucket (at most the largest sample), so it is never under the exact
value and at most 4.4 % over it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

BUCKETS_PER_DOUBLING = 16
SMALLEST_S = 1e-6
"""Samples up to this go in the first bucket."""
DOUBLINGS = 40
"""From 1 us up to about 12 days: larger samples share the last bucket."""
_BUCKETS = 1 + BUCKETS_PER_DOUBLING * DOUBLINGS


def _bucket(seconds: float) -> int:
    if not seconds > SMALLEST_S:  # nan and negatives too
        return 0
    index = 1 + int(math.log2(seconds / SMALLEST_S) * BUCKETS_PER_DOUBLING)
    return min(index, _BUCKETS - 1)


def _upper_edge(index: int) -> float:
    return float(SMALLEST_S * 2.0 ** (index / BUCKETS_PER_DOUBLING))


@dataclass
class LatencyHistogram:
    """Counts of latency samples (seconds) in fixed log-spaced buckets.

    Attributes:
        count: how many samples were added.
        max: the largest sample (nan before the first).
        min: the smallest sample (nan before the first).
    """

    count: int = 0
    max: float = math.nan
    min: float = math.nan
    _counts: list[int] = field(default_factory=lambda: [0] * _BUCKETS, repr=False)
    _top: int = field(default=0, repr=False)
    """The highest bucket holding a sample (0 before the first)."""

    def add(self, seconds: float) -> None:
        """Count one sample."""
        index = _bucket(seconds)
        self._counts[index] += 1
        if index > self._top:
            self._top = index
        if self.count == 0:
            self.max = self.min = seconds
        else:
            self.max = max(self.max, seconds)
            self.min = min(self.min, seconds)
        self.count += 1

    def __len__(self) -> int:
        return self.count

    @property
    def buckets(self) -> int:
        """How many buckets it keeps (the same from the first sample to the last)."""
        return len(self._counts)

    def percentile(self, q: float) -> float:
        """The q-th percentile (0-100) as its bucket's upper edge, at most `max`; nan if empty.

        The rank is the nearest-rank one: the smallest sample with at least q % of the
        samples at or below it.
        """
        if self.count == 0:
            return math.nan
        rank = min(self.count, max(1, math.ceil(q / 100 * self.count)))
        above = self.count - rank  # its bucket: the highest with more samples from it up
        seen = 0
        counts = self._counts
        for index in range(self._top, -1, -1):
            seen += counts[index]
            if seen > above:
                return min(_upper_edge(index), self.max) if index else min(SMALLEST_S, self.max)
        return self.max  # pragma: no cover - the counts add up to `count`


__all__ = ["BUCKETS_PER_DOUBLING", "LatencyHistogram"]
