"""The scikit-learn and PyOD adapters, the batch decision path, and the README recipes."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone
from sklearn.ensemble import IsolationForest
from sklearn.neighbors import LocalOutlierFactor

from fuelhm_bench.errors import MethodError, ParameterError
from fuelhm_bench.methods import (NullMethod, check_method, has_batch_path, make_check_data,
                                  run_table, run_unit)
from fuelhm_bench.methods.adapters import PyODMethod, SklearnMethod, indicator_matrix
from fuelhm_bench.taxonomy import INDICATOR_NAMES

README = Path(__file__).resolve().parents[1] / "README.md"
SMALL = dict(n_units=3, n_flights=8)


@pytest.fixture(scope="module")
def data():
    return make_check_data(0, **SMALL)


def _fitted(method, data, seed=0):
    return method.fit(data.healthy, knowledge=data.knowledge, random_state=seed)


@pytest.mark.slow  # ~5 s quiet; the README pipeline recipe runs check_method in the default run
def test_sklearn_forest_adapter_passes_check_method(data):
    check_method(SklearnMethod(estimator=IsolationForest(n_estimators=20)), data=data)


def test_threshold_comes_from_held_out_units_only(data):
    m = _fitted(SklearnMethod(estimator=IsolationForest(n_estimators=20), quantile=0.9), data)
    healthy = data.healthy
    # 4 training units, calibration_fraction 0.25: one whole unit held out, 3 used to fit
    assert m.n_fit_flights_ == 45 and m.n_calibration_flights_ == 15
    x = indicator_matrix(healthy)
    z = (x - m.feature_mean_) / m.feature_std_
    scores = -m.detector_.score_samples(z)
    held = np.isin(np.round(scores, 12), np.round(m.calibration_scores_, 12))
    held_units = set(healthy.loc[held, "unit_id"])
    assert len(held_units) == 1
    fit_part = healthy[~healthy["unit_id"].isin(held_units)]
    np.testing.assert_allclose(m.feature_mean_, np.nanmean(indicator_matrix(fit_part), axis=0))
    assert m.threshold_ == pytest.approx(np.quantile(m.calibration_scores_, 0.9))
    # the detector was fitted on the fit units only: refit there, same scores
    twin = clone(m.detector_).fit((indicator_matrix(fit_part) - m.feature_mean_) / m.feature_std_)
    np.testing.assert_allclose(-twin.score_samples(z), scores)
    # scored flights play no part: deciding on other units does not move the threshold
    before = m.threshold_
    run_table(m, data.units)
    assert m.threshold_ == before


def test_batch_path_equals_row_by_row_and_is_causal(data):
    m = _fitted(SklearnMethod(estimator=IsolationForest(n_estimators=20)), data)
    assert has_batch_path(m) and not has_batch_path(NullMethod())
    batch = run_table(m, data.units)
    rows = pd.concat([run_unit(m, t) for _, t in data.unit_tables()], ignore_index=True)
    pd.testing.assert_frame_equal(batch[["unit_id", "flight_index", "alarm"]],
                                  rows[["unit_id", "flight_index", "alarm"]])
    np.testing.assert_allclose(batch.drop(columns=["unit_id", "flight_index", "alarm"]),
                               rows.drop(columns=["unit_id", "flight_index", "alarm"]),
                               rtol=1e-9, atol=1e-12)
    assert batch["alarm"].any() and not batch["alarm"].all()


def test_run_table_batches_in_causal_waves(data):
    seen = []

    class Spy(SklearnMethod):
        def _decide_batch(self, rows):
            seen.append(rows[["unit_id", "flight_index"]].copy())
            return super()._decide_batch(rows)

    m = _fitted(Spy(estimator=IsolationForest(n_estimators=5)), data)
    shuffled = data.units.sample(frac=1.0, random_state=0)
    out = run_table(m, shuffled)
    assert len(seen) == SMALL["n_flights"]
    for k, wave in enumerate(seen):  # wave k: flight k of every unit, nothing later
        assert wave["unit_id"].is_unique and set(wave["flight_index"]) == {k}
    assert list(pd.unique(out["unit_id"])) == list(pd.unique(shuffled["unit_id"]))


def test_decide_batch_without_batch_path_is_refused(data):
    m = NullMethod().fit(data.healthy, random_state=0)
    with pytest.raises(MethodError, match="no batch decision path"):
        m.decide_batch(data.units)


def test_invalid_batch_output_names_the_flight(data):
    class Bad(SklearnMethod):
        def _decide_batch(self, rows):
            score, alarm, guilt = super()._decide_batch(rows)
            score[3] = np.nan
            return score, alarm, guilt

    m = _fitted(Bad(estimator=IsolationForest(n_estimators=5)), data)
    with pytest.raises(MethodError, match=r"Bad returned an invalid decision for unit "
                                          r"'check-0', flight 3: a non-finite score"):
        m.decide_batch(data.units)


@pytest.mark.parametrize("estimator, match", [
    (None, "must be an unfitted scikit-learn estimator instance"),
    (IsolationForest, "must be an unfitted scikit-learn estimator instance"),
    (LocalOutlierFactor(), "novelty=True"),
    ("sklearn.ensemble:NoSuchForest", "cannot be imported"),
    ("IsolationForest", "'package.module:Class' string"),
])
def test_bad_estimator_is_named(data, estimator, match):
    with pytest.raises(ParameterError, match=match):
        _fitted(SklearnMethod(estimator=estimator), data)


def test_bad_hyperparameter_is_named(data):
    with pytest.raises(ParameterError, match="The 'quantile' parameter of SklearnMethod must be "
                                             "a float in \\(0.5, 1\\). Got 1.5 instead."):
        _fitted(SklearnMethod(estimator=IsolationForest(), quantile=1.5), data)


def test_too_few_flights_to_calibrate():
    tiny = make_check_data(0).healthy.iloc[:3]
    with pytest.raises(ParameterError, match="at least 2 flights to fit and 2 held-out"):
        SklearnMethod(estimator=IsolationForest()).fit(tiny, random_state=0)


def test_single_unit_holds_out_its_last_flights(data):
    one = data.healthy[data.healthy["unit_id"] == data.healthy["unit_id"].iloc[0]]
    m = SklearnMethod(estimator=IsolationForest(n_estimators=5)).fit(one, random_state=0)
    assert (m.n_fit_flights_, m.n_calibration_flights_) == (12, 3)


def test_seed_reaches_nested_random_state(data):
    a = _fitted(SklearnMethod(estimator=IsolationForest(n_estimators=5)), data, seed=1)
    b = _fitted(SklearnMethod(estimator=IsolationForest(n_estimators=5)), data, seed=2)
    assert isinstance(a.detector_.random_state, int)
    assert a.detector_.random_state != b.detector_.random_state


# --------------------------------------------------------------------------- README recipes
def _readme_section() -> str:
    text = README.read_text()
    start = text.index("## Library detectors as methods")
    return text[start:text.index("\n## ", start + 3)]


def _evaluate_lines() -> list[tuple[str, dict]]:
    from fuelhm_bench.benchmark.loading import parse_params

    bash = re.search(r"```bash\n(.*?)```", _readme_section(), re.S).group(1).replace("\\\n", " ")
    out = []
    for line in bash.strip().splitlines():
        method = re.search(r"--method (\S+)", line).group(1)
        out.append((method, parse_params(re.findall(r"--param (\S+)", line))))
    return out


def test_readme_section_is_short():
    code = re.findall(r"```\w+\n(.*?)```", _readme_section(), re.S)
    assert all(len(block.strip().splitlines()) < 10 for block in code)


def test_readme_pipeline_recipe(tmp_path, monkeypatch):
    from fuelhm_bench.methods.loading import load_method

    code = re.search(r"```python\n(.*?)```", _readme_section(), re.S).group(1)
    (tmp_path / "my_ocsvm.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_ocsvm", raising=False)
    method = load_method("my_ocsvm:ScaledOCSVM")
    check_method(method, data=make_check_data(0, **SMALL))
    lines = _evaluate_lines()
    sk = [(m, p) for m, p in lines if m.endswith(":SklearnMethod")]
    assert sk == [("fuelhm_bench.methods.adapters:SklearnMethod",
                   {"estimator": "sklearn.ensemble:IsolationForest"})]
    # from the README to a scored row (fit on healthy units, decide on the drifting units, score)
    assert _score_in_process(method).summary_score > 0
    forest = load_method(*sk[0]).fit(make_check_data(0, **SMALL).healthy, random_state=0)
    assert type(forest.detector_).__name__ == "IsolationForest"


def test_readme_pipeline_recipe_through_the_cli(tmp_path, monkeypatch, tiny_scenario, capsys):
    """The README's two steps as a user runs them: my_ocsvm.py in the working directory, then its evaluate line.

    The output folder is inside the working directory, as in the README. Before the sandbox granted the
    directory around it, the sealed process could not import ``my_ocsvm`` (the recipe test above loads the
    class in this process, so it did not see that).
    """
    from fuelhm_bench.cli import main

    code = re.search(r"```python\n(.*?)```", _readme_section(), re.S).group(1)
    line = re.search(r"Then `(fuelhm-bench evaluate [^`]+)`", _readme_section()).group(1)
    (tmp_path / "scenario").mkdir()
    scenario = tiny_scenario(tmp_path / "scenario")
    project = tmp_path / "project"
    project.mkdir()
    (project / "my_ocsvm.py").write_text(code)
    monkeypatch.chdir(project)
    argv = line.split()[1:]
    argv[argv.index("--scenario") + 1] = str(scenario)
    assert argv[argv.index("--out") + 1] == "results/"
    assert main(argv) == 0, capsys.readouterr().err[-2000:]
    board = pd.read_csv(project / "results" / "leaderboard.csv")
    assert board["status"].tolist() == ["ok"] and board["method"].tolist() == ["my_ocsvm:ScaledOCSVM"]


def _score_in_process(method):
    """Fit on the check data's healthy flights, decide on its drifting units, score against their labels."""
    from fuelhm_bench.methods import run_table
    from fuelhm_bench.scoring import Run, score_run
    from fuelhm_bench.taxonomy import MODE_IDS

    d = make_check_data(0, **SMALL)
    n, onset = SMALL["n_flights"], SMALL["n_flights"] // 3
    rows = []
    for u in range(SMALL["n_units"]):
        for k in range(n):
            inten = float(np.clip((k - onset + 1) / (n - onset), 0, 1)) if u else 0.0
            row = {"unit_id": f"check-{u}", "flight_index": k}
            for j, m in enumerate(MODE_IDS):
                active = u and j == u % len(MODE_IDS)
                row[f"intensity_{m}"] = inten if active else 0.0
                row[f"max_intensity_{m}"] = 1.0 if active else 0.0
                row[f"onset_{m}"] = onset if active else -1
            rows.append(row)
    method.fit(d.healthy, knowledge=d.knowledge, random_state=0)
    healthy = run_table(method, d.healthy.iloc[:20])["score"].to_numpy()
    return score_run(Run(labels=pd.DataFrame(rows), decisions=run_table(method, d.units), healthy_scores=healthy))


def test_readme_pyod_recipe(data):
    pytest.importorskip("pyod", reason="PyOD is an optional extra: pip install 'fuelhm-bench[pyod]'")
    from fuelhm_bench.methods.loading import load_method

    [(spec, params)] = [(m, p) for m, p in _evaluate_lines() if m.endswith(":PyODMethod")]
    assert params == {"detector": "pyod.models.ecod:ECOD"}
    m = _fitted(load_method(spec, params), data)
    assert type(m.detector_).__name__ == "ECOD"
    # PyOD's own contamination threshold is not used: ours comes from held-out units
    assert m.threshold_ == pytest.approx(np.quantile(m.calibration_scores_, 0.99))


@pytest.mark.slow  # ECOD scores one flight per call: ~10 s
def test_pyod_ecod_passes_check_method(data):
    pytest.importorskip("pyod", reason="PyOD is an optional extra: pip install 'fuelhm-bench[pyod]'")
    from pyod.models.ecod import ECOD

    check_method(PyODMethod(detector=ECOD()), data=data)


def test_pyod_scores_each_flight_alone(data):
    pytest.importorskip("pyod", reason="PyOD is an optional extra: pip install 'fuelhm-bench[pyod]'")
    from pyod.models.ecod import ECOD

    m = _fitted(PyODMethod(detector=ECOD()), data)
    rows = data.units.iloc[:6]
    alone = np.concatenate([m.decide_batch(rows.iloc[[i]])["score"].to_numpy()
                            for i in range(len(rows))])
    np.testing.assert_allclose(m.decide_batch(rows)["score"].to_numpy(), alone, rtol=1e-12)


def test_pyod_missing_detector_is_named(data):
    with pytest.raises(ParameterError, match="must be an unfitted PyOD detector instance"):
        _fitted(PyODMethod(), data)


def test_indicator_matrix_masks_invalid(data):
    x = indicator_matrix(data.units)
    assert x.shape == (len(data.units), len(INDICATOR_NAMES))
    assert np.isnan(x).sum() == (~data.units[[f"{n}_valid" for n in INDICATOR_NAMES]]
                                 .to_numpy(bool)).sum() >= 1
