"""Streaming extractor: agreement with batch, chunk-size invariance, fixed memory.

Agreement contract: the streaming extractor and both batch engines produce the same binned
sums (they evaluate the same formulas in the same floating-point order and add to the bins in
sample order), and share the curve -> indicator step, so their indicators agree to float
precision. We assert ``rtol=1e-12`` (in practice the sums are bit-identical).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fuelhm_bench.errors import DataFormatError, ParameterError
from fuelhm_bench.indicators import (
    STREAMING_STATE_BUDGET_BYTES,
    ExtractionConfig,
    StreamingExtractor,
    extract_indicators,
    indicators_from_curve,
    velocity_gain_curve,
)
from fuelhm_bench.testing.indicators import synthetic_flight
from fuelhm_bench.taxonomy import INDICATOR_NAMES

RTOL = 1e-12


@pytest.fixture(scope="module")
def flight():
    return synthetic_flight(n_excursions=200, saturation_events=10, seed=21)


@pytest.fixture(scope="module")
def short_flight():
    return synthetic_flight(n_excursions=40, saturation_events=2, seed=22)


def feed(extractor, f, sizes):
    """Feed a flight in consecutive chunks of the given sizes (cycled)."""
    n = len(f.time_s)
    start, k = 0, 0
    while start < n:
        stop = min(n, start + sizes[k % len(sizes)])
        extractor.update(f.time_s[start:stop], f.current_ma[start:stop],
                         f.position_mm[start:stop])
        start, k = stop, k + 1
    return extractor


def assert_same_values(a, b, rtol=RTOL):
    for name in INDICATOR_NAMES:
        assert a.valid[name] == b.valid[name], name
        if a.valid[name]:
            assert a.values[name] == pytest.approx(b.values[name], rel=rtol, abs=1e-12), name
        else:
            assert math.isnan(a.values[name]) and math.isnan(b.values[name])
    assert a.n_points == b.n_points
    assert a.reasons == b.reasons


def test_streaming_equals_both_batch_engines(flight):
    stream = feed(StreamingExtractor(flight_id=1), flight, [4096])
    curves = {
        "stream": stream.curve(),
        "numba": velocity_gain_curve(flight.time_s, flight.current_ma, flight.position_mm),
        "numpy": velocity_gain_curve(flight.time_s, flight.current_ma, flight.position_mm,
                                     engine="numpy"),
    }
    ref = curves["numpy"]
    for name, curve in curves.items():
        np.testing.assert_allclose(curve.accumulators, ref.accumulators, rtol=RTOL, atol=0,
                                   err_msg=name)
        np.testing.assert_array_equal(curve.counters, ref.counters, err_msg=name)
    # The masks were exercised (end stops, current limit), not only the easy path.
    assert ref.counter("n_end_stop") > 0 and ref.counter("n_current_limit") > 0
    batch = extract_indicators(flight.time_s, flight.current_ma, flight.position_mm,
                               engine="numpy")
    assert batch.all_valid
    assert_same_values(stream.result(), batch)
    assert_same_values(indicators_from_curve(curves["numba"]), batch)


@pytest.mark.parametrize("sizes", [[1], [2, 3], [5], [7, 1, 13], [999], [10**9]])
def test_chunk_size_invariance(short_flight, sizes):
    reference = feed(StreamingExtractor(), short_flight, [10**9])
    other = feed(StreamingExtractor(), short_flight, sizes)
    np.testing.assert_allclose(other.curve().accumulators, reference.curve().accumulators,
                               rtol=RTOL, atol=0)
    np.testing.assert_array_equal(other.curve().counters, reference.curve().counters)
    assert_same_values(other.result(), reference.result())


def test_random_chunk_sizes_with_empty_chunks(short_flight):
    rng = np.random.default_rng(5)
    sizes = rng.integers(0, 300, size=500).tolist()
    sizes[0] = 0
    reference = feed(StreamingExtractor(), short_flight, [10**9])
    other = feed(StreamingExtractor(), short_flight, sizes + [1])
    assert_same_values(other.result(), reference.result())


def test_scalar_samples_are_accepted(short_flight):
    ex = StreamingExtractor()
    for k in range(2000):
        ex.update(short_flight.time_s[k], short_flight.current_ma[k],
                  short_flight.position_mm[k])
    ref = feed(StreamingExtractor(), short_flight, [2000])
    ref_curve = velocity_gain_curve(short_flight.time_s[:2000], short_flight.current_ma[:2000],
                                    short_flight.position_mm[:2000])
    np.testing.assert_allclose(ex.curve().accumulators, ref_curve.accumulators, rtol=RTOL)
    assert ex.n_samples == 2000
    assert ref.n_samples == len(short_flight.time_s)


def test_state_is_small_and_does_not_grow(flight):
    ex = StreamingExtractor()
    size0 = ex.state_nbytes
    assert size0 == ExtractionConfig().streaming_state_nbytes
    assert size0 <= STREAMING_STATE_BUDGET_BYTES
    arrays0 = {k: v.shape for k, v in vars(ex).items() if isinstance(v, np.ndarray)}
    for repeat in range(3):  # three flights' worth of samples, time shifted
        shift = repeat * (flight.time_s[-1] + 1.0)
        ex.update(flight.time_s + shift, flight.current_ma, flight.position_mm)
        assert ex.state_nbytes == size0
        assert {k: v.shape for k, v in vars(ex).items() if isinstance(v, np.ndarray)} == arrays0
    assert ex.n_samples == 3 * len(flight.time_s)
    # The result is built on demand and is not kept in the state.
    ex.result()
    assert ex.state_nbytes == size0


def test_state_budget_is_enforced_by_the_config():
    with pytest.raises(ParameterError, match="bin_width_ma.*ExtractionConfig"):
        ExtractionConfig(bin_width_ma=0.02)  # 1200 bins * 7 * 8 B > 64 KiB
    big = ExtractionConfig(bin_width_ma=0.025)  # 960 bins: 52.7 KiB, allowed
    assert StreamingExtractor(big).state_nbytes <= STREAMING_STATE_BUDGET_BYTES


def test_result_does_not_consume_state(short_flight):
    n = len(short_flight.time_s)
    half = n // 2
    ex = StreamingExtractor()
    ex.update(short_flight.time_s[:half], short_flight.current_ma[:half],
              short_flight.position_mm[:half])
    partial = ex.result()
    ex.update(short_flight.time_s[half:], short_flight.current_ma[half:],
              short_flight.position_mm[half:])
    whole = feed(StreamingExtractor(), short_flight, [n])
    assert_same_values(ex.result(), whole.result())
    assert partial.n_points < whole.result().n_points


def test_reset_starts_a_new_flight(short_flight, flight):
    ex = feed(StreamingExtractor(), flight, [10**9])
    ex.reset()
    assert ex.n_samples == 0
    feed(ex, short_flight, [333])
    assert_same_values(ex.result(), feed(StreamingExtractor(), short_flight, [10**9]).result())


def test_bad_chunk_leaves_state_unchanged(short_flight):
    f = short_flight
    ex = StreamingExtractor(flight_id="F7")
    ex.update(f.time_s[:1000], f.current_ma[:1000], f.position_mm[:1000])
    before = ex.curve().accumulators.copy()
    bad = f.position_mm[1000:2000].copy()
    bad[500] = np.nan
    with pytest.raises(DataFormatError, match=r"flight 'F7'.*position_mm.*sample 1500"):
        ex.update(f.time_s[1000:2000], f.current_ma[1000:2000], bad)
    np.testing.assert_array_equal(ex.curve().accumulators, before)
    assert ex.n_samples == 1000
    # Time going back across the chunk boundary.
    with pytest.raises(DataFormatError, match=r"flight 'F7'.*strictly increasing.*sample 1000"):
        ex.update(f.time_s[900:950], f.current_ma[900:950], f.position_mm[900:950])
    # Recovery: the good chunk is accepted afterwards.
    ex.update(f.time_s[1000:], f.current_ma[1000:], f.position_mm[1000:])
    assert_same_values(ex.result(), feed(StreamingExtractor(), f, [10**9]).result())


def test_streaming_rejects_observed_limits():
    with pytest.raises(ParameterError, match="'stroke_limits_mm' parameter of StreamingExtractor"):
        StreamingExtractor(ExtractionConfig(stroke_limits_mm=None))
    with pytest.raises(ParameterError, match="'current_limits_ma' parameter of Streaming"):
        StreamingExtractor(ExtractionConfig(current_limits_ma=None))
    with pytest.raises(ParameterError, match="'config' parameter of StreamingExtractor"):
        StreamingExtractor({"bin_width_ma": 0.1})


def test_streaming_end_of_flight_checks():
    ex = StreamingExtractor(flight_id=3)
    ex.update([0.0, 0.01, 0.02], [1.0, 1.1, 1.2], [30.0, 30.0, 30.0])
    with pytest.raises(DataFormatError, match="flight 3: 3 sample.*at least 5"):
        ex.result()
    ex.update([0.03, 0.04], [1.3, 1.4], [30.0, 30.0])
    assert ex.result().n_points == 1
    const = StreamingExtractor(flight_id=4)
    const.update(np.arange(100) * 0.01, np.full(100, 0.7), np.full(100, 30.0))
    with pytest.raises(DataFormatError, match="flight 4: 'current_ma' is constant"):
        const.result()


@pytest.mark.parametrize("seed", [3, 4])
def test_window_masks_at_chunk_edges_agree_with_the_numpy_engine(seed):
    """Gaps, end stops and current limits right at chunk edges: the compiled kernel tracks the
    last sample that trips each mask as it enters the window; the vectorised numpy engine tests
    every window whole. Both, and streaming in chunks cut next to the trips, give the same sums."""
    f = synthetic_flight(n_excursions=60, saturation_events=4, seed=20 + seed)
    rng = np.random.default_rng(seed)
    n = len(f.time_s)
    t = f.time_s.copy()
    holes = np.sort(rng.choice(np.arange(10, n - 10), size=12, replace=False))
    for k in holes:  # a hole before sample k (0.05 to 1 s): 2h windows see it
        t[k:] += rng.uniform(0.05, 1.0)
    flight = (t, f.current_ma, f.position_mm)
    numpy_curve = velocity_gain_curve(*flight, engine="numpy")
    numba_curve = velocity_gain_curve(*flight)
    np.testing.assert_array_equal(numba_curve.counters, numpy_curve.counters)
    np.testing.assert_array_equal(numba_curve.accumulators, numpy_curve.accumulators)
    for name in ("n_gap", "n_end_stop", "n_current_limit"):
        assert numpy_curve.counter(name) > 0, name
    # Chunks cut at, just before and just after each hole and at random places.
    cuts = sorted({0, n, *holes.tolist(), *(holes - 1).tolist(), *(holes + 2).tolist(),
                   *rng.integers(1, n, 40).tolist()})
    stream = StreamingExtractor()
    for a, b in zip(cuts[:-1], cuts[1:]):
        stream.update(t[a:b], f.current_ma[a:b], f.position_mm[a:b])
    np.testing.assert_array_equal(stream.curve().counters, numpy_curve.counters)
    np.testing.assert_allclose(stream.curve().accumulators, numpy_curve.accumulators, rtol=RTOL, atol=0)
