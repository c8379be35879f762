"""The zygote that forks sealed processes holds no scenario data; a forked sealed process is sealed as before."""

from __future__ import annotations

import os
import secrets
import signal
import time

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.methods import sandbox
from fuelhm_bench.methods.sandbox import SealedMethod
from fuelhm_bench.taxonomy import INDICATOR_NAMES
from submissions import Exits, IdleCurrent, Segfaults

pytestmark = pytest.mark.skipif(not hasattr(os, "fork") or not os.path.isdir("/proc/self"),
                                reason="the zygote exists where fork and /proc do (Linux)")


def _memory_holds(pid: int, marker: bytes) -> bool:
    """Whether ``marker`` is anywhere in the writable memory of process ``pid`` (heap, stacks, anonymous maps)."""
    with open(f"/proc/{pid}/maps") as maps, open(f"/proc/{pid}/mem", "rb", buffering=0) as mem:
        for line in maps:
            fields = line.split()
            if "w" not in fields[1] or "r" not in fields[1] or (len(fields) > 5 and fields[5] == "[vvar]"):
                continue
            start, end = (int(x, 16) for x in fields[0].split("-"))
            pos = start
            while pos < end:
                size = min(end - pos, 64 << 20)
                try:
                    mem.seek(pos)
                    chunk = mem.read(size)
                except (OSError, ValueError, OverflowError):
                    break
                if marker in chunk:
                    return True
                if pos + size >= end:
                    break
                pos += size - len(marker)  # overlapping windows: a marker across two reads is found
    return False


@pytest.fixture
def fresh_zygote(monkeypatch):
    """A zygote of its own for the test (started on first use), stopped afterwards."""
    monkeypatch.delenv("FUELHM_BENCH_ZYGOTE", raising=False)
    monkeypatch.setattr(sandbox, "_ZYGOTE", {})
    yield sandbox._ZYGOTE
    z = sandbox._ZYGOTE.pop("z", None)
    if z is not None:
        z.close()


def _table(n: int = 12) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    table = pd.DataFrame({"unit_id": np.repeat(np.arange(n // 2), 2), "flight_index": np.tile([0, 1], n // 2)})
    for name in INDICATOR_NAMES:
        table[name] = rng.normal(size=n)
        table[f"{name}_valid"] = True
    return table


def test_the_zygote_and_a_forked_process_hold_no_scenario_data(fresh_zygote):
    """Ground truth that exists in the harness before the zygote starts is in neither the zygote nor its fork."""
    marker = ("onset_GROUND_TRUTH_" + secrets.token_hex(16)).encode()
    truth = pd.DataFrame({marker.decode(): [3, 5]})  # noqa: F841 - what must not leak, alive while we look
    text = bytearray(marker * 4)  # noqa: F841 - and as raw bytes
    assert _memory_holds(os.getpid(), marker)  # the probe finds it where it is
    with SealedMethod(IdleCurrent(), limits={"wall_s": 60.0}) as m:
        zygote = fresh_zygote["z"]
        assert m._proc.pid != zygote.proc.pid
        assert int(open(f"/proc/{m.pid}/stat").read().rsplit(")", 1)[1].split()[1]) == zygote.proc.pid  # its parent
        assert os.getsid(m.pid) == m.pid  # its own session and process group
        assert not _memory_holds(zygote.proc.pid, marker)
        assert not _memory_holds(m.pid, marker)
        assert "fuelhm-sealed-" in os.readlink(f"/proc/{m.pid}/cwd")  # its own scratch directory
        m.fit(_table())
        assert m.sandbox.startswith(("landlock", "no file-system restriction"))


def test_forked_failures_are_reported_like_started_ones(fresh_zygote):
    """An exit code and a death by signal come through the zygote's status pipe unchanged."""
    from fuelhm_bench.methods.sandbox import SealedFailure

    with SealedMethod(Segfaults(), limits={"wall_s": 60.0}) as m:
        with pytest.raises(SealedFailure, match="killed by signal SIGSEGV during fit") as err:
            m.fit(_table())
        assert err.value.status == "crash"
    with SealedMethod(Exits(), limits={"wall_s": 60.0}) as m:
        m.fit(_table())
        m.start_unit(0)
        with pytest.raises(SealedFailure, match=r"exited \(exit code 7\) during decide") as err:
            m.decide(_table().iloc[0])
        assert err.value.status == "crash"


def test_a_killed_zygote_is_replaced_and_the_fallback_starts_an_interpreter(fresh_zygote, monkeypatch):
    with SealedMethod(IdleCurrent(), limits={"wall_s": 60.0}) as m:
        m.fit(_table())
    first = fresh_zygote["z"]
    os.killpg(first.proc.pid, signal.SIGKILL)
    first.proc.wait(10)
    with SealedMethod(IdleCurrent(), limits={"wall_s": 60.0}) as m:  # a new zygote forks this one
        m.fit(_table())
        assert fresh_zygote["z"] is not first and fresh_zygote["z"].alive()
    monkeypatch.setenv("FUELHM_BENCH_ZYGOTE", "0")  # no zygote: a fresh interpreter, a child of this process
    with SealedMethod(IdleCurrent(), limits={"wall_s": 60.0}) as m:
        assert int(open(f"/proc/{m.pid}/stat").read().rsplit(")", 1)[1].split()[1]) == os.getpid()
        m.fit(_table())
    with SealedMethod(IdleCurrent(), limits={"wall_s": 60.0}, zygote=False) as m:
        assert int(open(f"/proc/{m.pid}/stat").read().rsplit(")", 1)[1].split()[1]) == os.getpid()


def test_a_method_folder_added_after_the_zygote_started_is_importable(fresh_zygote, tmp_path, monkeypatch):
    """A forked process imports from the harness's import path of its run, not of the zygote's start."""
    with SealedMethod(IdleCurrent(), limits={"wall_s": 60.0}) as m:  # the zygote starts with today's path
        m.fit(_table())
    folder = tmp_path / "late_methods"
    folder.mkdir()
    (folder / "late_method_module.py").write_text("from submissions import IdleCurrent as LateMethod\n")
    monkeypatch.syspath_prepend(str(folder))
    with SealedMethod("late_method_module:LateMethod", limits={"wall_s": 60.0}) as m:
        assert int(open(f"/proc/{m.pid}/stat").read().rsplit(")", 1)[1].split()[1]) == fresh_zygote["z"].proc.pid
        m.fit(_table())


def test_closing_the_harness_side_ends_the_zygote_and_its_processes(fresh_zygote):
    m = SealedMethod(IdleCurrent(), limits={"wall_s": 60.0})
    m.start()
    zygote = fresh_zygote.pop("z")
    pid = m.pid
    zygote.close()  # the harness goes away while a sealed process still runs
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and _alive(pid):
        time.sleep(0.05)
    assert not _alive(pid) and zygote.proc.poll() is not None
    m.close()


def _alive(pid: int) -> bool:
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")
