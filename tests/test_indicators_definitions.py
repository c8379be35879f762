"""The documented definitions, checked piece by piece (differentiator, masks, idle samples,
curve fit), and a randomized check that valid indicators are never wildly wrong."""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.indicators import (
    ExtractionConfig,
    VelocityGainCurve,
    differentiate_position,
    extract_indicators,
    fit_curve,
    indicators_from_curve,
    velocity_gain_curve,
    velocity_points,
)
from fuelhm_bench.indicators.config import N_ACCUMULATORS
from fuelhm_bench.indicators.curve import COUNTER_NAMES
from fuelhm_bench.testing.indicators import DualGainCurve, synthetic_flight
from fuelhm_bench.indicators.velocity import matched_current


# ----------------------------------------------------------------------------- differentiator
def test_differentiator_is_exact_for_linear_motion_at_irregular_times():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.005, 0.015, 300))
    x = 12.0 + 37.5 * t
    v = differentiate_position(t, x, half_width=3)
    assert np.isnan(v[:3]).all() and np.isnan(v[-3:]).all()
    np.testing.assert_allclose(v[3:-3], 37.5, rtol=1e-9)


def test_differentiator_is_exact_for_quadratic_motion_at_uniform_times():
    t = np.arange(200) * 0.01
    x = 5.0 + 20.0 * t - 7.0 * t**2
    v = differentiate_position(t, x, half_width=2)
    np.testing.assert_allclose(v[2:-2], 20.0 - 14.0 * t[2:-2], atol=1e-9)


def test_velocity_quantum_of_the_five_point_window():
    # One ADC step q at the window edge moves the 5-point slope by 2q / (10 dt).
    q, dt = 70.0 / 4096, 0.01
    t = np.arange(5) * dt
    x = np.array([0.0, 0.0, 0.0, 0.0, q])
    assert differentiate_position(t, x)[2] == pytest.approx(2 * q / (10 * dt))  # 0.34 mm/s
    # Rest with a code flickering at random stays within a few velocity quanta of zero.
    rng = np.random.default_rng(2)
    t = np.arange(10_000) * dt
    x = 30.0 + q * rng.integers(0, 2, t.size)
    v = differentiate_position(t, x)[2:-2]
    assert np.abs(v).max() <= 6 * q / (10 * dt) + 1e-9  # |sum k*e_k| <= 6 for e_k in {0,1}
    assert np.mean(np.abs(v) <= 1.0) > 0.85  # most rest samples are idle candidates


# ----------------------------------------------------------------------------- matched current
def zoh_flight(current, dt=0.01, gain=6.0, i0=0.0, adc_q=70.0 / 4096, seed=0):
    """Current held over each frame, velocity gain * (i - i0), quantized noisy position."""
    rng = np.random.default_rng(seed)
    t = np.arange(len(current)) * dt
    v = gain * (current - i0)
    x = 30.0 + np.concatenate(([0.0], np.cumsum(v[:-1] * dt)))
    x = np.round((x + 0.003 * rng.standard_normal(len(x))) / adc_q) * adc_q
    return t, current, x


def test_matched_current_weights():
    t = np.arange(7) * 0.01
    unit = np.zeros(7)
    unit[3] = 1.0
    # Sample n pairs with currents n-2 .. n+1 weighted 0.2, 0.3, 0.3, 0.2 (h = 2): samples
    # 2, 3, 4 see the unit current at index 3 with weights 0.2, 0.3, 0.3.
    np.testing.assert_allclose(matched_current(t, unit)[2:5], [0.2, 0.3, 0.3])
    # The weights are positive and sum to one, also at irregular times.
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.005, 0.015, 50))
    np.testing.assert_allclose(matched_current(t, np.full(50, 2.5), 3)[3:-3], 2.5)


def test_white_current_noise_does_not_dilute_the_gain():
    # Current jumping from frame to frame (white noise, +/-1 mA) on a linear curve: the
    # window velocity paired with the matched current keeps the gain; paired with the centre
    # current it would fall to 30 % of it.
    rng = np.random.default_rng(4)
    t, i, x = zoh_flight(0.7 * rng.standard_normal(60_000), gain=6.0)
    curve = velocity_gain_curve(t, i, x, ExtractionConfig(max_current_rate_ma_s=None))
    ok = curve.moving_count >= 50
    slope = np.polyfit(curve.bin_centres_ma[ok], curve.moving_mean_velocity_mm_s[ok], 1)[0]
    assert slope == pytest.approx(6.0, rel=0.03)
    v = differentiate_position(t, x)[2:-2]
    centre_slope = np.polyfit(i[2:-2], v, 1)[0]
    assert centre_slope == pytest.approx(0.3 * 6.0, rel=0.1)


# ----------------------------------------------------------------------------- masks
def ramp_flight(n=400, dt=0.01):
    """Current ramps up and down between -4 and 4 mA; velocity 6 mm/s/mA * current."""
    t = np.arange(n) * dt
    return zoh_flight(4.0 * np.sin(2 * np.pi * t / 2.0), dt=dt)


def window_any(flags, h=2):
    return np.array([flags[c - h:c + h + 1].any() for c in range(h, len(flags) - h)])


def test_gap_mask():
    t, i, x = ramp_flight()
    t = t.copy()
    t[200:] += 1.0  # a 1 s hole between samples 199 and 200
    curve = velocity_gain_curve(t, i, x, ExtractionConfig(max_current_rate_ma_s=None))
    # Centres whose window contains the interval 199 -> 200: 198, 199, 200, 201 (h = 2).
    assert curve.counter("n_gap") == 4
    assert curve.counter("n_used") == len(t) - 4 - 4


def test_end_stop_mask_uses_the_whole_window():
    t, i, x = ramp_flight()
    cfg = ExtractionConfig(stroke_limits_mm=(0.0, float(x.max()) + 0.45),
                           max_current_rate_ma_s=None)
    curve = velocity_gain_curve(t, i, x, cfg)
    expected = int(window_any(x >= x.max() - 0.05).sum())  # within 0.5 mm of the stop
    assert curve.counter("n_end_stop") == expected > 0


def test_current_limit_and_out_of_range_masks():
    t, i, x = ramp_flight()
    cfg = ExtractionConfig(current_limits_ma=(-3.5, 3.5), current_limit_margin_ma=0.0,
                           max_current_rate_ma_s=None)
    curve = velocity_gain_curve(t, i, x, cfg)
    at_limit = window_any(np.abs(i) >= 3.5)  # any current of the window at a limit
    assert curve.counter("n_current_limit") == int(at_limit.sum()) > 0
    narrow = ExtractionConfig(current_range_ma=(-2.0, 2.0), max_current_rate_ma_s=None)
    curve = velocity_gain_curve(t, i, x, narrow)
    i_m = matched_current(t, i)[2:-2]
    assert curve.counter("n_out_of_range") == int(np.sum((i_m < -2.0) | (i_m >= 2.0)))


def test_fast_current_mask():
    t, i, x = ramp_flight()  # the sine peaks at 12.6 mA/s
    curve = velocity_gain_curve(t, i, x, ExtractionConfig(max_current_rate_ma_s=5.0))
    rate = np.abs(i[4:] - i[:-4]) / (t[4:] - t[:-4])
    assert curve.counter("n_fast_current") == int(np.sum(rate > 5.0)) > 100
    assert velocity_gain_curve(t, i, x).counter("n_fast_current") == 0  # default 100 mA/s


# ----------------------------------------------------------------------------- idle samples
def test_i0_and_hys0_follow_their_definition():
    f = synthetic_flight(n_excursions=120, seed=61, idle_current_std_ma=0.08)
    cfg = ExtractionConfig()
    result = extract_indicators(f.time_s, f.current_ma, f.position_mm, cfg)
    i, v = velocity_points(f.time_s, f.current_ma, f.position_mm, cfg)
    # Idle candidates: used samples with |v| <= idle_velocity_mm_s (0.5 mm/s); the current
    # of a sample is its matched current (velocity_points returns it).
    cand = i[np.abs(v) <= cfg.idle_velocity_mm_s]
    k = ((cand - cfg.current_range_ma[0]) * (1.0 / cfg.bin_width_ma)).astype(int)
    counts = np.bincount(k, minlength=cfg.n_bins)
    k_med = int(np.searchsorted(np.cumsum(counts), 0.5 * counts.sum()))
    half = int(cfg.idle_halfwidth_ma / cfg.bin_width_ma + 1e-9)  # 20 bins
    idle = cand[np.abs(k - k_med) <= half]
    assert result.n_idle == idle.size
    assert result.values["I0"] == pytest.approx(idle.mean(), rel=1e-12)
    assert result.values["Hys0"] == pytest.approx(idle.std(ddof=0), rel=1e-9)


# ----------------------------------------------------------------------------- curve fit
def exact_curve(curve_def: DualGainCurve, per_bin=30, idle=500):
    """A binned curve whose moving means lie exactly on the piecewise-linear model."""
    cfg = ExtractionConfig()
    c = cfg.bin_centres_ma
    acc = np.zeros((N_ACCUMULATORS, cfg.n_bins))
    inside = np.abs(c) < 9.9
    acc[0, inside] = per_bin
    acc[1, inside] = per_bin * curve_def.velocity(c[inside])
    k0 = int(np.argmin(np.abs(c - curve_def.i0)))
    acc[0, k0] += idle  # idle samples at v = 0, current exactly on the bin centre
    acc[3, k0] = idle
    counters = np.zeros(len(COUNTER_NAMES), dtype=np.int64)
    counters[COUNTER_NAMES.index("n_used")] = int(acc[0].sum())
    return VelocityGainCurve(cfg, acc, counters)


@pytest.mark.parametrize("inb", [0.5, -1.3, 2.2])
def test_fit_recovers_an_exact_piecewise_linear_curve(inb):
    i0 = np.round((inb + 0.025) / 0.05) * 0.05 - 0.025  # the nearest bin centre
    truth = DualGainCurve(inb_ma=inb, idle_offset_ma=float(i0 - inb))
    curve = exact_curve(truth)
    fit = fit_curve(curve)
    assert fit.x1_ma == pytest.approx(truth.x1, abs=1e-5)
    assert fit.x2_ma == pytest.approx(truth.x2, abs=1e-5)
    for s_fit, s_true in ((fit.s_in_ma, truth.s_in), (fit.s_out_ma, truth.s_out)):
        if abs(s_true) < 9.9:  # the saturation is inside the data
            assert s_fit == pytest.approx(s_true, abs=1e-5)
        else:  # no saturation in the data: the breakpoint stays at or beyond the data end
            assert abs(s_fit) >= 9.85
    for got, want in ((fit.g_in, truth.g_in), (fit.g_null, truth.g_null),
                      (fit.g_out, truth.g_out)):
        assert got == pytest.approx(want, rel=1e-6)
    assert fit.rms_residual_mm_s < 1e-4
    for (lo, hi), x in ((fit.x1_interval_ma, truth.x1), (fit.x2_interval_ma, truth.x2)):
        assert lo - 1e-5 <= x <= hi + 1e-5 and hi - lo < 0.02  # a sharp optimum
    result = indicators_from_curve(curve)
    assert result.all_valid
    assert result.values["Inb"] == 0.5 * (result.values["X1"] + result.values["X2"])
    assert result.values["Y1"] == pytest.approx(truth.y1, abs=1e-4)
    assert result.values["Y2"] == pytest.approx(truth.y2, abs=1e-4)
    assert result.values["I0"] == pytest.approx(curve.bin_centres_ma[
        int(np.argmax(curve.idle_count))], abs=1e-12)
    assert result.values["Hys0"] == 0.0


# ----------------------------------------------------------------------------- robustness
def test_valid_indicators_are_never_far_off_on_random_partial_flights():
    """Random curves, partial current ranges, idle spreads, hysteresis, rates, saturation
    events: whatever is flagged valid must be close to the truth (generous bounds: the point
    is "no silent wrong number", not precision)."""
    rng = np.random.default_rng(2024)
    n_valid = 0
    for trial in range(10):
        g_null = rng.uniform(3, 8)
        curve = DualGainCurve(inb_ma=rng.uniform(-1.5, 2.0),
                              null_halfwidth_ma=rng.uniform(1.2, 2.8),
                              idle_offset_ma=rng.uniform(-0.4, 0.4), g_null=g_null,
                              g_in=g_null * rng.uniform(1.3, 2.5),
                              g_out=g_null * rng.uniform(1.3, 2.5))
        lo = min(rng.uniform(-9.8, 0.0), curve.i0 - 1.05)
        hi = max(rng.uniform(1.5, 9.8), curve.i0 + 1.05)
        rate = float(rng.choice([50.0, 100.0, 200.0]))
        f = synthetic_flight(curve, n_excursions=int(rng.integers(60, 300)),
                             peak_range_ma=(lo, hi), idle_current_std_ma=rng.uniform(0.01, 0.3),
                             hysteresis_ma=rng.uniform(0.0, 0.25), rate_hz=rate,
                             saturation_events=int(rng.integers(0, 5)), seed=trial)
        r = extract_indicators(f.time_s, f.current_ma, f.position_mm,
                               ExtractionConfig.for_frame_rate(rate))
        for name, bound in (("X1", 0.3), ("X2", 0.3), ("Inb", 0.3), ("Y1", 3.0), ("Y2", 3.0),
                            ("I0", 0.02)):
            if r.valid[name]:
                n_valid += 1
                assert abs(r.values[name] - f.truth[name]) < bound, (trial, name)
        for name in ("G_in", "G_null", "G_out"):
            if r.valid[name]:
                n_valid += 1
                assert r.values[name] == pytest.approx(f.truth[name], rel=0.15), (trial, name)
    assert n_valid > 40  # the check is not vacuous
