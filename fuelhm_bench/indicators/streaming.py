"""Streaming (on-board) extraction with fixed memory: :class:`StreamingExtractor`.

The extractor consumes a flight in chunks of any size (down to one sample) and keeps only:

* the binned sums of the velocity-gain curve, ``accumulators`` of shape ``(7, n_bins)``
  float64 (count, sum v, sum v^2, idle count, idle sum v, idle sum of (i - c_k), idle sum of
  (i - c_k)^2);
* the supply-pressure band accumulators, ``(8, n_band_cells)`` float64 (per band: idle count,
  sums of ``i - c_j`` and ``(i - c_j)^2``, sum of N2; cells of ``BAND_CELL_BINS`` bins);
* a ring of the last ``2h`` samples (``h = diff_half_width``), ``(4, 2h)`` float64 (time,
  current, position, N2), so that the differentiator window can straddle chunk boundaries;
* 9 int64 counters and 2 float64 scalars (current min and max, for the constant-current
  check).

Memory budget: ``7*8*n_bins + 8*8*ceil(n_bins/10) + 64*h + 88`` bytes; with the default
configuration (480 bins, h = 2) that is 30 168 bytes, under the 64 KiB budget that
:class:`ExtractionConfig` enforces.
It does not depend on the flight length.

The per-sample work is the numba-compiled loop of :mod:`fuelhm_bench.indicators.kernel`, which
evaluates exactly the formulas of :mod:`fuelhm_bench.indicators.velocity` in the same
floating-point order and adds to the bins in sample order, so its sums equal those of the
batch :func:`~fuelhm_bench.indicators.velocity_gain_curve` (either engine), whatever the chunk
sizes.
"""

from __future__ import annotations

import numpy as np

from fuelhm_bench.errors import DataFormatError, ParameterError
from fuelhm_bench.indicators.config import (
    N_ACCUMULATORS,
    N_BAND_ACCUMULATORS,
    N_COUNTERS,
    N_RING_ROWS,
    N_SCALARS,
    ExtractionConfig,
)
from fuelhm_bench.indicators.curve import COUNTER_NAMES, VelocityGainCurve
from fuelhm_bench.indicators.indicators import indicators_from_curve
from fuelhm_bench.indicators.inputs import (
    ARRAY_NAMES,
    as_1d_float,
    check_lengths,
    constant_current_message,
    nonfinite_message,
    time_order_message,
    too_short_message,
    validate_n2,
)
from fuelhm_bench.indicators.kernel import accumulate, check_chunk, sample_kernel_args
from fuelhm_bench.indicators.result import IndicatorResult
from fuelhm_bench.indicators.velocity import resolve_zones

_N_SAMPLES = COUNTER_NAMES.index("n_samples")
_N_EDGE = COUNTER_NAMES.index("n_edge")
_I_MIN, _I_MAX = 0, 1  # indices in the float scalars


class StreamingExtractor:
    """On-board indicator extraction over a flight fed in chunks, with fixed memory.

    Parameters
    ----------
    config : ExtractionConfig, optional
        Extraction configuration (default :class:`ExtractionConfig()`). Its
        ``stroke_limits_mm`` and ``current_limits_ma`` must be set (not ``None``): observed
        limits need the whole flight.
    flight_id : object, optional
        Flight identifier used in error messages.

    Attributes
    ----------
    config : ExtractionConfig
        The configuration.
    flight_id : object
        The flight identifier.
    n_samples : int
        Samples fed so far.
    state_nbytes : int
        Bytes of all NumPy arrays of the state (fixed; at most 64 KiB).

    Raises
    ------
    ParameterError
        If the configuration asks for observed stroke or current limits.

    Notes
    -----
    Samples are processed when their differentiator window is complete, so the last
    ``diff_half_width`` samples of the flight wait in the ring buffer and never enter the
    curve, exactly as in the batch extractor (whose first and last ``h`` samples have no
    complete window). :meth:`result` and :meth:`curve` do not change the state: feeding may
    continue afterwards.

    Examples
    --------
    >>> from fuelhm_bench.indicators import StreamingExtractor
    >>> from fuelhm_bench.testing.indicators import DualGainCurve, synthetic_flight
    >>> f = synthetic_flight(DualGainCurve(), n_excursions=200, seed=1)
    >>> ex = StreamingExtractor(flight_id="demo")
    >>> for s in range(0, len(f.time_s), 1000):
    ...     ex.update(f.time_s[s:s + 1000], f.current_ma[s:s + 1000], f.position_mm[s:s + 1000])
    >>> ex.result().all_valid
    True
    """

    def __init__(self, config: ExtractionConfig | None = None, *, flight_id: object = None):
        cfg = ExtractionConfig() if config is None else config
        if not isinstance(cfg, ExtractionConfig):
            raise ParameterError(
                f"The 'config' parameter of StreamingExtractor must be an ExtractionConfig. "
                f"Got {cfg!r} instead."
            )
        for name in ("stroke_limits_mm", "current_limits_ma"):
            if getattr(cfg, name) is None:
                raise ParameterError(
                    f"The '{name}' parameter of StreamingExtractor must be a (low, high) pair "
                    f"(observed limits need the whole flight; use the batch extractor). "
                    f"Got None instead."
                )
        self.config = cfg
        self.flight_id = flight_id
        self._kernel_args = sample_kernel_args(cfg, resolve_zones(cfg, None, None))
        h = cfg.diff_half_width
        self._acc = np.zeros((N_ACCUMULATORS, cfg.n_bins))
        self._band = np.zeros((N_BAND_ACCUMULATORS, cfg.n_band_cells))
        self._ring = np.zeros((N_RING_ROWS, 2 * h))
        self._counters = np.zeros(N_COUNTERS, dtype=np.int64)
        self._scalars = np.empty(N_SCALARS)
        self._scalars[_I_MIN], self._scalars[_I_MAX] = np.inf, -np.inf

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything fed so far (start a new flight with the same configuration)."""
        self._acc[...] = 0.0
        self._band[...] = 0.0
        self._ring[...] = 0.0
        self._counters[...] = 0
        self._scalars[_I_MIN], self._scalars[_I_MAX] = np.inf, -np.inf

    @property
    def n_samples(self) -> int:
        """Samples fed so far."""
        return int(self._counters[_N_SAMPLES])

    @property
    def state_nbytes(self) -> int:
        """Sum of ``nbytes`` of every NumPy array the extractor holds (its whole state)."""
        return sum(v.nbytes for v in vars(self).values() if isinstance(v, np.ndarray))

    # ------------------------------------------------------------------ feeding
    def update(self, time_s: object, current_ma: object, position_mm: object,
               n2_pct: object = None) -> None:
        """Consume the next chunk of samples of the flight.

        Parameters
        ----------
        time_s : array_like
            Time stamps, in s; strictly increasing, also across chunks.
        current_ma : array_like
            Control current, in mA.
        position_mm : array_like
            LVDT position, in mm.
        n2_pct : array_like, optional
            Engine HP speed N2, in %, one value per sample (NaN: missing). A chunk without it
            (None) joins no supply-pressure band, as in the batch extractor.

        Raises
        ------
        DataFormatError
            Mismatched lengths, NaN/inf values, or non-increasing time (within the chunk or
            with respect to the previous chunk), malformed ``n2_pct``. The state is left
            unchanged: the chunk is checked before anything is accumulated.
        """
        fid = self.flight_id
        t, i, x = (as_1d_float(v, name, fid)
                   for v, name in zip((time_s, current_ma, position_mm), ARRAY_NAMES))
        check_lengths((t, i, x), fid)
        m = len(t)
        n2 = validate_n2(n2_pct, m, fid)
        if m == 0:
            return
        if n2 is None:
            n2 = np.full(m, np.nan)
        n_seen = self.n_samples
        h = self.config.diff_half_width
        n_ring = min(n_seen, 2 * h)
        t_prev = self._ring[0, n_ring - 1] if n_ring else 0.0
        code, j = check_chunk(t, i, x, t_prev, n_ring > 0)
        if code:
            index = n_seen + j
            if code == 4:
                prev = t[j - 1] if j > 0 else t_prev
                raise DataFormatError(time_order_message(index, float(prev), float(t[j]), fid))
            arr = (t, i, x)[code - 1]
            raise DataFormatError(
                nonfinite_message(ARRAY_NAMES[code - 1], index, float(arr[j]), None, fid)
            )
        self._feed(t, i, x, n2, n_ring)
        sc = self._scalars
        sc[_I_MIN] = min(sc[_I_MIN], i.min())
        sc[_I_MAX] = max(sc[_I_MAX], i.max())
        self._counters[_N_SAMPLES] += m

    def _feed(self, t: np.ndarray, i: np.ndarray, x: np.ndarray, n2: np.ndarray,
              n_ring: int) -> None:
        cfg = self.config
        h = cfg.diff_half_width
        m = len(t)
        args = (*self._kernel_args, self._acc, self._counters, self._band)
        # Virtual sequence V = ring (n_ring samples) + chunk; the next centre is V[h].
        # Phase 1: centres whose window touches the ring, on a small concatenation.
        head = min(m, 2 * h)
        small = [np.concatenate((self._ring[r, :n_ring], a[:head])) for r, a in
                 enumerate((t, i, x, n2))]
        stop1 = min(n_ring + h, n_ring + head - h)
        if stop1 > h:
            accumulate(small[0], small[1], small[2], small[3], h, stop1, *args)
        # Phase 2: centres entirely inside the chunk.
        start2 = max(h, stop1 - n_ring)
        if m - h > start2:
            accumulate(t, i, x, n2, start2, m - h, *args)
        # Keep the last 2h samples of V.
        total = n_ring + m
        keep = min(total, 2 * h)
        if m >= keep:
            for r, a in enumerate((t, i, x, n2)):
                self._ring[r, :keep] = a[m - keep:]
        else:
            for r, a in enumerate((t, i, x, n2)):
                merged = np.concatenate((self._ring[r, :n_ring], a))
                self._ring[r, :keep] = merged[total - keep:]

    # ------------------------------------------------------------------ results
    def curve(self) -> VelocityGainCurve:
        """The binned velocity-gain curve of the samples fed so far.

        Returns
        -------
        VelocityGainCurve
            A copy (the extractor keeps accumulating).

        Raises
        ------
        DataFormatError
            Fewer samples than one differentiator window, or a constant current.
        """
        n = self.n_samples
        cfg = self.config
        if n < cfg.window_length:
            raise DataFormatError(too_short_message(n, cfg.window_length, self.flight_id))
        if self._scalars[_I_MIN] == self._scalars[_I_MAX]:
            raise DataFormatError(
                constant_current_message(float(self._scalars[_I_MIN]), n, self.flight_id)
            )
        counters = self._counters.copy()
        counters[_N_EDGE] = 2 * cfg.diff_half_width
        return VelocityGainCurve(config=cfg, accumulators=self._acc, counters=counters,
                                 band_accumulators=self._band)

    def result(self) -> IndicatorResult:
        """Indicators of the samples fed so far (normally called at the end of the flight).

        Returns
        -------
        IndicatorResult

        Raises
        ------
        DataFormatError
            Fewer samples than one differentiator window, or a constant current.
        """
        return indicators_from_curve(self.curve())
