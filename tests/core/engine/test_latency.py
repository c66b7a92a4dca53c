"""Latency histograms: fixed size whatever the number of samples, percentiles within a bucket."""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from core.engine.latency import BUCKETS_PER_DOUBLING, LatencyHistogram

RESOLUTION = 2.0 ** (1 / BUCKETS_PER_DOUBLING)
"""A percentile is at most this factor over the exact one."""


def exact(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q / 100 * len(ordered)) - 1))]


@given(
    st.lists(st.floats(0.0, 100.0, allow_nan=False), min_size=1, max_size=300),
    st.floats(0.0, 100.0),
)
def test_a_percentile_is_the_exact_one_rounded_up_to_its_bucket(
    values: list[float], q: float
) -> None:
    h = LatencyHistogram()
    for v in values:
        h.add(v)
    want = exact(values, q)
    got = h.percentile(q)
    assert want <= got <= max(want * RESOLUTION, 1e-6)
    assert (h.count, h.max, h.min) == (len(values), max(values), min(values))


def test_200000_samples_take_the_space_of_one() -> None:
    h = LatencyHistogram()
    size = h.buckets
    for i in range(200_000):
        h.add((i % 1000) * 1e-5)
    assert h.buckets == size  # a read walks the same buckets for a run of any age
    assert 989e-5 <= h.percentile(99) <= 989e-5 * RESOLUTION


def test_an_empty_histogram_has_no_percentile() -> None:
    h = LatencyHistogram()
    assert math.isnan(h.percentile(99)) and math.isnan(h.max) and len(h) == 0
