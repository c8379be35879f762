"""Extended indicators: definitions on curves with known answers, streaming == batch, fixed memory."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fuelhm_bench.indicators import (
    ExtractionConfig,
    StreamingExtractor,
    VelocityGainCurve,
    extract_indicators,
    extract_table,
    indicators_from_curve,
)
from fuelhm_bench.indicators.config import N_ACCUMULATORS
from fuelhm_bench.indicators.curve import COUNTER_NAMES
from fuelhm_bench.indicators.extended import MIN_WINDOW_POINTS
from fuelhm_bench.testing.indicators import DualGainCurve, synthetic_flight
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, EXTENDED_INDICATOR_UNITS


def built_curve(cfg, entries):
    """A curve from explicit per-bin content: {bin index: (count, sum_v, sum_v2, idle_count)}."""
    acc = np.zeros((N_ACCUMULATORS, cfg.n_bins))
    for k, (n, sv, sv2, idle) in entries.items():
        acc[0, k], acc[1, k], acc[2, k], acc[3, k] = n, sv, sv2, idle
    counters = np.zeros(len(COUNTER_NAMES), dtype=np.int64)
    counters[COUNTER_NAMES.index("n_used")] = int(acc[0].sum())
    return VelocityGainCurve(config=cfg, accumulators=acc, counters=counters)


def test_definitions_on_a_built_curve():
    cfg = ExtractionConfig()
    k0 = int(np.argmin(np.abs(cfg.bin_centres_ma - 0.3)))
    i0 = float(cfg.bin_centres_ma[k0])
    k1 = k0 + 16          # I0 + 0.80 mA: in V_out1's window and in the null scatter window
    k3 = k0 - 60          # I0 - 3.00 mA: V_in3
    k7 = k0 + 140         # I0 + 7.00 mA: V_out7, with too few samples
    r = indicators_from_curve(built_curve(cfg, {
        k0: (100, 0.0, 0.0, 100),            # idle: v = 0
        k1: (30, 150.0, 750.0, 0),           # 30 moving samples at 5 mm/s
        k3: (25, -25 * 17.0, 25 * 289.0, 0),  # 25 at -17 mm/s
        k7: (MIN_WINDOW_POINTS - 1, 50.0, 200.0, 0),
    }))
    assert r.values["I0"] == pytest.approx(i0)
    ext, ok = r.extended_values, r.extended_valid
    assert ok["V_out1"] and ext["V_out1"] == pytest.approx(5.0)
    assert ok["V_in3"] and ext["V_in3"] == pytest.approx(-17.0)
    n = 130.0
    assert ok["Vsd_null"] and ext["Vsd_null"] == pytest.approx(math.sqrt(750.0 / n - (150.0 / n) ** 2))
    assert ok["Idle_frac"] and ext["Idle_frac"] == pytest.approx(100.0 / (100 + 30 + 25 + MIN_WINDOW_POINTS - 1))
    for name in ("V_in1", "V_out3", "V_in7", "V_out7"):
        assert not ok[name] and math.isnan(ext[name])
    assert any(s.startswith("V_out7: 19 moving samples") for s in r.extended_reasons)
    # Extended validity never enters the paper's quality_reason.
    assert "V_out7" not in r.quality_reason


def test_no_idle_current_invalidates_the_offsets():
    cfg = ExtractionConfig()
    r = indicators_from_curve(built_curve(cfg, {200: (500, 5000.0, 60000.0, 0)}))
    assert not r.valid["I0"]
    assert not any(r.extended_valid[n] for n in EXTENDED_INDICATOR_NAMES if n != "Idle_frac")
    assert r.extended_valid["Idle_frac"] and r.extended_values["Idle_frac"] == 0.0
    assert any("I0 is not valid" in s for s in r.extended_reasons)


def test_velocities_at_fixed_currents_follow_a_known_curve():
    curve = DualGainCurve()
    f = synthetic_flight(curve, n_excursions=300, peak_range_ma=(-9.0, 9.0), hysteresis_ma=0.0, seed=5)
    r = extract_indicators(f.time_s, f.current_ma, f.position_mm)
    i0 = r.values["I0"]
    assert i0 == pytest.approx(curve.i0, abs=0.05)
    for name, offset in (("V_in1", -1.0), ("V_out1", 1.0), ("V_in3", -3.0), ("V_out3", 3.0)):
        assert r.extended_valid[name], r.extended_reasons
        expected = float(curve.velocity(np.array([i0 + offset]))[0])
        assert r.extended_values[name] == pytest.approx(expected, rel=0.05, abs=0.3), name
    assert set(EXTENDED_INDICATOR_UNITS) == set(EXTENDED_INDICATOR_NAMES)


def test_streaming_equals_batch_bit_for_bit_and_memory_is_unchanged():
    f = synthetic_flight(n_excursions=150, peak_range_ma=(-9.0, 9.0), saturation_events=4, seed=8)
    batch = extract_indicators(f.time_s, f.current_ma, f.position_mm, engine="numpy")
    for sizes in (1000, 7, 100000):
        ex = StreamingExtractor(flight_id=1)
        for s in range(0, len(f.time_s), sizes):
            ex.update(f.time_s[s:s + sizes], f.current_ma[s:s + sizes], f.position_mm[s:s + sizes])
        got = ex.result()
        assert got.extended_valid == batch.extended_valid
        for name in EXTENDED_INDICATOR_NAMES:
            a, b = got.extended_values[name], batch.extended_values[name]
            assert (a == b) or (math.isnan(a) and math.isnan(b)), name
        cfg = ExtractionConfig()
        # The extended indicators read the curve's sums: the state is the paper extractor's, unchanged.
        assert ex.state_nbytes == 7 * 8 * cfg.n_bins + 48 * cfg.diff_half_width + 88
    assert sum(batch.extended_valid.values()) >= 6


def test_table_carries_extended_columns_with_flags():
    f = synthetic_flight(n_excursions=60, seed=3)
    t = extract_table([f])
    for name in EXTENDED_INDICATOR_NAMES:
        assert t[name].dtype == np.float64 and t[f"{name}_valid"].dtype == bool
        assert t[f"{name}_valid"].iloc[0] == np.isfinite(t[name].iloc[0])
