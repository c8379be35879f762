"""Extended, model-free indicators from the binned velocity-gain curve (beyond the paper's ten).

The paper's ten indicators confuse some modes (their signatures are nearly collinear, or a mode
moves none of them much). These indicators read the same binned curve
(:class:`~fuelhm_bench.indicators.curve.VelocityGainCurve`) at fixed places, without a fitted
model, so the batch and the streaming extractors produce them bit for bit alike. Eight read the
per-bin sums of the paper's extractor; the three supply-pressure indicators read the curve's band
accumulators (``8 x ceil(n_bins / 10)`` float64, filled only when N2 is recorded).

Definitions (currents in mA relative to the idle current ``I0``, velocities in mm/s)
-----------------------------------------------------------------------------------
*Velocity at a fixed current offset* ``V(a, b)``: the mean velocity of the *moving* samples
(``|v| > idle_velocity_mm_s``) of the bins whose centre lies in ``[I0 + a, I0 + b)``:
``sum_k (sum_v[k] - idle_sum_v[k]) / sum_k moving_count[k]``; valid iff at least
:data:`MIN_WINDOW_POINTS` moving samples fall in the window.

* ``V_in1 = V(-1.25, -0.75)``, ``V_out1 = V(0.75, 1.25)``: inside the null region (null gain,
  leakage through the piston, the diaphragm's flow);
* ``V_in3 = V(-3.5, -2.5)``, ``V_out3 = V(2.5, 3.5)``: on the inlet and outlet gains;
* ``V_in7 = V(-7.5, -6.5)``, ``V_out7 = V(6.5, 7.5)``: at large currents, near saturation
  (supply restriction, leakage at high load).

``Vsd_null``: the pooled population standard deviation of the velocity of *all* used samples in
``[I0 - 1, I0 + 1)`` (moving and idle): the vertical scatter of the curve around the null
(stick-slip, limit cycling, play), ``sqrt(sum sum_v2 / n - (sum sum_v / n)**2)``; valid iff
``n >= MIN_WINDOW_POINTS``.

``Idle_frac``: the fraction of the used samples that are idle candidates
(``|v| <= idle_velocity_mm_s``), dimensionless, i.e. the share of the flight the rod rests:
a dead zone (friction, play) lengthens the rests. Valid iff at least ``min_idle_points`` samples
were used.

Every indicator relative to ``I0`` is invalid when ``I0`` is (fewer than ``min_idle_points``
idle samples).

Supply-pressure indicators (need the engine HP speed N2 per sample; the supply pressure rise
follows ``N2**2``, so N2 bands are supply-pressure bands)
-----------------------------------------------------------------------------------------
The idle candidates of the cells (``BAND_CELL_BINS`` bins) that overlap the idle window of
``I0``/``Hys0`` are split by the N2 of their centre sample: the *low-pressure band*
``N2 < pressure_bands_n2_pct[0]`` (70 %: ground idle, taxi, descent, landing) and the
*high-pressure band* ``N2 >= pressure_bands_n2_pct[1]`` (80 %: climb, cruise).

* ``Hys_lo``, ``Hys_hi`` (mA): the paper's ``Hys0`` (population standard deviation of the idle
  current) within the low and the high band. A friction dead zone on the spool is
  ``F_c / k_d`` with a drive stiffness ``k_d`` proportional to the pilot supply pressure, so the
  idle spread it causes scales with 1/pressure (larger in the low band); a play (backlash) has a
  fixed width and adds the same spread in both bands. Valid iff the band holds at least
  ``min_idle_points`` samples.
* ``I0_slope`` (mA per % N2): ``(I0_hi - I0_lo) / (N2_hi - N2_lo)``, the change of the idle
  current between the two bands' means over the change of their mean N2 (the least-squares
  slope of the two band means). A null bias moves ``I0`` equally at every pressure; the spool
  offset that feeds a leak or a flow against a load scales with the flow over the
  pressure-dependent flow gain, so it changes with N2. Valid iff ``Hys_lo`` and ``Hys_hi`` are
  and ``N2_hi - N2_lo >= MIN_BAND_N2_SEPARATION_PCT``.
"""

from __future__ import annotations

import math

import numpy as np

from fuelhm_bench.indicators.config import ExtractionConfig
from fuelhm_bench.indicators.curve import VelocityGainCurve, band_statistics
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES

__all__ = ["FIXED_CURRENT_WINDOWS_MA", "MIN_BAND_N2_SEPARATION_PCT", "MIN_WINDOW_POINTS",
           "NULL_SCATTER_HALFWIDTH_MA", "extended_from_curve"]

#: Indicator -> (low, high) current window relative to ``I0``, in mA.
FIXED_CURRENT_WINDOWS_MA: dict[str, tuple[float, float]] = {
    "V_in1": (-1.25, -0.75), "V_out1": (0.75, 1.25),
    "V_in3": (-3.5, -2.5), "V_out3": (2.5, 3.5),
    "V_in7": (-7.5, -6.5), "V_out7": (6.5, 7.5),
}

#: Half-width of the window of ``Vsd_null`` around ``I0``, in mA.
NULL_SCATTER_HALFWIDTH_MA: float = 1.0

#: Minimum number of samples in a window for its indicator to be valid.
MIN_WINDOW_POINTS: int = 20

#: Minimum difference of the two bands' mean N2 for ``I0_slope`` to be valid, in %.
MIN_BAND_N2_SEPARATION_PCT: float = 5.0


def _window(curve: VelocityGainCurve, i0: float, low: float, high: float) -> np.ndarray:
    c = curve.bin_centres_ma
    return (c >= i0 + low) & (c < i0 + high)


def extended_from_curve(curve: VelocityGainCurve, i0: float, i0_valid: bool, min_idle_points: int,
                        config: ExtractionConfig | None = None
                        ) -> tuple[dict[str, float], dict[str, bool], list[str]]:
    """The extended indicators of one curve (see the module docstring).

    Parameters
    ----------
    curve : VelocityGainCurve
        The binned curve.
    i0 : float
        The idle current ``I0`` of the same curve, in mA.
    i0_valid : bool
        Whether ``I0`` is valid.
    min_idle_points : int
        The configuration's ``min_idle_points`` (validity of ``Idle_frac``, ``Hys_lo``,
        ``Hys_hi``).
    config : ExtractionConfig, optional
        Supplies ``idle_halfwidth_ma`` (the idle window); defaults to the curve's.

    Returns
    -------
    tuple
        ``(values, valid, reasons)``: dicts keyed by
        :data:`~fuelhm_bench.taxonomy.EXTENDED_INDICATOR_NAMES` (NaN when invalid) and the reason
        of every invalid one.
    """
    values = {n: math.nan for n in EXTENDED_INDICATOR_NAMES}
    valid = {n: False for n in EXTENDED_INDICATOR_NAMES}
    reasons: list[str] = []
    used = float(curve.count.sum())
    if used >= min_idle_points:
        values["Idle_frac"] = float(curve.idle_count.sum()) / used
        valid["Idle_frac"] = True
    else:
        reasons.append(f"Idle_frac: {int(used)} used samples, need >= {min_idle_points}")
    _pressure_bands(curve, config, min_idle_points, values, valid, reasons)
    if not (i0_valid and math.isfinite(i0)):
        reasons.append("V_in1, V_out1, V_in3, V_out3, V_in7, V_out7, Vsd_null: I0 is not valid")
        return values, valid, reasons
    moving_sum = curve.sum_v - curve.idle_sum_v
    for name, (low, high) in FIXED_CURRENT_WINDOWS_MA.items():
        m = _window(curve, i0, low, high)
        n = float(curve.moving_count[m].sum())
        if n >= MIN_WINDOW_POINTS:
            values[name] = float(moving_sum[m].sum()) / n
            valid[name] = True
        else:
            reasons.append(f"{name}: {int(n)} moving samples within [I0 {low:+g}, I0 {high:+g}) mA, "
                           f"need >= {MIN_WINDOW_POINTS}")
    w = NULL_SCATTER_HALFWIDTH_MA
    m = _window(curve, i0, -w, w)
    n = float(curve.count[m].sum())
    if n >= MIN_WINDOW_POINTS:
        mean = float(curve.sum_v[m].sum()) / n
        values["Vsd_null"] = math.sqrt(max(float(curve.sum_v2[m].sum()) / n - mean * mean, 0.0))
        valid["Vsd_null"] = True
    else:
        reasons.append(f"Vsd_null: {int(n)} samples within I0 +- {w:g} mA, need >= {MIN_WINDOW_POINTS}")
    return values, valid, reasons


def _pressure_bands(curve: VelocityGainCurve, config: ExtractionConfig | None, min_idle_points: int,
                    values: dict[str, float], valid: dict[str, bool], reasons: list[str]) -> None:
    """Fill ``Hys_lo``, ``Hys_hi`` and ``I0_slope`` (see the module docstring)."""
    cfg = curve.config if config is None else config
    low, high = curve.config.pressure_bands_n2_pct
    bands = {}
    for name, band, where in (("Hys_lo", "low", f"N2 < {low:g} %"), ("Hys_hi", "high", f"N2 >= {high:g} %")):
        mean, std, n, n2_mean = band_statistics(curve, band, cfg)
        bands[band] = (mean, n2_mean)
        if n >= min_idle_points:
            values[name] = std
            valid[name] = True
        else:
            reasons.append(f"{name}: {n} idle samples with {where} in the idle window, need >= "
                           f"{min_idle_points} (N2 not recorded, or the flight spent too little "
                           f"time at rest at that speed)")
    if not (valid["Hys_lo"] and valid["Hys_hi"]):
        reasons.append("I0_slope: needs valid Hys_lo and Hys_hi (idle samples in both N2 bands)")
        return
    (i_lo, n2_lo), (i_hi, n2_hi) = bands["low"], bands["high"]
    if n2_hi - n2_lo < MIN_BAND_N2_SEPARATION_PCT:
        reasons.append(f"I0_slope: the bands' mean N2 differ by {n2_hi - n2_lo:.3g} %, need >= "
                       f"{MIN_BAND_N2_SEPARATION_PCT:g} %")
        return
    values["I0_slope"] = (i_hi - i_lo) / (n2_hi - n2_lo)
    valid["I0_slope"] = True
