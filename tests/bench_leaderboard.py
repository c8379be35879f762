"""Benchmarks of the leaderboard and the paper study (run separately; not unit tests).

    pytest tests/bench_leaderboard.py -m benchmark -p no:cacheprovider -s

Targets (issue 10 §6, 2-core machine):

* ``test_default_leaderboard_cold_jobs2``: ``fuelhm-bench leaderboard`` on ``leaderboard/methods.yaml``
  (6 entries x 7 scenarios, physics), cold simulation cache, ``--jobs 2``: <= 180 s;
* ``test_rerun_with_everything_stored``: the same command again (every key in the store): <= 10 s;
* ``test_parallel_efficiency``: the same board, cold, with one worker on one CPU, against the
  ``--jobs 2`` run above: efficiency T1 / (2 T2) >= 0.8 (``--jobs 1`` alone would still simulate
  on every CPU the process may use, so the one-worker run is pinned to one CPU);
* ``test_paper_end_to_end``: ``fuelhm-bench paper`` with a cold cache: <= 30 s.

The harness's own overhead (no target; side by side in one run, CPU time):

* ``test_sealed_start``: CPU time of a sealed process from start to a constructed method, forked
  from the zygote against a fresh interpreter (``FUELHM_BENCH_ZYGOTE=0``), per shipped baseline;
* ``test_board_with_data_cached``: two scenarios x the default methods at scale 0.3 with their data
  already simulated (what every evaluation costs beyond the data), with and without the zygote.

Every command runs in a fresh interpreter (start-up and imports included, as a user sees it), with
its own empty simulation cache (``--cache-dir``) and output folder. "Cold" means an empty simulation
cache with numba's functions already compiled, as for a user after their first run: the test
session keeps its caches in a temporary ``FUELHM_BENCH_CACHE`` (``tests/conftest.py``), numba's
compiled functions included, so the fixture ``_compiled`` compiles them there first (a small
``paper`` run) and no timed command pays for compiling. Each line printed gives the wall time and
the CPU time of the command and its children.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.benchmark
ROOT = Path(__file__).resolve().parents[1]


def timed(*args: str, env: dict | None = None, one_cpu: bool = False) -> tuple[float, float]:
    """Run ``fuelhm-bench ARGS`` in a fresh interpreter; returns (wall s, CPU s of it and its children).

    ``one_cpu``: the command and its children may run on one CPU only (as ``taskset -c``), so that
    nothing in it (the simulation's process pool uses every CPU it may run on) uses a second one.
    """
    cpu0 = min(os.sched_getaffinity(0))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "fuelhm_bench.cli", *args], cwd=ROOT, capture_output=True,
                          text=True, env={**os.environ, "FUELHM_NO_PROGRESS": "1", **(env or {})},
                          preexec_fn=(lambda: os.sched_setaffinity(0, {cpu0})) if one_cpu else None)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert done.returncode == 0, done.stderr[-3000:]
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def _leaderboard(config, out, cache, *extra, env: dict | None = None, one_cpu: bool = False) -> tuple[float, float]:
    return timed("leaderboard", "--config", str(config), "--out", str(out), "--cache-dir", str(cache), *extra,
                 env=env, one_cpu=one_cpu)


@pytest.fixture(scope="module", autouse=True)
def _compiled(tmp_path_factory):
    """Compile numba's functions into the session's cache before any timed command (see above)."""
    root = tmp_path_factory.mktemp("bench-compile")
    timed("paper", "--scale", "0.1", "--doe-units", "1", "--out", str(root / "out"), "--cache-dir",
          str(root / "cache"))


@pytest.fixture(scope="module")
def cold_board(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench-board")
    wall, cpu = _leaderboard(ROOT / "leaderboard" / "methods.yaml", root / "out", root / "cache", "--jobs", "2")
    return root, wall, cpu


def test_default_leaderboard_cold_jobs2(benchmark, cold_board):
    _, wall, cpu = cold_board
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    benchmark.extra_info.update({"wall_s": wall, "cpu_s": cpu})
    print(f"\ndefault leaderboard, physics, cold cache, --jobs 2: {wall:.1f} s wall, {cpu:.1f} s CPU "
          f"(target <= 180 s wall)")


def test_rerun_with_everything_stored(benchmark, cold_board):
    root, _, _ = cold_board
    wall, cpu = benchmark.pedantic(_leaderboard, args=(ROOT / "leaderboard" / "methods.yaml", root / "out",
                                                       root / "cache"), rounds=1, iterations=1)
    print(f"\nre-run with every result stored: {wall:.1f} s wall, {cpu:.1f} s CPU (target <= 10 s)")


def test_parallel_efficiency(benchmark, cold_board, tmp_path):
    """The default board on one worker and one CPU against ``cold_board`` (``--jobs 2``)."""
    _, t2, c2 = cold_board
    t1, c1 = benchmark.pedantic(_leaderboard, args=(ROOT / "leaderboard" / "methods.yaml", tmp_path / "out1",
                                                    tmp_path / "cache1"), kwargs={"one_cpu": True},
                                rounds=1, iterations=1)
    efficiency = t1 / (2.0 * t2)
    benchmark.extra_info.update({"t1": t1, "t2": t2, "cpu1": c1, "cpu2": c2, "efficiency": efficiency})
    print(f"\ndefault board, cold: 1 worker on one CPU {t1:.1f} s ({c1:.1f} s CPU), --jobs 2 {t2:.1f} s "
          f"({c2:.1f} s CPU): parallel efficiency {efficiency:.2f} (target >= 0.8)")


def test_paper_end_to_end(benchmark, tmp_path):
    """Cold (empty cache) with 2 and 1 processes side by side, then warm (everything cached)."""
    cold2 = benchmark.pedantic(timed, args=("paper", "--out", str(tmp_path / "p2"), "--cache-dir",
                                            str(tmp_path / "c2"), "--jobs", "2"), rounds=1, iterations=1)
    cold1 = timed("paper", "--out", str(tmp_path / "p1"), "--cache-dir", str(tmp_path / "c1"), "--jobs", "1")
    warm = timed("paper", "--out", str(tmp_path / "p3"), "--cache-dir", str(tmp_path / "c2"), "--jobs", "2")
    for name in ("table_iv.csv", "table_v.csv", "table_vi.csv"):  # same bytes whatever the number of processes
        assert (tmp_path / "p1" / name).read_bytes() == (tmp_path / "p2" / name).read_bytes()
    benchmark.extra_info.update({"cold_jobs2": cold2, "cold_jobs1": cold1, "warm_jobs2": warm})
    print(f"\nfuelhm-bench paper, cold cache: --jobs 2 {cold2[0]:.1f} s wall ({cold2[1]:.1f} s CPU), --jobs 1 "
          f"{cold1[0]:.1f} s wall ({cold1[1]:.1f} s CPU), ratio {cold1[0] / cold2[0]:.2f}; warm cache --jobs 2 "
          f"{warm[0]:.1f} s wall ({warm[1]:.1f} s CPU) (target <= 30 s)")


BASELINES = ("fuelhm_baselines.trivial:NullMethod", "fuelhm_baselines.paper_mahalanobis:PaperMahalanobis",
             "fuelhm_baselines.isolation_forest:IsolationForestMethod",
             "fuelhm_baselines.itl_classifier:ITLClassifierMethod")


def _process_cpu_s(pid: int) -> float:
    """User + system CPU time of a live process [s] (from /proc: it may be another process's child)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_sealed_start(benchmark, monkeypatch):
    from fuelhm_bench.methods.sandbox import SealedMethod, prestart_zygote

    prestart_zygote()

    def starts() -> dict:
        out = {}
        for method in BASELINES:
            for zygote in (True, False):
                with SealedMethod(method, zygote=zygote) as m:
                    out[(method.rsplit(":", 1)[1], zygote)] = _process_cpu_s(m.pid)
        return out

    starts()  # the zygote's own start-up, once per harness process, is not a start
    cpu = benchmark.pedantic(starts, rounds=1, iterations=1)
    for (name, zygote), value in cpu.items():
        benchmark.extra_info[f"{name}-{'zygote' if zygote else 'interpreter'}"] = value
    print("\nCPU of a sealed start [s]: " + "; ".join(
        f"{name}: forked {cpu[(name, True)]:.2f}, fresh interpreter {cpu[(name, False)]:.2f}"
        for name in dict.fromkeys(n for n, _ in cpu)))


def test_board_with_data_cached(benchmark, tmp_path):
    cfg = tmp_path / "two.yaml"
    text = (ROOT / "leaderboard" / "methods.yaml").read_text().split("scenarios:")[0]
    cfg.write_text(text + "scenarios: [paper_2012, robustness_drift]\nscale: 0.3\n")
    cache = tmp_path / "cache"
    _leaderboard(cfg, tmp_path / "warm", cache)  # simulates the data once

    def both() -> dict:
        return {"zygote": _leaderboard(cfg, tmp_path / "z", cache),
                "interpreter": _leaderboard(cfg, tmp_path / "i", cache, env={"FUELHM_BENCH_ZYGOTE": "0"}),
                "rerun": _leaderboard(cfg, tmp_path / "z", cache)}

    runs = benchmark.pedantic(both, rounds=1, iterations=1)
    benchmark.extra_info.update({k: {"wall_s": w, "cpu_s": c} for k, (w, c) in runs.items()})
    print("\nboard with its data cached (12 evaluations + 6 nominal runs): "
          + "; ".join(f"{k}: {w:.1f} s wall, {c:.1f} s CPU" for k, (w, c) in runs.items()))
