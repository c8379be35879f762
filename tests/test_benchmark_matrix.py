"""Every shipped baseline runs on every shipped scenario (small scale: short flights, few scored units).

The training fleet keeps each scenario's own number of units and flights when it is small (that is the
point of ``low_data``), shorter flights keep the simulation cheap. The methods are fitted, scored on the
calibration units and decide on the scored observations in this process (the sealing itself is tested
in ``test_benchmark_sealed.py``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fuelhm_baselines
from fuelhm_bench.benchmark.harness import action_from_decision, observation_row, prepare_evaluation
from fuelhm_bench.envs import KnowledgeSize
from fuelhm_bench.methods import run_table
from fuelhm_bench.scenarios import load_scenario, shipped_scenario_files

SCENARIOS = sorted(shipped_scenario_files())
BASELINES = sorted(fuelhm_baselines.ENTRY_POINTS)


def _small(name: str):
    sc = load_scenario(name)
    training = sc.training
    if training.units * training.flights_per_unit > 24:  # keep small training sets (low_data) as shipped
        training = dataclasses.replace(training, units=4, flights_per_unit=6)
    degradations = tuple(dataclasses.replace(d, onset_min=1, onset_max=3, ramp_flights=3) for d in sc.degradations)
    unknown = tuple(dataclasses.replace(u, onset_min=1, onset_max=3) for u in sc.unknown_faults)
    return dataclasses.replace(sc, fleet=dataclasses.replace(sc.fleet, units=2, flights_per_unit=8),
                               mission=dataclasses.replace(sc.mission, duration_min=2.0), training=training,
                               degradations=degradations, unknown_faults=unknown)


@pytest.fixture(scope="module")
def evaluations(tmp_path_factory):
    cache = tmp_path_factory.mktemp("matrix-cache")
    return {name: prepare_evaluation(_small(name), fidelity="physics", knowledge_size=KnowledgeSize.small(),
                                     robustness=False, cache_dir=cache) for name in SCENARIOS}


# 8 scenarios x 9 baselines at small scale: 23 s on a quiet machine (one xdist worker)
@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("baseline", BASELINES)
def test_every_baseline_runs_on_every_scenario(evaluations, scenario, baseline):
    ev = evaluations[scenario]
    method = fuelhm_baselines.load(baseline)()
    method.fit(ev.fit_indicators, knowledge=ev.method_knowledge, random_state=0)
    healthy = run_table(method, ev.calibration_indicators)["score"].to_numpy(dtype=float)
    assert np.all(np.isfinite(healthy))
    env = ev.env
    obs, _ = env.reset(options={"unit": 0})
    method.start_unit(0)
    for f in range(env.n_flights):
        decision = method.decide(observation_row(obs, 0, f))
        assert np.isfinite(decision.score)
        obs, _, terminated, _, _ = env.step(action_from_decision(decision))
    assert terminated


def _run_raw(ev) -> tuple[np.ndarray, list]:
    """RawTrackingMethod through the raw path of the harness, in this process (fit, calibration, one unit)."""
    from fuelhm_bench.benchmark.harness import _training_raw
    from fuelhm_bench.benchmark.raw_flights import raw_flight_from_info
    from fuelhm_baselines.raw_tracking import RawTrackingMethod

    method = RawTrackingMethod(random_state=0)
    method.fit(ev.fit_indicators, knowledge=ev.method_knowledge, raw_flights=_training_raw(ev, ev.fit_indicators))
    cal = ev.calibration_indicators
    flights = {(f.unit_id, f.flight_index): f for f in _training_raw(ev, cal)}
    healthy = run_table(method, cal, raw=lambda row: flights[(row["unit_id"], int(row["flight_index"]))])
    env = ev.env
    obs, info = env.reset(options={"unit": 0, "raw_flight": True})
    method.start_unit(0)
    decisions = []
    for f in range(env.n_flights):
        raw = raw_flight_from_info(info["raw_flight"], 0, f)
        decisions.append(method.decide(observation_row(obs, 0, f), raw=raw))
        obs, _, terminated, _, info = env.step(action_from_decision(decisions[-1]))
    assert terminated
    return healthy["score"].to_numpy(dtype=float), decisions


# The raw-signal baseline flies its flights again at full rate: 0.11-0.16 s of CPU per scenario at this size
# (time.process_time around _run_raw, all 8 scenarios: 1.2 s), so every scenario is in the default run.
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_raw_baseline_runs_on_every_scenario(evaluations, scenario):
    healthy, decisions = _run_raw(evaluations[scenario])
    assert np.all(np.isfinite(healthy)) and healthy.size == len(evaluations[scenario].calibration_indicators)
    scores = np.array([d.score for d in decisions])
    assert np.all(np.isfinite(scores)) and np.ptp(scores) > 0  # the scores move with the flights
