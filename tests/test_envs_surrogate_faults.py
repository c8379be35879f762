"""Faults outside the seven modes at surrogate fidelity (a scenario's ``unknown_faults``).

The surrogate learns each declared fault's response from design-of-experiments flights of the
physics (each DOE unit flown healthy and with the fault at full strength, on the same missions),
and the environment adds it from the fault's onset. A tiny scenario (2-minute flights,
``KnowledgeSize.small()``) with one strong fault: the draws move the way the DOE says, labels say
"unknown", and the draws are reproducible.
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.datasets.cache import surrogate_doe, surrogate_knowledge
from fuelhm_bench.datasets.doe import fault_case
from fuelhm_bench.envs.actuation_loop import INDICATOR_BOUNDS, ActuationLoopEnv
from fuelhm_bench.errors import ParameterError
from fuelhm_bench.scenarios.schema import UnknownFaultSpec
from fuelhm_bench.taxonomy import INDICATOR_NAMES
from sizes import FLIGHT_MINUTES, TINY_ONSET_MAX, TINY_ONSET_MIN, knowledge_size, tiny_scenario

NO_ALARM = {"alarm": 0, "guilt": np.zeros(7, dtype=np.float32)}
HYSTERESIS = UnknownFaultSpec(effect="torque_motor_hysteresis", parameters=(("width_a", 0.002),), probability=1.0,
                              onset_min=TINY_ONSET_MIN, onset_max=TINY_ONSET_MAX)


def fault_scenario(fault=HYSTERESIS, name="tiny_faults"):
    """robustness_drift shrunk: half the units draw a mode, every other one develops ``fault``."""
    base = tiny_scenario("robustness_drift", name=name)
    return dataclasses.replace(base, healthy_probability=0.5,
                               degradations=tuple(dataclasses.replace(d, probability=0.25)
                                                  for d in base.degradations),
                               unknown_faults=(fault,))


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    sc = fault_scenario()
    knowledge = surrogate_knowledge(sc, size=knowledge_size(), cache_dir=cache)
    return sc, knowledge, cache


def make(setup, **kwargs):
    sc, knowledge, _ = setup
    return ActuationLoopEnv(scenario=sc, fidelity="surrogate", knowledge=knowledge, **kwargs)


def episode(env, seed):
    obs, _ = env.reset(seed=seed)
    rows = [obs]
    done = False
    while not done:
        obs, _, done, _, info = env.step(NO_ALARM)
        rows.append(obs)
    return rows[:-1], info["episode_truth"]  # the terminal observation repeats the last flight


def doe_response(doe: pd.DataFrame, label: str) -> pd.Series:
    """Mean over DOE units and missions of I(unit, fault) - I(unit, healthy), per indicator (valid pairs)."""
    keys = ["unit_id", "replicate"] if "replicate" in doe.columns else ["unit_id"]
    healthy = doe[doe["mode"] == "healthy"].set_index(keys)
    faulty = doe[doe["mode"] == label].set_index(keys).loc[healthy.index]
    out = {}
    for n in INDICATOR_NAMES:
        ok = healthy[f"{n}_valid"].to_numpy(bool) & faulty[f"{n}_valid"].to_numpy(bool)
        out[n] = float(np.mean(faulty[n].to_numpy(float)[ok] - healthy[n].to_numpy(float)[ok])) if ok.any() else np.nan
    return pd.Series(out)


def test_the_doe_flies_each_declared_fault_and_the_surrogate_learns_it(setup):
    sc, knowledge, _ = setup
    label = fault_case(sc.test_fleet_config().unknown_faults[0])
    assert label == "unknown:torque_motor_hysteresis@width_a=0.002"
    doe = knowledge.doe_table
    healthy = doe[doe["mode"] == "healthy"]
    faulty = doe[doe["mode"] == label]
    assert len(faulty) == len(healthy) > 0  # every DOE unit, every mission
    assert (faulty["intensity"] == 1.0).all()
    env = make(setup)
    assert env.surrogate.faults == (label,) and env.surrogate.fault_learnt.tolist() == [True]


def test_indicators_move_after_the_onset_as_the_physics_doe_says(setup):
    sc, knowledge, _ = setup
    label = fault_case(sc.test_fleet_config().unknown_faults[0])
    response = doe_response(knowledge.doe_table, label)
    spread = knowledge.healthy_table[list(INDICATOR_NAMES)].std()
    j = (response.abs() / spread).idxmax()  # the indicator the fault moves most, in healthy standard deviations
    assert abs(response[j]) > spread[j]  # a fault the DOE sees clearly
    env = make(setup, maintenance=False)
    column = list(INDICATOR_NAMES).index(j)
    shifts = []
    for seed in range(40):
        rows, truth = episode(env, seed)
        if truth["unknown_fault"]:
            onset = truth["unknown_onset"]
            assert truth["detectable"].tolist() == [t >= onset for t in range(len(rows))]
            x = np.array([r["indicators"][column] for r in rows])
            ok = np.array([r["valid"][column] for r in rows], dtype=bool)
            if ok[onset:].any() and ok[:onset].any():
                shifts.append(x[onset:][ok[onset:]].mean() - x[:onset][ok[:onset]].mean())
    assert len(shifts) >= 10
    mean_shift = float(np.mean(shifts))
    assert np.sign(mean_shift) == np.sign(response[j])
    assert 0.5 < mean_shift / response[j] < 2.0, (j, mean_shift, response[j])


def test_labels_say_unknown_from_the_onset(setup):
    from fuelhm_bench.benchmark.harness import _labels
    from fuelhm_bench.scoring.run import UNKNOWN

    env = make(setup, maintenance=False)
    for seed in range(20):
        rows, truth = episode(env, seed)
        if truth["unknown_fault"]:
            break
    labels = _labels(truth, len(rows))
    assert (labels["unknown_fault"] == "torque_motor_hysteresis").all()
    assert (labels["onset_unknown"] == truth["unknown_onset"]).all()
    assert UNKNOWN == "unknown"
    assert not truth["intensity"].any()  # no mode: the flights are faulty with the true mode "unknown"


def test_same_seed_same_bytes_and_a_repair_removes_the_fault(setup):
    def digest(env, seed):
        h = hashlib.sha256()
        for r in episode(env, seed)[0]:
            h.update(b"".join(v.tobytes() for v in r.values()))
        return h.hexdigest()

    first, second = make(setup), make(setup)
    assert [digest(first, s) for s in range(8)] == [digest(second, s) for s in range(8)]
    env = make(setup, maintenance=True)  # an alarm after the onset repairs: later flights are healthy draws
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        if env._schedule.unknown is not None:
            break
    onset = env._schedule.unknown_onset
    before = env._tables["indicators"].copy()
    for t in range(onset):
        env.step(NO_ALARM)
    env.step({"alarm": 1, "guilt": np.zeros(7, dtype=np.float32)})
    after = env._tables["indicators"]
    np.testing.assert_array_equal(after[:onset + 1], before[:onset + 1])
    parts = env.surrogate.tail(env._parts, onset + 1)
    healthy, valid = env.surrogate.degrade(parts, np.zeros((len(after) - onset - 1, 7)))
    expected = np.where(valid[:, env._columns], healthy[:, env._columns], 0.0)
    low, high = np.array([INDICATOR_BOUNDS[n] for n in INDICATOR_NAMES]).T
    np.testing.assert_array_equal(after[onset + 1:], np.clip(expected, low, high).astype(np.float32))


def test_knowledge_without_the_fault_is_refused_naming_scenario_and_fault(setup):
    sc, knowledge, _ = setup
    doe = knowledge.doe_table
    without = dataclasses.replace(knowledge, doe_table=doe[~doe["mode"].astype(str).str.startswith("unknown:")])
    with pytest.raises(ParameterError, match=r"tiny_faults.*unknown:torque_motor_hysteresis@width_a=0\.002"):
        ActuationLoopEnv(scenario=sc, fidelity="surrogate", knowledge=without)


def test_scenarios_with_different_unknown_faults_never_share_a_surrogate(tmp_path):
    size = dataclasses.replace(knowledge_size(), surrogate_doe_units=1, surrogate_doe_missions=1,
                               surrogate_doe_intensities=(1.0,))
    a = surrogate_doe(fault_scenario(), size=size, cache_dir=tmp_path)
    other = fault_scenario(dataclasses.replace(HYSTERESIS, parameters=(("width_a", 0.001),)))  # same name
    b = surrogate_doe(other, size=size, cache_dir=tmp_path)
    entries = sorted(p.name for p in (tmp_path / "fuelhm-v1").iterdir() if p.name.startswith("surrogate-doe-"))
    assert len(entries) == 2, entries
    assert set(a["mode"]) ^ set(b["mode"]) == {"unknown:torque_motor_hysteresis@width_a=0.002",
                                                "unknown:torque_motor_hysteresis@width_a=0.001"}


def test_fit_surrogate_learns_a_fault_like_a_mode_at_one_intensity():
    """Synthetic tables (no simulation): a fault that shifts A by 3 + unit and makes B invalid."""
    from test_envs_surrogate import MODES, doe_table, healthy_table

    from fuelhm_bench.envs.surrogate import fit_surrogate

    doe = doe_table()
    healthy_rows = doe[doe["mode"] == "healthy"].copy()
    fault = healthy_rows.copy()
    fault["mode"], fault["intensity"] = "unknown:lvdt_lag", 1.0
    fault["A"] = fault["A"] + 3.0 + fault["unit_id"]  # a unit-to-unit spread of the response
    fault["C"] = 0.5 * (fault["A"] + fault["B"])
    fault["B_valid"] = False
    model = fit_surrogate(healthy_table(), pd.concat([doe, fault], ignore_index=True), modes=MODES, bootstrap=0)
    assert model.faults == ("unknown:lvdt_lag",) and model.fault_learnt.tolist() == [True]
    spread = 3.0 + np.arange(5)
    np.testing.assert_allclose(model.fault_mean[0, 0] + model.fault_responses[:, 0, 0], spread, atol=1e-9)
    assert model.fault_invalid[:, 0, 1].all() and not model.fault_invalid[:, 0, [0, 2, 3, 4]].any()
    rng = np.random.default_rng(0)
    parts = model.draw_parts(rng, 6)
    present = np.zeros((6, 1), dtype=bool)
    present[2:] = True
    clean, clean_valid = model.degrade(parts, np.zeros((6, 2)))
    values, valid = model.degrade(parts, np.zeros((6, 2)), present)
    np.testing.assert_array_equal(values[:2], clean[:2])  # before the onset: the healthy draws
    shift = values[2:, 0] - clean[2:, 0]
    np.testing.assert_allclose(shift, shift[0])  # one mission: no flight-to-flight deviation, a unit's own shift
    assert np.isclose(spread, shift[0]).any()  # one DOE unit's own response
    assert not valid[2:, 1].any() and clean_valid[2:, 1].any()
    with pytest.raises(ParameterError, match="'faults' parameter of SurrogateModel.degrade"):
        model.degrade(parts, np.zeros((6, 2)), np.full((6, 1), 2))
    unlearnt = fit_surrogate(healthy_table(), doe, modes=MODES, bootstrap=0, faults=("unknown:lvdt_lag",))
    assert unlearnt.fault_learnt.tolist() == [False]
    with pytest.raises(ParameterError, match="not learnt for the fault"):
        unlearnt.degrade(unlearnt.draw_parts(rng, 6), np.zeros((6, 2)), present)
    # a model without faults draws exactly what it drew before faults existed
    plain = fit_surrogate(healthy_table(), doe, modes=MODES, bootstrap=0)
    a, b = plain.draw_parts(np.random.default_rng(5), 6), model.draw_parts(np.random.default_rng(5), 6)
    np.testing.assert_array_equal(a["healthy"], b["healthy"])
    assert "fault_units" not in a


@pytest.mark.slow  # (both fidelities of the panel's runs: about 5 CPU-s beyond the module's knowledge)
def test_the_fidelity_check_runs_a_scenario_with_unknown_faults(setup):
    from fuelhm_baselines.paper_mahalanobis import PaperMahalanobis
    from fuelhm_baselines.trivial import NullMethod

    from fuelhm_bench.benchmark.fidelity import fidelity_check

    sc, _, cache = setup
    report = fidelity_check(sc, methods={"null": NullMethod(), "paper": PaperMahalanobis(cv=None)},
                            flight_minutes=FLIGHT_MINUTES, knowledge_size=knowledge_size(), cache_dir=cache,
                            timeout_s=120)
    methods = report.methods.set_index("method")
    assert (methods["status_physics"] == "ok").all() and (methods["status_surrogate"] == "ok").all()
    assert np.isfinite(methods["summary_surrogate"]).all()
