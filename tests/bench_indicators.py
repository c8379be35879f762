"""Throughput of indicator extraction (pytest-benchmark).

Run separately::

    pytest tests/bench_indicators.py --benchmark-only -m benchmark -p no:cacheprovider

Each benchmark processes one 10-million-sample flight (about 28 hours at 100 Hz: a synthetic
flight of about 1 million samples repeated with shifted time stamps) and records
``samples_per_s`` in the benchmark's ``extra_info`` (shown with ``--benchmark-verbose`` /
saved with ``--benchmark-json``) and prints it. The on-board target is >= 20 million samples
per second per core for the streaming extractor.
"""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.indicators import StreamingExtractor, extract_indicators
from fuelhm_bench.testing.indicators import synthetic_flight

N_SAMPLES = 10_000_000
CHUNK = 65_536


@pytest.fixture(scope="module")
def big_flight():
    base = synthetic_flight(n_excursions=4600, seed=99)  # ~1.0 million samples
    repeat = -(-N_SAMPLES // len(base.time_s))
    period = base.time_s[-1] + 0.01
    t = np.concatenate([base.time_s + k * period for k in range(repeat)])[:N_SAMPLES]
    i = np.tile(base.current_ma, repeat)[:N_SAMPLES]
    x = np.tile(base.position_mm, repeat)[:N_SAMPLES]
    # Compile (or load from cache) the kernels outside the timed region.
    warm = StreamingExtractor()
    warm.update(t[:10_000], i[:10_000], x[:10_000])
    warm.result()
    extract_indicators(t[:10_000], i[:10_000], x[:10_000])
    return t, i, x


def _report(benchmark, n_samples: int, label: str) -> float:
    rate = n_samples / benchmark.stats.stats.mean
    benchmark.extra_info["n_samples"] = n_samples
    benchmark.extra_info["samples_per_s"] = rate
    print(f"\n{label}: {n_samples} samples, {rate / 1e6:.1f} million samples/s")
    return rate


@pytest.mark.benchmark(group="indicators")
def test_streaming_throughput_chunked(benchmark, big_flight):
    t, i, x = big_flight
    n = len(t)

    def run():
        ex = StreamingExtractor()
        for s in range(0, n, CHUNK):
            ex.update(t[s:s + CHUNK], i[s:s + CHUNK], x[s:s + CHUNK])
        return ex.result()

    result = benchmark.pedantic(run, rounds=5, iterations=1, warmup_rounds=1)
    assert result.all_valid, result.reasons
    _report(benchmark, n, f"streaming, chunks of {CHUNK}")


@pytest.mark.benchmark(group="indicators")
def test_streaming_throughput_one_call(benchmark, big_flight):
    t, i, x = big_flight

    def run():
        ex = StreamingExtractor()
        ex.update(t, i, x)
        return ex.result()

    result = benchmark.pedantic(run, rounds=5, iterations=1, warmup_rounds=1)
    assert result.all_valid, result.reasons
    _report(benchmark, len(t), "streaming, one update")


@pytest.mark.benchmark(group="indicators")
@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_batch_throughput(benchmark, big_flight, engine):
    t, i, x = big_flight
    result = benchmark.pedantic(extract_indicators, args=(t, i, x), kwargs={"engine": engine},
                                rounds=3, iterations=1, warmup_rounds=0)
    assert result.all_valid, result.reasons
    _report(benchmark, len(t), f"batch, engine={engine}")
