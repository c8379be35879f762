"""Velocity from positions, as both the measured and the replayed signals are differentiated.

A small, self-contained helper (the indicator package has its own extractor; this module
only needs the differentiator and a current-binned local mean, and uses the same
definitions so the two agree on uniformly sampled data).

Differentiator
--------------
On a uniformly sampled segment (period ``T``), the velocity of sample ``n`` is the
least-squares slope of the position over the ``2h+1`` samples ``n-h .. n+h`` (the
Savitzky-Golay first derivative). Written on the per-frame displacement rates
``d[k] = (y[k+1] - y[k]) / T`` it is a weighted mean::

    v[n] = sum_{k=-h}^{h-1} w_k d[n+k],   w_k = sum_{m=k+1}^{h} m / sum_{m=-h}^{h} m^2

(``h = 2``: 0.2, 0.3, 0.3, 0.2). The *matched current* of the sample is the current
averaged with the same weights, ``i_m[n] = sum_k w_k i[n+k]``: the displacement of frame
``k`` is driven by the current held during that frame (zero-order hold), so on a linear
part of the curve ``E[v | i_m] = G (i_m - I0)`` exactly. Writing the differentiator on
displacement rates is what lets the replay compare like with like: the model's
per-frame rates (see :mod:`fuelhm_bench.calibration.replay`) go through the same weights.

Units: these functions are unit-agnostic (they are linear); callers pass mm and mA.
"""

from __future__ import annotations

import numpy as np

from fuelhm_bench.errors import range_error

#: Direction of the current change over the window: steady, rising, falling.
STEADY, RISING, FALLING = 0, 1, -1


def window_weights(half_width: int) -> np.ndarray:
    """Weights of the per-frame rates in the least-squares slope over ``2h+1`` samples.

    Parameters
    ----------
    half_width : int
        ``h`` >= 1 [samples].

    Returns
    -------
    numpy.ndarray of shape (2h,)
        ``w_k`` for ``k = -h .. h-1``; positive, summing to one.

    Examples
    --------
    >>> window_weights(2).round(3).tolist()
    [0.2, 0.3, 0.3, 0.2]
    """
    if not isinstance(half_width, (int, np.integer)) or isinstance(half_width, bool) or half_width < 1:
        raise range_error("half_width", "an integer >= 1", half_width)
    m = np.arange(-half_width, half_width + 1, dtype=float)
    denom = float(np.sum(m * m))
    ks = np.arange(-half_width, half_width)
    return np.array([np.sum(m[m > k]) / denom for k in ks])


def windowed(rates: np.ndarray, half_width: int) -> np.ndarray:
    """Window per-frame rates into sample velocities (NaN where the window is incomplete).

    Parameters
    ----------
    rates : numpy.ndarray of shape (n-1,)
        Per-frame rates ``d[k] = (y[k+1] - y[k]) / T`` of a segment of ``n`` samples
        (any unit per second); or any per-frame quantity to average (the current).
    half_width : int
        ``h``.

    Returns
    -------
    numpy.ndarray of shape (n,)
        ``sum_k w_k d[n+k]`` for ``n = h .. n-1-h``; NaN elsewhere.
    """
    w = window_weights(half_width)
    n = rates.shape[0] + 1
    out = np.full(n, np.nan)
    if n - 2 * half_width > 0:
        out[half_width:n - half_width] = np.correlate(rates, w, mode="valid")
    return out


def frame_rates(position: np.ndarray, frame_s: float) -> np.ndarray:
    """Per-frame displacement rates ``(y[k+1] - y[k]) / T`` of a uniformly sampled segment."""
    return np.diff(position) / frame_s


def matched_current(current: np.ndarray, half_width: int) -> np.ndarray:
    """Current averaged with the differentiator weights (same unit as ``current``; NaN at the edges)."""
    return windowed(np.asarray(current, dtype=float)[:-1], half_width)


def current_direction(current_ma: np.ndarray, half_width: int, frame_s: float, rate_ma_s: float) -> np.ndarray:
    """Direction of the current change across each sample's window.

    Parameters
    ----------
    current_ma : numpy.ndarray (n,)
        Current [mA] of a uniformly sampled segment.
    half_width : int
        ``h``.
    frame_s : float
        Frame period [s].
    rate_ma_s : float
        Rates below this magnitude are *steady* [mA/s].

    Returns
    -------
    numpy.ndarray of int8 (n,)
        :data:`RISING`, :data:`FALLING` or :data:`STEADY` (also at the incomplete edges).
    """
    n = current_ma.shape[0]
    out = np.zeros(n, dtype=np.int8)
    if n > 2 * half_width:
        rate = (current_ma[2 * half_width:] - current_ma[:-2 * half_width]) / (2 * half_width * frame_s)
        core = np.zeros(n - 2 * half_width, dtype=np.int8)
        core[rate > rate_ma_s] = RISING
        core[rate < -rate_ma_s] = FALLING
        out[half_width:n - half_width] = core
    return out


def binned_mean(x: np.ndarray, y: np.ndarray, edges: np.ndarray,
                groups: np.ndarray | None = None, n_groups: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Local mean of ``y`` per bin of ``x`` (and per group): the paper's smoothed curve.

    Parameters
    ----------
    x, y : numpy.ndarray (n,)
        Abscissa (e.g. matched current, mA) and values (e.g. velocity, mm/s); NaN pairs are skipped.
    edges : numpy.ndarray (n_bins + 1,)
        Increasing bin edges of ``x``.
    groups : numpy.ndarray of int (n,), optional
        Group index in ``[0, n_groups)`` of each sample (e.g. the current direction + 1).
    n_groups : int, default=1
        Number of groups.

    Returns
    -------
    mean : numpy.ndarray (n_groups, n_bins)
        Mean of ``y`` per cell (NaN where empty).
    count : numpy.ndarray of int (n_groups, n_bins)
        Samples per cell.
    """
    n_bins = edges.shape[0] - 1
    ok = np.isfinite(x) & np.isfinite(y) & (x >= edges[0]) & (x < edges[-1])
    b = np.clip(np.searchsorted(edges, x[ok], side="right") - 1, 0, n_bins - 1)
    g = np.zeros_like(b) if groups is None else np.asarray(groups)[ok].astype(np.int64)
    flat = g * n_bins + b
    count = np.bincount(flat, minlength=n_groups * n_bins).reshape(n_groups, n_bins)
    total = np.bincount(flat, weights=y[ok], minlength=n_groups * n_bins).reshape(n_groups, n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return mean, count
