"""Tests of the confidence intervals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.scoring import bootstrap_ratio_interval, rates_with_intervals, wilson_interval


@pytest.mark.parametrize("k, n, low, high", [
    # Newcombe (1998), Stat. Med. 17:857-872, Table I, method 3 (Wilson score, 95 %)
    (81, 263, 0.2553, 0.3662),
    (15, 148, 0.0624, 0.1605),
    (0, 20, 0.0, 0.1611),
    (1, 29, 0.0061, 0.1718),
])
def test_wilson_matches_published_values(k, n, low, high):
    lo, hi = wilson_interval(k, n)
    assert round(float(lo), 4) == low and round(float(hi), 4) == high


def test_wilson_contains_point_estimate_and_stays_in_unit_interval():
    n = np.repeat(np.arange(1, 60), 60)
    k = np.concatenate([np.arange(60)] * 59)
    keep = k <= n
    k, n = k[keep], n[keep]
    for conf in (0.8, 0.95, 0.99):
        lo, hi = wilson_interval(k, n, confidence=conf)
        p = k / n
        assert np.all(lo <= p + 1e-12) and np.all(p <= hi + 1e-12)
        assert np.all(lo >= 0) and np.all(hi <= 1)
        assert np.all(lo[k == 0] == 0) and np.all(hi[k == n] == 1)


def test_wilson_widens_with_confidence_and_narrows_with_n():
    lo90, hi90 = wilson_interval(5, 20, confidence=0.90)
    lo99, hi99 = wilson_interval(5, 20, confidence=0.99)
    assert lo99 < lo90 and hi99 > hi90
    lo_big, hi_big = wilson_interval(50, 200)
    lo_small, hi_small = wilson_interval(5, 20)
    assert hi_big - lo_big < hi_small - lo_small


def test_wilson_undefined_and_invalid():
    lo, hi = wilson_interval([0, 3], [0, 5])
    assert np.isnan(lo[0]) and np.isnan(hi[0]) and not np.isnan(lo[1])
    with pytest.raises(ParameterError, match="0 <= successes <= trials"):
        wilson_interval(6, 5)
    with pytest.raises(ParameterError, match=r"'confidence' parameter of wilson_interval must be "
                                             r"a float in \(0, 1\). Got 1.5 instead."):
        wilson_interval(1, 5, confidence=1.5)


def test_bootstrap_is_seeded_and_brackets_the_pooled_rate():
    rng = np.random.default_rng(1)
    den = rng.integers(5, 30, size=(2, 12))
    num = rng.binomial(den, [[0.2], [0.6]])
    a = bootstrap_ratio_interval(num, den, n_resamples=500, random_state=3)
    b = bootstrap_ratio_interval(num, den, n_resamples=500, random_state=3)
    c = bootstrap_ratio_interval(num, den, n_resamples=500, random_state=4)
    np.testing.assert_array_equal(a[0], b[0])
    assert not np.array_equal(a[0], c[0])
    pooled = num.sum(axis=1) / den.sum(axis=1)
    assert np.all(a[0] <= pooled) and np.all(pooled <= a[1])


def test_bootstrap_is_wider_than_wilson_for_clustered_data():
    # two units, one always wrong, one always right: flights are not independent
    num = np.array([50, 0])
    den = np.array([50, 50])
    blo, bhi = bootstrap_ratio_interval(num, den, n_resamples=400, random_state=0)
    wlo, whi = wilson_interval(num.sum(), den.sum())
    assert bhi - blo > whi - wlo


def test_bootstrap_undefined_when_no_denominator():
    lo, hi = bootstrap_ratio_interval(np.zeros(4), np.zeros(4), n_resamples=10)
    assert np.isnan(lo) and np.isnan(hi)
    with pytest.raises(ParameterError, match="same shape"):
        bootstrap_ratio_interval(np.zeros(3), np.zeros(4))


def test_rates_with_intervals_pools_units():
    counts = pd.DataFrame({"g": ["a", "a", "b", "b"], "unit_id": [1, 2, 1, 2],
                           "k": [1, 2, 0, 0], "n": [4, 6, 0, 0]})
    out = rates_with_intervals(counts, keys=["g"], counts=["k", "n"],
                               rates={"rate": ("k", "n")}, n_bootstrap=50)
    assert out["g"].tolist() == ["a", "b"] and out["k"].tolist() == [3, 0]
    assert out.loc[0, "rate"] == pytest.approx(0.3) and np.isnan(out.loc[1, "rate"])
    lo, hi = wilson_interval(3, 10)
    assert out.loc[0, "rate_ci_low"] == lo and out.loc[0, "rate_ci_high"] == hi
    assert {"rate_boot_low", "rate_boot_high"} <= set(out.columns)
