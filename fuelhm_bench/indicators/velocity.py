"""Cylinder velocity from the LVDT position, its matched current, and the masks (NumPy).

Differentiator
--------------
The velocity of sample ``n`` is the least-squares slope of position against time over the
``2h+1`` samples ``n-h .. n+h`` (``h = diff_half_width``), written with the actual time stamps
relative to the centre sample::

    tau_k = t[n+k] - t[n],   xi_k = x[n+k] - x[n],   k = -h .. h   (summed in this order)
    D     = N * S_tt - S_t**2,   N = 2h+1
    v[n]  = (N * S_tx - S_t * S_x) / D

with ``S_t = sum tau_k``, ``S_x = sum xi_k``, ``S_tt = sum tau_k**2``, ``S_tx = sum tau_k*xi_k``.
For uniform sampling this is the Savitzky-Golay first derivative of length ``2h+1``
(polynomial order 1 or 2), ``v = sum k*x[n+k] / (dt * sum k**2)``: it is exact for a
quadratic position, and it divides white position noise by ``dt*sqrt(sum k**2)`` and the
quantum ``q`` of the ADC by ``dt*sum k**2`` (``h=2``: 10 dt; a one-code step at the window
edge moves v by ``2q/(10 dt)``, 0.34 mm/s for 17 um at 100 Hz, against 1.7 mm/s for a
one-step difference). The first and last ``h`` samples of a flight have no complete window
and are not used.

Matched current
---------------
The slope is a weighted sum of the displacements over the ``2h`` frames of the window,
``v = sum_k w_k * (x[n+k+1] - x[n+k]) / (t[n+k+1] - t[n+k])`` for ``k = -h .. h-1``, with
weights ``w_k = c_k * (t[n+k+1] - t[n+k])``, ``c_k = sum_{m>k} a_m``,
``a_m = (N * tau_m - S_t) / D``; the weights are positive and sum to one (uniform sampling,
h=2: 0.2, 0.3, 0.3, 0.2). The FADEC holds the current over a frame (zero-order hold) and the
displacement of frame ``k`` is driven by the current ``i[n+k]``, so the velocity is paired
with the current averaged with the same weights::

    i_m[n] = sum_{k=-h}^{h-1} w_k * i[n+k]      (accumulated for k = h-1 down to -h)

On a linear part of the curve ``E[v | i_m] = G * (i_m - I0)`` exactly, whatever the spectrum of
the current: pairing the window velocity with the centre current instead would dilute the
gain when the current moves from frame to frame (by 70 % for white current noise with h=2),
and bias the extreme bins of each excursion. ``i_m`` is "the current" of the sample for the
bins, the curve and the idle statistics.

Masks (in priority order; a masked sample does not enter the curve)
------------------------------------------------------------------
1. *gap*: an interval between consecutive samples of the window exceeds ``max_frame_s``;
2. *end stop*: a position of the window is within ``end_stop_margin_mm`` of an end stop
   (configured ``stroke_limits_mm``, or the observed min/max of the flight when ``None``);
3. *current limit*: a current of the window is within ``current_limit_margin_ma`` of a
   controller limit (configured ``current_limits_ma`` or the observed min/max when ``None``);
4. *out of range*: the matched current is outside ``current_range_ma`` (no bin);
5. *fast current*: the current changes across the window faster than
   ``max_current_rate_ma_s`` (``|i[n+h] - i[n-h]| > rate * (t[n+h] - t[n-h])``): a current
   step; the window would average the velocity over distant, non-linearly related parts of
   the curve.

The compiled kernel (:mod:`fuelhm_bench.indicators.kernel`) evaluates the same formulas, in
the same floating-point order, one sample at a time.
"""

from __future__ import annotations

import numpy as np

from fuelhm_bench.indicators.config import ExtractionConfig

#: Sample categories returned by :func:`classify_samples`.
USED, GAP, END_STOP, CURRENT_LIMIT, OUT_OF_RANGE, FAST_CURRENT = 0, 1, 2, 3, 4, 5


def window_slope(time_s: np.ndarray, position_mm: np.ndarray, half_width: int,
                 current_ma: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None]:
    """Least-squares velocity (and matched current) of every sample with a complete window.

    Parameters
    ----------
    time_s : numpy.ndarray
        Strictly increasing time stamps, in s (float64).
    position_mm : numpy.ndarray
        Position, in mm (float64, same length).
    half_width : int
        Half-width ``h`` of the window, in samples.
    current_ma : numpy.ndarray, optional
        Control current, in mA (float64, same length); when given, the matched current is
        computed too.

    Returns
    -------
    velocity_mm_s : numpy.ndarray
        Velocity in mm/s of samples ``h .. n-h-1`` (length ``n - 2h``).
    matched_current_ma : numpy.ndarray or None
        Matched current in mA of the same samples (None without ``current_ma``).
    """
    n = len(time_s)
    h = int(half_width)
    m = n - 2 * h
    if m <= 0:
        empty = np.empty(0, dtype=np.float64)
        return empty, (None if current_ma is None else empty)
    tc = time_s[h:n - h]
    xc = position_mm[h:n - h]
    s_t = np.zeros(m)
    s_x = np.zeros(m)
    s_tt = np.zeros(m)
    s_tx = np.zeros(m)
    for k in range(-h, h + 1):
        tau = time_s[h + k:n - h + k] - tc
        xi = position_mm[h + k:n - h + k] - xc
        s_t += tau
        s_x += xi
        s_tt += tau * tau
        s_tx += tau * xi
    n_w = float(2 * h + 1)
    den = n_w * s_tt - s_t * s_t
    velocity = (n_w * s_tx - s_t * s_x) / den
    if current_ma is None:
        return velocity, None
    c_w = np.zeros(m)
    matched = np.zeros(m)
    for k in range(h, -h, -1):
        tau = time_s[h + k:n - h + k] - tc
        c_w += (n_w * tau - s_t) / den
        matched += c_w * (time_s[h + k:n - h + k] - time_s[h + k - 1:n - h + k - 1]) * (
            current_ma[h + k - 1:n - h + k - 1])
    return velocity, matched


def differentiate_position(time_s: np.ndarray, position_mm: np.ndarray,
                           half_width: int = 2) -> np.ndarray:
    """Cylinder velocity from the LVDT position, aligned with the input samples.

    Parameters
    ----------
    time_s : array_like
        Strictly increasing time stamps, in s.
    position_mm : array_like
        LVDT position, in mm.
    half_width : int, default=2
        Half-width ``h`` of the least-squares window, in samples (window ``2h+1``).

    Returns
    -------
    numpy.ndarray
        Velocity in mm/s, same length as the input; NaN for the first and last ``h`` samples.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(10) * 0.01
    >>> differentiate_position(t, 5.0 * t)[2:-2]
    array([5., 5., 5., 5., 5., 5.])
    """
    t = np.ascontiguousarray(time_s, dtype=np.float64)
    x = np.ascontiguousarray(position_mm, dtype=np.float64)
    h = int(half_width)
    out = np.full(len(t), np.nan)
    if len(t) > 2 * h:
        out[h:len(t) - h] = window_slope(t, x, h)[0]
    return out


def matched_current(time_s: np.ndarray, current_ma: np.ndarray,
                    half_width: int = 2) -> np.ndarray:
    """Current paired with the differentiator's velocity, aligned with the input samples.

    Parameters
    ----------
    time_s : array_like
        Strictly increasing time stamps, in s.
    current_ma : array_like
        Control current, in mA (held over each frame).
    half_width : int, default=2
        Half-width ``h`` of the differentiator window, in samples.

    Returns
    -------
    numpy.ndarray
        Matched current in mA (see the module docstring), NaN for the first and last ``h``
        samples.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(7) * 0.01
    >>> matched_current(t, np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]))[2:-2]
    array([0.3, 0.3, 0.2])
    """
    t = np.ascontiguousarray(time_s, dtype=np.float64)
    i = np.ascontiguousarray(current_ma, dtype=np.float64)
    h = int(half_width)
    out = np.full(len(t), np.nan)
    if len(t) > 2 * h:
        out[h:len(t) - h] = window_slope(t, np.zeros_like(t), h, i)[1]
    return out


def resolve_zones(config: ExtractionConfig, current_ma: np.ndarray | None,
                  position_mm: np.ndarray | None) -> tuple[float, float, float, float]:
    """Thresholds of the end-stop and current-limit masks.

    Parameters
    ----------
    config : ExtractionConfig
        Extraction configuration.
    current_ma, position_mm : numpy.ndarray or None
        The flight's arrays, used only when the corresponding limits are ``None`` (observed).

    Returns
    -------
    tuple of float
        ``(x_low, x_high, i_low, i_high)``: a position ``<= x_low`` or ``>= x_high`` (mm) is
        at an end stop; a current ``<= i_low`` or ``>= i_high`` (mA) is at a current limit.
    """
    if config.stroke_limits_mm is None:
        if position_mm is None:
            raise ValueError("observed stroke limits need the position array")
        x_min, x_max = float(position_mm.min()), float(position_mm.max())
    else:
        x_min, x_max = (float(v) for v in config.stroke_limits_mm)
    if config.current_limits_ma is None:
        if current_ma is None:
            raise ValueError("observed current limits need the current array")
        i_min, i_max = float(current_ma.min()), float(current_ma.max())
    else:
        i_min, i_max = (float(v) for v in config.current_limits_ma)
    return (
        x_min + config.end_stop_margin_mm,
        x_max - config.end_stop_margin_mm,
        i_min + config.current_limit_margin_ma,
        i_max - config.current_limit_margin_ma,
    )


def _window_any(flags: np.ndarray, h: int, offset: int) -> np.ndarray:
    """Sliding OR over windows of ``2h + 1 - offset`` consecutive flags.

    ``out[j] = flags[j] | ... | flags[j + 2h - offset]``, length ``len(flags) - 2h + offset``.
    With per-sample flags (``offset=0``) entry ``j`` covers the window of sample ``j + h``;
    with per-interval flags (``np.diff``, ``offset=1``) it covers the window's 2h intervals.
    """
    n_out = len(flags) - 2 * h + offset
    out = np.zeros(n_out, dtype=bool)
    for k in range(2 * h + 1 - offset):
        out |= flags[k:k + n_out]
    return out


def classify_samples(time_s: np.ndarray, current_ma: np.ndarray, position_mm: np.ndarray,
                     matched_ma: np.ndarray, config: ExtractionConfig,
                     zones: tuple[float, float, float, float]) -> np.ndarray:
    """Category of every sample that has a complete differentiator window.

    Parameters
    ----------
    time_s, current_ma, position_mm : numpy.ndarray
        Validated float64 flight arrays (s, mA, mm).
    matched_ma : numpy.ndarray
        Matched current of samples ``h .. n-h-1`` (mA), from :func:`window_slope`.
    config : ExtractionConfig
        Extraction configuration.
    zones : tuple of float
        Output of :func:`resolve_zones`.

    Returns
    -------
    numpy.ndarray of int8
        For samples ``h .. n-h-1``: :data:`USED`, :data:`GAP`, :data:`END_STOP`,
        :data:`CURRENT_LIMIT`, :data:`OUT_OF_RANGE` or :data:`FAST_CURRENT` (first
        applicable, in this order).
    """
    h = config.diff_half_width
    n = len(time_s)
    x_low, x_high, i_low, i_high = zones
    long_step = np.diff(time_s) > config.max_frame_s            # length n-1
    gap = _window_any(long_step, h, 1)                          # intervals of the window
    at_stop = _window_any((position_mm <= x_low) | (position_mm >= x_high), h, 0)
    at_limit = _window_any((current_ma <= i_low) | (current_ma >= i_high), h, 0)
    low, _ = config.current_range_ma
    kf = (matched_ma - low) * (1.0 / config.bin_width_ma)
    out_of_range = ~((kf >= 0) & (kf < config.n_bins))
    cat = np.full(n - 2 * h, USED, dtype=np.int8)
    rate = config.max_current_rate_ma_s
    if rate is not None:
        fast = np.abs(current_ma[2 * h:] - current_ma[:n - 2 * h]) > rate * (
            time_s[2 * h:] - time_s[:n - 2 * h])
        cat[fast] = FAST_CURRENT
    cat[out_of_range] = OUT_OF_RANGE
    cat[at_limit] = CURRENT_LIMIT
    cat[at_stop] = END_STOP
    cat[gap] = GAP
    return cat
