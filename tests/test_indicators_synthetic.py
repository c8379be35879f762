"""Indicators recovered on synthetic flights drawn on a known piecewise-linear curve.

The synthetic flights (``fuelhm_bench.testing.indicators``) have a known dual-gain curve
(X1=-1.5, X2=2.5 mA, Inb=0.5 mA, I0=0.74 mA, G_in=11, G_null=6, G_out=12.5 mm/s/mA,
saturation at -75 / +87 mm/s), a rate-independent hysteresis of +/-0.1 mA during ramps, an
idle current wandering in levels of standard deviation 0.05 mA (the known Hys0), current and
velocity held over each frame, 3 um position noise and 12-bit quantization over 70 mm (17 um).

Tolerances, and why (measured worst cases over 20 seeds at 50/100/200 Hz and with irregular
sampling are 15-85 % of them):

* X1, X2: 0.05 mA, one bin width. The kinks are rounded over about +/-0.3 mA by the
  hysteresis (+/-0.1 mA) and by the differentiator window (+/-2 frames at ramp rates up to
  40 mA/s); the rounding is symmetric, so the fitted asymptotes still cross within ~0.02 mA.
* Inb: 0.03 mA (mean of two breakpoints whose errors partly cancel).
* Y1, Y2: 0.5 mm/s. The continuous fit through rounded kinks tilts the short null segment
  (G_null about +1.5 %), moving the model values at the kinks by up to ~0.3 mm/s.
* G_in, G_out, G_null: 3 % (the same rounding; 11-12.5 mm/s/mA segments lose ~1 %).
* I0: 0.005 mA (the idle current is ~2500 random levels of std 0.05 mA: their mean is known
  to ~1e-3 mA; the few transient samples slower than 0.5 mm/s near I0 bias it less).
* Hys0: 6 % (sampling error ~1.5 % at 1 sigma, plus a bias of up to -3.5 % from the transient
  samples counted as idle, seen with irregular time stamps).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fuelhm_bench.indicators import (
    ExtractionConfig,
    StreamingExtractor,
    extract_indicators,
    indicators_from_curve,
    velocity_gain_curve,
)
from fuelhm_bench.testing.indicators import DualGainCurve, synthetic_flight
from fuelhm_bench.taxonomy import INDICATOR_NAMES

ABS_TOL = {"X1": 0.05, "X2": 0.05, "Inb": 0.03, "Y1": 0.5, "Y2": 0.5, "I0": 0.005}
REL_TOL = {"G_in": 0.03, "G_out": 0.03, "G_null": 0.03, "Hys0": 0.06}


def assert_recovered(result, truth):
    assert result.all_valid, result.reasons
    assert result.reasons == ()
    for name in INDICATOR_NAMES:
        got, want = result.values[name], truth[name]
        tol = ABS_TOL[name] if name in ABS_TOL else REL_TOL[name] * abs(want)
        assert abs(got - want) <= tol, f"{name}: extracted {got:.4f}, true {want:.4f}, tol {tol}"


@pytest.mark.parametrize("seed", [0, 1])
def test_recovers_known_indicators_at_100_hz(seed):
    flight = synthetic_flight(n_excursions=300, seed=seed)
    result = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm)
    assert_recovered(result, flight.truth)
    # Most samples are idle, as in a real flight, and all of them enter the curve.
    assert result.n_idle > 0.6 * len(flight.time_s)
    assert result.n_points > 0.95 * len(flight.time_s)


def test_recovers_a_shifted_asymmetric_curve():
    # Another curve: null-bias drift of +1 mA, wider null region, different gains.
    curve = DualGainCurve(inb_ma=1.5, null_halfwidth_ma=2.4, idle_offset_ma=-0.2, g_in=9.0,
                          g_null=5.0, g_out=14.0, v_retract_mm_s=-70.0, v_extend_mm_s=90.0)
    flight = synthetic_flight(curve, n_excursions=300, seed=7)
    result = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm)
    assert_recovered(result, flight.truth)
    assert result.values["Inb"] == pytest.approx(0.5 * (result.values["X1"] + result.values["X2"]))


@pytest.mark.parametrize("rate_hz", [50.0, 200.0])
def test_other_frame_rates(rate_hz):
    flight = synthetic_flight(n_excursions=300, rate_hz=rate_hz, seed=3)
    assert np.median(np.diff(flight.time_s)) == pytest.approx(1.0 / rate_hz)
    config = ExtractionConfig.for_frame_rate(rate_hz)
    assert config.diff_half_width == {50.0: 1, 200.0: 4}[rate_hz]
    result = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm, config)
    assert_recovered(result, flight.truth)
    # The streaming extractor handles the same rate identically.
    stream = StreamingExtractor(config)
    stream.update(flight.time_s, flight.current_ma, flight.position_mm)
    assert stream.result().values == result.values


def test_default_window_still_works_at_200_hz():
    # Default h=2 at 200 Hz: a 20 ms window, more quantization noise per sample; still fine.
    flight = synthetic_flight(n_excursions=300, rate_hz=200.0, seed=4)
    result = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm)
    assert_recovered(result, flight.truth)


def test_irregular_time_stamps():
    # Intervals of 10 ms +/- 2 ms: the differentiator uses the actual time stamps.
    flight = synthetic_flight(n_excursions=300, seed=5, time_jitter_s=0.002)
    steps = np.diff(flight.time_s)
    assert steps.min() < 0.0085 and steps.max() > 0.0115
    result = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm)
    assert_recovered(result, flight.truth)


def test_ignoring_time_stamps_would_be_wrong():
    # Guard for the test above: with the same data relabelled on a uniform grid, the gains
    # would still be right on average but the velocities of individual samples differ.
    flight = synthetic_flight(n_excursions=50, seed=5, time_jitter_s=0.002)
    uniform = np.arange(len(flight.time_s)) * 0.01
    a = velocity_gain_curve(flight.time_s, flight.current_ma, flight.position_mm)
    b = velocity_gain_curve(uniform, flight.current_ma, flight.position_mm)
    assert not np.allclose(a.sum_v2, b.sum_v2, rtol=1e-3)


def test_end_stops_and_current_saturation_are_masked():
    # A controller limited at +/-10 mA (inside the bin range, so that unmasked points would land
    # in bins), with the extraction told so.
    flight = synthetic_flight(n_excursions=300, saturation_events=25, seed=2, current_limit_ma=10.0)
    config = ExtractionConfig(current_limits_ma=(-10.0, 10.0))
    curve = velocity_gain_curve(flight.time_s, flight.current_ma, flight.position_mm, config)
    assert curve.counter("n_end_stop") > 1000
    assert curve.counter("n_current_limit") > 100
    # No spurious (I_sat, v=0) point survives: the bins at the current limits are empty.
    at_limit = np.abs(curve.bin_centres_ma) > 9.95
    assert curve.count[at_limit].sum() == 0
    assert_recovered(indicators_from_curve(curve), flight.truth)

    # Without the masks the spurious points are there: the limit bins are full of v = 0.
    no_masks = ExtractionConfig(stroke_limits_mm=(-100.0, 100.0),
                                current_limits_ma=(-50.0, 50.0))
    raw = velocity_gain_curve(flight.time_s, flight.current_ma, flight.position_mm, no_masks)
    k_hi = int(np.argmin(np.abs(raw.bin_centres_ma - 10.025)))
    k_lo = int(np.argmin(np.abs(raw.bin_centres_ma + 9.975)))
    assert raw.count[k_hi] + raw.count[k_lo] > 1000
    stuck = raw.mean_velocity_mm_s[[k_hi, k_lo]]
    assert np.nanmin(np.abs(stuck)) < 20.0  # far from the saturated +/-75..87 mm/s


def test_observed_limits_mask_the_end_stops_too():
    flight = synthetic_flight(n_excursions=300, saturation_events=25, seed=2)
    config = ExtractionConfig(stroke_limits_mm=None, current_limits_ma=None)
    curve = velocity_gain_curve(flight.time_s, flight.current_ma, flight.position_mm, config)
    assert curve.counter("n_end_stop") > 1000
    assert_recovered(indicators_from_curve(curve), flight.truth)


def test_hys0_follows_the_idle_spread():
    # Transient samples slower than 0.5 mm/s pass within ~0.2 mA of I0 and count as idle; for
    # a small idle spread they weigh more (+2 % at 0.02 mA); 10 % here.
    values = []
    for std in (0.02, 0.08):
        flight = synthetic_flight(n_excursions=150, idle_current_std_ma=std, seed=11)
        result = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm)
        assert result.valid["Hys0"]
        assert result.values["Hys0"] == pytest.approx(std, rel=0.10)
        values.append(result.values["Hys0"])
    assert values[1] > 3 * values[0]


def test_null_bias_drift_moves_the_right_indicators():
    # Paper Table IV: a null-bias drift moves X1, X2, Inb, I0 together, not the gains.
    base = synthetic_flight(DualGainCurve(), n_excursions=300, seed=9)
    drift = synthetic_flight(DualGainCurve(inb_ma=0.5 + 1.6), n_excursions=300, seed=9)
    r0 = extract_indicators(base.time_s, base.current_ma, base.position_mm)
    r1 = extract_indicators(drift.time_s, drift.current_ma, drift.position_mm)
    for name in ("X1", "X2", "Inb", "I0"):
        assert r1.values[name] - r0.values[name] == pytest.approx(1.6, abs=0.05)
    for name in ("G_in", "G_null", "G_out"):
        assert r1.values[name] == pytest.approx(r0.values[name], rel=0.03)
    for name in ("Y1", "Y2"):
        assert r1.values[name] == pytest.approx(r0.values[name], abs=0.5)
    assert not math.isnan(r1.values["Hys0"])
