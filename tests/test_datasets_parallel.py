"""Simulation spread over worker processes gives the same bytes as one process (datasets/parallel.py)."""

from __future__ import annotations

import io

import time

import pytest

from fuelhm_bench.datasets.doe import DesignOfExperiments, run_doe
from fuelhm_bench.datasets.fleets import fleet_indicators
from fuelhm_bench.datasets.parallel import check_workers, run_ordered
from fuelhm_bench.errors import ParameterError
from fuelhm_bench.flights.fleet import FleetConfig
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.flights.schedule import ModeSchedule

MISSION = MissionProfile(duration_s=120.0)


def _bytes(table) -> bytes:
    buffer = io.BytesIO()
    table.to_parquet(buffer, index=False)
    return buffer.getvalue()


def _square_plus(x: int, y: int) -> int:
    return x * x + y


def test_fleet_tables_do_not_depend_on_workers_or_batches():
    config = FleetConfig(n_units=2, n_flights=3, mission=MISSION, seed=5,
                         schedules=(ModeSchedule("null_bias_drift", probability=1.0, onset_min=0, onset_max=1,
                                                 ramp_flights=2),))
    one = fleet_indicators(config, batch_size=4, workers=1)
    two = fleet_indicators(config, batch_size=2, workers=2)
    for a, b in zip(one, two):
        assert _bytes(a) == _bytes(b)
    assert list(one[0]["flight_id"]) == list(range(6))
    assert one[1]["intensity_null_bias_drift"].max() > 0  # the schedule is in the labels


def test_doe_table_does_not_depend_on_workers():
    doe = DesignOfExperiments(n_units=2, intensities=(1.0,), modes=("null_bias_drift", "internal_leakage"),
                              mission=MISSION)
    one = run_doe(doe, workers=1)
    two = run_doe(doe, batch_size=2, workers=2)
    assert _bytes(one) == _bytes(two)
    assert list(one["mode"]) == ["healthy", "null_bias_drift", "internal_leakage"] * 2


def test_run_ordered_keeps_the_order_and_counts_progress():
    seen = []
    tasks = [(k, 1) for k in range(7)]
    assert run_ordered(_square_plus, tasks, workers=2, sizes=[2] * 7, progress=seen.append) == [
        k * k + 1 for k in range(7)]
    assert seen == [2] * 7
    assert run_ordered(_square_plus, tasks, workers=1) == [k * k + 1 for k in range(7)]


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_workers_must_be_a_positive_integer(bad):
    with pytest.raises(ParameterError, match="'workers' parameter of here must be an integer >= 1"):
        check_workers(bad, "here")
    assert check_workers(None, "here") >= 1


def test_ctrl_c_ends_the_workers_and_the_next_call_starts_afresh():
    from fuelhm_bench.datasets import parallel

    def interrupt(_n: int) -> None:
        raise KeyboardInterrupt

    run_ordered(_square_plus, [(1, 0), (2, 0)], workers=2)
    processes = list(parallel._POOLS[2]._processes.values())
    with pytest.raises(KeyboardInterrupt):
        run_ordered(_square_plus, [(k, 0) for k in range(6)], workers=2, progress=interrupt)
    assert 2 not in parallel._POOLS
    deadline = time.monotonic() + 10.0
    for p in processes:
        # exitcode, not is_alive(): the pool's own thread may reap the killed worker concurrently, and
        # then a waitpid of ours fails and is_alive() answers True for a process that is gone
        while p.exitcode is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert p.exitcode is not None, f"worker {p.pid} still running 10 s after Ctrl-C"
    assert run_ordered(_square_plus, [(k, 0) for k in range(3)], workers=2) == [0, 1, 4]


def test_ctrl_c_leaves_no_exception_in_the_pool_thread(monkeypatch):
    """After Ctrl-C the pool's own thread ends cleanly (it raised InvalidStateError on futures cancelled meanwhile)."""
    import threading

    def interrupt(_n: int) -> None:
        raise KeyboardInterrupt

    failures = []
    monkeypatch.setattr(threading, "excepthook", lambda args: failures.append(repr(args.exc_value)))
    for _ in range(5):
        run_ordered(_square_plus, [(1, 0), (2, 0)], workers=2)
        with pytest.raises(KeyboardInterrupt):
            run_ordered(_square_plus, [(k, 0) for k in range(12)], workers=2, progress=interrupt)
        time.sleep(0.3)  # the pool's thread settles its futures
    assert failures == []


def test_allocator_is_tuned_once_per_process():
    """On glibc the heap keeps freed flight-sized arrays (fewer page faults); the call is idempotent and harmless."""
    import platform
    import subprocess
    import sys

    code = ("from fuelhm_bench.datasets.parallel import tune_allocator; "
            "print(tune_allocator(), tune_allocator())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    glibc = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"
    assert out == (["True", "False"] if glibc else ["False", "False"])


def _fails(message: str):
    raise ValueError(message)


def test_concurrent_builds_give_the_same_tables_in_call_order():
    """Builds made at once on threads (their pieces sharing one pool) return what they return in series."""
    import threading

    from fuelhm_bench.datasets.parallel import run_concurrently

    configs = [FleetConfig(n_units=2, n_flights=2, mission=MISSION, seed=s) for s in (3, 4)]
    doe = DesignOfExperiments(n_units=1, intensities=(1.0,), modes=("internal_leakage",), mission=MISSION)
    calls = [lambda c=c: fleet_indicators(c, batch_size=1, workers=2)[0] for c in configs]
    calls.append(lambda: run_doe(doe, batch_size=1, workers=2))
    together = run_concurrently(calls, workers=2)
    alone = [fleet_indicators(c, workers=1)[0] for c in configs] + [run_doe(doe, workers=1)]
    assert [_bytes(t) for t in together] == [_bytes(t) for t in alone]
    threads = run_concurrently([threading.get_ident] * 2, workers=1)  # one worker: in this thread, in order
    assert threads == [threading.get_ident()] * 2
    with pytest.raises(ValueError, match="first"):  # the first failure in call order
        run_concurrently([lambda: 1, lambda: _fails("first"), lambda: _fails("second")], workers=2)
