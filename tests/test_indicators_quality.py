"""Quality flags: an indicator the flight cannot support is NaN, flagged and explained."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from fuelhm_bench.errors import ParameterError, UnknownNameError
from fuelhm_bench.indicators import (
    ExtractionConfig,
    IndicatorResult,
    VelocityGainCurve,
    extract_indicators,
    fit_curve,
    indicators_from_curve,
)
from fuelhm_bench.indicators.config import N_ACCUMULATORS
from fuelhm_bench.indicators.curve import COUNTER_NAMES
from fuelhm_bench.testing.indicators import DualGainCurve, synthetic_flight
from fuelhm_bench.taxonomy import INDICATOR_NAMES

OUTLET_SIDE = {"X2", "Y2", "G_out", "Inb"}
INLET_SIDE = {"X1", "Y1", "G_in", "Inb"}


def extract(flight, config=None):
    return extract_indicators(flight.time_s, flight.current_ma, flight.position_mm, config)


def assert_consistent(result: IndicatorResult):
    for name in INDICATOR_NAMES:
        assert result.valid[name] == (not math.isnan(result.values[name])), name
    assert (result.reasons == ()) == result.all_valid
    assert result.to_row()["quality_reason"] == "; ".join(result.reasons)


@pytest.mark.parametrize("peak_hi", [1.5, 2.4, 3.0])
def test_flight_that_never_goes_above_x2(peak_hi):
    # X2 = 2.5 mA; excursions on the outlet side stop at peak_hi (+0.1 mA of hysteresis).
    flight = synthetic_flight(n_excursions=300, peak_range_ma=(-9.8, peak_hi), seed=31)
    assert flight.current_ma.max() <= peak_hi + 1e-9
    result = extract(flight)
    assert_consistent(result)
    invalid = {name for name in INDICATOR_NAMES if not result.valid[name]}
    assert invalid == OUTLET_SIDE
    assert any(r.startswith("G_out") or r.startswith("X2, Y2, G_out") for r in result.reasons)
    assert any(r.startswith("Inb:") for r in result.reasons)
    # What the flight does support is still right (X1 within 0.1 mA: the upper end of the
    # null segment is the excursions' turning region, slightly less well measured).
    truth = flight.truth
    assert result.values["X1"] == pytest.approx(truth["X1"], abs=0.1)
    assert result.values["G_in"] == pytest.approx(truth["G_in"], rel=0.03)
    assert result.values["G_null"] == pytest.approx(truth["G_null"], rel=0.05)
    assert result.values["I0"] == pytest.approx(truth["I0"], abs=0.005)


def test_flight_that_never_goes_below_x1():
    flight = synthetic_flight(n_excursions=300, peak_range_ma=(-1.0, 9.8), seed=32)
    result = extract(flight)
    assert_consistent(result)
    assert {name for name in INDICATOR_NAMES if not result.valid[name]} == INLET_SIDE
    assert any("inlet segment" in r for r in result.reasons)
    assert result.values["G_out"] == pytest.approx(flight.truth["G_out"], rel=0.03)
    assert result.values["X2"] == pytest.approx(flight.truth["X2"], abs=0.1)


def test_flight_confined_to_the_null_region():
    flight = synthetic_flight(n_excursions=300, peak_range_ma=(-0.5, 1.9), seed=33)
    result = extract(flight)
    assert_consistent(result)
    curve_names = {"X1", "Y1", "X2", "Y2", "Inb", "G_in", "G_out", "G_null"}
    assert {n for n in INDICATOR_NAMES if not result.valid[n]} == curve_names
    assert result.valid["I0"] and result.valid["Hys0"]


def test_barely_past_x2_is_not_enough():
    # Data reach 0.35 mA beyond X2: fewer points/bins/span than the gates need.
    flight = synthetic_flight(n_excursions=300, peak_range_ma=(-9.8, 2.75), seed=34)
    result = extract(flight)
    assert_consistent(result)
    assert not result.valid["G_out"] and not result.valid["X2"]
    # Lowering the gates does not make a silent wrong G_out appear either: either the fit
    # keeps X2 out of the data, or the outlet segment it finds is short but correct-ish.
    lax = ExtractionConfig(min_segment_points=2, min_segment_bins=2, min_segment_span_ma=0.0)
    lax_result = extract(flight, lax)
    if lax_result.valid["G_out"]:
        assert lax_result.values["G_out"] > lax_result.values["G_null"]


def test_reason_format_names_indicator_count_and_requirement():
    flight = synthetic_flight(n_excursions=300, peak_range_ma=(-9.8, 2.0), seed=35)
    result = extract(flight)
    reasons = "; ".join(result.reasons)
    # e.g. "G_out: 7 occupied bins in the outlet segment (above X2), need >= 10"
    assert re.search(r"G_out: (\d+ points|\d+ occupied bins|the outlet segment \(above X2\) "
                     r"spans [\d.]+ mA).*need >= ", reasons), reasons
    demanding = extract(flight, ExtractionConfig(min_segment_points=10**6))
    assert re.search(r"G_in: \d+ points in the inlet segment \(below X1\), need >= 1000000",
                     "; ".join(demanding.reasons))


def test_no_idle_samples_invalidates_i0_and_hys0():
    flight = synthetic_flight(n_excursions=100, seed=36)
    strict = ExtractionConfig(min_idle_points=10**7)
    result = extract(flight, strict)
    assert_consistent(result)
    assert not result.valid["I0"] and not result.valid["Hys0"]
    assert result.reasons[0].startswith("I0, Hys0: ")
    assert "need >= 10000000" in result.reasons[0]
    others = [n for n in INDICATOR_NAMES if n not in ("I0", "Hys0")]
    assert all(result.valid[n] for n in others)


def test_weak_slope_change_is_not_reported():
    # A "dual-gain" curve whose gains differ by 5 %: the kinks cannot be located reliably.
    curve = DualGainCurve(g_in=6.3, g_null=6.0, g_out=6.3, v_retract_mm_s=-70.0,
                          v_extend_mm_s=70.0)
    flight = synthetic_flight(curve, n_excursions=300, seed=37)
    result = extract(flight)
    assert_consistent(result)
    for name in ("X1", "Y1", "X2", "Y2", "Inb", "G_in", "G_out", "G_null"):
        assert not result.valid[name], name
    assert any("slope change" in r for r in result.reasons)


def test_empty_curve_gives_all_curve_indicators_invalid():
    config = ExtractionConfig()
    curve = VelocityGainCurve(config, np.zeros((N_ACCUMULATORS, config.n_bins)),
                              np.zeros(len(COUNTER_NAMES), dtype=np.int64))
    result = indicators_from_curve(curve)
    assert_consistent(result)
    assert not any(result.valid.values())
    assert result.n_points == 0
    assert any("0 current bins with moving samples" in r for r in result.reasons)
    assert fit_curve(curve) is None


def test_decreasing_curve_has_no_admissible_fit():
    # Velocity decreasing with current (reversed polarity): no admissible dual-gain model.
    config = ExtractionConfig()
    c = config.bin_centres_ma
    acc = np.zeros((N_ACCUMULATORS, config.n_bins))
    occupied = np.abs(c) < 6
    acc[0, occupied] = 10
    acc[1, occupied] = 10 * (-8.0 * c[occupied])
    centre = np.argmin(np.abs(c))
    acc[0, centre] += 100  # 100 idle samples at v = 0 in the centre bin
    acc[3, centre] = 100
    curve = VelocityGainCurve(config, acc, np.zeros(len(COUNTER_NAMES), dtype=np.int64))
    result = indicators_from_curve(curve)
    assert_consistent(result)
    assert any("no increasing dual-gain curve" in r for r in result.reasons)
    assert result.valid["I0"]


def test_result_invariants_are_enforced():
    values = dict.fromkeys(INDICATOR_NAMES, 1.0)
    valid = dict.fromkeys(INDICATOR_NAMES, True)
    valid["Hys0"] = False
    r = IndicatorResult(values=values, valid=valid, reasons=("Hys0: test",), n_points=3)
    assert math.isnan(r.values["Hys0"])  # an invalid indicator is always NaN
    bad = dict(values, X1=math.nan)
    with pytest.raises(ParameterError, match="Got X1=nan flagged valid instead"):
        IndicatorResult(values=bad, valid=dict.fromkeys(INDICATOR_NAMES, True), reasons=(),
                        n_points=1)
    with pytest.raises(ParameterError, match="one entry per indicator name"):
        IndicatorResult(values={"X1": 1.0}, valid={"X1": True}, reasons=(), n_points=1)
    with pytest.raises(AttributeError):
        r.n_points = 5  # frozen


def test_curve_construction_errors():
    config = ExtractionConfig()
    with pytest.raises(ParameterError, match="'accumulators' and 'counters' parameters of "
                                             "VelocityGainCurve must have shapes \\(7, 480\\)"):
        VelocityGainCurve(config, np.zeros((6, config.n_bins)), np.zeros(len(COUNTER_NAMES)))
    curve = VelocityGainCurve(config, np.zeros((N_ACCUMULATORS, config.n_bins)),
                              np.zeros(len(COUNTER_NAMES), dtype=np.int64))
    with pytest.raises(UnknownNameError, match="Unknown counter 'n_stops'"):
        curve.counter("n_stops")
    assert curve.accumulators.flags.writeable is False  # the curve is immutable


def test_slope_change_pinned_on_its_search_limit_is_not_reported():
    # X2 only 0.7 mA above I0: with min_null_halfwidth_ma = 1 mA the fit may not go closer, so
    # its optimum sits on that limit and drags the other parameters (here X1 by ~0.2 mA):
    # every curve indicator is flagged rather than reported.
    curve = DualGainCurve(null_halfwidth_ma=1.2, idle_offset_ma=0.5)
    flight = synthetic_flight(curve, n_excursions=300, seed=38)
    result = extract(flight, ExtractionConfig(min_null_halfwidth_ma=1.0))
    assert_consistent(result)
    curve_names = ("X1", "Y1", "X2", "Y2", "Inb", "G_in", "G_out", "G_null")
    assert not any(result.valid[n] for n in curve_names)
    assert result.valid["I0"] and result.valid["Hys0"]
    assert any("X2 sits on its search limit I0 + 1 mA" in r for r in result.reasons)
    # With a smaller margin the same flight is fully identified.
    relaxed = extract(flight, ExtractionConfig(min_null_halfwidth_ma=0.3))
    assert relaxed.all_valid, relaxed.reasons
    assert relaxed.values["X1"] == pytest.approx(curve.x1, abs=0.05)
    assert relaxed.values["X2"] == pytest.approx(curve.x2, abs=0.05)


def test_imprecisely_located_slope_change_is_not_reported():
    # A sparse 50 Hz flight (64 excursions) on a weak dual-gain curve (3.0 vs 3.9 mm/s/mA):
    # the best-fitting X2 is 0.64 mA off, but its profile interval is 0.77 mA wide.
    curve = DualGainCurve(inb_ma=-0.3996, null_halfwidth_ma=2.402, idle_offset_ma=0.1263,
                          g_in=4.065, g_null=3.014, g_out=3.935)
    flight = synthetic_flight(curve, n_excursions=64, peak_range_ma=(-2.16, 5.66), seed=115,
                              idle_current_std_ma=0.177, hysteresis_ma=0.246,
                              saturation_events=3, rate_hz=50.0)
    result = extract(flight, ExtractionConfig.for_frame_rate(50.0))
    assert_consistent(result)
    assert not result.valid["X2"] and not result.valid["G_out"]
    assert any(re.search(r"X2, Y2, G_out: slope change located only within .*\(95% profile "
                         r"interval [\d.]+ mA wide\), need <= 0.4 mA", r)
               for r in result.reasons), result.reasons
    lax = extract(flight, ExtractionConfig.for_frame_rate(50.0, max_breakpoint_interval_ma=5.0,
                                                          min_null_halfwidth_ma=1.0))
    assert lax.valid["X2"] and abs(lax.values["X2"] - curve.x2) > 0.4  # what it would report
