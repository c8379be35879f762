"""Benchmarks of the long pipelines (run separately; not unit tests).

    pytest tests/bench_pipeline.py -m benchmark -p no:cacheprovider -s

* ``test_itl_default_design``: the default ``fuelhm-bench itl`` work - design of experiments
  (8 units x 29 flights of 15 min), healthy fleet (8 x 5 flights), 70 laws, signature matrix
  (target <= 60 s on the 2-core machine);
* ``test_paper_study``: the paper study (``run_paper``) on paper_2012 as shipped, in this process, on every
  CPU available (target of the whole command, start-up and outputs included, <= 30 s: measured by
  ``tests/bench_leaderboard.py::test_paper_end_to_end``).
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
