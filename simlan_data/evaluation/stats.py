"""Statistics of a V&V suite: mean and t confidence interval over seeds, verdicts on intervals.

A check never rests on one run. For every (case, metric) the suite has one value per seed:

- **bound** (``max: B`` or ``min: B``): the whole confidence interval of the mean must lie within
  the bound (demonstrated compliance); with a single value, that value decides.
- **baseline** (``tolerance: T``): a regression is a change for the worse of more than T that
  the interval of the difference (current - accepted baseline) shows with confidence: the whole
  interval lies beyond T. Paired over seeds when the current seeds are among the baseline's (a
  seed is the same run, so unchanged code differs by exactly 0), else Welch's interval. With one
  value each, the difference itself decides.

Intervals are Student-t intervals (scipy) at the suite's confidence (default 0.95).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class Interval:
    """Mean of n values and its two-sided confidence interval (low == high == mean for n < 2)."""

    n: int
    mean: float
    low: float
    high: float
    std: float

    @property
    def half_width(self) -> float:
        return 0.5 * (self.high - self.low)


def interval(values: Sequence[float], confidence: float = 0.95) -> Interval:
    """Mean and t interval of ``values`` (NaN values are dropped; none left gives NaN)."""
    x = np.asarray([v for v in values if v is not None and not math.isnan(v)], dtype=float)
    n = len(x)
    if n == 0:
        nan = float("nan")
        return Interval(0, nan, nan, nan, nan)
    mean = float(x.mean())
    if n == 1:
        return Interval(1, mean, mean, mean, 0.0)
    std = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * std / math.sqrt(n) if std > 0 else 0.0
    return Interval(n, mean, mean - half, mean + half, std)


def difference_interval(
    current: dict[int, float], baseline: dict[int, float], confidence: float = 0.95
) -> tuple[Interval, str]:
    """Interval of mean(current) - mean(baseline); values keyed by seed.

    Returns the interval and how it was formed: ``paired`` (current seeds among the baseline's),
    ``welch`` or ``single``.
    """
    cur = {s: v for s, v in current.items() if not math.isnan(v)}
    base = {s: v for s, v in baseline.items() if not math.isnan(v)}
    if cur and set(cur) <= set(base):  # the same seeds (or some of them): the same runs, paired
        return interval([cur[s] - base[s] for s in sorted(cur)], confidence), "paired"
    a, b = interval(list(cur.values()), confidence), interval(list(base.values()), confidence)
    if a.n == 0 or b.n == 0:
        nan = float("nan")
        return Interval(0, nan, nan, nan, nan), "none"
    diff = a.mean - b.mean
    if a.n < 2 or b.n < 2:
        return Interval(min(a.n, b.n), diff, diff, diff, 0.0), "single"
    va, vb = a.std**2 / a.n, b.std**2 / b.n
    se = math.sqrt(va + vb)
    if se == 0:
        return Interval(min(a.n, b.n), diff, diff, diff, 0.0), "welch"
    dof = (va + vb) ** 2 / (va**2 / (a.n - 1) + vb**2 / (b.n - 1))
    half = float(stats.t.ppf(0.5 + confidence / 2, dof)) * se
    return Interval(min(a.n, b.n), diff, diff - half, diff + half, se), "welch"


@dataclass(frozen=True)
class Bound:
    """What a metric must meet: an absolute bound and/or a tolerance against the baseline."""

    max: float | None = None
    min: float | None = None
    tolerance: float | None = None  # absolute, in the metric's unit
    rel_tolerance: float | None = None  # of the baseline mean's magnitude
    better: str = "lower"  # lower | higher: which direction a change is an improvement

    def describe(self) -> str:
        parts = []
        if self.max is not None:
            parts.append(f"<= {self.max:g}")
        if self.min is not None:
            parts.append(f">= {self.min:g}")
        return ", ".join(parts) or "-"

    def allowed_change(self, baseline_mean: float) -> float | None:
        tols = []
        if self.tolerance is not None:
            tols.append(self.tolerance)
        if self.rel_tolerance is not None and not math.isnan(baseline_mean):
            tols.append(self.rel_tolerance * abs(baseline_mean))
        return max(tols) if tols else None


def bound_ok(bound: Bound, iv: Interval) -> bool:
    """True if the whole interval lies within the bound (a NaN interval never does)."""
    if iv.n == 0 or math.isnan(iv.mean):
        return False
    if bound.max is not None and not iv.high <= bound.max:
        return False
    return not (bound.min is not None and not iv.low >= bound.min)


def baseline_change(bound: Bound, diff: Interval, baseline_mean: float) -> str:
    """``regression``, ``improved`` or ``same`` for the interval of (current - baseline)."""
    tol = bound.allowed_change(baseline_mean)
    if tol is None or diff.n == 0 or math.isnan(diff.mean):
        return "same"
    worse = diff if bound.better == "lower" else Interval(diff.n, -diff.mean, -diff.high, -diff.low, diff.std)
    if worse.low > tol:
        return "regression"
    if worse.high < -tol:
        return "improved"
    return "same"
