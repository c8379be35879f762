"""Configuration of the indicator extraction (binning, differentiator, masks, quality gates).

One frozen dataclass, :class:`ExtractionConfig`, holds every number the batch and the
streaming extractors use, so that both read the same definition and a configuration can be
recorded next to the indicators it produced (provenance). All physical quantities carry their
unit in the field name (currents in mA, positions in mm, velocities in mm/s, times in s): these
are data-boundary units, the same as the flight files (docs/data-format.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from fuelhm_bench.errors import ParameterError, parameter_error

#: Hard budget of the streaming extractor's state (bytes of all its NumPy arrays).
STREAMING_STATE_BUDGET_BYTES: int = 64 * 1024

#: Number of per-bin accumulators kept by the streaming extractor (count, sum v, sum v^2,
#: idle count, idle sum v, idle sum of (i - bin centre), idle sum of (i - bin centre)^2).
N_ACCUMULATORS: int = 7

#: Number of int64 counters kept by the streaming extractor (see ``curve.COUNTER_NAMES``).
N_COUNTERS: int = 9

#: Number of float64 scalars kept by the streaming extractor (current min and max).
N_SCALARS: int = 2

#: Rows of the supply-pressure band accumulators, per band (low, high): idle count, sum of
#: ``i - c_j``, sum of ``(i - c_j)^2`` (``c_j`` the centre of the cell) and sum of N2 (%).
N_BAND_ACCUMULATORS: int = 8

#: Bins per cell of the band accumulators (0.5 mA cells with the default 0.05 mA bins).
BAND_CELL_BINS: int = 10

#: Rows of the streaming ring buffer: time, current, position, N2.
N_RING_ROWS: int = 4


def _param_error(name: str, allowed: str, given: object) -> ParameterError:
    """Build the project's uniform parameter error for :class:`ExtractionConfig`."""
    return parameter_error(name, "ExtractionConfig", allowed, given)


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _check_pair(name: str, value: object, *, optional: bool) -> None:
    if value is None and optional:
        return
    allowed = "None or a (low, high) pair of finite numbers with low < high" if optional else (
        "a (low, high) pair of finite numbers with low < high"
    )
    if not isinstance(value, tuple) or len(value) != 2 or not all(_is_real(v) for v in value):
        raise _param_error(name, allowed, value)
    low, high = float(value[0]), float(value[1])
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise _param_error(name, allowed, value)


@dataclass(frozen=True)
class ExtractionConfig:
    """How velocity-gain curves are built and indicators extracted (batch and streaming).

    Parameters
    ----------
    current_range_ma : tuple of float, default=(-12.0, 12.0)
        Lower and upper edge of the fixed current bins, in mA. Samples whose current falls
        outside are not used (counted as ``n_out_of_range``).
    bin_width_ma : float, default=0.05
        Width of a current bin, in mA. ``(high - low) / bin_width_ma`` must be an integer
        (the number of bins, ``n_bins``).
    diff_half_width : int, default=2
        Half-width ``h`` of the differentiator, in samples: the velocity of sample ``n`` is the
        least-squares slope of position against time over samples ``n-h .. n+h`` (a
        Savitzky-Golay first derivative of length ``2h+1`` written with the actual time stamps,
        so it holds at any, even irregular, frame rate). At 100 Hz with ``h=2`` the window spans
        40 ms and a 15 um position quantum gives a velocity step of 0.15 mm/s.
    max_frame_s : float, default=0.1
        Largest allowed interval between consecutive samples, in s. A sample whose
        differentiator window contains a longer interval (a gap in the recording) is masked.
    stroke_limits_mm : tuple of float or None, default=(0.0, 60.0)
        Positions of the mechanical end stops, in mm. ``None`` means "use the observed minimum
        and maximum position of the flight" (batch extraction only: a streaming extractor cannot
        know them in advance).
    end_stop_margin_mm : float, default=0.5
        A sample is masked if any position in its differentiator window is within this margin
        of an end stop (``x <= low + margin`` or ``x >= high - margin``), in mm.
    current_limits_ma : tuple of float or None, default=(-12.0, 12.0)
        Saturation limits of the controller's current, in mA. ``None`` means "use the observed
        minimum and maximum current of the flight" (batch extraction only).
    current_limit_margin_ma : float, default=0.05
        A sample is masked if its current is within this margin of a current limit, in mA.
    max_current_rate_ma_s : float or None, default=100.0
        A sample is masked if the current changes across its differentiator window faster
        than this rate: ``|i[n+h] - i[n-h]| > max_current_rate_ma_s * (t[n+h] - t[n-h])``
        (mA/s). The velocity estimate then mixes distant parts of the curve (a current step
        of the controller: 100 mA/s spans 4 mA over a 40 ms window). ``None`` disables it.
    idle_velocity_mm_s : float, default=0.5
        A used sample is an *idle candidate* if ``|v| <= idle_velocity_mm_s`` (mm/s).
    idle_halfwidth_ma : float, default=1.0
        Half-width of the idle window around the median idle bin, in mA (rounded down to whole
        bins). Idle candidates outside the window are not idle samples.
    min_idle_points : int, default=50
        Minimum number of idle samples for ``I0`` and ``Hys0`` to be valid.
    min_bin_count : int, default=1
        Minimum number of moving samples (``|v| > idle_velocity_mm_s``) in a bin for its
        moving mean to enter the curve fit.
    max_idle_ratio : float, default=1.0
        A bin is left out of the curve fit when its idle candidates outnumber its moving
        samples by more than this ratio (the rest region around ``I0``).
    weight_cap : float, default=25.0
        Weight of a bin in the curve fit: ``min(moving count, weight_cap)``: well-populated
        bins weigh the same, sparse bins less.
    min_segment_points : int, default=50
        Minimum number of moving samples in a gain segment (inlet, null, outlet) for its gain
        to be valid.
    min_segment_bins : int, default=10
        Minimum number of bins holding moving samples in a gain segment for its gain to be
        valid.
    min_segment_span_ma : float, default=1.5
        Minimum current span covered by those bins, in mA. The kinks are rounded over a few
        tenths of a mA (hysteresis, differentiator); on a shorter segment the fitted gain is
        biased by the rounding (on synthetic flights, 1 mA segments gave gains 10-20 % low).
    min_slope_change : float, default=0.1
        Minimum relative slope change ``|G_a - G_b| / max(|G_a|, |G_b|)`` at a slope change for
        its coordinates (X, Y) to be valid. Without it, a flight that never reaches X2 would
        place a spurious breakpoint inside the null region.
    min_null_halfwidth_ma : float, default=0.25
        The fit keeps both slope changes at least this far from the idle current ``I0``, in
        mA (``X1 <= I0 - w``, ``X2 >= I0 + w``; the nominal null half-width is ~2 mA). The null
        region is centred on the null bias, not on I0: internal leakage and filter contamination
        move I0 to within ~0.5 mA of a slope change at full intensity, so the margin must stay
        well below that (with 1 mA those flights lost all eight curve indicators).
    max_breakpoint_interval_ma : float, default=0.4
        Largest width of the approximate 95 % profile interval of a slope change (X1, X2) for
        it to count as identified, in mA (dense flights give a few hundredths; sparse flights
        with a weak slope change can give most of a mA).
    coarse_grid_size : int, default=24
        Number of candidate breakpoint positions in the exhaustive coarse search of the fit.
    pressure_bands_n2_pct : tuple of float, default=(70.0, 80.0)
        Engine HP speed N2 (%) that bounds the two supply-pressure bands of the extended
        indicators ``Hys_lo``, ``Hys_hi`` and ``I0_slope``: idle samples with ``N2 < low`` form the
        low-pressure band (ground idle, taxi, descent), those with ``N2 >= high`` the
        high-pressure band (climb, cruise). The supply pressure rise follows ``N2**2``
        (:class:`~fuelhm_bench.physics.fluid.FluidParams`), so the default bands differ by a
        factor of about 1.9 in supply pressure. Samples between them (and every sample of a
        flight without recorded N2) are in neither band.

    Attributes
    ----------
    n_bins : int
        Number of current bins.
    bin_edges_ma : numpy.ndarray
        ``n_bins + 1`` bin edges, in mA.
    bin_centres_ma : numpy.ndarray
        ``n_bins`` bin centres, in mA.
    streaming_state_nbytes : int
        Bytes of array state a :class:`~fuelhm_bench.indicators.StreamingExtractor` holds
        with this configuration; must not exceed ``STREAMING_STATE_BUDGET_BYTES`` (64 KiB).

    Examples
    --------
    >>> from fuelhm_bench.indicators import ExtractionConfig
    >>> cfg = ExtractionConfig(bin_width_ma=0.1)
    >>> cfg.n_bins
    240
    """

    current_range_ma: tuple[float, float] = (-12.0, 12.0)
    bin_width_ma: float = 0.05
    diff_half_width: int = 2
    max_frame_s: float = 0.1
    stroke_limits_mm: tuple[float, float] | None = (0.0, 60.0)
    end_stop_margin_mm: float = 0.5
    current_limits_ma: tuple[float, float] | None = (-12.0, 12.0)
    current_limit_margin_ma: float = 0.05
    max_current_rate_ma_s: float | None = 100.0
    idle_velocity_mm_s: float = 0.5
    idle_halfwidth_ma: float = 1.0
    min_idle_points: int = 50
    min_bin_count: int = 1
    max_idle_ratio: float = 1.0
    weight_cap: float = 25.0
    min_segment_points: int = 50
    min_segment_bins: int = 10
    min_segment_span_ma: float = 1.5
    min_slope_change: float = 0.1
    min_null_halfwidth_ma: float = 0.25
    max_breakpoint_interval_ma: float = 0.4
    coarse_grid_size: int = 24
    pressure_bands_n2_pct: tuple[float, float] = (70.0, 80.0)

    def __post_init__(self) -> None:
        _check_pair("current_range_ma", self.current_range_ma, optional=False)
        _check_pair("stroke_limits_mm", self.stroke_limits_mm, optional=True)
        _check_pair("current_limits_ma", self.current_limits_ma, optional=True)
        _check_pair("pressure_bands_n2_pct", self.pressure_bands_n2_pct, optional=False)
        positive = ("bin_width_ma", "max_frame_s", "idle_velocity_mm_s", "idle_halfwidth_ma",
                    "max_breakpoint_interval_ma")
        for name in positive:
            value = getattr(self, name)
            if not _is_real(value) or not math.isfinite(value) or value <= 0:
                raise _param_error(name, "a finite number > 0", value)
        non_negative = ("end_stop_margin_mm", "current_limit_margin_ma", "min_segment_span_ma",
                        "min_null_halfwidth_ma")
        for name in non_negative:
            value = getattr(self, name)
            if not _is_real(value) or not math.isfinite(value) or value < 0:
                raise _param_error(name, "a finite number >= 0", value)
        rate = self.max_current_rate_ma_s
        if rate is not None and (not _is_real(rate) or not math.isfinite(rate) or rate <= 0):
            raise _param_error("max_current_rate_ma_s", "None or a finite number > 0", rate)
        if not _is_real(self.max_idle_ratio) or not self.max_idle_ratio >= 0:
            raise _param_error("max_idle_ratio", "a number >= 0", self.max_idle_ratio)
        cap = self.weight_cap
        if not _is_real(cap) or not math.isfinite(cap) or cap < 1:
            raise _param_error("weight_cap", "a finite number >= 1", self.weight_cap)
        if not _is_real(self.min_slope_change) or not 0 <= self.min_slope_change < 1:
            raise _param_error("min_slope_change", "a number in [0, 1)", self.min_slope_change)
        int_ranges = {
            "diff_half_width": (1, 32),
            "min_idle_points": (2, None),
            "min_bin_count": (1, None),
            "min_segment_points": (2, None),
            "min_segment_bins": (2, None),
            "coarse_grid_size": (16, 64),
        }
        for name, (low, high) in int_ranges.items():
            value = getattr(self, name)
            if not _is_int(value) or value < low or (high is not None and value > high):
                allowed = f"an integer in [{low}, {high}]" if high is not None else (
                    f"an integer >= {low}"
                )
                raise _param_error(name, allowed, value)
        low, high = self.current_range_ma
        ratio = (high - low) / self.bin_width_ma
        if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio) or round(ratio) < 8:
            raise _param_error(
                "bin_width_ma",
                f"a divisor of the current range width {high - low!r} mA giving at least 8 bins",
                self.bin_width_ma,
            )
        if self.streaming_state_nbytes > STREAMING_STATE_BUDGET_BYTES:
            room = STREAMING_STATE_BUDGET_BYTES - self._fixed_state_nbytes
            max_bins = room // (8 * N_ACCUMULATORS)
            while max_bins > 0 and 8 * (N_ACCUMULATORS * max_bins + N_BAND_ACCUMULATORS * -(
                    -max_bins // BAND_CELL_BINS)) > room:
                max_bins -= 1
            raise _param_error(
                "bin_width_ma",
                f"large enough for at most {max_bins} bins over {self.current_range_ma!r} mA "
                f"(streaming state budget {STREAMING_STATE_BUDGET_BYTES} bytes)",
                self.bin_width_ma,
            )

    @property
    def n_bins(self) -> int:
        """Number of current bins."""
        low, high = self.current_range_ma
        return int(round((high - low) / self.bin_width_ma))

    @property
    def bin_edges_ma(self) -> np.ndarray:
        """Bin edges ``low + k * bin_width_ma`` for ``k = 0 .. n_bins``, in mA."""
        return self.current_range_ma[0] + np.arange(self.n_bins + 1) * self.bin_width_ma

    @property
    def bin_centres_ma(self) -> np.ndarray:
        """Bin centres ``low + (k + 0.5) * bin_width_ma``, in mA (the value used for the fit)."""
        return self.current_range_ma[0] + (np.arange(self.n_bins) + 0.5) * self.bin_width_ma

    @property
    def window_length(self) -> int:
        """Differentiator window length ``2 * diff_half_width + 1``, in samples."""
        return 2 * self.diff_half_width + 1

    @property
    def _fixed_state_nbytes(self) -> int:
        ring = N_RING_ROWS * 2 * self.diff_half_width * 8
        return ring + N_COUNTERS * 8 + N_SCALARS * 8

    @property
    def n_band_cells(self) -> int:
        """Number of cells of the supply-pressure band accumulators (``BAND_CELL_BINS`` bins each)."""
        return -(-self.n_bins // BAND_CELL_BINS)

    @property
    def band_cell_centres_ma(self) -> np.ndarray:
        """Centres of the band cells ``low + (j + 0.5) * BAND_CELL_BINS * bin_width_ma``, in mA."""
        cell_w = BAND_CELL_BINS * self.bin_width_ma
        return self.current_range_ma[0] + (np.arange(self.n_band_cells) + 0.5) * cell_w

    @property
    def streaming_state_nbytes(self) -> int:
        """Bytes of array state of a streaming extractor with this configuration."""
        return ((N_ACCUMULATORS * self.n_bins + N_BAND_ACCUMULATORS * self.n_band_cells) * 8
                + self._fixed_state_nbytes)

    @classmethod
    def for_frame_rate(cls, rate_hz: float, window_s: float = 0.04,
                       **changes: object) -> ExtractionConfig:
        """Configuration whose differentiator spans about ``window_s`` at a given frame rate.

        The differentiator window is set in samples; at a rate other than 100 Hz the default
        ``diff_half_width=2`` (40 ms at 100 Hz) smooths the curve more (lower rates) or less
        (higher rates). This picks ``h = max(1, round(window_s * rate_hz / 2))``: h=1 at
        50 Hz, 2 at 100 Hz, 4 at 200 Hz.

        Parameters
        ----------
        rate_hz : float
            Nominal frame rate of the flights, in Hz.
        window_s : float, default=0.04
            Target span ``2h / rate_hz`` of the differentiator window, in s.
        **changes
            Other :class:`ExtractionConfig` fields.

        Returns
        -------
        ExtractionConfig

        Raises
        ------
        ParameterError
            Non-positive ``rate_hz`` or ``window_s``, or an invalid field.
        """
        for name, value in (("rate_hz", rate_hz), ("window_s", window_s)):
            if not _is_real(value) or not math.isfinite(value) or value <= 0:
                raise ParameterError(
                    f"The '{name}' parameter of ExtractionConfig.for_frame_rate must be a "
                    f"finite number > 0. Got {value!r} instead."
                )
        if "diff_half_width" in changes:
            raise ParameterError(
                "The 'diff_half_width' parameter of ExtractionConfig.for_frame_rate must be "
                "left out (it is derived from rate_hz and window_s). Got "
                f"{changes['diff_half_width']!r} instead."
            )
        h = max(1, int(round(window_s * rate_hz / 2.0)))
        return cls(diff_half_width=h, **changes)

    def to_dict(self) -> dict[str, object]:
        """Return the configuration as a plain dict (for provenance records)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
