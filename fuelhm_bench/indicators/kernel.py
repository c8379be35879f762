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

from fuelhm_bench.indicators.config import (
    BAND_CELL_BINS,
    N_ACCUMULATORS,
    N_BAND_ACCUMULATORS,
    N_COUNTERS,
    ExtractionConfig,
)
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
def accumulate(t, cur, x, n2, c_start, c_stop, h, low, inv_w, width, n_bins, x_low, x_high,
               i_low, i_high, max_frame, max_rate, v_idle, n2_low, n2_high, cell_bins, cell_w,
               acc, counters, band_acc):
    """Differentiate, mask, bin and accumulate the centres c_start..c_stop-1 of (t, cur, x).

    Same formulas (velocity and matched current), order of operations and mask priority as
    ``velocity.window_slope`` and ``velocity.classify_samples``; counters are indexed as
    ``curve.COUNTER_NAMES``. An idle candidate whose centre sample has ``n2 < n2_low`` (%)
    also enters the low-pressure band rows 0-3 of ``band_acc``, one with ``n2 >= n2_high``
    the high-pressure rows 4-7, at cell ``b // cell_bins`` (a NaN N2 enters neither).

    The default half-width (2) runs a copy of the loop compiled with ``h`` a constant, so
    that the window loops are unrolled (about a quarter faster; the same operations in the
    same order, so the same bits). The three window masks test each sample once, as it enters
    the window (another quarter; the same masks).
    """
    if h == 2:
        _accumulate(t, cur, x, n2, c_start, c_stop, 2, low, inv_w, width, n_bins, x_low, x_high,
                    i_low, i_high, max_frame, max_rate, v_idle, n2_low, n2_high, cell_bins, cell_w,
                    acc, counters, band_acc)
    else:
        _accumulate(t, cur, x, n2, c_start, c_stop, h, low, inv_w, width, n_bins, x_low, x_high,
                    i_low, i_high, max_frame, max_rate, v_idle, n2_low, n2_high, cell_bins, cell_w,
                    acc, counters, band_acc)


@njit(nogil=True, inline="always")
def _accumulate(t, cur, x, n2, c_start, c_stop, h, low, inv_w, width, n_bins, x_low, x_high,
                i_low, i_high, max_frame, max_rate, v_idle, n2_low, n2_high, cell_bins, cell_w,
                acc, counters, band_acc):
    """The loop of :func:`accumulate` (inlined into it, once per case of ``h``)."""
    n_w = float(2 * h + 1)
    cell_of = np.empty(n_bins, np.int64)  # b // cell_bins, looked up (an integer division per sample is slow)
    for b in range(n_bins):
        cell_of[b] = b // cell_bins
    if c_stop <= c_start:
        return
    # The three window masks, tracked as the last sample (or frame, for a gap) that trips each:
    # the window c-h .. c+h is masked when that sample lies inside it. Each sample is tested once,
    # when it enters the window, instead of 2h+1 times (the same masks, about a quarter faster).
    never = c_start - 2 * h - 2
    last_gap = never  # frame j - 1 -> j longer than max_frame
    last_stop = never
    last_limit = never
    for j in range(c_start - h, c_stop + h):
        if j > c_start - h and t[j] - t[j - 1] > max_frame:
            last_gap = j
        xj = x[j]
        if xj <= x_low or xj >= x_high:
            last_stop = j
        ij = cur[j]
        if ij <= i_low or ij >= i_high:
            last_limit = j
        c = j - h
        if c < c_start:
            continue
        if last_gap > c - h:
            counters[2] += 1
            continue
        if last_stop >= c - h:
            counters[3] += 1
            continue
        if last_limit >= c - h:
            counters[4] += 1
            continue
        tc = t[c]
        xc = x[c]
        s_t = 0.0
        s_x = 0.0
        s_tt = 0.0
        s_tx = 0.0
        for k in range(-h, h + 1):
            tau = t[c + k] - tc
            xi = x[c + k] - xc
            s_t += tau
            s_x += xi
            s_tt += tau * tau
            s_tx += tau * xi
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
            nc = n2[c]
            r = -1
            if nc < n2_low:
                r = 0
            elif nc >= n2_high:
                r = 4
            if r >= 0:
                j = cell_of[b]
                dc = i - (low + (j + 0.5) * cell_w)
                band_acc[r, j] += 1.0
                band_acc[r + 1, j] += dc
                band_acc[r + 2, j] += dc * dc
                band_acc[r + 3, j] += nc


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
        v_idle, n2_low, n2_high, cell_bins, cell_w)``.
    """
    max_rate = np.inf if config.max_current_rate_ma_s is None else config.max_current_rate_ma_s
    n2_low, n2_high = config.pressure_bands_n2_pct
    return (config.diff_half_width, float(config.current_range_ma[0]),
            1.0 / config.bin_width_ma, float(config.bin_width_ma), config.n_bins,
            *(float(z) for z in zones), float(config.max_frame_s), float(max_rate),
            float(config.idle_velocity_mm_s), float(n2_low), float(n2_high), BAND_CELL_BINS,
            band_cell_width_ma(config))


def band_cell_width_ma(config: ExtractionConfig) -> float:
    """Width of a cell of the band accumulators, ``BAND_CELL_BINS * bin_width_ma``, in mA.

    Parameters
    ----------
    config : ExtractionConfig
        Supplies ``bin_width_ma``.

    Returns
    -------
    float
        The cell width, in mA (the same product in both batch engines, so their sums agree).
    """
    return BAND_CELL_BINS * float(config.bin_width_ma)


def accumulate_flight(time_s: np.ndarray, current_ma: np.ndarray, position_mm: np.ndarray,
                      config: ExtractionConfig, zones: tuple[float, float, float, float],
                      n2_pct: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Binned sums and counters of a whole validated flight with the compiled kernel.

    Parameters
    ----------
    time_s, current_ma, position_mm : numpy.ndarray
        Validated contiguous float64 arrays (s, mA, mm), at least one window long.
    config : ExtractionConfig
        Extraction configuration.
    zones : tuple of float
        Output of :func:`fuelhm_bench.indicators.velocity.resolve_zones`.
    n2_pct : numpy.ndarray or None, default=None
        Validated engine HP speed N2 (%) per sample (NaN allowed: in no band); None: not
        recorded (the band accumulators stay empty).

    Returns
    -------
    tuple of numpy.ndarray
        ``accumulators`` (7, n_bins), ``counters`` (9,) and ``band_accumulators``
        (8, n_band_cells), as in :class:`~fuelhm_bench.indicators.VelocityGainCurve`.
    """
    n = len(time_s)
    h = config.diff_half_width
    acc = np.zeros((N_ACCUMULATORS, config.n_bins))
    band = np.zeros((N_BAND_ACCUMULATORS, config.n_band_cells))
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    n2 = np.full(n, np.nan) if n2_pct is None else n2_pct
    accumulate(time_s, current_ma, position_mm, n2, h, n - h, *sample_kernel_args(config, zones),
               acc, counters, band)
    counters[COUNTER_NAMES.index("n_samples")] = n
    counters[COUNTER_NAMES.index("n_edge")] = 2 * h
    return acc, counters, band
