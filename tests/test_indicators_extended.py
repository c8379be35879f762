"""Extended indicators: definitions on curves with known answers, streaming == batch, fixed memory."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.indicators import (
    STREAMING_STATE_BUDGET_BYTES,
    ExtractionConfig,
    StreamingExtractor,
    VelocityGainCurve,
    extract_indicators,
    extract_table,
    indicators_from_curve,
    velocity_gain_curve,
)
from fuelhm_bench.indicators.config import BAND_CELL_BINS, N_ACCUMULATORS, N_BAND_ACCUMULATORS
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


def two_pressure_flight(*, std_lo=0.06, std_hi=0.02, i0_shift=0.12, n2=(62.0, 88.0), seed=0):
    """Two synthetic halves joined in time: N2 = n2[0] % then n2[1] %, each with its own idle spread
    and the second with its idle current moved by ``i0_shift`` mA."""
    base = DualGainCurve()
    f1 = synthetic_flight(base, n_excursions=120, idle_current_std_ma=std_lo, hysteresis_ma=0.0, seed=seed)
    f2 = synthetic_flight(DualGainCurve(idle_offset_ma=base.idle_offset_ma + i0_shift), n_excursions=120,
                          idle_current_std_ma=std_hi, hysteresis_ma=0.0, seed=seed + 1)
    dt = f1.time_s[1] - f1.time_s[0]
    t = np.concatenate([f1.time_s, f2.time_s + f1.time_s[-1] + dt])
    i = np.concatenate([f1.current_ma, f2.current_ma])
    x = np.concatenate([f1.position_mm, f2.position_mm])
    n2_pct = np.concatenate([np.full(f1.time_s.size, n2[0]), np.full(f2.time_s.size, n2[1])])
    return t, i, x, n2_pct


def test_pressure_band_definitions_on_a_built_curve():
    cfg = ExtractionConfig()
    k0 = int(np.argmin(np.abs(cfg.bin_centres_ma - 0.3)))
    acc = np.zeros((N_ACCUMULATORS, cfg.n_bins))
    acc[0, k0] = acc[3, k0] = 300.0          # 300 idle samples, all at the bin centre on average
    band = np.zeros((N_BAND_ACCUMULATORS, cfg.n_band_cells))
    j = k0 // BAND_CELL_BINS
    c = cfg.band_cell_centres_ma[j]
    # Low band: 100 samples at c + 0.1 +/- 0.05 mA, N2 60 %; high band: 200 at c + 0.2 +/- 0.02, N2 90 %.
    band[0:4, j] = (100, 100 * 0.1, 100 * (0.1 ** 2 + 0.05 ** 2), 100 * 60.0)
    band[4:8, j] = (200, 200 * 0.2, 200 * (0.2 ** 2 + 0.02 ** 2), 200 * 90.0)
    counters = np.zeros(len(COUNTER_NAMES), dtype=np.int64)
    r = indicators_from_curve(VelocityGainCurve(cfg, acc, counters, band_accumulators=band))
    ext, ok = r.extended_values, r.extended_valid
    assert ok["Hys_lo"] and ext["Hys_lo"] == pytest.approx(0.05)
    assert ok["Hys_hi"] and ext["Hys_hi"] == pytest.approx(0.02)
    assert ok["I0_slope"] and ext["I0_slope"] == pytest.approx(0.1 / 30.0)
    # Too few samples in the low band: Hys_lo and the slope are invalid, with a reason.
    band[0, j] = cfg.min_idle_points - 1
    r = indicators_from_curve(VelocityGainCurve(cfg, acc, counters, band_accumulators=band))
    assert not r.extended_valid["Hys_lo"] and not r.extended_valid["I0_slope"]
    assert r.extended_valid["Hys_hi"]
    assert any(s.startswith("Hys_lo: 49 idle samples with N2 < 70 %") for s in r.extended_reasons)
    # Bands too close in N2: no slope.
    band[0, j] = 100
    band[3, j] = 100 * 88.0
    r = indicators_from_curve(VelocityGainCurve(cfg, acc, counters, band_accumulators=band))
    assert r.extended_valid["Hys_lo"] and not r.extended_valid["I0_slope"]
    assert any(s.startswith("I0_slope: the bands' mean N2 differ by 2 %") for s in r.extended_reasons)


def test_pressure_band_indicators_recover_known_spreads_and_slope():
    t, i, x, n2 = two_pressure_flight()
    r = extract_indicators(t, i, x, n2_pct=n2)
    ext, ok = r.extended_values, r.extended_valid
    assert ok["Hys_lo"] and ok["Hys_hi"] and ok["I0_slope"], r.extended_reasons
    assert ext["Hys_lo"] == pytest.approx(0.06, rel=0.15)
    assert ext["Hys_hi"] == pytest.approx(0.02, rel=0.15)
    assert ext["I0_slope"] == pytest.approx(0.12 / 26.0, rel=0.15)
    # Without N2 (or N2 between the bands) the three are invalid and say why.
    for missing in (None, np.full(t.size, 75.0), np.full(t.size, np.nan)):
        r = extract_indicators(t, i, x, n2_pct=missing)
        assert not any(r.extended_valid[n] for n in ("Hys_lo", "Hys_hi", "I0_slope"))
        assert any("N2 not recorded" in s for s in r.extended_reasons)
        assert r.extended_valid["Idle_frac"]


def test_n2_input_is_checked():
    t, i, x, n2 = two_pressure_flight()
    with pytest.raises(DataFormatError, match="'n2_pct' must have one value per sample"):
        extract_indicators(t, i, x, n2_pct=n2[:-1])
    bad = n2.copy()
    bad[7] = np.inf
    with pytest.raises(DataFormatError, match="'n2_pct' contains an infinite value .* sample 7"):
        extract_indicators(t, i, x, n2_pct=bad)
    ex = StreamingExtractor()
    with pytest.raises(DataFormatError, match="'n2_pct' must have one value per sample"):
        ex.update(t[:10], i[:10], x[:10], n2[:9])
    assert ex.n_samples == 0


def test_streaming_equals_batch_bit_for_bit_within_the_memory_budget():
    t, i, x, n2 = two_pressure_flight(seed=4)
    batch = {e: velocity_gain_curve(t, i, x, engine=e, n2_pct=n2) for e in ("numpy", "numba")}
    assert np.array_equal(batch["numpy"].band_accumulators, batch["numba"].band_accumulators)
    assert batch["numba"].band_accumulators[0].sum() > 0 and batch["numba"].band_accumulators[4].sum() > 0
    ref = indicators_from_curve(batch["numpy"])
    for sizes in (1000, 7, 1, 100000):
        ex = StreamingExtractor(flight_id=1)
        stop = len(t) if sizes > 1 else 3000   # one sample at a time: a prefix is enough
        for s in range(0, stop, sizes):
            ex.update(t[s:s + sizes], i[s:s + sizes], x[s:s + sizes], n2[s:s + sizes])
        if sizes == 1:
            pre = velocity_gain_curve(t[:stop], i[:stop], x[:stop], engine="numpy", n2_pct=n2[:stop])
            assert np.array_equal(ex.curve().band_accumulators, pre.band_accumulators)
            continue
        assert np.array_equal(ex.curve().band_accumulators, batch["numpy"].band_accumulators)
        got = ex.result()
        assert got.extended_valid == ref.extended_valid
        for name in EXTENDED_INDICATOR_NAMES:
            a, b = got.extended_values[name], ref.extended_values[name]
            assert (a == b) or (math.isnan(a) and math.isnan(b)), name
        cfg = ExtractionConfig()
        # Paper curve (7 rows per bin) + band cells (8 rows per 10 bins) + ring (4 x 2h) + scalars.
        assert ex.state_nbytes == (7 * cfg.n_bins + 8 * cfg.n_band_cells) * 8 + 64 * cfg.diff_half_width + 88
        assert ex.state_nbytes == cfg.streaming_state_nbytes <= STREAMING_STATE_BUDGET_BYTES
    assert sum(ref.extended_valid.values()) >= 9


def test_table_carries_extended_columns_with_flags():
    f = synthetic_flight(n_excursions=60, seed=3)
    t = extract_table([f])
    for name in EXTENDED_INDICATOR_NAMES:
        assert t[name].dtype == np.float64 and t[f"{name}_valid"].dtype == bool
        assert t[f"{name}_valid"].iloc[0] == np.isfinite(t[name].iloc[0])


def test_table_reads_n2_from_an_attribute_or_the_extras():
    from fuelhm_bench.io import FlightArrays

    t, i, x, n2 = two_pressure_flight(seed=6)
    direct = extract_indicators(t, i, x, n2_pct=n2)
    table = extract_table([FlightArrays(1, None, t, i, x, extras={"n2_pct": n2})])
    for name in ("Hys_lo", "Hys_hi", "I0_slope"):
        assert table[f"{name}_valid"].iloc[0] and table[name].iloc[0] == direct.extended_values[name]
