"""Raw-signal methods through the harness: fit on raw training flights, full-rate flights per decision, sealed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fuelhm_bench.benchmark.harness import evaluate, prepare_evaluation, run_in_env
from fuelhm_bench.benchmark.raw_flights import training_raw_flights
from fuelhm_bench.envs import KnowledgeSize
from fuelhm_bench.envs.actuation_loop import RAW_FLIGHT_SIGNALS, ActuationLoopEnv
from fuelhm_bench.errors import MethodError, ParameterError
from fuelhm_bench.indicators import extract_indicators
from fuelhm_bench.methods import BaseMethod, Decision, NullMethod, check_method, iter_checks, make_check_data
from fuelhm_bench.scenarios import load_scenario
from fuelhm_bench.taxonomy import INDICATOR_NAMES

RAW_ENTRY = "fuelhm_baselines.raw_tracking:RawTrackingMethod"


def _small():
    sc = load_scenario("paper_2012")
    degradations = tuple(dataclasses.replace(d, onset_min=1, onset_max=2, ramp_flights=2) for d in sc.degradations)
    return dataclasses.replace(sc, fleet=dataclasses.replace(sc.fleet, units=2, flights_per_unit=4),
                               degradations=degradations,
                               mission=dataclasses.replace(sc.mission, duration_min=2.0),
                               training=dataclasses.replace(sc.training, units=4, flights_per_unit=3))


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory):
    return prepare_evaluation(_small(), fidelity="physics", knowledge_size=KnowledgeSize.small(), robustness=False,
                              cache_dir=tmp_path_factory.mktemp("raw-cache"))


class SampleCounter(BaseMethod):
    """Scores each flight by its number of raw samples; checks it got every training flight."""

    needs_raw = True

    def __init__(self, *, offset: float = 0.0):
        self.offset = offset

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        keys = [(f.unit_id, f.flight_index, f.n_samples) for f in raw_flights]
        expected = list(zip(healthy["unit_id"], healthy["flight_index"]))
        if [k[:2] for k in keys] != expected:
            raise ValueError(f"raw training flights {[k[:2] for k in keys]} != table rows {expected}")
        self.samples_ = keys[0][2]

    def _decide(self, row, raw):
        return Decision.no_alarm(float(raw.n_samples) + self.offset + 1e-3 * float(raw.current_mA.mean()))


def test_training_raw_flights_are_the_flights_of_the_cached_table(evaluation):
    """Flown again from their seeds, the raw training flights give the cached indicators bit for bit."""
    table = evaluation.fit_indicators
    unit = int(table["unit_id"].iloc[-1])
    flights = list(training_raw_flights(evaluation.scenario, [unit], flight_minutes=evaluation.env.flight_minutes))
    rows = table[table["unit_id"] == unit].sort_values("flight_index")
    assert [f.flight_index for f in flights] == rows["flight_index"].tolist()
    for f, (_, row) in zip(flights, rows.iterrows()):
        result = extract_indicators(f.time_s, f.current_mA, f.position_mm, flight_id=0)
        got = [result.values[n] if result.valid[n] else np.nan for n in INDICATOR_NAMES]
        np.testing.assert_array_equal(got, row[list(INDICATOR_NAMES)].to_numpy(float))
        assert np.all(np.isfinite(f.demand_mm)) and np.all(np.isfinite(f.n2_pct))


def test_raw_method_runs_sealed_with_full_rate_flights(evaluation):
    outcome = run_in_env(SampleCounter(), evaluation)
    assert outcome.status == "ok", outcome.message
    n_samples = round(evaluation.scenario.mission.duration_min * 60 / 0.01)  # every 10 ms sample
    scores = outcome.decisions["score"].to_numpy()
    assert np.all(np.abs(scores - n_samples) < 1.0) and np.ptp(scores) > 0  # per-flight samples, not resampled
    assert np.all(np.abs(outcome.healthy_scores - n_samples) < 1.0)
    assert len(outcome.healthy_scores) == len(evaluation.calibration_indicators)


@pytest.mark.slow  # the sealed raw path runs in the default run through the docs recipe below
def test_raw_baseline_scores_through_the_sealed_harness(evaluation):
    outcome = run_in_env(RAW_ENTRY, evaluation)
    assert outcome.status == "ok", outcome.message
    assert np.isfinite(outcome.kpis()["summary_score"])


def test_raw_method_is_refused_at_surrogate_fidelity(evaluation):
    outcome = run_in_env(RAW_ENTRY, dataclasses.replace(evaluation, fidelity="surrogate"))
    assert outcome.status == "refused"
    assert "needs the raw flights" in outcome.message and "physics" in outcome.message
    assert "\n" not in outcome.message
    with pytest.raises(ParameterError, match="needs the raw flights .*fidelity='physics'"):
        evaluate(SampleCounter(), "paper_2012", fidelity="surrogate")


def test_environment_raw_flight_is_full_rate_and_uncapped():
    env = ActuationLoopEnv(scenario="paper_2012", fidelity="physics", flight_minutes=20.0, maintenance=False)
    obs, info = env.reset(options={"unit": 0, "raw_flight": True})
    raw = info["raw_flight"]
    assert set(raw) == set(RAW_FLIGHT_SIGNALS)
    n = raw["time_s"].size
    assert n == 120_000 > 100_000  # 20 min at 100 Hz: every sample, beyond the resampled view's 100,000 cap
    assert all(v.shape == (n,) and v.dtype == np.float64 for v in raw.values())
    result = extract_indicators(raw["time_s"], raw["current_mA"], raw["position_mm"], flight_id=0)
    valid = obs["valid"].astype(bool)
    np.testing.assert_allclose(obs["indicators"][valid],
                               np.array([result.values[n] for n in INDICATOR_NAMES])[valid], rtol=1e-6)
    _, info = env.reset(options={"unit": 0})
    assert "raw_flight" not in info
    with pytest.raises(ParameterError, match="'raw_flight' option .* must be a bool"):
        env.reset(options={"raw_flight": "yes"})


def test_raw_flight_option_refused_at_surrogate():
    # building a surrogate is costly; the option is checked against the fidelity attribute
    env = ActuationLoopEnv.__new__(ActuationLoopEnv)
    env.fidelity = "surrogate"
    with pytest.raises(ParameterError, match="'raw_flight' option .* needs fidelity='physics'"):
        ActuationLoopEnv.reset(env, options={"raw_flight": True})


class IgnoresRaw(SampleCounter):
    """Declares needs_raw but decides from the indicators only."""

    def _decide(self, row, raw):
        return Decision.no_alarm(float(np.nan_to_num(row["X1"])))


def test_check_method_passes_the_raw_baseline_and_catches_a_method_ignoring_its_flights():
    from fuelhm_baselines.raw_tracking import RawTrackingMethod

    check_method(RawTrackingMethod(random_state=0), sealed=False)
    data = make_check_data(0, raw=True)
    raw_used = {type(m).__name__: next(c for c in iter_checks(m, data=data) if c.name == "check_raw_used")
                for m in (SampleCounter(), IgnoresRaw())}
    raw_used["SampleCounter"]()
    with pytest.raises(MethodError, match="check_raw_used failed for IgnoresRaw: .*does not use the raw"):
        raw_used["IgnoresRaw"]()
    assert "check_raw_used" not in [c.name for c in iter_checks(NullMethod())]  # only for raw methods


def _docs_section() -> str:
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "methods.md").read_text()
    start = text.index("## 4b. Methods on the raw signals")
    return text[start:text.index("\n## ", start + 3)]


def test_docs_raw_recipe_runs_sealed_to_a_score(evaluation, tmp_path, monkeypatch):
    """The few-line recipe of docs/methods.md section 4b, from an empty file to a scored outcome."""
    import re
    import sys

    from fuelhm_bench.methods.loading import load_method

    section = _docs_section()
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert len(code.strip().splitlines()) <= 20
    command = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    entry = re.search(r"--method (\S+)", command).group(1)
    assert entry == "my_raw:TrackingError" and "--fidelity physics" in command
    (tmp_path / "my_raw.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_raw", raising=False)
    check_method(load_method(entry, {}), sealed=False)
    outcome = run_in_env(entry, evaluation)
    assert outcome.status == "ok", outcome.message
    assert np.isfinite(outcome.kpis()["summary_score"])


def test_a_method_built_here_may_import_an_editable_package(tmp_path, monkeypatch):
    """A class defined outside any package, subclassing a baseline, runs sealed (its imports are readable)."""
    import sys

    from fuelhm_bench.methods.sandbox import SealedMethod

    (tmp_path / "my_forest.py").write_text(
        "from fuelhm_baselines.raw_tracking import RawTrackingMethod\n\n"
        "class MyTracking(RawTrackingMethod):\n    pass\n")
    import os

    # the source folder of the editable install is not on the path (run from elsewhere, as a user would)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if not os.path.isdir(os.path.join(p or ".", "baselines"))])
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_forest", raising=False)
    from my_forest import MyTracking

    with SealedMethod(MyTracking(random_state=0)) as sealed:
        assert sealed.needs_raw
