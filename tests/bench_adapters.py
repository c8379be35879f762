"""Batch decision path of the adapters against row-by-row decisions (run separately).

    pytest tests/bench_adapters.py -m benchmark -p no:cacheprovider

Side by side, in one run: ``run_table`` on 600 flights (20 units x 30 flights of the check
data) and ``check_method`` at its default size, for an adapter with its batch path and for the
same adapter forced to decide row by row. Ratios are printed and kept in ``extra_info``.
"""

from __future__ import annotations

import time

import pytest
from sklearn.ensemble import IsolationForest

from fuelhm_bench.methods import Decision, check_method, make_check_data, run_table
from fuelhm_bench.methods.adapters import PyODMethod, SklearnMethod, _DetectorAdapter


class _RowByRow:
    """The same adapter without a batch path (decides through a 1-row batch per flight)."""

    _decide_batch = None

    def _decide(self, row):
        s, a, g = _DetectorAdapter._decide_batch(self, row.to_frame().T)
        return Decision(score=float(s[0]), alarm=bool(a[0]), guilt=g[0])


class RowSklearnMethod(_RowByRow, SklearnMethod):
    pass


class RowPyODMethod(_RowByRow, PyODMethod):
    pass


def _makers():
    out = [("IsolationForest", lambda cls: cls(estimator=IsolationForest()),
            SklearnMethod, RowSklearnMethod)]
    try:
        from pyod.models.ecod import ECOD
    except ImportError:
        return out
    return out + [("ECOD", lambda cls: cls(detector=ECOD()), PyODMethod, RowPyODMethod)]


@pytest.mark.benchmark(group="adapters")
@pytest.mark.parametrize("name, make, batch_cls, row_cls", _makers(), ids=lambda v: v if isinstance(v, str) else "")
def test_batch_against_rows(benchmark, name, make, batch_cls, row_cls):
    data = make_check_data(0, n_units=20, n_flights=30)
    fitted = {k: make(c).fit(data.healthy, knowledge=data.knowledge, random_state=0)
              for k, c in (("batch", batch_cls), ("row", row_cls))}
    benchmark.pedantic(run_table, args=(fitted["batch"], data.units), rounds=3, iterations=1)
    batch_s = benchmark.stats.stats.min
    t = time.perf_counter()
    run_table(fitted["row"], data.units)
    row_s = time.perf_counter() - t
    checks = {}
    for k, c in (("batch", batch_cls), ("row", row_cls)):
        t = time.perf_counter()
        check_method(make(c))
        checks[k] = time.perf_counter() - t
    benchmark.extra_info.update(run_table_ratio=row_s / batch_s, check_batch_s=checks["batch"],
                                check_row_s=checks["row"])
    print(f"\n{name}: run_table 600 flights batch {batch_s:.2f} s, row by row {row_s:.2f} s "
          f"({row_s / batch_s:.1f}x); check_method batch {checks['batch']:.1f} s, "
          f"row by row {checks['row']:.1f} s")
    assert row_s > batch_s


def _cpu_s() -> float:
    """CPU time of this process and of its finished children (the sealed process) [s]."""
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


@pytest.mark.benchmark(group="check_method")
@pytest.mark.parametrize("name, make, batch_cls, row_cls", _makers(), ids=lambda v: v if isinstance(v, str) else "")
def test_check_method_cpu(benchmark, monkeypatch, name, make, batch_cls, row_cls):
    """CPU time of check_method at its default size: sealed, in process, and in process without the
    shared fit and single-batch runs (the checks as they were before), side by side in one run."""
    from fuelhm_bench.methods import checks

    check_method(make(batch_cls), sealed=False)  # warm-up: imports, JIT compilation
    cpu = {}
    with monkeypatch.context() as m:
        fresh = checks._fresh
        m.setattr(checks, "_fresh", lambda method, data, seed=0, shared=True: fresh(method, data, seed, shared=False))
        m.setattr(checks, "_run_units", lambda method, data: run_table(method, data.units))
        c = _cpu_s()
        check_method(make(batch_cls), sealed=False)
        cpu["in_process_unshared"] = _cpu_s() - c
    for label, sealed in (("in_process", False), ("sealed", True)):
        c = _cpu_s()
        check_method(make(batch_cls), sealed=sealed)
        cpu[label] = _cpu_s() - c
    benchmark.pedantic(check_method, args=(make(batch_cls),), kwargs={"sealed": False}, rounds=1, iterations=1)
    benchmark.extra_info.update({f"cpu_{k}_s": v for k, v in cpu.items()})
    print(f"\n{name}: check_method CPU sealed {cpu['sealed']:.2f} s, in process {cpu['in_process']:.2f} s, "
          f"in process without shared fit / single batch {cpu['in_process_unshared']:.2f} s")
