"""The compiled per-sample kernel shared by the streaming and the fast batch extractor.

:func:`accumulate` evaluates, for a range of centre samples, exactly the formulas of
:mod:`fuelhm_bench.indicators.velocity` (least-squares differentiator, matched current,
masks in the same priority) in the same floating-point order, and adds to the bins in
sample order. It is compiled with numba (``cache=True``, no fast-math, so no reassociation
or FMA contraction) and runs at several tens of millions of samples per second on one core.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fuelhm_bench.indicators.config import N_ACCUMULATORS, N_COUNTERS, ExtractionConfig
from fuelhm_bench.indicators.curve import COUNTER_NAMES


@njit(cache=True, nogil=True)
def check_chunk(t, cur, x, t_prev, has_prev):
    """First problem in a chunk: (code, index); code 0 = fine, 1-3 = non-finite t/i/x,
    4 = time not strictly increasing (index -1: first sample vs the previous chunk)."""
    n = t.shape[0]
    prev = t_prev
    for j in range(n):
        tj = t[j]
        if not np.isfinite(tj):
            return 1, j
        if not np.isfinite(cur[j]):
            return 2, j
        if not np.isfinite(x[j]):
            return 3, j
        if (j > 0 or has_prev) and not tj > prev:
            return 4, j
        prev = tj
    return 0, -1


@njit(cache=True, nogil=True)
def accumulate(t, cur, x, c_start, c_stop, h, low, inv_w, width, n_bins, x_low, x_high,
               i_low, i_high, max_frame, max_rate, v_idle, acc, counters):
    """Differentiate, mask, bin and accumulate the centres c_start..c_stop-1 of (t, cur, x).

    Same formulas (velocity and matched current), order of operations and mask priority as
    ``velocity.window_slope`` and ``velocity.classify_samples``; counters are indexed as
    ``curve.COUNTER_NAMES``.
    """
    n_w = float(2 * h + 1)
    for c in range(c_start, c_stop):
        tc = t[c]
        xc = x[c]
        s_t = 0.0
        s_x = 0.0
        s_tt = 0.0
        s_tx = 0.0
        gap = False
        stop = False
        limit = False
        for k in range(-h, h + 1):
            tk = t[c + k]
            xk = x[c + k]
            ik = cur[c + k]
            tau = tk - tc
            xi = xk - xc
            s_t += tau
            s_x += xi
            s_tt += tau * tau
            s_tx += tau * xi
            if k > -h and tk - t[c + k - 1] > max_frame:
                gap = True
            if xk <= x_low or xk >= x_high:
                stop = True
            if ik <= i_low or ik >= i_high:
                limit = True
        if gap:
            counters[2] += 1
            continue
        if stop:
            counters[3] += 1
            continue
        if limit:
            counters[4] += 1
            continue
        den = n_w * s_tt - s_t * s_t
        c_w = 0.0
        i = 0.0
        for k in range(h, -h, -1):
            c_w += (n_w * (t[c + k] - tc) - s_t) / den
            i += c_w * (t[c + k] - t[c + k - 1]) * cur[c + k - 1]
        kf = (i - low) * inv_w
        if not (kf >= 0.0 and kf < n_bins):
            counters[5] += 1
            continue
        if abs(cur[c + h] - cur[c - h]) > max_rate * (t[c + h] - t[c - h]):
            counters[6] += 1
            continue
        v = (n_w * s_tx - s_t * s_x) / den
        b = int(kf)
        if b > n_bins - 1:
            b = n_bins - 1
        counters[7] += 1
        acc[0, b] += 1.0
        acc[1, b] += v
        acc[2, b] += v * v
        if abs(v) <= v_idle:
            counters[8] += 1
            d = i - (low + (b + 0.5) * width)
            acc[3, b] += 1.0
            acc[4, b] += v
            acc[5, b] += d
            acc[6, b] += d * d


def sample_kernel_args(config: ExtractionConfig, zones: tuple[float, float, float, float]
                       ) -> tuple:
    """Scalar arguments of :func:`accumulate` after ``c_stop`` and before the arrays.

    Parameters
    ----------
    config : ExtractionConfig
        Extraction configuration.
    zones : tuple of float
        Output of :func:`fuelhm_bench.indicators.velocity.resolve_zones`.

    Returns
    -------
    tuple
        ``(h, low, inv_w, width, n_bins, x_low, x_high, i_low, i_high, max_frame, max_rate,
        v_idle)``.
    """
    max_rate = np.inf if config.max_current_rate_ma_s is None else config.max_current_rate_ma_s
    return (config.diff_half_width, float(config.current_range_ma[0]),
            1.0 / config.bin_width_ma, float(config.bin_width_ma), config.n_bins,
            *(float(z) for z in zones), float(config.max_frame_s), float(max_rate),
            float(config.idle_velocity_mm_s))


def accumulate_flight(time_s: np.ndarray, current_ma: np.ndarray, position_mm: np.ndarray,
                      config: ExtractionConfig, zones: tuple[float, float, float, float]
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Binned sums and counters of a whole validated flight with the compiled kernel.

    Parameters
    ----------
    time_s, current_ma, position_mm : numpy.ndarray
        Validated contiguous float64 arrays (s, mA, mm), at least one window long.
    config : ExtractionConfig
        Extraction configuration.
    zones : tuple of float
        Output of :func:`fuelhm_bench.indicators.velocity.resolve_zones`.

    Returns
    -------
    tuple of numpy.ndarray
        ``accumulators`` (7, n_bins) and ``counters`` (9,), as in
        :class:`~fuelhm_bench.indicators.VelocityGainCurve`.
    """
    n = len(time_s)
    h = config.diff_half_width
    acc = np.zeros((N_ACCUMULATORS, config.n_bins))
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    accumulate(time_s, current_ma, position_mm, h, n - h, *sample_kernel_args(config, zones),
               acc, counters)
    counters[COUNTER_NAMES.index("n_samples")] = n
    counters[COUNTER_NAMES.index("n_edge")] = 2 * h
    return acc, counters
