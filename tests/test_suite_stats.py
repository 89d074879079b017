"""The suite's statistics: t intervals, paired and Welch differences, verdicts on intervals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from simlan_data.evaluation.stats import (
    Bound,
    Interval,
    baseline_change,
    bound_ok,
    difference_interval,
    interval,
)


def test_interval_matches_scipy_t_interval() -> None:
    x = [0.011, 0.014, 0.009, 0.012]
    iv = interval(x, 0.95)
    low, high = stats.t.interval(0.95, len(x) - 1, loc=np.mean(x), scale=stats.sem(x))
    assert iv.n == 4
    assert iv.mean == pytest.approx(np.mean(x))
    assert (iv.low, iv.high) == pytest.approx((low, high))


def test_interval_of_one_value_and_of_none() -> None:
    one = interval([0.5])
    assert (one.n, one.low, one.mean, one.high) == (1, 0.5, 0.5, 0.5)
    none = interval([float("nan")])
    assert none.n == 0 and math.isnan(none.mean)


def test_bound_needs_the_whole_interval_inside() -> None:
    bound = Bound(max=0.02)
    assert bound_ok(bound, Interval(3, 0.010, 0.005, 0.015, 0.002))
    # the mean is inside, but the interval reaches beyond: not demonstrated
    assert not bound_ok(bound, Interval(3, 0.015, 0.008, 0.022, 0.003))
    assert bound_ok(Bound(min=0.97), Interval(3, 0.99, 0.98, 1.0, 0.005))
    assert not bound_ok(Bound(min=0.97), Interval(3, 0.99, 0.96, 1.0, 0.01))
    assert not bound_ok(bound, Interval(0, math.nan, math.nan, math.nan, math.nan))


def test_paired_difference_of_unchanged_runs_is_exactly_zero() -> None:
    base = {0: 0.011, 1: 0.014, 2: 0.009}
    diff, how = difference_interval(dict(base), base)
    assert how == "paired"
    assert (diff.low, diff.high) == (0.0, 0.0)
    assert baseline_change(Bound(max=0.02, tolerance=0.001), diff, 0.011) == "same"
    # fewer seeds than the baseline (--seeds 2): still the same runs, still paired
    diff, how = difference_interval({0: 0.011, 1: 0.014}, base)
    assert how == "paired" and (diff.n, diff.low, diff.high) == (2, 0.0, 0.0)


def test_regression_is_decided_on_the_interval_not_on_one_noisy_run() -> None:
    base = {0: 0.010, 1: 0.010, 2: 0.010}
    bound = Bound(max=0.05, tolerance=0.004)
    # one seed much worse, the others better: the interval of the mean change straddles the tolerance
    noisy = {0: 0.020, 1: 0.006, 2: 0.007}
    diff, _ = difference_interval(noisy, base)
    assert diff.high > 0.004 > diff.low
    assert baseline_change(bound, diff, 0.010) == "same"
    # every seed worse by 5 cm (an injected bias): a regression
    biased = {s: v + 0.05 for s, v in {0: 0.011, 1: 0.009, 2: 0.010}.items()}
    diff, _ = difference_interval(biased, base)
    assert baseline_change(bound, diff, 0.010) == "regression"
    # better beyond the tolerance: improved (suggests --accept), never a failure
    diff, _ = difference_interval({0: 0.002, 1: 0.003, 2: 0.002}, {0: 0.012, 1: 0.011, 2: 0.013})
    assert baseline_change(bound, diff, 0.012) == "improved"


def test_higher_is_better_flips_the_direction() -> None:
    bound = Bound(min=0.97, tolerance=0.01, better="higher")
    diff, _ = difference_interval({0: 0.90, 1: 0.91, 2: 0.89}, {0: 1.0, 1: 1.0, 2: 0.99})
    assert baseline_change(bound, diff, 0.997) == "regression"
    diff, _ = difference_interval({0: 1.0, 1: 1.0, 2: 1.0}, {0: 0.95, 1: 0.96, 2: 0.94})
    assert baseline_change(bound, diff, 0.95) == "improved"


def test_welch_interval_when_seeds_differ() -> None:
    a = {0: 1.0, 1: 1.2, 2: 0.9, 3: 1.1}
    b = {10: 0.5, 11: 0.6, 12: 0.4}
    diff, how = difference_interval(a, b)
    assert how == "welch"
    res = stats.ttest_ind(list(a.values()), list(b.values()), equal_var=False)
    ci = res.confidence_interval(0.95)
    assert (diff.low, diff.high) == pytest.approx((ci.low, ci.high))


def test_relative_tolerance_scales_with_the_baseline() -> None:
    bound = Bound(max=10.0, tolerance=0.1, rel_tolerance=0.05)
    assert bound.allowed_change(100.0) == pytest.approx(5.0)
    assert bound.allowed_change(1.0) == pytest.approx(0.1)
