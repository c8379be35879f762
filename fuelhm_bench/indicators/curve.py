"""The binned velocity-gain curve: the sufficient statistics both extractors produce.

A :class:`VelocityGainCurve` is the local-mean smoothing of the paper's Fig. 4 kept as running
sums over fixed current bins, so that it can be accumulated on board with fixed memory and
turned into indicators on the ground (or at the end of a flight) by one shared function,
:func:`fuelhm_bench.indicators.indicators_from_curve`. The batch and the streaming extractors
both produce this object; everything downstream of it is common code.

Per bin ``k`` (centre ``c_k``, in mA) it holds, over the *used* samples of the flight (not
masked, current inside the bin range):

* ``count[k]``: number of samples;
* ``sum_v[k]``, ``sum_v2[k]``: sum of the velocity (mm/s) and of its square (mm^2/s^2);
* ``idle_count[k]``, ``idle_sum_v[k]``: number of idle candidates
  (``|v| <= idle_velocity_mm_s``) and sum of their velocities (mm/s);
* ``idle_sum_di[k]``, ``idle_sum_di2[k]``: sum of ``i - c_k`` and of ``(i - c_k)^2`` over the
  idle candidates (mA, mA^2). Deviations from the bin centre keep the variance of the idle
  current free of cancellation.

Per cell ``j`` of ``BAND_CELL_BINS`` bins (centre ``c_j``) and per supply-pressure band (low:
``N2 < pressure_bands_n2_pct[0]``, high: ``N2 >= pressure_bands_n2_pct[1]``), the *band
accumulators* hold, over the idle candidates of that band: their number, the sums of ``i - c_j``
and of ``(i - c_j)^2`` (mA, mA^2) and the sum of N2 (%) (zero when N2 was not recorded).

Two local means follow: over all samples (:attr:`VelocityGainCurve.mean_velocity_mm_s`, the
paper's smoothed curve, dominated near ``I0`` by the resting samples) and over the *moving*
samples only (:attr:`VelocityGainCurve.moving_mean_velocity_mm_s`, what the slope changes are
fitted on: the rest points at idle carry ``I0`` and ``Hys0``, not the gain, and with a large
idle hysteresis they would draw a spurious flat band around ``I0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fuelhm_bench.errors import ParameterError, UnknownNameError
from fuelhm_bench.indicators.config import (
    BAND_CELL_BINS,
    N_ACCUMULATORS,
    N_BAND_ACCUMULATORS,
    ExtractionConfig,
)

#: Names of the per-sample bookkeeping counters, in storage order.
COUNTER_NAMES: tuple[str, ...] = (
    "n_samples",        # samples fed (all)
    "n_edge",           # first and last diff_half_width samples (no complete window)
    "n_gap",            # masked: window contains an interval > max_frame_s
    "n_end_stop",       # masked: a window position within end_stop_margin_mm of a stop
    "n_current_limit",  # masked: current within current_limit_margin_ma of a limit
    "n_out_of_range",   # current outside current_range_ma
    "n_fast_current",   # masked: current changes faster than max_current_rate_ma_s
    "n_used",           # entered the curve (= n_points)
    "n_idle",           # used samples with |v| <= idle_velocity_mm_s (idle candidates)
)


@dataclass(frozen=True, eq=False)
class VelocityGainCurve:
    """Binned velocity-gain curve of one flight (sufficient statistics for the indicators).

    Parameters
    ----------
    config : ExtractionConfig
        Configuration the curve was built with (bins, masks, idle threshold).
    accumulators : numpy.ndarray of shape (7, n_bins)
        Rows ``count``, ``sum_v`` (mm/s), ``sum_v2`` (mm^2/s^2), ``idle_count``,
        ``idle_sum_v`` (mm/s), ``idle_sum_di`` (mA), ``idle_sum_di2`` (mA^2), all float64
        (counts are exact integers up to 2**53).
    counters : numpy.ndarray of shape (9,)
        int64 bookkeeping counters, in the order of :data:`COUNTER_NAMES`.
    band_accumulators : numpy.ndarray of shape (8, n_band_cells) or None, default=None
        Supply-pressure band rows, low band then high band, each ``idle_count``,
        ``idle_sum_di`` (mA), ``idle_sum_di2`` (mA^2), ``idle_sum_n2`` (%), over cells of
        ``BAND_CELL_BINS`` bins; None: all zero (N2 not recorded).

    Attributes
    ----------
    bin_centres_ma : numpy.ndarray
        Bin centres, in mA.
    count, sum_v, sum_v2, idle_count, idle_sum_v, idle_sum_di, idle_sum_di2 : numpy.ndarray
        Read-only views of the accumulator rows.
    mean_velocity_mm_s : numpy.ndarray
        Local mean of the velocity per bin, in mm/s (NaN in empty bins): the smoothed curve
        of the paper's Fig. 4.
    moving_count : numpy.ndarray
        Samples per bin that are not idle candidates.
    moving_mean_velocity_mm_s : numpy.ndarray
        Local mean of the velocity of the moving samples, in mm/s (NaN where there is none):
        the curve the slope changes are fitted on.
    std_velocity_mm_s : numpy.ndarray
        Population standard deviation of the velocity per bin, in mm/s (NaN in empty bins):
        the vertical dispersion (hysteresis, noise) around the local mean.
    n_points : int
        Number of samples that entered the curve.
    """

    config: ExtractionConfig
    accumulators: np.ndarray
    counters: np.ndarray
    band_accumulators: np.ndarray | None = None

    def __post_init__(self) -> None:
        acc = np.array(self.accumulators, dtype=np.float64, copy=True)
        cnt = np.array(self.counters, dtype=np.int64, copy=True)
        band_shape = (N_BAND_ACCUMULATORS, self.config.n_band_cells)
        band = (np.zeros(band_shape) if self.band_accumulators is None
                else np.array(self.band_accumulators, dtype=np.float64, copy=True))
        if band.shape != band_shape:
            raise ParameterError(
                f"The 'band_accumulators' parameter of VelocityGainCurve must be None or have "
                f"shape {band_shape}. Got {band.shape} instead."
            )
        band.setflags(write=False)
        object.__setattr__(self, "band_accumulators", band)
        if acc.shape != (N_ACCUMULATORS, self.config.n_bins) or cnt.shape != (
                len(COUNTER_NAMES),):
            raise ParameterError(
                f"The 'accumulators' and 'counters' parameters of VelocityGainCurve must have "
                f"shapes ({N_ACCUMULATORS}, {self.config.n_bins}) and ({len(COUNTER_NAMES)},). "
                f"Got {acc.shape} and {cnt.shape} instead."
            )
        acc.setflags(write=False)
        cnt.setflags(write=False)
        object.__setattr__(self, "accumulators", acc)
        object.__setattr__(self, "counters", cnt)

    @property
    def bin_centres_ma(self) -> np.ndarray:
        """Bin centres, in mA."""
        return self.config.bin_centres_ma

    @property
    def count(self) -> np.ndarray:
        """Samples per bin."""
        return self.accumulators[0]

    @property
    def sum_v(self) -> np.ndarray:
        """Sum of velocities per bin, in mm/s."""
        return self.accumulators[1]

    @property
    def sum_v2(self) -> np.ndarray:
        """Sum of squared velocities per bin, in mm^2/s^2."""
        return self.accumulators[2]

    @property
    def idle_count(self) -> np.ndarray:
        """Idle candidates per bin."""
        return self.accumulators[3]

    @property
    def idle_sum_v(self) -> np.ndarray:
        """Sum of the velocities of the idle candidates of each bin, in mm/s."""
        return self.accumulators[4]

    @property
    def idle_sum_di(self) -> np.ndarray:
        """Sum of ``i - c_k`` over the idle candidates of each bin, in mA."""
        return self.accumulators[5]

    @property
    def idle_sum_di2(self) -> np.ndarray:
        """Sum of ``(i - c_k)^2`` over the idle candidates of each bin, in mA^2."""
        return self.accumulators[6]

    def band_rows(self, band: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The band accumulator rows of one supply-pressure band.

        Parameters
        ----------
        band : {"low", "high"}
            Low (``N2 < pressure_bands_n2_pct[0]``) or high (``N2 >= pressure_bands_n2_pct[1]``)
            supply pressure.

        Returns
        -------
        tuple of numpy.ndarray
            ``(idle_count, idle_sum_di, idle_sum_di2, idle_sum_n2)`` per cell (mA, mA^2, %).

        Raises
        ------
        UnknownNameError
            If ``band`` is neither ``"low"`` nor ``"high"``.
        """
        if band not in ("low", "high"):
            raise UnknownNameError(f"Unknown band {band!r}; the bands are 'low' and 'high'.")
        r = 0 if band == "low" else 4
        b = self.band_accumulators
        return b[r], b[r + 1], b[r + 2], b[r + 3]

    @property
    def moving_count(self) -> np.ndarray:
        """Samples per bin that are not idle candidates (``|v| > idle_velocity_mm_s``)."""
        return self.count - self.idle_count

    @property
    def moving_mean_velocity_mm_s(self) -> np.ndarray:
        """Local mean velocity of the moving samples per bin, in mm/s (NaN if none)."""
        n = self.moving_count
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 0, (self.sum_v - self.idle_sum_v) / n, np.nan)

    @property
    def mean_velocity_mm_s(self) -> np.ndarray:
        """Local mean of the velocity per bin, in mm/s (NaN where the bin is empty)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.count > 0, self.sum_v / self.count, np.nan)

    @property
    def std_velocity_mm_s(self) -> np.ndarray:
        """Population standard deviation of the velocity per bin, in mm/s (NaN if empty)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = self.sum_v / self.count
            var = np.maximum(self.sum_v2 / self.count - mean * mean, 0.0)
            return np.where(self.count > 0, np.sqrt(var), np.nan)

    @property
    def n_points(self) -> int:
        """Number of samples that entered the curve."""
        return int(self.counters[COUNTER_NAMES.index("n_used")])

    def counter(self, name: str) -> int:
        """Return one bookkeeping counter by name (see :data:`COUNTER_NAMES`).

        Parameters
        ----------
        name : str
            Counter name, e.g. ``"n_end_stop"``.

        Returns
        -------
        int

        Raises
        ------
        UnknownNameError
            If ``name`` is not a counter name.
        """
        if name not in COUNTER_NAMES:
            raise UnknownNameError(
                f"Unknown counter {name!r}; the counters are {', '.join(COUNTER_NAMES)}."
            )
        return int(self.counters[COUNTER_NAMES.index(name)])

    def counters_dict(self) -> dict[str, int]:
        """Return all bookkeeping counters as a dict."""
        return {name: int(v) for name, v in zip(COUNTER_NAMES, self.counters)}


def idle_statistics(curve: VelocityGainCurve, config: ExtractionConfig | None = None
                    ) -> tuple[float, float, int]:
    """Mean and standard deviation of the control current over the idle samples.

    Parameters
    ----------
    curve : VelocityGainCurve
        Binned curve with its idle accumulators.
    config : ExtractionConfig, optional
        Supplies ``idle_halfwidth_ma``; defaults to the curve's configuration.

    Returns
    -------
    tuple
        ``(I0, Hys0, n_idle)``: mean current (mA), population standard deviation (mA) and
        number of idle samples. ``(nan, nan, 0)`` when there is no idle candidate.

    Notes
    -----
    Idle candidates are the used samples with ``|v| <= idle_velocity_mm_s``. The idle samples
    are the candidates in bins ``k_med - H .. k_med + H``, with ``k_med`` the first bin where
    the cumulative count of candidates reaches half their total (the median bin) and
    ``H = floor(idle_halfwidth_ma / bin_width_ma)``. The mean and the variance are combined
    exactly from the per-bin sums of ``i - c_k``: ``M2 = sum_k (S2_k - S1_k**2 / n_k) +
    sum_k n_k (mean_k - mean)**2``.
    """
    sl = idle_window(curve, config)
    if sl is None:
        return math.nan, math.nan, 0
    mean, std, n_tot, _ = _pooled(curve.idle_count[sl], curve.idle_sum_di[sl],
                                  curve.idle_sum_di2[sl], curve.bin_centres_ma[sl])
    return mean, std, n_tot


def idle_window(curve: VelocityGainCurve, config: ExtractionConfig | None = None) -> slice | None:
    """The bins of the idle window, ``k_med - H .. k_med + H`` (see :func:`idle_statistics`).

    Parameters
    ----------
    curve : VelocityGainCurve
        Binned curve with its idle accumulators.
    config : ExtractionConfig, optional
        Supplies ``idle_halfwidth_ma``; defaults to the curve's configuration.

    Returns
    -------
    slice or None
        Bin slice (clipped to the bin range); None when there is no idle candidate.
    """
    cfg = curve.config if config is None else config
    n_k = curve.idle_count
    total = float(n_k.sum())
    if total <= 0:
        return None
    k_med = int(np.searchsorted(np.cumsum(n_k), 0.5 * total))
    half = int(math.floor(cfg.idle_halfwidth_ma / curve.config.bin_width_ma + 1e-9))
    return slice(max(k_med - half, 0), min(k_med + half + 1, len(n_k)))


def _pooled(n: np.ndarray, s1: np.ndarray, s2: np.ndarray, c: np.ndarray,
            extra: np.ndarray | None = None) -> tuple[float, float, int, float]:
    """Mean, population std and count of values kept as per-group sums of ``v - c``.

    ``extra`` (optional) is a per-group sum of another quantity whose overall mean is returned
    as the fourth element (NaN without it).
    """
    occupied = n > 0
    if not occupied.any():
        return math.nan, math.nan, 0, math.nan
    n = n[occupied]
    s1 = s1[occupied]
    s2 = s2[occupied]
    c = c[occupied]
    n_tot = float(n.sum())
    mean_k = c + s1 / n
    mean = float((n * mean_k).sum() / n_tot)
    within = np.maximum(s2 - s1 * s1 / n, 0.0)
    m2 = float(within.sum() + (n * (mean_k - mean) ** 2).sum())
    extra_mean = math.nan if extra is None else float(extra[occupied].sum() / n_tot)
    return mean, math.sqrt(m2 / n_tot), int(n_tot), extra_mean


def band_statistics(curve: VelocityGainCurve, band: str, config: ExtractionConfig | None = None
                    ) -> tuple[float, float, int, float]:
    """Idle current and its spread within one supply-pressure band.

    Parameters
    ----------
    curve : VelocityGainCurve
        Binned curve with its band accumulators.
    band : {"low", "high"}
        Supply-pressure band (see :meth:`VelocityGainCurve.band_rows`).
    config : ExtractionConfig, optional
        Supplies ``idle_halfwidth_ma``; defaults to the curve's configuration.

    Returns
    -------
    tuple
        ``(mean, std, n, n2_mean)``: mean control current (mA), population standard deviation
        (mA), number of samples and mean N2 (%) of the band's idle candidates in the cells
        that overlap the idle window of :func:`idle_statistics` (cells of ``BAND_CELL_BINS``
        bins: the window rounded out to whole cells). ``(nan, nan, 0, nan)`` when there is none.
    """
    count, s1, s2, sn2 = curve.band_rows(band)
    sl = idle_window(curve, config)
    if sl is None:
        return math.nan, math.nan, 0, math.nan
    cells = slice(sl.start // BAND_CELL_BINS, (sl.stop - 1) // BAND_CELL_BINS + 1)
    return _pooled(count[cells], s1[cells], s2[cells], curve.config.band_cell_centres_ma[cells],
                   sn2[cells])
