"""Wall time of the discrepancy workflow on 20 flights of 20 minutes (pytest-benchmark).

Run separately::

    pytest tests/bench_discrepancy.py --benchmark-only -m benchmark -p no:cacheprovider -s

The data set: 4 units x 5 flights of 20 min at 100 Hz (2.4 million samples) with
``rod_friction`` hidden (the slowest candidate to fit: the simulator solves the rod force
balance at every frame for it), written to Parquet and read back as the command would.
The timed region is the whole workflow (split, recalibration, five candidates on two worker
processes, decision, held-out evaluation, region maps), one round. Target: <= 120 s on the
2-core development machine. The measured figures are printed and stored in ``extra_info``.
"""

from __future__ import annotations

import os
import resource
import time

import pytest

from fuelhm_bench.calibration.discrepancy import DiscrepancyConfig, find_discrepancy
from fuelhm_bench.calibration.synthetic import hidden_effect_flights
from fuelhm_bench.io import read_flights, split_flights, write_flights

TARGET_S = 120.0
#: Issue 14: 12 flights x 20 min of data from the second simulator, whole v2 workflow (flags, held
#: refits, forward selection, probe), at most 60 s on 2 cores.
TARGET_ALT_S = 60.0


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    frame, case = hidden_effect_flights("rod_friction", n_units=4, n_flights=5, minutes=20.0, seed=3)
    path = write_flights(frame, tmp_path_factory.mktemp("bench") / "measured.parquet")
    flights, rejected = split_flights(read_flights(path), source=str(path))
    assert len(flights) == 20 and not rejected
    # Compile (or load from cache) the kernels outside the timed region.
    find_discrepancy(flights[:2], config=DiscrepancyConfig(candidates=("lvdt_lag",), n_jobs=1))
    return flights, case


@pytest.mark.benchmark
def test_discrepancy_on_20_flights_of_20_minutes(benchmark, fleet):
    flights, case = fleet
    config = DiscrepancyConfig(n_jobs=2)
    t0 = time.perf_counter()
    result = benchmark.pedantic(find_discrepancy, args=(flights,), kwargs={"config": config}, rounds=1,
                                iterations=1)
    seconds = time.perf_counter() - t0
    benchmark.extra_info.update({"seconds": seconds, "effect": result.effect, "gap_before": result.gap_before,
                                 "gap_after": result.gap_after, "target_s": TARGET_S})
    print(f"\ndiscrepancy workflow, 20 flights x 20 min: {seconds:.1f} s (target {TARGET_S:g} s); named "
          f"{result.effect} (hidden {case.effect}, coulomb {case.parameters['coulomb_n']:.0f} N -> "
          f"{result.parameters.get('coulomb_n', float('nan')):.0f} N); held-out gap {result.gap_before:.3f} -> "
          f"{result.gap_recalibrated:.3f} -> {result.gap_after:.3f} mm/s")
    for c in result.ranking:
        print(f"  {c.effect:18s} dBIC {c.delta_bic:10.1f}  held-out gap {c.gap_after:.3f} mm/s  "
              f"{c.passes} replays  {c.seconds:.1f} s")
    assert result.effect == "rod_friction"
    assert seconds <= TARGET_S


@pytest.fixture(scope="module")
def alt_fleet(tmp_path_factory):
    from fuelhm_bench.validation.altsim import AltEffects, simulate_flights

    frame = simulate_flights(AltEffects(coulomb_n=500.0), n_units=4, n_flights=3, minutes=20.0, seed=3)
    path = write_flights(frame, tmp_path_factory.mktemp("bench") / "alt.parquet")
    flights, rejected = split_flights(read_flights(path), source=str(path))
    assert len(flights) == 12 and not rejected
    find_discrepancy(flights[:2], config=DiscrepancyConfig(candidates=("lvdt_lag",), n_jobs=1))
    return flights


def _cpu_seconds() -> float:
    """CPU time of this process and of its waited-for children (the worker processes) [s]."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _timed_workflow(benchmark, flights, config):
    """One timed round of the workflow: (result, wall seconds, CPU seconds of this process and its workers,
    load average at the end)."""
    c0 = _cpu_seconds()
    t0 = time.perf_counter()
    result = benchmark.pedantic(find_discrepancy, args=(flights,), kwargs={"config": config}, rounds=1,
                                iterations=1)
    return result, time.perf_counter() - t0, _cpu_seconds() - c0, os.getloadavg()[0]


@pytest.mark.benchmark
def test_discrepancy_v2_on_12_altsim_flights_of_20_minutes(benchmark, alt_fleet):
    # On a shared machine the wall time measures the other users' load; the CPU time of the workflow
    # (this process + its two workers) over the two cores is what a quiet 2-core machine would take
    # at best, so both are reported and the target is checked on the CPU time / 2 as well as on the wall
    # time when the machine is quiet (load average below 2).
    result, seconds, cpu, load = _timed_workflow(benchmark, alt_fleet, DiscrepancyConfig(n_jobs=2))
    benchmark.extra_info.update({"seconds": seconds, "cpu_seconds": cpu, "load_average": load,
                                 "verdict": result.verdict, "target_s": TARGET_ALT_S,
                                 "set": [m.effect for m in result.effect_set]})
    print(f"\ndiscrepancy v2, 12 altsim flights x 20 min (rod friction 500 N): wall {seconds:.1f} s, CPU "
          f"{cpu:.1f} s (/2 cores = {cpu / 2:.1f} s) at load average {load:.1f} (target {TARGET_ALT_S:g} s); "
          f"verdict {result.verdict}, set {[m.effect for m in result.effect_set]}")
    for c in result.ranking:
        print(f"  {c.label:40s} dBIC {c.delta_bic:10.1f}  held-out gap {c.gap_after:.3f} mm/s  "
              f"{c.passes} replays  {c.seconds:.1f} s" + ("  (stopped early)" if c.stopped_early else ""))
    # Timing is what this benchmark measures; naming on altsim data is the study's (docs/discrepancy.md
    # section 10). It still must never be a confident wrong effect.
    assert result.verdict in ("effect", "none", "unexplained")
    assert result.verdict != "effect" or "rod_friction" in [m.effect for m in result.effect_set]
    assert cpu / 2 <= TARGET_ALT_S
    if load < 2.0:
        assert seconds <= TARGET_ALT_S


#: The study's slowest cases at the issue's size (docs/discrepancy.md section 10, fifteenth round):
#: the 2x lap (free then plausible rod-friction fits on the critical path) and rod friction 1x (the
#: case whose held-out data fell just under the score gate's old size limit: 67 s before the gate
#: was made consistent). Same data as ``python -m fuelhm_bench.validation.study --units 3 --flights 4
#: --minutes 20 --seed-offset 2000``.
STUDY_CASES = ("spool_overlap x2", "rod_friction x1")


@pytest.fixture(scope="module", params=STUDY_CASES)
def study_case(request):
    import dataclasses

    from fuelhm_bench.validation.altsim import simulate_flights
    from fuelhm_bench.validation.study import default_cases

    case = next(c for c in default_cases() if c.name == request.param)
    case = dataclasses.replace(case, seed=case.seed + 2000)
    frame = simulate_flights(case.effects, n_units=3, n_flights=4, minutes=20.0, seed=case.seed)
    flights, rejected = split_flights(frame)
    assert len(flights) == 12 and not rejected
    find_discrepancy(flights[:2], config=DiscrepancyConfig(candidates=("lvdt_lag",), n_jobs=1))
    return case, flights


@pytest.mark.benchmark
def test_discrepancy_v2_on_the_slowest_study_cases(benchmark, study_case):
    case, flights = study_case
    result, seconds, cpu, load = _timed_workflow(benchmark, flights, DiscrepancyConfig(n_jobs=2, seed=case.seed))
    benchmark.extra_info.update({"case": case.name, "seconds": seconds, "cpu_seconds": cpu, "load_average": load,
                                 "verdict": result.verdict, "set": [m.effect for m in result.effect_set]})
    print(f"\ndiscrepancy v2, study case {case.name} (3 x 4 x 20 min, seeds +2000): wall {seconds:.1f} s, CPU "
          f"{cpu:.1f} s (/2 cores = {cpu / 2:.1f} s) at load average {load:.1f} (target {TARGET_ALT_S:g} s); "
          f"verdict {result.verdict}, set {[m.effect for m in result.effect_set]}")
    assert result.verdict != "effect" or case.truth in [m.effect for m in result.effect_set]
    assert cpu / 2 <= TARGET_ALT_S
    if load < 2.0:
        assert seconds <= TARGET_ALT_S
