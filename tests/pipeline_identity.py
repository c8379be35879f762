"""Dump (or compare) the simulated data products of a few small scenarios, byte for byte.

A developer's tool for speed work on the data path (issue 10): a change that is meant to be pure speed
must leave every product bit-identical. Run it on the reference tree and on the changed tree::

    PYTHONPATH=<reference checkout> python tests/pipeline_identity.py dump /tmp/ref
    python tests/pipeline_identity.py check /tmp/ref

    python tests/pipeline_identity.py cost       # CPU ms per flight-hour of a scored fleet, in this tree

``dump`` writes one ``.npz`` per product (every column as an array, text columns as strings);
``check`` rebuilds them in this tree and reports the first differing column of each (exit 1 on any).
It covers healthy training fleets, scored fleets with faulty units (drifted and not), a degraded sensor,
faults outside the seven modes, hidden effects (model discrepancy), a design of experiments and a
velocity-gain sweep (open-loop current, no end stops).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd


def _products():
    from fuelhm_bench.datasets import cache
    from fuelhm_bench.datasets.doe import DesignOfExperiments, run_doe
    from fuelhm_bench.flights.mission import MissionProfile

    m = 3.0  # flight minutes
    for sc in ("paper_2012", "sensor_degraded", "multi_fault", "robustness_drift", "model_discrepancy",
               "incipient", "low_data", "all_modes"):
        yield f"training-{sc}", lambda sc=sc: cache.training_indicators(sc, flight_minutes=m, units=3, flights=2,
                                                                         cache_dir=False)
        yield f"scored-{sc}", lambda sc=sc: cache.scored_indicators(sc, flight_minutes=m, units=4, cache_dir=False)
    yield "scored-undrifted-robustness_drift", lambda: cache.scored_indicators(
        "robustness_drift", flight_minutes=m, units=3, drifted=False, cache_dir=False)
    yield "training-drifted-robustness_drift", lambda: cache.training_indicators(
        "robustness_drift", flight_minutes=m, units=2, flights=2, drifted=True, cache_dir=False)
    yield "doe", lambda: run_doe(DesignOfExperiments(n_units=1, intensities=(0.5, 1.0),
                                                     mission=MissionProfile(duration_s=60.0 * m)))
    yield "surrogate-healthy-model_discrepancy", lambda: cache.surrogate_healthy(
        "model_discrepancy", flight_minutes=m, size=cache.KnowledgeSize.small(), cache_dir=False)
    yield "sweep", _sweep


def _sweep() -> pd.DataFrame:
    from fuelhm_bench.flights.sweep import run_sweep
    from fuelhm_bench.physics.model import LoopModel

    r = run_sweep(LoopModel().degraded({"spool_friction": 0.5}), seed=3)
    return pd.DataFrame({"current_a": r.current_a, "velocity_m_s": r.velocity_m_s, "increasing": r.increasing})


def _arrays(table: pd.DataFrame) -> dict[str, np.ndarray]:
    out = {}
    for c in table.columns:
        v = table[c].to_numpy()
        out[str(c)] = v.astype(str) if v.dtype == object else v
    return out


def cost(repeats: int = 5) -> None:
    """Print the CPU cost of 16 flights of paper_2012's scored fleet (25 min) built in this process, per flight-hour
    (the smallest and the median of ``repeats`` builds, after a warm-up; page faults and system time included)."""
    import dataclasses
    import resource
    import time

    from fuelhm_bench.datasets.cache import resolve_scenario
    from fuelhm_bench.datasets.fleets import fleet_indicators

    config = dataclasses.replace(resolve_scenario("paper_2012").test_fleet_config(), n_units=2, n_flights=8)
    fleet_indicators(dataclasses.replace(config, n_units=1, n_flights=1,
                                         mission=dataclasses.replace(config.mission, duration_s=180.0)))
    before = resource.getrusage(resource.RUSAGE_SELF)
    costs = []
    for _ in range(repeats):
        start = time.process_time()
        fleet_indicators(config)
        costs.append(time.process_time() - start)
    after = resource.getrusage(resource.RUSAGE_SELF)
    hours = 16 * config.mission.duration_s / 3600.0
    costs.sort()
    print(f"{1e3 * costs[0] / hours:.1f} ms CPU per flight-hour (median {1e3 * costs[len(costs) // 2] / hours:.1f}; "
          f"{(after.ru_minflt - before.ru_minflt) / (16 * repeats):.0f} page faults per flight and "
          f"{1e3 * (after.ru_stime - before.ru_stime) / (hours * repeats):.1f} ms system time per flight-hour)")


def main(argv: list[str]) -> int:
    if argv[0] == "cost":
        cost()
        return 0
    mode, folder = argv[0], Path(argv[1])
    folder.mkdir(parents=True, exist_ok=True)
    bad = 0
    only = set(argv[2:])
    for name, build in _products():
        if only and name not in only:
            continue
        arrays = _arrays(build())
        path = folder / f"{name}.npz"
        if mode == "dump":
            np.savez(path, **arrays)
            print(f"dumped {name}: {len(next(iter(arrays.values())))} rows")
            continue
        ref = dict(np.load(path, allow_pickle=False))
        diff = [c for c in ref if c not in arrays or ref[c].dtype != arrays[c].dtype
                or ref[c].tobytes() != arrays[c].tobytes()]
        diff += [c for c in arrays if c not in ref]
        print(f"{name}: {'IDENTICAL' if not diff else 'DIFFERS in ' + ', '.join(diff[:5])}")
        bad += bool(diff)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
