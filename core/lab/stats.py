"""Statistics over seeds: confidence intervals, paired differences, sign-flip tests, Holm.

Numpy only, seeded, so every figure is reproducible. A seed is the unit of replication: each
seed's value (its success rate over a horizon, say) is one observation, and comparisons
between conditions pair seeds, since every condition meets the same obstacles and lamp
cycles on the same seed.

Every summary reports Student's t interval (`INTERVAL`), chosen by its coverage on
synthetic samples shaped like srlab's (per-seed success rates of Bernoulli episodes, with
and without seed-to-seed differences, and paired differences of them): at 20 and 40 seeds
it covers the true mean 94.5-95.2% of the time, where the percentile bootstrap and BCa
cover 92.4-92.9% at 20 seeds and 93.6-93.8% at 40 (`tests/core/lab/test_stats.py` measures
all three). Both bootstraps are too narrow by about the same factor: they use the plug-in
spread (`sqrt((n - 1) / n)` of the sample's) and in effect the normal quantile where the
mean of `n` values has Student's; BCa corrects a skew these samples hardly have.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import Literal

import numpy as np
import numpy.typing as npt

RESAMPLES = 10_000
"""Bootstrap resamples (and sign flips when they are drawn at random)."""
EXACT_FLIPS_UP_TO = 16
"""Up to this many pairs the sign-flip test enumerates every flip (2**16 = 65,536)."""

IntervalMethod = Literal["t", "percentile", "bca"]
INTERVAL: IntervalMethod = "t"
"""The interval every summary reports (see the module's docstring for why)."""
INTERVAL_NAMES: dict[IntervalMethod, str] = {
    "t": "Student's t",
    "percentile": "percentile bootstrap",
    "bca": "bias-corrected and accelerated (BCa) bootstrap",
}
_CHUNK = 4_000_000
"""Resampled values held at once when bootstrapping many samples (about 32 MB)."""
_NORMAL = NormalDist()


@dataclass(frozen=True, slots=True)
class Estimate:
    """A mean over seeds with its 95% interval (`mean_interval`'s method).

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


def interval_name(method: IntervalMethod = INTERVAL) -> str:
    """The method's name as a summary states it: ``95% Student's t interval over seeds``."""
    return f"95% {INTERVAL_NAMES[method]} interval over seeds"


def _t_two_sided(t: float, df: int) -> float:
    """P(|T| <= t) for Student's T with integer `df` (Abramowitz & Stegun 26.7.3-4)."""
    theta = math.atan(t / math.sqrt(df))
    s, c2 = math.sin(theta), math.cos(theta) ** 2
    term = total = 1.0
    if df % 2:
        if df == 1:
            return 2.0 * theta / math.pi
        for k in range(3, df - 1, 2):
            term *= c2 * (k - 1) / k
            total += term
        return 2.0 / math.pi * (theta + s * math.sqrt(c2) * total)
    for k in range(2, df - 1, 2):
        term *= c2 * (k - 1) / k
        total += term
    return s * total


def t_quantile(df: int, level: float = 0.95) -> float:
    """Student's t two-sided quantile: P(|T| <= q) = `level` with `df` degrees of freedom.

    Exact for any integer `df` (the closed form of the CDF, inverted by bisection to
    machine precision); NaN for `df` < 1.
    """
    if df < 1:
        return math.nan
    low, high = 0.0, 1.0
    while _t_two_sided(high, df) < level:
        high *= 2.0
    for _ in range(200):
        mid = (low + high) / 2.0
        if mid in (low, high):
            break
        if _t_two_sided(mid, df) < level:
            low = mid
        else:
            high = mid
    return high


def _bootstrap_means(
    x: npt.NDArray[np.float64], seed: int, resamples: int
) -> npt.NDArray[np.float64]:
    """Each row's bootstrap means, (rows, resamples); the same resampled seeds for every row.

    The rows are independent samples, so sharing one draw of indices among them leaves
    each row's bootstrap as it is alone; it is the draw a single row gets with `seed`.
    """
    rows, n = x.shape
    idx = _rng(seed).integers(0, n, size=(resamples, n))
    out = np.empty((rows, resamples))
    step = max(1, _CHUNK // (resamples * n))
    for i in range(0, rows, step):
        out[i : i + step] = x[i : i + step][:, idx].mean(axis=2)
    return out


def _row_quantiles(
    means: npt.NDArray[np.float64], q: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Each row's quantile at its own level `q[row]` (linear interpolation, as np.quantile)."""
    ranked = np.sort(means, axis=1)
    pos = np.clip(q, 0.0, 1.0) * (ranked.shape[1] - 1)
    below = np.floor(pos).astype(np.int64)
    above = np.minimum(below + 1, ranked.shape[1] - 1)
    rows = np.arange(ranked.shape[0])
    frac = pos - below
    return np.asarray(ranked[rows, below] * (1 - frac) + ranked[rows, above] * frac)


def _bca(
    x: npt.NDArray[np.float64], means: npt.NDArray[np.float64], level: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """BCa bounds of each row's mean from its bootstrap means (Efron & Tibshirani, 14.3)."""
    m = x.mean(axis=1, keepdims=True)
    resamples = means.shape[1]
    below = (np.sum(means < m, axis=1) + 0.5 * np.sum(means == m, axis=1)) / resamples
    below = np.clip(below, 1.0 / resamples, 1.0 - 1.0 / resamples)
    z0 = np.array([_NORMAL.inv_cdf(float(b)) for b in below])
    # The jackknife's acceleration; for the mean it is the sample's skewness / (6 sqrt(n)).
    d = x - m
    spread = np.sum(d**2, axis=1) ** 1.5
    accel = np.divide(np.sum(d**3, axis=1), 6.0 * spread, out=np.zeros(len(x)), where=spread > 0)
    bounds = []
    for tail in ((1.0 - level) / 2, (1.0 + level) / 2):
        z = z0 + _NORMAL.inv_cdf(tail)
        q = np.array([_NORMAL.cdf(float(v)) for v in z0 + z / (1.0 - accel * z)])
        bounds.append(_row_quantiles(means, q))
    return bounds[0], bounds[1]


def mean_intervals(
    samples: npt.ArrayLike,
    *,
    method: IntervalMethod = INTERVAL,
    level: float = 0.95,
    seed: int = 0,
    resamples: int = RESAMPLES,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The interval of each row's mean at `level`: arrays of the low and the high bounds.

    `samples` is (rows, n), each row one sample of `n` values (seeds). Every method's
    interval lies within its row's range, so a rate's stays within [0, 1] (Student's t is
    clipped there; the bootstraps are there by construction). A row of equal values has
    that value as both bounds; with one value per row the bounds are NaN.
    """
    x = np.atleast_2d(np.asarray(samples, dtype=np.float64))
    rows, n = x.shape
    if n < 2:
        nan = np.full(rows, math.nan)
        return nan, nan.copy()
    lo, hi = x.min(axis=1), x.max(axis=1)
    if method == "t":
        half = t_quantile(n - 1, level) * x.std(axis=1, ddof=1) / math.sqrt(n)
        m = x.mean(axis=1)
        low, high = m - half, m + half
    elif method in ("percentile", "bca"):
        means = _bootstrap_means(x, seed, resamples)
        if method == "percentile":
            alpha = (1.0 - level) / 2
            low, high = np.quantile(means, [alpha, 1.0 - alpha], axis=1)
        else:
            low, high = _bca(x, means, level)
    else:
        raise ValueError(f"unknown interval method {method!r}")
    flat = lo == hi
    return np.where(flat, lo, np.clip(low, lo, hi)), np.where(flat, hi, np.clip(high, lo, hi))


def mean_interval(
    values: Sequence[float],
    *,
    method: IntervalMethod = INTERVAL,
    seed: int = 0,
    level: float = 0.95,
) -> Estimate:
    """The mean of `values` and its interval at `level` (Student's t unless told).

    The interval lies inside the values' range, so a rate's interval stays within [0, 1].
    """
    x = np.asarray(values, dtype=np.float64)
    n = len(x)
    if n == 0:
        return Estimate(math.nan, math.nan, math.nan, 0)
    low, high = mean_intervals(x[None, :], method=method, level=level, seed=seed)
    return Estimate(float(x.mean()), float(low[0]), float(high[0]), n)


def bootstrap_mean(values: Sequence[float], *, seed: int = 0, level: float = 0.95) -> Estimate:
    """The mean of `values` and its percentile bootstrap interval at `level`.

    Kept for the callers that want the bootstrap by name; summaries use `mean_interval`,
    since the percentile bootstrap covers about 92% at 20 seeds where it says 95%.
    """
    return mean_interval(values, method="percentile", seed=seed, level=level)


@dataclass(frozen=True, slots=True)
class Paired:
    """A difference between two conditions, paired by seed.

    `diff` is the mean of `a - b` over seeds with its interval; `p` the two-sided
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
    a: Sequence[float],
    b: Sequence[float],
    *,
    seed: int = 0,
    level: float = 0.95,
    method: IntervalMethod = INTERVAL,
) -> Paired:
    """`a - b` seed by seed: its mean with an interval (Student's t unless told), a sign-flip p."""
    if len(a) != len(b):
        raise ValueError("paired values need one of each per seed")
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return Paired(
        mean_interval(d.tolist(), method=method, seed=seed, level=level),
        sign_flip_p(d.tolist(), seed=seed),
    )


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of a family of p-values, in their order.

    The k-th smallest of m p-values is multiplied by m - k + 1, and each adjusted p is at
    least the one before it (capped at 1): rejecting where the adjusted p is below alpha
    keeps the chance of any false rejection in the family below alpha. NaNs stay NaN and
    do not count in m.
    """
    p = np.asarray(p_values, dtype=np.float64)
    out = np.full(len(p), math.nan)
    known = np.flatnonzero(~np.isnan(p))
    m = len(known)
    order = known[np.argsort(p[known], kind="stable")]
    running = 0.0
    for k, i in enumerate(order):
        running = max(running, min(1.0, (m - k) * float(p[i])))
        out[i] = running
    return out.tolist()


def wilson(successes: int, trials: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson's score interval of a binomial rate: one run's `successes` of `trials`.

    For a count reported without seeds (the paper's Table II); NaN with no trials.
    """
    if trials <= 0:
        return math.nan, math.nan
    z = _NORMAL.inv_cdf((1.0 + level) / 2)
    p = successes / trials
    centre = (p + z * z / (2 * trials)) / (1 + z * z / trials)
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials**2)) / (1 + z * z / trials)
    return max(0.0, centre - half), min(1.0, centre + half)


def pct(e: Estimate, digits: int = 0) -> str:
    """A rate and its interval as percentages: ``52% [40, 63]``."""
    if math.isnan(e.mean):
        return "n/a"
    mean = f"{100 * e.mean:.{digits}f}%"
    if math.isnan(e.low):
        return mean
    return f"{mean} [{100 * e.low:.{digits}f}, {100 * e.high:.{digits}f}]"


def p_text(p: float) -> str:
    """A p-value as a summary prints it: ``p 0.013``, ``p < 0.001``."""
    if math.isnan(p):
        return "p -"
    return "p < 0.001" if p < 0.001 else f"p {p:.3f}"
