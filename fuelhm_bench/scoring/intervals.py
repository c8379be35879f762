"""Confidence intervals on rates: Wilson score intervals and a bootstrap over units."""

from __future__ import annotations

import functools
import warnings
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd
from scipy.stats import norm

from fuelhm_bench.errors import ParameterError

__all__ = ["bootstrap_ratio_interval", "per_unit_counts", "pooled_rates", "rates_with_intervals", "wilson_interval"]


def _z(confidence: float, owner: str) -> float:
    if not (0 < confidence < 1):
        raise ParameterError(f"The 'confidence' parameter of {owner} must be a float in (0, 1). "
                             f"Got {confidence!r} instead.")
    return _normal_quantile(float(0.5 + confidence / 2))


@functools.lru_cache(maxsize=64)
def _normal_quantile(p: float) -> float:
    """``norm.ppf(p)``, remembered: a scoring run asks for the same few quantiles a hundred times."""
    return float(norm.ppf(p))


def wilson_interval(successes: Any, trials: Any, *,
                    confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of a binomial proportion (Wilson 1927; Newcombe 1998).

    With ``p = k / n`` and ``z`` the two-sided normal quantile::

        centre = (p + z**2 / (2 n)) / (1 + z**2 / n)
        half   = z / (1 + z**2 / n) * sqrt(p (1 - p) / n + z**2 / (4 n**2))

    Unlike the Wald interval it stays in [0, 1] and is not degenerate at
    ``k = 0`` or ``k = n``.

    Parameters
    ----------
    successes : array-like of int
        Numbers of successes ``k``.
    trials : array-like of int
        Numbers of trials ``n`` (``k <= n``).
    confidence : float, default=0.95
        Confidence level in (0, 1).

    Returns
    -------
    low, high : numpy.ndarray of float
        Bounds, NaN where ``n == 0``.

    Raises
    ------
    ParameterError
        When counts are negative or ``k > n``.

    Examples
    --------
    >>> low, high = wilson_interval(81, 263)
    >>> round(float(low), 4), round(float(high), 4)
    (0.2553, 0.3662)
    """
    k = np.asarray(successes, dtype=float)
    n = np.asarray(trials, dtype=float)
    if np.any(k < 0) or np.any(n < 0) or np.any(k > n):
        raise ParameterError(f"The 'successes' and 'trials' parameters of wilson_interval must "
                             f"satisfy 0 <= successes <= trials. Got {successes!r} and "
                             f"{trials!r} instead.")
    z = _z(confidence, "wilson_interval")
    with np.errstate(divide="ignore", invalid="ignore"):
        p = k / n
        denom = 1 + z**2 / n
        centre = (p + z**2 / (2 * n)) / denom
        half = z / denom * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2))
        low = np.where(n > 0, np.clip(centre - half, 0.0, 1.0), np.nan)
        high = np.where(n > 0, np.clip(centre + half, 0.0, 1.0), np.nan)
    low = np.where(k == 0, np.where(n > 0, 0.0, np.nan), low)
    high = np.where((k == n) & (n > 0), 1.0, high)
    return low, high


def bootstrap_ratio_interval(numerators: Any, denominators: Any, *, n_resamples: int = 1000,
                             confidence: float = 0.95,
                             random_state: int | np.random.Generator = 0
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Percentile bootstrap interval of pooled ratios, resampling *units* with replacement.

    Flights of one unit are correlated (same unit, same degradation history), so
    the Wilson interval, which assumes independent flights, is too narrow when
    a few units dominate. Resampling whole units keeps that correlation: each
    resample draws ``U`` units with replacement and recomputes
    ``sum(numerator) / sum(denominator)`` over the drawn units.

    Parameters
    ----------
    numerators, denominators : array-like of shape (n_groups, n_units) or (n_units,)
        Per-unit counts of each group (a group = one rate of one table row).
    n_resamples : int, default=1000
        Number of bootstrap resamples (> 0).
    confidence : float, default=0.95
        Confidence level.
    random_state : int or numpy.random.Generator, default=0
        Seed; the same seed gives the same interval.

    Returns
    -------
    low, high : numpy.ndarray of shape (n_groups,) (or scalars for 1-D input)
        Percentile bounds; NaN when no resample has a positive denominator.
    """
    num = np.atleast_2d(np.asarray(numerators, dtype=float))
    den = np.atleast_2d(np.asarray(denominators, dtype=float))
    if num.shape != den.shape:
        raise ParameterError(f"The 'numerators' and 'denominators' parameters of "
                             f"bootstrap_ratio_interval must have the same shape. Got "
                             f"{num.shape} and {den.shape} instead.")
    if not (isinstance(n_resamples, (int, np.integer)) and n_resamples > 0):
        raise ParameterError(f"The 'n_resamples' parameter of bootstrap_ratio_interval must be an "
                             f"int > 0. Got {n_resamples!r} instead.")
    alpha = 1 - confidence
    _z(confidence, "bootstrap_ratio_interval")
    rng = (random_state if isinstance(random_state, np.random.Generator)
           else np.random.default_rng(random_state))
    n_units = num.shape[1]
    if n_units == 0:
        nan = np.full(num.shape[0], np.nan)
        return nan, nan.copy()
    weights = rng.multinomial(n_units, np.full(n_units, 1.0 / n_units), size=n_resamples)
    num_b = num @ weights.T.astype(float)
    den_b = den @ weights.T.astype(float)
    with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ratio = np.where(den_b > 0, num_b / den_b, np.nan)
        low = np.nanquantile(ratio, alpha / 2, axis=1)
        high = np.nanquantile(ratio, 1 - alpha / 2, axis=1)
    if np.ndim(numerators) == 1:
        return low[0], high[0]
    return low, high


def rates_with_intervals(unit_counts: pd.DataFrame, *, keys: Sequence[str],
                         counts: Sequence[str], rates: Mapping[str, tuple[str, str]],
                         confidence: float = 0.95, n_bootstrap: int = 0, random_state: int = 0,
                         unit_column: str = "unit_id") -> pd.DataFrame:
    """Pool per-unit counts into rates with Wilson (and optionally bootstrap) intervals.

    Parameters
    ----------
    unit_counts : pandas.DataFrame
        One row per (keys..., unit) with integer count columns.
    keys : sequence of str
        Grouping columns of the output rows (no missing values).
    counts : sequence of str
        Count columns to sum over units (kept in the output).
    rates : mapping of str to (str, str)
        ``name -> (numerator column, denominator column)``.
    confidence : float, default=0.95
        Confidence level.
    n_bootstrap : int, default=0
        Bootstrap resamples over units; 0 = Wilson intervals only.
    random_state : int, default=0
        Bootstrap seed.
    unit_column : str, default="unit_id"
        Column identifying the resampling cluster.

    Returns
    -------
    pandas.DataFrame
        ``keys``, summed ``counts``, then for each rate ``<name>``,
        ``<name>_ci_low``, ``<name>_ci_high`` (and ``<name>_boot_low/high``).
        Rates with a zero denominator are NaN.
    """
    keys = list(keys)
    grouped = unit_counts.groupby(keys, sort=False, dropna=False)
    out = grouped[list(counts)].sum().reset_index()
    wide = None
    if n_bootstrap:
        g = grouped.ngroup().to_numpy()
        u, _ = pd.factorize(unit_counts[unit_column])
        shape = (len(out), int(u.max()) + 1 if len(u) else 0)
        wide = {}
        for col in {c for pair in rates.values() for c in pair}:
            arr = np.zeros(shape)
            np.add.at(arr, (g, u), unit_counts[col].to_numpy(dtype=float))
            wide[col] = arr
    pooled = {c: out[c].to_numpy(dtype=float) for pair in rates.values() for c in pair}
    for name, values in _rate_columns(pooled, rates, wide, confidence=confidence, n_bootstrap=n_bootstrap,
                                      random_state=random_state).items():
        out[name] = values
    return out


def per_unit_counts(row: np.ndarray, unit: np.ndarray, shape: tuple[int, int],
                    member: np.ndarray | None = None) -> np.ndarray:
    """How many flights of each (row, unit) pair are members, for :func:`pooled_rates`.

    Parameters
    ----------
    row, unit : numpy.ndarray of int
        Row (output group) and unit (column) of every flight; ``-1`` in either leaves the flight out.
    shape : (int, int)
        ``(n_rows, n_units)``.
    member : numpy.ndarray of bool or None, default=None
        Flights to count; None counts every flight.

    Returns
    -------
    numpy.ndarray of int64, shape ``shape``
    """
    n_rows, n_units = shape
    keep = (row >= 0) & (unit >= 0)
    if member is not None:
        keep &= member
    cell = row[keep] * n_units + unit[keep]
    return np.bincount(cell, minlength=n_rows * n_units).astype(np.int64).reshape(n_rows, n_units)


def pooled_rates(keys: Mapping[str, np.ndarray], unit_counts: Mapping[str, np.ndarray], *,
                 rates: Mapping[str, tuple[str, str]], confidence: float = 0.95, n_bootstrap: int = 0,
                 random_state: int = 0) -> pd.DataFrame:
    """:func:`rates_with_intervals` from counts already laid out per (row, unit).

    The table is the one :func:`rates_with_intervals` gives for a long table whose groups
    (the output rows) are in the order of ``keys`` and whose units, in order of first appearance,
    are the columns of ``unit_counts`` (a unit absent from a group counts 0): the same values,
    dtypes and, with ``n_bootstrap``, the same resamples. It skips building and grouping the long
    table, which cost most of the scoring tables.

    Parameters
    ----------
    keys : mapping of str to numpy.ndarray
        Key columns of the output rows, each of length ``n_rows``.
    unit_counts : mapping of str to numpy.ndarray of int64, shape (n_rows, n_units)
        Per-unit count of every count column; the output keeps their order.
    rates : mapping of str to (str, str)
        ``name -> (numerator column, denominator column)``.
    confidence : float, default=0.95
    n_bootstrap : int, default=0
    random_state : int, default=0

    Returns
    -------
    pandas.DataFrame
        ``keys``, the counts summed over units, then the rates and their intervals.
    """
    pooled = {c: per_unit.sum(axis=1) for c, per_unit in unit_counts.items()}
    wide = ({c: unit_counts[c].astype(float) for pair in rates.values() for c in pair}
            if n_bootstrap else None)
    rate_columns = _rate_columns(pooled, rates, wide, confidence=confidence, n_bootstrap=n_bootstrap,
                                 random_state=random_state)
    return pd.DataFrame({**keys, **pooled, **rate_columns})  # one frame: a column insertion each costs more


def _rate_columns(pooled: Mapping[str, Any], rates: Mapping[str, tuple[str, str]],
                  wide: Mapping[str, np.ndarray] | None, *, confidence: float, n_bootstrap: int,
                  random_state: int) -> dict[str, np.ndarray]:
    """Each rate of the pooled counts with its Wilson (and bootstrap) interval, by output column name.

    ``pooled`` maps count columns to arrays summed over units, ``wide`` (with ``n_bootstrap``) to
    arrays of float of shape (n_rows, n_units) per unit.
    """
    columns = {}
    for name, (num_col, den_col) in rates.items():
        k = np.asarray(pooled[num_col], dtype=float)
        n = np.asarray(pooled[den_col], dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            columns[name] = np.where(n > 0, k / np.where(n > 0, n, 1.0), np.nan)
        columns[f"{name}_ci_low"], columns[f"{name}_ci_high"] = wilson_interval(k, n, confidence=confidence)
        if n_bootstrap:
            low, high = bootstrap_ratio_interval(wide[num_col], wide[den_col],
                                                 n_resamples=n_bootstrap, confidence=confidence,
                                                 random_state=random_state)
            columns[f"{name}_boot_low"], columns[f"{name}_boot_high"] = low, high
    return columns
