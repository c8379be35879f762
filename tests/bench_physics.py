"""Benchmarks of the simulator (run separately; not part of the unit tests).

    pytest tests/bench_physics.py -m benchmark -p no:cacheprovider

Reports, in ``extra_info`` and on stdout:

* ``real_time_factor``: simulated flight-seconds per wall-second on one core
  (and ``real_time_factor_cpu``, per CPU-second of this process, which a busy
  shared machine disturbs less than the wall clock),
  for a batch of 8 one-hour flights of 8 manufactured units through
  :func:`fuelhm_bench.physics.simulate.simulate` (noise generation and packing
  included; velocity tables built in the warm-up round, as they are when units
  fly several flights);
* ``speed_ratio_fast_over_reference``: wall time of the reference path over the
  fast path on the same 3-second segment, measured in the same run.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.physics.model import LoopModel, manufacture
from fuelhm_bench.physics.reference import simulate_reference
from fuelhm_bench.physics.simulate import FlightInputs, simulate


@pytest.mark.benchmark(group="physics")
def test_fast_path_real_time_factor(benchmark):
    n = 8
    mission = MissionProfile(duration_s=3600.0)
    inputs = [mission.sample(np.random.default_rng(s)) for s in range(n)]
    units = [manufacture(LoopModel(), np.random.default_rng(100 + s)) for s in range(n)]

    def run():
        return simulate(units, inputs, [np.random.default_rng(s) for s in range(n)])

    run()  # compile and build the velocity tables
    cpu = []
    for _ in range(5):
        t0 = time.process_time()
        run()
        cpu.append(time.process_time() - t0)
    benchmark.pedantic(run, rounds=5, iterations=1)
    rtf = n * mission.duration_s / benchmark.stats.stats.min
    benchmark.extra_info["real_time_factor"] = rtf
    benchmark.extra_info["real_time_factor_cpu"] = n * mission.duration_s / min(cpu)
    benchmark.extra_info["ms_per_flight_hour"] = 1e3 * benchmark.stats.stats.min / n
    print(f"\nfast path: {rtf:,.0f}x real time on one core "
          f"({1e3 * benchmark.stats.stats.min / n:.1f} ms per one-hour flight); "
          f"{n * mission.duration_s / min(cpu):,.0f}x per CPU-second")


@pytest.mark.benchmark(group="physics")
def test_fast_vs_reference_speed_ratio(benchmark):
    model = LoopModel()
    d = np.concatenate([np.full(50, 0.030), np.full(150, 0.045), np.linspace(0.045, 0.020, 100)])
    inp = FlightInputs(d, np.full(d.size, 0.82), 0.01)
    simulate([model], [inp], [np.random.default_rng(0)])
    t0 = time.perf_counter()
    simulate_reference(model, inp, np.random.default_rng(0))
    t_ref = time.perf_counter() - t0
    benchmark.pedantic(lambda: simulate([model], [inp], [np.random.default_rng(0)]), rounds=20, iterations=1)
    ratio = t_ref / benchmark.stats.stats.min
    benchmark.extra_info["reference_s"] = t_ref
    benchmark.extra_info["speed_ratio_fast_over_reference"] = ratio
    print(f"\nreference {t_ref:.2f} s vs fast {1e3 * benchmark.stats.stats.min:.2f} ms on the same 3 s: {ratio:,.0f}x")
