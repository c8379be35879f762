"""Benchmarks of the leaderboard and the paper study (run separately; not unit tests).

    pytest tests/bench_leaderboard.py -m benchmark -p no:cacheprovider -s

Targets (issue 10 §6, 2-core machine):

* ``test_default_leaderboard_cold_jobs2``: ``fuelhm-bench leaderboard`` on ``leaderboard/methods.yaml``
  (6 entries x 7 scenarios, physics), cold simulation cache, ``--jobs 2``: <= 180 s;
* ``test_rerun_with_everything_stored``: the same command again (every key in the store): <= 10 s;
* ``test_parallel_efficiency``: two scenarios of the default file, cold caches, 1 worker against
  2 workers measured side by side: efficiency T1 / (2 T2) >= 0.8;
* ``test_paper_end_to_end``: ``fuelhm-bench paper`` with a cold cache: <= 30 s.

Every cold run uses its own empty cache directory (``--cache-dir``) and output folder.
"""

from __future__ import annotations

import time

import pytest

from fuelhm_bench.cli import main

pytestmark = pytest.mark.benchmark


def _leaderboard(out, cache, *extra):
    t0 = time.perf_counter()
    assert main(["leaderboard", "--config", "leaderboard/methods.yaml", "--out", str(out), "--cache-dir", str(cache),
                 *extra]) == 0
    return time.perf_counter() - t0


@pytest.fixture(scope="module")
def cold_board(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench-board")
    seconds = _leaderboard(root / "out", root / "cache", "--jobs", "2")
    return root, seconds


def test_default_leaderboard_cold_jobs2(benchmark, cold_board):
    _, seconds = cold_board
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    benchmark.extra_info["seconds"] = seconds
    print(f"\ndefault leaderboard, physics, cold cache, --jobs 2: {seconds:.1f} s (target <= 180 s)")


def test_rerun_with_everything_stored(benchmark, cold_board):
    root, _ = cold_board
    seconds = benchmark.pedantic(_leaderboard, args=(root / "out", root / "cache"), rounds=1, iterations=1)
    print(f"\nre-run with every result stored: {seconds:.1f} s (target <= 10 s)")


def test_parallel_efficiency(benchmark, tmp_path):
    cfg = tmp_path / "two.yaml"
    text = open("leaderboard/methods.yaml").read().split("scenarios:")[0]
    cfg.write_text(text + "scenarios: [paper_2012, incipient]\n")

    def run(jobs: int) -> float:
        t0 = time.perf_counter()
        assert main(["leaderboard", "--config", str(cfg), "--out", str(tmp_path / f"out{jobs}"),
                     "--cache-dir", str(tmp_path / f"cache{jobs}"), "--jobs", str(jobs)]) == 0
        return time.perf_counter() - t0

    t1 = run(1)
    t2 = benchmark.pedantic(run, args=(2,), rounds=1, iterations=1)
    efficiency = t1 / (2.0 * t2)
    benchmark.extra_info.update({"t1": t1, "t2": t2, "efficiency": efficiency})
    print(f"\n1 worker {t1:.1f} s, 2 workers {t2:.1f} s: parallel efficiency {efficiency:.2f} (target >= 0.8)")


def test_paper_end_to_end(benchmark, tmp_path):
    def run() -> float:
        t0 = time.perf_counter()
        assert main(["paper", "--out", str(tmp_path / "paper"), "--cache-dir", str(tmp_path / "cache")]) == 0
        return time.perf_counter() - t0

    seconds = benchmark.pedantic(run, rounds=1, iterations=1)
    print(f"\nfuelhm-bench paper, cold cache: {seconds:.1f} s (target <= 30 s)")
