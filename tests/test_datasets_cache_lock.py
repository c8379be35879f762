"""Two processes asking for the same uncached product build it once (the build lock of datasets.cache)."""

from __future__ import annotations

import multiprocessing
import time

import pandas as pd
import pytest

from fuelhm_bench.datasets import cache


def _ask(entry, marker, out):
    def build():
        with open(marker, "a", encoding="utf-8") as f:
            f.write("built\n")
        time.sleep(1.0)  # long enough for the other process to find the build under way
        return {"t": pd.DataFrame({"x": [1.0, 2.0, 3.0]})}

    product = cache._cached("k" * 64, entry, ("t",), build, lambda tables: tables["t"], {"kind": "test"})
    with open(out, "w", encoding="utf-8") as f:
        f.write(product.to_json())


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs fork")
def test_concurrent_requests_build_a_product_once(tmp_path):
    ctx = multiprocessing.get_context("fork")
    entry = tmp_path / "cache" / "fleet-kkkk"
    marker = tmp_path / "builds.txt"
    procs = [ctx.Process(target=_ask, args=(entry, marker, tmp_path / f"out{j}.json")) for j in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(30)
        assert p.exitcode == 0
    assert marker.read_text(encoding="utf-8").splitlines() == ["built"]  # the second process read the entry
    assert (tmp_path / "out0.json").read_text() == (tmp_path / "out1.json").read_text()


def test_without_disk_cache_the_build_runs_unlocked():
    calls = []
    table = cache._cached("m" * 64, None, ("t",), lambda: calls.append(1) or {"t": pd.DataFrame({"x": [1]})},
                          lambda tables: tables["t"], {})
    assert calls == [1] and list(table["x"]) == [1]
    cache._MEMORY.pop("m" * 64, None)


def _hold_then_fork(entry, child_pid, started):
    import os

    with cache._build_lock(entry):
        pid = os.fork()  # like a worker pool forked during a build: it outlives the build
        if pid == 0:
            time.sleep(30)
            os._exit(0)
    child_pid.value = pid
    started.set()
    os.waitpid(pid, 0)


def _take(entry, taken):
    with cache._build_lock(entry):
        taken.set()


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs fork")
def test_a_process_forked_during_a_build_does_not_keep_the_lock(tmp_path):
    import os
    import signal

    ctx = multiprocessing.get_context("fork")
    entry = tmp_path / "cache" / "fleet-kkkk"
    started, child_pid = ctx.Event(), ctx.Value("i", 0)
    holder = ctx.Process(target=_hold_then_fork, args=(entry, child_pid, started))
    holder.start()
    try:
        assert started.wait(30)
        taken = ctx.Event()
        taker = ctx.Process(target=_take, args=(entry, taken))
        taker.start()
        taker.join(10)
        ok = taker.exitcode == 0 and taken.is_set()
        if not ok:
            taker.kill()
            taker.join()
        assert ok, "the lock stayed held by the process forked during the build"
    finally:
        if child_pid.value:
            os.kill(child_pid.value, signal.SIGKILL)
        holder.join(10)
