"""From a binned velocity-gain curve to the ten indicators and their validity (shared step).

Both extractors (batch :func:`~fuelhm_bench.indicators.extract_indicators` and streaming
:class:`~fuelhm_bench.indicators.StreamingExtractor`) end here, so they agree whenever they
produce the same binned sums.

Definitions (currents in mA, velocities in mm/s, gains in mm/s/mA)
------------------------------------------------------------------
The current of a sample is its *matched current* (the current averaged with the weights the
differentiator gives to each frame's displacement, :mod:`fuelhm_bench.indicators.velocity`).

Idle indicators, from the idle statistics of the curve
(:func:`~fuelhm_bench.indicators.curve.idle_statistics`, independent of the fit):

* idle candidates: used samples with ``|v| <= idle_velocity_mm_s``;
* idle window: bins ``k_med - H .. k_med + H``, where ``k_med`` is the bin holding the median
  of the idle candidates' currents (first bin where their cumulative count reaches half the
  total) and ``H = floor(idle_halfwidth_ma / bin_width_ma)``;
* idle samples: the idle candidates in the idle window;
* ``I0``: mean control current of the idle samples (where the loop rests, v = 0);
* ``Hys0``: population standard deviation (ddof=0) of the control current of the idle
  samples: the horizontal spread at idle (hysteresis, limit cycling, quantization).

Curve indicators, from the constrained piecewise-linear fit of
:mod:`fuelhm_bench.indicators.fit` (segments: saturation, inlet, null, outlet, saturation;
the null segment contains ``I0``):

* ``X1``, ``Y1``: the slope change between the inlet segment (shaft inlet, retraction,
  v < 0, currents below X1) and the null segment; ``Y1 = v(X1)``;
* ``X2``, ``Y2``: the slope change between the null segment and the outlet segment (shaft
  outlet, extension, v > 0, currents above X2); ``Y2 = v(X2)``;
* ``Inb = (X1 + X2) / 2`` (paper Table I);
* ``G_in``, ``G_null``, ``G_out``: slopes of the inlet, null and outlet segments.

Validity (each failed check adds one reason string; an invalid indicator is NaN)
--------------------------------------------------------------------------------
1. *support* of a gain segment (inlet, null, outlet): ``>= min_segment_points`` moving
   samples, ``>= min_segment_bins`` bins with moving samples and a current span
   ``>= min_segment_span_ma``;
2. *slope change X1* is identified iff the inlet and null segments are supported,
   ``(G_in - G_null) / G_in >= min_slope_change`` and its approximate 95 % profile interval
   (:class:`~fuelhm_bench.indicators.CurveFit`) is at most ``max_breakpoint_interval_ma``
   wide; likewise *X2* with the null and outlet segments and ``(G_out - G_null) / G_out``;
3. if a slope change inside the data sits within one bin of its search limit
   ``I0 -/+ min_null_halfwidth_ma``, the constrained fit is distorted (the data want a slope
   change the model forbids): all eight curve indicators are invalid;
4. otherwise ``X1``, ``Y1`` and ``G_in`` are valid iff X1 is identified; ``X2``, ``Y2`` and
   ``G_out`` iff X2 is identified (a gain is only meaningful on a segment that starts at a
   real slope change); ``G_null`` iff the null segment is supported and X1 or X2 is
   identified; ``Inb`` iff both are identified;
5. ``I0`` and ``Hys0`` are valid iff there are ``>= min_idle_points`` idle samples.
"""

from __future__ import annotations

import math

from fuelhm_bench.indicators.config import ExtractionConfig
from fuelhm_bench.indicators.curve import VelocityGainCurve, idle_statistics
from fuelhm_bench.indicators.extended import extended_from_curve
from fuelhm_bench.indicators.fit import CurveFit, fit_curve
from fuelhm_bench.indicators.result import IndicatorResult
from fuelhm_bench.taxonomy import INDICATOR_NAMES


_SEGMENTS = {  # gain name -> (segment index in the fit, description)
    "G_in": (1, "inlet segment (below X1)"),
    "G_null": (2, "null segment (between X1 and X2)"),
    "G_out": (3, "outlet segment (above X2)"),
}


def segment_support(fit: CurveFit, config: ExtractionConfig) -> tuple[dict[str, bool], list[str]]:
    """Check that each gain segment of a fit holds enough data (validity rule 1).

    Parameters
    ----------
    fit : CurveFit
        The piecewise-linear fit.
    config : ExtractionConfig
        Supplies ``min_segment_points``, ``min_segment_bins``, ``min_segment_span_ma``.

    Returns
    -------
    tuple
        ``({"G_in": ok, "G_null": ok, "G_out": ok}, reasons)``.
    """
    ok: dict[str, bool] = {}
    reasons: list[str] = []
    for name, (seg, where) in _SEGMENTS.items():
        pts, bins, span = fit.segment_points[seg], fit.segment_bins[seg], fit.segment_span_ma[seg]
        problems = []
        if pts < config.min_segment_points:
            problems.append(f"{pts} points in the {where}, need >= {config.min_segment_points}")
        if bins < config.min_segment_bins:
            problems.append(f"{bins} occupied bins in the {where}, need >= "
                            f"{config.min_segment_bins}")
        if span < config.min_segment_span_ma:
            problems.append(f"the {where} spans {span:.3g} mA, need >= "
                            f"{config.min_segment_span_ma:g} mA")
        ok[name] = not problems
        reasons.extend(f"{name}: {p}" for p in problems)
    return ok, reasons


def _slope_change(label: str, outer: str, outer_gain: float, null_gain: float,
                  interval: tuple[float, float], support: dict[str, bool],
                  config: ExtractionConfig) -> tuple[bool, str | None]:
    """Validity rule 2 for one slope change."""
    if not (support[outer] and support["G_null"]):
        missing = " and ".join(g for g in (outer, "G_null") if not support[g])
        return False, f"{label}: slope change not bracketed by data ({missing} segment " \
                      f"insufficient)"
    change = (outer_gain - null_gain) / outer_gain if outer_gain > 0 else -math.inf
    if not change >= config.min_slope_change:
        return False, (f"{label}: slope change {100 * change:.1f}% ({outer}={outer_gain:.3g}, "
                       f"G_null={null_gain:.3g} mm/s/mA), need >= "
                       f"{100 * config.min_slope_change:g}%")
    width = interval[1] - interval[0]
    if not width <= config.max_breakpoint_interval_ma:
        return False, (f"{label}: slope change located only within [{interval[0]:.2f}, "
                       f"{interval[1]:.2f}] mA (95% profile interval {width:.2f} mA wide), "
                       f"need <= {config.max_breakpoint_interval_ma:g} mA")
    return True, None


def _pinned(fit: CurveFit, i0: float, config: ExtractionConfig) -> str | None:
    """Reason when a slope change inside the data sits on its search limit (rule 3)."""
    first, last = fit.data_range_ma
    tol = config.bin_width_ma  # within one candidate spacing of the limit
    w = config.min_null_halfwidth_ma
    for name, x, limit, sign in (("X1", fit.x1_ma, i0 - w, -1.0), ("X2", fit.x2_ma, i0 + w, 1.0)):
        if first < x < last and sign * (x - limit) <= tol:
            return (f"the slope change {name} sits on its search limit I0 {'+-'[sign < 0]} "
                    f"{w:g} mA: the null region is narrower than min_null_halfwidth_ma allows, "
                    f"the fit is not valid")
    return None


def indicators_from_curve(curve: VelocityGainCurve,
                          config: ExtractionConfig | None = None) -> IndicatorResult:
    """Extract the ten indicators (paper Table I) from a binned velocity-gain curve.

    Parameters
    ----------
    curve : VelocityGainCurve
        Binned curve from :func:`~fuelhm_bench.indicators.velocity_gain_curve` or
        :meth:`StreamingExtractor.curve <fuelhm_bench.indicators.StreamingExtractor.curve>`.
    config : ExtractionConfig, optional
        Fit and quality settings; defaults to the curve's configuration (the binning settings
        always come from the curve).

    Returns
    -------
    IndicatorResult
        Values (NaN when invalid), validity flags and reasons; see the module docstring for
        the exact definitions.
    """
    cfg = curve.config if config is None else config
    values = {name: math.nan for name in INDICATOR_NAMES}
    valid = {name: False for name in INDICATOR_NAMES}
    reasons: list[str] = []

    i0, hys0, n_idle = idle_statistics(curve, cfg)
    if n_idle >= cfg.min_idle_points:
        values["I0"], values["Hys0"] = i0, hys0
        valid["I0"] = valid["Hys0"] = True
    else:
        reasons.append(f"I0, Hys0: {n_idle} idle samples (|v| <= {cfg.idle_velocity_mm_s:g} "
                       f"mm/s within {cfg.idle_halfwidth_ma:g} mA of the median idle current), "
                       f"need >= {cfg.min_idle_points}")

    fit = fit_curve(curve, cfg, anchor_ma=i0)
    n_occupied = int(((curve.moving_count >= cfg.min_bin_count)
                      & (curve.idle_count <= cfg.max_idle_ratio * curve.moving_count)).sum())
    curve_names = "X1, Y1, X2, Y2, Inb, G_in, G_out, G_null"
    if fit is None and n_occupied < 4:
        reasons.append(f"{curve_names}: {n_occupied} current bins with moving samples "
                       f"({curve.n_points} points), need >= 4 to fit the curve")
    elif fit is None:
        reasons.append(f"{curve_names}: no increasing dual-gain curve with the idle current "
                       f"in its null region fits the data")
    else:
        support, support_reasons = segment_support(fit, cfg)
        reasons.extend(support_reasons)
        ok1, why1 = _slope_change("X1, Y1, G_in", "G_in", fit.g_in, fit.g_null,
                                  fit.x1_interval_ma, support, cfg)
        ok2, why2 = _slope_change("X2, Y2, G_out", "G_out", fit.g_out, fit.g_null,
                                  fit.x2_interval_ma, support, cfg)
        reasons.extend(r for r in (why1, why2) if r)
        pinned = _pinned(fit, i0, cfg)
        if pinned:
            reasons.append(f"{curve_names}: {pinned}")
            ok1 = ok2 = False
        null_ok = support["G_null"] and (ok1 or ok2)
        if support["G_null"] and not null_ok and not pinned:
            reasons.append("G_null: no identified slope change delimits the null segment")
        if not (ok1 and ok2) and not pinned:
            reasons.append("Inb: needs identified X1 and X2")
        values.update(X1=fit.x1_ma, Y1=fit.y1_mm_s, G_in=fit.g_in, X2=fit.x2_ma,
                      Y2=fit.y2_mm_s, G_out=fit.g_out, G_null=fit.g_null,
                      Inb=0.5 * (fit.x1_ma + fit.x2_ma))
        valid.update(X1=ok1, Y1=ok1, G_in=ok1, X2=ok2, Y2=ok2, G_out=ok2, G_null=null_ok,
                     Inb=ok1 and ok2)
    ext_values, ext_valid, ext_reasons = extended_from_curve(curve, i0, valid["I0"], cfg.min_idle_points,
                                                           cfg)
    return IndicatorResult(values=values, valid=valid, reasons=tuple(reasons),
                           n_points=curve.n_points, fit=fit, n_idle=n_idle, extended_values=ext_values,
                           extended_valid=ext_valid, extended_reasons=tuple(ext_reasons))
