"""Statistics over seeds: bootstrap confidence intervals, paired differences, sign-flip tests.

Numpy only, seeded, so every figure is reproducible. A seed is the unit of replication: each
seed's value (its success rate over a horizon, say) is one observation, and comparisons
between conditions pair seeds, since every condition meets the same obstacles and lamp
cycles on the same seed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

RESAMPLES = 10_000
"""Bootstrap resamples (and sign flips when they are drawn at random)."""
EXACT_FLIPS_UP_TO = 16
"""Up to this many pairs the sign-flip test enumerates every flip (2**16 = 65,536)."""


@dataclass(frozen=True, slots=True)
class Estimate:
    """A mean over seeds with its 95% bootstrap percentile interval.

    `low` and `high` are NaN with fewer than two seeds: one seed says nothing of spread.
    """

    mean: float
    low: float
    high: float
    n: int

    def as_dict(self) -> dict[str, float | int]:
        """The estimate as JSON-ready numbers."""
        return {"mean": self.mean, "low": self.low, "high": self.high, "n": self.n}

    @classmethod
    def of(cls, d: Mapping[str, float]) -> Estimate:
        """The estimate back from `as_dict`'s numbers (or `analysis.mean_ci`'s)."""
        return cls(float(d["mean"]), float(d["low"]), float(d["high"]), int(d["n"]))


def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, 7919]))


def bootstrap_mean(values: Sequence[float], *, seed: int = 0, level: float = 0.95) -> Estimate:
    """The mean of `values` and its percentile bootstrap interval at `level`.

    The interval lies inside the values' range, so a rate's interval stays within [0, 1].
    """
    x = np.asarray(values, dtype=np.float64)
    n = len(x)
    if n == 0:
        return Estimate(math.nan, math.nan, math.nan, 0)
    mean = float(x.mean())
    if n == 1 or np.all(x == x[0]):
        spread = math.nan if n == 1 else mean
        return Estimate(mean, spread, spread, n)
    idx = _rng(seed).integers(0, n, size=(RESAMPLES, n))
    means = x[idx].mean(axis=1)
    alpha = (1.0 - level) / 2
    low, high = np.quantile(means, [alpha, 1.0 - alpha])
    return Estimate(mean, float(low), float(high), n)


@dataclass(frozen=True, slots=True)
class Paired:
    """A difference between two conditions, paired by seed.

    `diff` is the mean of `a - b` over seeds with its bootstrap interval; `p` the two-sided
    sign-flip p-value of "no difference".
    """

    diff: Estimate
    p: float


def sign_flip_p(diffs: Sequence[float], *, seed: int = 0) -> float:
    """Two-sided p of the sign-flip (paired permutation) test that the mean difference is 0.

    Under the null each seed's difference is as likely to have either sign; p is the share
    of sign assignments whose mean is at least as far from 0 as the observed one. Exact up
    to `EXACT_FLIPS_UP_TO` pairs, else `RESAMPLES` random flips (counting the observed one).
    """
    d = np.asarray(diffs, dtype=np.float64)
    n = len(d)
    if n == 0:
        return math.nan
    observed = abs(d.mean())
    if observed == 0.0:
        return 1.0
    tol = 1e-12 * max(1.0, observed)
    if n <= EXACT_FLIPS_UP_TO:
        codes = np.arange(2**n, dtype=np.int64)
        signs = 1.0 - 2.0 * ((codes[:, None] >> np.arange(n)) & 1)
        means = np.abs(signs @ d) / n
        return float(np.mean(means >= observed - tol))
    signs = _rng(seed).choice(np.array([-1.0, 1.0]), size=(RESAMPLES, n))
    means = np.abs(signs @ d) / n
    return float((np.sum(means >= observed - tol) + 1) / (RESAMPLES + 1))


def paired_difference(
    a: Sequence[float], b: Sequence[float], *, seed: int = 0, level: float = 0.95
) -> Paired:
    """`a - b` seed by seed: its mean with a bootstrap interval, and a sign-flip p."""
    if len(a) != len(b):
        raise ValueError("paired values need one of each per seed")
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return Paired(
        bootstrap_mean(d.tolist(), seed=seed, level=level), sign_flip_p(d.tolist(), seed=seed)
    )


def pct(e: Estimate, digits: int = 0) -> str:
    """A rate and its interval as percentages: ``52% [40, 63]``."""
    if math.isnan(e.mean):
        return "n/a"
    mean = f"{100 * e.mean:.{digits}f}%"
    if math.isnan(e.low):
        return mean
    return f"{mean} [{100 * e.low:.{digits}f}, {100 * e.high:.{digits}f}]"
