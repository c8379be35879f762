"""The velocity-gain curve of replayed samples, and the gap between model and measurement.

The curve is the paper's local-mean smoothing (section III.B, Fig. 4): the mean velocity
per current bin. Because the model is replayed on the measured samples
(:mod:`~fuelhm_bench.calibration.replay`), the measured and the model curves are local means
over *the same samples*, and their difference per bin is the mean velocity residual of the
bin.

Gap metric
----------
``gap = sqrt(mean_c (mean residual in cell c)^2)`` [mm/s], over the cells ``c`` = current
bin (``bin_width_ma``, by matched current) x current direction (rising, falling, steady)
that hold at least ``min_count`` scored samples; every cell weighs the same (the curve,
not the time spent at idle). Splitting by direction keeps the two branches of a
rate-dependent loop apart (their residuals would cancel in a pooled bin).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuelhm_bench.calibration import velocity as vel
from fuelhm_bench.errors import range_error

#: Direction groups of the curve, in storage order (index = direction + 1).
DIRECTION_NAMES: tuple[str, ...] = ("falling", "steady", "rising")


@dataclass(frozen=True)
class CurveConfig:
    """Bins of the velocity-gain curve and of the gap metric.

    Parameters
    ----------
    bin_width_ma : float, default=0.1
        Width of a current bin [mA].
    current_range_ma : tuple of float, default=(-12.5, 12.5)
        Range of the bins [mA] (samples outside are not binned).
    min_count : int, default=20
        Fewest scored samples for a cell to enter the gap [-].
    """

    bin_width_ma: float = 0.1
    current_range_ma: tuple = (-12.5, 12.5)
    min_count: int = 20

    def __post_init__(self) -> None:
        if not (isinstance(self.bin_width_ma, (int, float)) and 0.005 <= self.bin_width_ma <= 5.0):
            raise range_error("CurveConfig.bin_width_ma", "in [0.005, 5] mA", self.bin_width_ma)
        lo, hi = self.current_range_ma
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise range_error("CurveConfig.current_range_ma", "a (low, high) pair with low < high",
                              self.current_range_ma)
        if not isinstance(self.min_count, int) or isinstance(self.min_count, bool) or self.min_count < 1:
            raise range_error("CurveConfig.min_count", "an integer >= 1", self.min_count)

    @property
    def edges(self) -> np.ndarray:
        """Bin edges [mA]."""
        lo, hi = self.current_range_ma
        n = int(round((hi - lo) / self.bin_width_ma))
        return lo + self.bin_width_ma * np.arange(n + 1)

    @property
    def centres(self) -> np.ndarray:
        """Bin centres [mA]."""
        e = self.edges
        return 0.5 * (e[:-1] + e[1:])


def gap_metric_text(config: CurveConfig) -> str:
    """Definition of the gap metric with the configured numbers."""
    return (f"RMS over the cells (current bin of {config.bin_width_ma:g} mA x current direction: rising, falling, "
            f"steady) holding at least {config.min_count} scored samples of the mean velocity residual "
            "(measured - model) in the cell, every cell weighted equally [mm/s]; the model is replayed on the "
            "measured samples (imposed current, forced position) and differentiated like the measured position")


def cell_residuals(rs, v_model: np.ndarray, config: CurveConfig = CurveConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Mean residual and count per (direction, current bin) cell.

    Parameters
    ----------
    rs : ReplaySet
        Prepared samples (only the scored ones count).
    v_model : numpy.ndarray (N,)
        Replayed model velocity [mm/s].
    config : CurveConfig

    Returns
    -------
    mean : numpy.ndarray (3, n_bins)
        Mean of ``v_meas - v_model`` [mm/s] (NaN when empty).
    count : numpy.ndarray (3, n_bins)
    """
    s = rs.scored
    r = rs.v_meas_mm_s[s] - v_model[s]
    return vel.binned_mean(rs.i_ma[s], r, config.edges, rs.direction[s].astype(np.int64) + 1, 3)


def gap(rs, v_model: np.ndarray, config: CurveConfig = CurveConfig()) -> float:
    """The gap metric [mm/s] (see the module docstring); NaN when no cell is populated."""
    mean, count = cell_residuals(rs, v_model, config)
    ok = count >= config.min_count
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.mean(mean[ok] ** 2)))


def pooled_curve(i_ma: np.ndarray, v_mm_s: np.ndarray, config: CurveConfig = CurveConfig()
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local-mean curve pooled over directions (Fig. 4 / Fig. 7 of the paper).

    Returns
    -------
    centres : numpy.ndarray
        Bin centres [mA] of the bins with at least ``min_count`` samples.
    mean : numpy.ndarray
        Mean velocity [mm/s] in those bins.
    count : numpy.ndarray
        Samples in those bins.
    """
    mean, count = vel.binned_mean(i_ma, v_mm_s, config.edges)
    ok = count[0] >= config.min_count
    return config.centres[ok], mean[0][ok], count[0][ok]


def gap_noise_floor(rs, v_model: np.ndarray, config: CurveConfig = CurveConfig(), tau: float = 1.0) -> float:
    """Part of the gap explained by noise alone [mm/s].

    ``sqrt(mean_c (s_c^2 tau / n_c))`` over the cells of the gap, with ``s_c`` the standard
    deviation of the residuals in cell ``c``, ``n_c`` their number and ``tau`` the residuals'
    correlation time in samples (:class:`~fuelhm_bench.calibration.discrepancy.NoiseModel`):
    the RMS standard error of the cell means. A gap within a small multiple of it is noise.
    """
    s = rs.scored
    r = rs.v_meas_mm_s[s] - v_model[s]
    groups = rs.direction[s].astype(np.int64) + 1
    mean, count = vel.binned_mean(rs.i_ma[s], r, config.edges, groups, 3)
    mean2, _ = vel.binned_mean(rs.i_ma[s], r * r, config.edges, groups, 3)
    ok = count >= config.min_count
    if not ok.any():
        return float("nan")
    var = np.clip(mean2[ok] - mean[ok] ** 2, 0.0, None) * count[ok] / np.maximum(count[ok] - 1, 1)
    return float(np.sqrt(np.mean(var * max(tau, 1.0) / count[ok])))
