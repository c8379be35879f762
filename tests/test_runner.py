"""The runner: methods of the common interface through FuelHM/ActuationLoop-v3, safely.

A tiny scenario (3 units x 8 flights, 4 x 4 training flights, 2-minute flights) keeps every test fast.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
import yaml

from fuelhm_bench.envs import KnowledgeSize
from fuelhm_bench.errors import ParameterError
from fuelhm_bench.methods import Decision, NullMethod
from fuelhm_bench.benchmark.harness import (Outcome, action_from_decision, evaluate, observation_row, prepare_evaluation,
                                           run_in_env)
from fuelhm_bench.scenarios import load_scenario
from fuelhm_bench.scoring import LABEL_COLUMNS
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES, MODE_IDS
from sizes import DOE_UNITS, knowledge_size
from sizes import tiny_scenario as tiny
from submissions import Exits, Hangs, IdleCurrent, NaNScore, NotADecision, Peeks, Raises

SIZE = KnowledgeSize(doe_units=DOE_UNITS)
SMALL = knowledge_size()


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuelhm-cache")


@pytest.fixture(scope="module")
def surrogate_eval(cache_dir):
    return prepare_evaluation(tiny(), fidelity="surrogate", knowledge_size=SMALL, cache_dir=cache_dir)



# --------------------------------------------------------------------------- the adapter
def test_observation_row_and_action():
    n_ext = len(EXTENDED_INDICATOR_NAMES)
    obs = {"indicators": np.arange(10, dtype=np.float32), "valid": np.array([1] * 9 + [0], dtype=np.int8),
           "extended": np.arange(n_ext, dtype=np.float32) + 100, "extended_valid": np.r_[[1] * (n_ext - 1), 0]}
    row = observation_row(obs, unit_id=4, flight_index=2, flight_id=42)
    assert list(row.index) == ["flight_id", "unit_id", "flight_index", *INDICATOR_NAMES,
                               *(f"{n}_valid" for n in INDICATOR_NAMES), *EXTENDED_INDICATOR_NAMES,
                               *(f"{n}_valid" for n in EXTENDED_INDICATOR_NAMES)]
    assert row["flight_id"] == 42 and row["unit_id"] == 4 and row["flight_index"] == 2
    assert row["X1"] == 0.0 and row["G_out"] == 8.0 and np.isnan(row["G_null"]) and row["G_null_valid"] is False
    first, last = EXTENDED_INDICATOR_NAMES[0], EXTENDED_INDICATOR_NAMES[-1]
    assert row[first] == 100.0 and row[f"{first}_valid"] is True
    assert np.isnan(row[last]) and row[f"{last}_valid"] is False
    bare = observation_row({k: obs[k] for k in ("indicators", "valid")}, unit_id=4, flight_index=2)
    assert not any(bare[f"{n}_valid"] for n in EXTENDED_INDICATOR_NAMES) and np.isnan(bare[first])
    action = action_from_decision(Decision(score=1.0, alarm=True, guilt=[0, 1.0000004, 0, 0, 0, 0, 0]))
    assert action["alarm"] == 1 and action["guilt"].dtype == np.float32 and action["guilt"].max() == 1.0


# --------------------------------------------------------------------------- equivalence with the data pipeline
def test_physics_runner_reproduces_the_table_pipeline(cache_dir):
    """The sealed run through the environment gives the decisions of the same method run in process on the tables."""
    from fuelhm_baselines.paper_mahalanobis import PaperMahalanobis
    from fuelhm_bench.datasets.cache import scored_indicators
    from fuelhm_bench.methods import run_table

    sc = tiny()
    evaluation = prepare_evaluation(sc, fidelity="physics", knowledge_size=SIZE, cache_dir=cache_dir)
    columns = list(evaluation.fit_indicators.columns)  # the observation's columns (no n_points, quality_reason)
    assert columns == ["flight_id", "unit_id", "flight_index", *INDICATOR_NAMES,
                       *(f"{n}_valid" for n in INDICATOR_NAMES), *EXTENDED_INDICATOR_NAMES,
                       *(f"{n}_valid" for n in EXTENDED_INDICATOR_NAMES)]
    assert set(evaluation.fit_indicators["unit_id"]).isdisjoint(evaluation.calibration_indicators["unit_id"])
    method = PaperMahalanobis().fit(evaluation.fit_indicators, knowledge=evaluation.method_knowledge, random_state=0)
    healthy = run_table(method, evaluation.calibration_indicators)["score"].to_numpy()
    test_ind = scored_indicators(sc, units=3, cache_dir=cache_dir)
    reference_decisions = run_table(method, test_ind[columns])
    outcome = run_in_env(PaperMahalanobis(), evaluation)
    assert outcome.ok, outcome.message
    assert set(LABEL_COLUMNS) <= set(outcome.labels.columns) and len(outcome.labels) == len(test_ind)
    np.testing.assert_array_equal(outcome.healthy_scores, healthy)
    assert outcome.fit_seconds >= 0 and outcome.decide_seconds > 0
    reference = Outcome("ref", "ok", decisions=reference_decisions)
    # the environment's observations are float32: scores agree to float32 precision
    np.testing.assert_allclose(outcome.decisions["score"], reference.decisions["score"], rtol=1e-4)
    assert (outcome.decisions["alarm"] == reference.decisions["alarm"]).mean() >= 0.95
    card = outcome.score()
    assert 0.0 <= card.summary_score <= 100.0


def test_surrogate_null_method_cost_is_the_cost_model(surrogate_eval):
    """A never-alarming method pays undetected_flight_kusd per detectable flight and failure_kusd per failure;
    a failure overhauls the unit (every present mode is removed), as the maintenance protocol says."""
    outcome = run_in_env(NullMethod(), surrogate_eval)
    assert outcome.ok and outcome.fidelity == "surrogate" and outcome.scenario == surrogate_eval.scenario.id == f"tiny-v{surrogate_eval.scenario.version}"
    costs = surrogate_eval.scenario.costs
    assert outcome.costs == costs
    expected, failures = 0.0, 0
    for _, unit in outcome.labels.groupby("unit_id"):
        inten = unit[[f"intensity_{m}" for m in MODE_IDS]].to_numpy()
        maxi = unit[[f"max_intensity_{m}" for m in MODE_IDS]].to_numpy()
        removed = np.zeros(7, bool)
        for t in range(len(unit)):
            present = (inten[t] > 0) & ~removed
            expected += costs.undetected_flight_kusd * (present & (inten[t] >= costs.detectable_fraction
                                                                   * maxi[t])).any()
            if (present & (inten[t] >= costs.failure_fraction * maxi[t])).any():
                expected += costs.failure_kusd
                failures += 1
                removed |= present
    assert failures >= 1 and outcome.cost_kusd == pytest.approx(expected)
    kpis = outcome.kpis()
    assert kpis["fnr_standard_alarm"] == 1.0 and kpis["cost_kusd"] == outcome.cost_kusd
    assert list(outcome.episodes["unit_id"]) == [0, 1, 2]


# --------------------------------------------------------------------------- safety
def test_misbehaving_methods_are_reported_and_others_unaffected(surrogate_eval):
    outcomes = {type(m).__name__: run_in_env(m, surrogate_eval, timeout_s=3.0)
                for m in (Raises(), Hangs(), NaNScore(), NotADecision(), Exits(), Peeks())}
    assert outcomes["Raises"].status == "error" and "boom at flight 3" in outcomes["Raises"].message
    assert outcomes["Hangs"].status == "timeout" and "3 s" in outcomes["Hangs"].message
    assert outcomes["NaNScore"].status == "invalid" and "NaNScore returned an invalid decision" in \
        outcomes["NaNScore"].message
    assert outcomes["NotADecision"].status == "invalid" and "not a Decision" in outcomes["NotADecision"].message
    assert outcomes["Exits"].status == "crash" and "exit code 7" in outcomes["Exits"].message
    assert outcomes["Peeks"].ok, outcomes["Peeks"].message
    for name in ("Raises", "Hangs", "NaNScore", "Exits"):
        assert outcomes[name].decisions is None and outcomes[name].labels is None
        with pytest.raises(Exception, match="Cannot score"):
            outcomes[name].run()
    assert run_in_env(IdleCurrent(), surrogate_eval).ok  # the evaluation is still usable


def test_environment_failure_is_not_blamed_on_the_method(cache_dir):
    evaluation = prepare_evaluation(tiny(), fidelity="surrogate", knowledge_size=SMALL,
                                    cache_dir=cache_dir)

    def broken(action):
        raise FloatingPointError("simulator diverged")

    evaluation.env.step = broken
    outcome = run_in_env(NullMethod(), evaluation)
    assert outcome.status == "error" and outcome.message.startswith("The environment failed (not the method)")
    assert "simulator diverged" in outcome.message


def test_progress_counts_every_scored_flight(surrogate_eval):
    done = []
    assert run_in_env(NullMethod(), surrogate_eval, progress=done.append).ok
    assert done == [8, 8, 8] and sum(done) == surrogate_eval.n_flights


def test_one_call_evaluate_with_progress_bars(cache_dir, tmp_path):
    from tqdm import tqdm

    outcome = evaluate(IdleCurrent(), tiny(), fidelity="surrogate", knowledge_size=SMALL,
                       cache_dir=cache_dir, progress=tqdm)
    assert outcome.ok and len(outcome.decisions) == 24
    assert set(outcome.kpis().index) >= {"summary_score", "cost_kusd"}


def test_drift_scenario_prepares_the_nominal_fleet(cache_dir):
    evaluation = prepare_evaluation(tiny("robustness_drift", name="drifty"), fidelity="surrogate",
                                    knowledge_size=SMALL, cache_dir=cache_dir)
    nominal = evaluation.nominal
    assert nominal is not None and nominal.env.drifted is False and evaluation.env.drifted is True
    a, b = run_in_env(NullMethod(), evaluation), run_in_env(NullMethod(), nominal)
    pd.testing.assert_frame_equal(a.labels, b.labels)  # same fleet and faults, only the nominal model differs
    assert prepare_evaluation(tiny(), fidelity="surrogate", knowledge_size=SMALL,
                              cache_dir=cache_dir).nominal is None


def test_seed_and_scale(cache_dir):
    evaluation = prepare_evaluation(tiny(), fidelity="surrogate", seed=5, scale=0.4,
                                    knowledge_size=SMALL, cache_dir=cache_dir)
    # --scale keeps every mode of the fleet: the first round(0.4 * 3) = 1 unit, extended as needed
    from fuelhm_bench.datasets.cache import resolve_scenario
    from fuelhm_bench.flights.scale import scaled_unit_count

    sc = resolve_scenario(tiny())
    sc = dataclasses.replace(sc, seeds=dataclasses.replace(sc.seeds, master=5, training=None, test=None))
    n = scaled_unit_count(sc.test_fleet_config(), 0.4)
    assert evaluation.units == tuple(range(n)) and evaluation.scenario.seeds.master == 5
    assert evaluation.n_flights == 8 * n


@pytest.mark.parametrize("kwargs, match", [
    ({"seed": -1}, r"'seed' parameter of prepare_evaluation must be an int in \[0, "),
    ({"scale": 0.0}, r"'scale' parameter of prepare_evaluation must be a finite number > 0"),
    ({"fidelity": "fast"}, r"'fidelity' parameter .*Got 'fast'"),
    ({"knowledge_size": {"doe_unts": 1}}, r"Did you mean 'doe_units'"),
])
def test_bad_arguments(cache_dir, kwargs, match):
    with pytest.raises(ParameterError, match=match):
        prepare_evaluation(tiny(), **{"knowledge_size": SMALL, "cache_dir": cache_dir, **kwargs})


def test_bad_timeout(surrogate_eval):
    with pytest.raises(ParameterError, match="'timeout_s' parameter of run_in_env must be a number > 0"):
        run_in_env(NullMethod(), surrogate_eval, timeout_s=0)


def test_outcome_is_a_frozen_record():
    outcome = Outcome("m", "error", "bad")
    assert not outcome.ok and np.isnan(outcome.cost_kusd)
    with pytest.raises(dataclasses.FrozenInstanceError):
        outcome.status = "ok"


# --------------------------------------------------------------------------- the README example
README_EXAMPLE = '''
import numpy as np
from fuelhm_bench.methods import BaseMethod, Decision
from fuelhm_bench.benchmark.harness import evaluate

class IdleCurrent(BaseMethod):          # alarms when I0 (mA) leaves its healthy band
    def __init__(self, *, a=4.0):
        self.a = a
    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        self.mu_, self.sd_ = healthy["I0"].mean(), healthy["I0"].std()
    def _decide(self, row):
        z = 0.0 if np.isnan(row["I0"]) else abs(row["I0"] - self.mu_) / self.sd_
        return Decision(score=z, alarm=z > self.a, guilt=np.eye(7)[1] * (z > self.a))

outcome = evaluate(IdleCurrent(), "my_scenario.yaml", fidelity="surrogate")
print(outcome.status, outcome.kpis()[["fpr_standard_thr", "fnr_standard_thr", "cost_kusd"]])
'''


def test_readme_example_runs_on_a_custom_scenario(tmp_path, monkeypatch, capsys):
    leak = dataclasses.replace(tiny().degradations[1], probability=0.7)  # internal leakage in 70 % of the units
    sc = tiny(name="my_scenario", degradations=(leak,), healthy_probability=0.3)
    (tmp_path / "my_scenario.yaml").write_text(yaml.safe_dump(sc.to_dict(), sort_keys=False))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("FUELHM_BENCH_CACHE", str(tmp_path / "cache"))
    code = README_EXAMPLE.replace('fidelity="surrogate")', 'fidelity="surrogate", knowledge_size=SMALL)')
    exec(compile(code, "README.md", "exec"), {"SMALL": SMALL, "__name__": "readme"})
    out = capsys.readouterr().out
    assert out.startswith("ok") and "cost_kusd" in out
    assert len(README_EXAMPLE.strip().splitlines()) <= 16


def test_a_duration_override_is_held_to_the_run_budget(monkeypatch):
    """``--minutes`` / ``flight_minutes`` bypassed the run budget a scenario file is held to (a 1440-minute
    override of paper_2012 started a 31,000 flight-hour run without a word)."""
    monkeypatch.delenv("FUELHM_RUN_BUDGET_FLIGHT_HOURS", raising=False)
    with pytest.raises(ParameterError, match=r"1300 flights of 1440 min of scenario paper_2012-v3 are 3.12e\+04 "
                                             r"flight-hours, over the run budget of 2000"):
        prepare_evaluation("paper_2012", fidelity="surrogate", flight_minutes=1440)
    monkeypatch.setenv("FUELHM_RUN_BUDGET_FLIGHT_HOURS", "40000")  # raised on purpose: the override is allowed
    from fuelhm_bench.datasets.cache import _check_minutes
    from fuelhm_bench.scenarios import load_scenario

    _check_minutes(1440, "x", load_scenario("paper_2012"))


# --------------------------------------------------------------------------- scenarios that excite too little
def _indicator_table(n: int, valid: dict, reason: str = "") -> pd.DataFrame:
    """``n`` flights, every indicator valid except ``valid[name]`` flights of ``name``."""
    data = {"unit_id": np.arange(n) // 2}
    for name in (*INDICATOR_NAMES, *EXTENDED_INDICATOR_NAMES):
        data[f"{name}_valid"] = np.arange(n) < valid.get(name, n)
    data["quality_reason"] = ["" if all(data[f"{k}_valid"][i] for k in valid) else reason for i in range(n)]
    return pd.DataFrame(data)


def test_check_training_indicators_rule():
    """Each of the paper's ten valid in >= 11 / knowledge_flights of the training flights; at the surrogate
    fidelity every extended indicator valid somewhere."""
    from fuelhm_bench.datasets.checks import check_training_indicators
    from fuelhm_bench.errors import ScenarioError

    def check(table, fidelity="physics", knowledge_flights=40):
        check_training_indicators(table, "x.yaml (x-v1)", fidelity=fidelity, knowledge_flights=knowledge_flights)

    check(_indicator_table(400, {"X1": 110}))  # 27.5 %: the published knowledge's 40 flights expect 11
    check(_indicator_table(400, {"V_in7": 0}))  # physics: the extended indicators are not needed
    with pytest.raises(ScenarioError) as info:
        check(_indicator_table(400, {"X1": 109, "Y1": 109, "Inb": 3}, reason="X1: slope change at 2.5 mA"))
    message = str(info.value)
    assert message.startswith("x.yaml (x-v1): too few valid indicators in its 400 healthy training flights. "
                              "Valid in 3 flights: Inb; in 109: X1, Y1 (each of the paper's ten must be valid in at "
                              "least 27.5 % of them")
    assert "Main reasons: 'X1: slope change at 2.5 mA' (397 flights)." in message
    assert "mission.test_sweep" in message and "sensor.adc_bits" in message
    with pytest.raises(ScenarioError, match=r"too few .* Valid in 10 flights: X1 .* 11 of its 16 healthy flights"):
        check(_indicator_table(16, {"X1": 10}), knowledge_flights=16)
    with pytest.raises(ScenarioError, match=r"At the surrogate fidelity, V_in7, V_out7 must be valid in some flights"):
        check(_indicator_table(400, {"V_in7": 0, "V_out7": 0}), fidelity="surrogate")


@pytest.mark.parametrize("fidelity", ["physics", "surrogate"])
def test_a_scenario_without_test_sweep_is_refused_with_its_file_and_fields(tmp_path, cache_dir, fidelity):
    """test_sweep: false passed validate, then every evaluate failed in the knowledge build with "HealthyModel
    needs at least 11 healthy flights ... use the 'features' parameter" (a Python parameter, no file, no field)."""
    from conftest import _tiny_scenario
    from fuelhm_bench.errors import ScenarioError

    path = _tiny_scenario(tmp_path, "no_sweep")
    path.write_text(path.read_text().replace("test_sweep: true", "test_sweep: false"))
    with pytest.raises(ScenarioError) as info:
        prepare_evaluation(path, fidelity=fidelity, knowledge_size=SMALL, cache_dir=cache_dir)
    message = str(info.value)
    assert message.startswith(f"{path} (no_sweep-v3): too few valid indicators in its 24 healthy training flights")
    assert "Valid in 0 flights: X1, Y1" in message and "Main reasons: '" in message
    assert "mission.test_sweep" in message and "HealthyModel" not in message
    from fuelhm_bench.benchmark.exchange import scenario_tables  # export / score: the same rule, before writing

    with pytest.raises(ScenarioError, match=r"no_sweep-v3\): too few valid indicators in its 24 healthy training"):
        scenario_tables(path, fidelity=fidelity, knowledge_size=SMALL, cache_dir=cache_dir)
    # the environment on its own (gym.make): at the surrogate fidelity it learns from healthy flights of its own
    # and from the published knowledge, and each build refuses them the same way, naming the file
    import gymnasium as gym

    from fuelhm_bench.datasets.cache import published_knowledge

    with pytest.raises(ScenarioError, match=rf"{path} \(no_sweep-v3\): too few valid indicators in its \d+ healthy "
                                            r"flights of its published knowledge.*mission.test_sweep") as info:
        published_knowledge(path, size=SMALL, cache_dir=cache_dir)
    assert "HealthyModel" not in str(info.value)
    if fidelity == "surrogate":
        with pytest.raises(ScenarioError, match=r"no_sweep-v3\): too few valid indicators in its \d+ healthy flights"):
            gym.make("FuelHM/ActuationLoop-v3", scenario=path, fidelity="surrogate", knowledge_size=SMALL,
                     cache_dir=cache_dir)
