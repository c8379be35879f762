"""Benchmarks of the long pipelines (run separately; not unit tests).

    pytest tests/bench_pipeline.py -m benchmark -p no:cacheprovider -s

* ``test_itl_default_design``: the default ``fuelhm-bench itl`` work - design of experiments
  (8 units x 29 flights of 15 min), healthy fleet (8 x 5 flights), 70 laws, signature matrix
  (target <= 60 s on the 2-core machine);
* ``test_paper_study``: the paper study (``run_paper``) on paper_2012 as shipped, in this process, on every
  CPU available (target of the whole command, start-up and outputs included, <= 30 s: measured by
  ``tests/bench_leaderboard.py::test_paper_end_to_end``);
* ``test_cost_per_flight_hour``: the cost of simulated data, in CPU milliseconds per flight-hour, of 16 flights
  of paper_2012's scored fleet (25 min, degrading units) built in this process (``fleet_indicators``, one
  worker), with the share of each stage: drawing the inputs, simulating, extracting the indicators.
"""

from __future__ import annotations

import pytest

from fuelhm_bench.datasets.knowledge import KnowledgeBuild, build_knowledge


@pytest.mark.benchmark(group="pipeline")
def test_itl_default_design(benchmark):
    build = KnowledgeBuild()
    build_knowledge(KnowledgeBuild.from_scenario(None, doe_units=1, healthy_units=3, healthy_flights=4,
                                                 minutes=2.0))  # compile
    result = benchmark.pedantic(build_knowledge, args=(build,), rounds=1, iterations=1)
    assert len(result.itl.table) == 70 and result.signatures.shape == (7, 10)
    benchmark.extra_info["flights"] = build.n_flights
    print(f"\nITL design of experiments + healthy model + signatures: {benchmark.stats.stats.min:.1f} s "
          f"for {build.n_flights} flights")


@pytest.mark.benchmark(group="pipeline")
def test_paper_study(benchmark):
    from fuelhm_bench.benchmark.paper import run_paper

    result = benchmark.pedantic(run_paper, rounds=1, iterations=1)
    assert result.table_v.shape[0] == 5
    benchmark.extra_info.update(result.timings)
    print(f"\nfuelhm-bench paper (paper_2012 as shipped): {benchmark.stats.stats.min:.1f} s "
          f"(data {result.timings['data_s']:.1f} s, method and scoring {result.timings['method_and_scoring_s']:.1f} s)")


@pytest.mark.benchmark(group="pipeline")
def test_cost_per_flight_hour(benchmark):
    import dataclasses
    import time

    from fuelhm_bench.datasets.cache import resolve_scenario
    from fuelhm_bench.datasets.fleets import fleet_indicators
    from fuelhm_bench.flights import fleet as fleet_module
    from fuelhm_bench.flights import mission as mission_module
    from fuelhm_bench.indicators import extract_table

    sc = resolve_scenario("paper_2012")
    config = dataclasses.replace(sc.test_fleet_config(), n_units=2, n_flights=8)
    fleet_indicators(dataclasses.replace(config, n_units=1, n_flights=1, mission=dataclasses.replace(
        config.mission, duration_s=180.0)))  # compile or load the numba functions
    stages = {"inputs": 0.0, "simulate": 0.0, "extract": 0.0}

    def timed(name, fn):
        def wrapper(*args, **kwargs):
            start = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                stages[name] += time.process_time() - start
        return wrapper

    def build():
        cpu = time.process_time()
        table = fleet_indicators(config)[0]
        return table, time.process_time() - cpu

    import fuelhm_bench.indicators as indicators_module  # _fleet_part imports extract_table from it per call

    saved = (mission_module.MissionProfile.sample, fleet_module.simulate, indicators_module.extract_table)
    try:
        mission_module.MissionProfile.sample = timed("inputs", saved[0])
        fleet_module.simulate = timed("simulate", saved[1])
        indicators_module.extract_table = timed("extract", extract_table)
        table, cpu_s = benchmark.pedantic(build, rounds=1, iterations=1)
    finally:
        mission_module.MissionProfile.sample, fleet_module.simulate, indicators_module.extract_table = saved
    hours = config.n_units * config.n_flights * config.mission.duration_s / 3600.0
    assert len(table) == config.n_units * config.n_flights
    benchmark.extra_info.update({"cpu_ms_per_flight_hour": 1e3 * cpu_s / hours,
                                 **{f"{k}_ms_per_flight_hour": 1e3 * v / hours for k, v in stages.items()}})
    print(f"\nsimulated data: {1e3 * cpu_s / hours:.0f} ms CPU per flight-hour ("
          + ", ".join(f"{k} {1e3 * v / hours:.0f}" for k, v in stages.items()) + ")")
