"""Tests of the reference methods in ``baselines/`` (written against the public API only).

* conformance: every baseline passes ``check_method`` (several configurations);
* the paper's method on a synthetic world built with the public diagnosis API
  (healthy table + DOE -> ``fit_itl`` -> ``signature_matrix`` -> ``Knowledge``):
  alarms on strongly shifted flights and names the right mode by collinearity,
  false-alarm rate at ``A = 2`` close to the Gaussian expectation, the
  leave-one-out threshold is not biased low, smoothing, symmetric modes;
* the scikit-learn baselines: calibrated false-alarm rates, diagnosis;
* the methods differ; determinism under a seed.

Statistical tolerances are stated next to each test; every test uses fixed
seeds, so it is deterministic, but the bounds are set from the sampling
variability so that a real regression (not a reseeding) makes them fail.
"""

from __future__ import annotations

import ast
import math
import re
import sys
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.special import gammaln
from scipy.stats import chi2

import fuelhm_baselines
from fuelhm_baselines.isolation_forest import IsolationForestMethod
from fuelhm_baselines.itl_classifier import ITLClassifierMethod
from fuelhm_baselines.paper_mahalanobis import PaperMahalanobis
from fuelhm_baselines.trivial import NullMethod, RandomMethod
from fuelhm_bench.diagnosis import HealthyModel, fit_itl, signature_matrix
from fuelhm_bench.testing.diagnosis import DEFAULT_STD, make_doe_table, make_healthy_table
from fuelhm_bench.errors import MethodError, ParameterError
from fuelhm_bench.methods import (BaseMethod, CheckData, Knowledge, check_method, make_check_data, run_table,
                                  parametrize_with_checks)
from fuelhm_bench.methods import NullMethod as PackageNullMethod
from fuelhm_bench.methods import RandomMethod as PackageRandomMethod
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

IND = list(INDICATOR_NAMES)
GUILT = [f"guilt_{m}" for m in MODE_IDS]

# ----------------------------------------------------------------------------- instances
#: Configurations run through every conformance check. Small forests and few folds keep the
#: checks fast; conformance does not depend on those sizes (the default configurations of the
#: scikit-learn baselines are checked in the slow test below).
CHECK_INSTANCES = [
    NullMethod(),
    RandomMethod(),
    RandomMethod(alarm_probability=0.3, random_state=None),
    PaperMahalanobis(),
    PaperMahalanobis(a=1.0, window=3, cv=4, references="itl", symmetric_modes=()),
    PaperMahalanobis(cv=None, shrinkage=0.1, window=2),
    IsolationForestMethod(n_estimators=10, cv=2),
    IsolationForestMethod(n_estimators=5, cv=None, max_samples=0.5, diagnosis="uniform"),
    ITLClassifierMethod(cv=2, n_synthetic_per_mode=40),
    ITLClassifierMethod(cv=None, n_synthetic_per_mode=20, C=10.0, symmetric_modes=()),
]


@parametrize_with_checks(CHECK_INSTANCES)
def test_conformance(check):
    check()


@pytest.mark.slow
@pytest.mark.parametrize("method", [IsolationForestMethod(), ITLClassifierMethod()])
def test_conformance_default_configuration(method):
    check_method(method, sealed=False)


@pytest.mark.parametrize("method", [PaperMahalanobis(),
                                    IsolationForestMethod(n_estimators=5, cv=2)])
def test_conformance_without_knowledge(method):
    base = make_check_data(0)
    data = CheckData(healthy=base.healthy, other_healthy=base.other_healthy, units=base.units,
                     knowledge=Knowledge())
    check_method(method, data=data, sealed=False)


def test_itl_classifier_needs_knowledge():
    data = make_check_data(0)
    with pytest.raises(ValueError, match=r"The 'knowledge' parameter of ITLClassifierMethod.fit "
                                         r"must provide 'itl' and 'max_intensity' for at least "
                                         r"one mode. Got None instead."):
        ITLClassifierMethod().fit(data.healthy, random_state=0)
    base = make_check_data(0)
    data = CheckData(healthy=base.healthy, other_healthy=base.other_healthy, units=base.units,
                     knowledge=Knowledge(signatures=base.knowledge.signatures))
    with pytest.raises(MethodError, match=r"^check_fit_returns_self failed for "
                                          r"ITLClassifierMethod: raised ValueError: "
                                          r".*no such mode"):
        check_method(ITLClassifierMethod(cv=2), data=data, sealed=False)


# ----------------------------------------------------------------------------- entry points
def test_entry_points_load_public_methods():
    classes = {name: fuelhm_baselines.load(name) for name in fuelhm_baselines.ENTRY_POINTS}
    for name, entry in fuelhm_baselines.ENTRY_POINTS.items():
        cls = fuelhm_baselines.load(entry)
        assert cls is classes[name] and issubclass(cls, BaseMethod)
        module, _, class_name = entry.partition(":")
        assert cls.__name__ == class_name and module.startswith("fuelhm_baselines.")
    assert fuelhm_baselines.load("fuelhm_baselines.trivial:NullMethod") is PackageNullMethod
    assert issubclass(RandomMethod, PackageRandomMethod) and RandomMethod().random_state == 0
    with pytest.raises(KeyError, match="Unknown baseline 'nope'"):
        fuelhm_baselines.load("nope")
    with pytest.raises(ValueError, match="must look like 'module:Class'"):
        fuelhm_baselines.load("fuelhm_baselines.trivial:Null:Method")


def test_baselines_use_only_the_public_api():
    """Only public names of fuelhm_bench.methods / .diagnosis / .taxonomy are imported."""
    import importlib

    allowed = ("fuelhm_bench.methods", "fuelhm_bench.diagnosis", "fuelhm_bench.taxonomy")
    root = Path(fuelhm_baselines.__file__).parent
    for path in sorted(root.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                modules = [(a.name, []) for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                modules = [(node.module, [a.name for a in node.names])]
            else:
                continue
            for module, names in modules:
                if not module.startswith("fuelhm_bench"):
                    continue
                assert module.startswith(allowed), f"{path.name} imports {module}"
                assert not any(p.startswith("_") for p in module.split(".")), \
                    f"{path.name} imports private module {module}"
                public = getattr(importlib.import_module(module), "__all__", None)
                for name in names:
                    assert not name.startswith("_"), f"{path.name}: {module}.{name}"
                    assert public is None or name in public, f"{path.name}: {module}.{name}"


@pytest.mark.parametrize("method, match", [
    (PaperMahalanobis(a=-1), r"The 'a' parameter of PaperMahalanobis must be a float in "
                             r"\[0, inf\). Got -1 instead."),
    (PaperMahalanobis(window=0), r"The 'window' parameter of PaperMahalanobis must be an int"),
    (PaperMahalanobis(cv=1), r"The 'cv' parameter of PaperMahalanobis must be one of 'loo', 'units', "
                             r"an int in \[2, inf\) or None. Got 1 instead."),
    (PaperMahalanobis(symmetric_modes=["null_bias_drift"]),
     r"The 'symmetric_modes' parameter of PaperMahalanobis must be a tuple of distinct mode ids"),
    (PaperMahalanobis(symmetric_modes=("drift",)), r"'symmetric_modes' parameter"),
    (IsolationForestMethod(quantile=1.0), r"The 'quantile' parameter of IsolationForestMethod "
                                          r"must be a float in \(0, 1\). Got 1.0 instead."),
    (ITLClassifierMethod(detectable_fraction=1.0), r"The 'detectable_fraction' parameter"),
    (ITLClassifierMethod(C=0), r"The 'C' parameter of ITLClassifierMethod must be a float"),
])
def test_invalid_hyperparameters_are_rejected_in_fit(method, match):
    data = make_check_data(0)
    with pytest.raises(ParameterError, match=match):
        method.fit(data.healthy, knowledge=data.knowledge, random_state=0)


def test_more_folds_than_flights_is_rejected():
    data = make_check_data(0)
    with pytest.raises(ValueError, match=r"The 'cv' parameter of PaperMahalanobis must not exceed "
                                         r"the number of healthy training flights \(60\). Got 61"):
        PaperMahalanobis(cv=61).fit(data.healthy, knowledge=data.knowledge, random_state=0)


# ----------------------------------------------------------------------------- synthetic world
#: Z-scores of the indicators at maximal intensity of each mode (null-bias drift and internal
#: leakage from the paper's Table IV, the others after the expected signatures of docs/physics.md
#: §6 Degradation modes). The true ITL slopes are these times the healthy standard deviations.
SIGNATURE_Z = {
    "filter_contamination": {"Y1": 6, "Y2": -6, "G_in": -8, "G_out": -8, "G_null": -6},
    "null_bias_drift": {"X1": 24, "X2": 26, "Inb": 28, "I0": 24},
    "backlash": {"Hys0": 12, "G_null": -3, "I0": 2},
    "spool_friction": {"X1": -5, "X2": 5, "Hys0": 6, "G_null": -4},
    "radial_clearance": {"G_null": 8, "X1": -3, "X2": 3, "G_in": 2, "G_out": 2},
    "internal_leakage": {"Y1": 4, "Y2": 11, "I0": 1},
    "diaphragm_clogging": {"I0": -6, "Y1": -1, "Y2": -3},
}
TRUE_A = (pd.DataFrame(SIGNATURE_Z).T.reindex(index=list(MODE_IDS), columns=IND).fillna(0.0)
          * np.array([DEFAULT_STD[f] for f in IND]))


def _as_units(table: pd.DataFrame, n_units: int, prefix: str) -> pd.DataFrame:
    """Add unit_id / flight_index: consecutive rows form units of equal length."""
    out = table.copy()
    per = len(out) // n_units
    out["unit_id"] = [f"{prefix}-{i // per}" for i in range(len(out))]
    out["flight_index"] = np.arange(len(out)) % per
    return out


def _one_flight_units(table: pd.DataFrame, prefix: str) -> pd.DataFrame:
    out = table.copy()
    out["unit_id"] = [f"{prefix}-{i}" for i in range(len(out))]
    out["flight_index"] = 0
    return out


def _degraded(rng, n_per_mode: int, low: float, high: float, sign: float = 1.0) -> pd.DataFrame:
    """Fresh healthy flights moved by the true laws at intensities uniform in [low, high]."""
    parts = []
    for mode in MODE_IDS:
        t = make_healthy_table(n_per_mode, rng=rng)
        s = sign * rng.uniform(low, high, n_per_mode)
        t[IND] = t[IND].to_numpy() + s[:, None] * TRUE_A.loc[mode].to_numpy()
        t["true_mode"] = mode
        parts.append(t)
    return _one_flight_units(pd.concat(parts, ignore_index=True), "deg")


@pytest.fixture(scope="module")
def world():
    """Healthy training flights (20 units x 20 flights) and the published knowledge."""
    rng = np.random.default_rng(2012)
    doe = make_doe_table(TRUE_A, rng=rng, n_units=6)
    itl = fit_itl(doe)
    train = _as_units(make_healthy_table(400, rng=rng), 20, "train")
    sig = signature_matrix(itl, HealthyModel().fit(train), max_intensity=1.0)
    knowledge = Knowledge(itl=itl.table, signatures=sig,
                          max_intensity={m: 1.0 for m in MODE_IDS})
    fresh = _as_units(make_healthy_table(3000, rng=rng), 30, "fresh")
    strong = _degraded(rng, 40, 0.5, 1.0)
    return {"train": train, "knowledge": knowledge, "fresh": fresh, "strong": strong, "rng": rng}


@pytest.fixture(scope="module")
def fitted(world):
    """The default configuration of every non-trivial baseline, fitted once on the world."""
    methods = {"paper": PaperMahalanobis(), "iforest": IsolationForestMethod(),
               "itl": ITLClassifierMethod()}
    return {k: m.fit(world["train"], knowledge=world["knowledge"], random_state=0)
            for k, m in methods.items()}


#: Fresh healthy flights decided by each method (the isolation forest gets the first 1000: its
#: false-alarm tolerance below is computed for that many).
N_FRESH = {"paper": 3000, "iforest": 1000, "itl": 3000}


@pytest.fixture(scope="module")
def fresh_decisions(world, fitted):
    return {k: m.decide_table(world["fresh"].iloc[:N_FRESH[k]]) for k, m in fitted.items()}


@pytest.fixture(scope="module")
def strong_decisions(world, fitted):
    return {k: m.decide_table(world["strong"]) for k, m in fitted.items()}


def _per_mode(decisions: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Per true mode: detection rate, and share of alarms whose largest guilt is the true mode."""
    alarm = decisions["alarm"].to_numpy()
    top = np.asarray(MODE_IDS)[decisions[GUILT].to_numpy().argmax(axis=1)]
    right = top == truth["true_mode"].to_numpy()
    frame = pd.DataFrame({"mode": truth["true_mode"].to_numpy(), "alarm": alarm,
                          "right": np.where(alarm, right, np.nan)})
    return frame.groupby("mode").agg(detected=("alarm", "mean"), diagnosed=("right", "mean"))


def _chi_moments(k: int) -> tuple[float, float]:
    mean = math.sqrt(2.0) * math.exp(gammaln((k + 1) / 2) - gammaln(k / 2))
    return mean, math.sqrt(k - mean**2)


# ----------------------------------------------------------------------------- paper method
def test_paper_detects_and_diagnoses_strong_shifts(world, strong_decisions):
    """Intensities in [50 %, 100 %] of the maximum, 40 flights per mode.

    Every mode is detected on >= 90 % of its flights and, among alarms, the largest guilt
    is the true mode for >= 85 % of them (>= 95 % over all modes): the collinearity
    classifier of section VI.B.3 diagnoses "most of the time".
    """
    table = _per_mode(strong_decisions["paper"], world["strong"])
    assert (table["detected"] >= 0.90).all(), table
    assert (table["diagnosed"] >= 0.85).all(), table
    d = strong_decisions["paper"]
    top = np.asarray(MODE_IDS)[d[GUILT].to_numpy().argmax(axis=1)]
    assert np.mean(top[d["alarm"]] == world["strong"]["true_mode"].to_numpy()[d["alarm"]]) >= 0.95


def test_paper_guilt_follows_the_decision_contract(fresh_decisions, strong_decisions):
    for d in (fresh_decisions["paper"], strong_decisions["paper"]):
        g = d[GUILT].to_numpy()
        assert np.all(g[~d["alarm"]] == 0.0)
        np.testing.assert_allclose(g[d["alarm"]].sum(axis=1), 1.0, atol=1e-12)


def test_paper_false_alarm_rate_matches_gaussian_expectation(world, fitted, fresh_decisions):
    """False alarms on 3000 fresh healthy flights at A = 2.

    For a Gaussian healthy population the Mahalanobis score is chi-distributed with 10
    degrees of freedom; fitting it with a Gaussian as in eq. 10 and thresholding at
    mu + 2 sigma gives P = 2.9 % (the paper's Gaussian approximation says 1 - Phi(2) =
    2.3 %). With 400 training flights, the threshold's own sampling error moves the rate by
    about +/- 0.6 % (one sigma) and the 3000 test flights by +/- 0.3 %. Tolerance: the
    observed rate lies in [1.5 %, 4.5 %], and the training scores' mean and standard
    deviation are within 0.15 and 0.12 of the chi(10) values (3.08, 0.70).
    """
    method = fitted["paper"]
    mean, sd = _chi_moments(10)
    expected = chi2.sf((mean + 2 * sd) ** 2, 10)
    assert 0.028 < expected < 0.030
    far = fresh_decisions["paper"]["alarm"].mean()
    assert 0.015 <= far <= 0.045, far
    assert abs(method.mu_ - mean) < 0.15 and abs(method.sigma_ - sd) < 0.12
    assert method.threshold_ == pytest.approx(method.mu_ + 2.0 * method.sigma_)
    assert method.sigma_ == pytest.approx(np.std(method.training_scores_))  # ddof=0 (ML)


def test_leave_one_out_threshold_is_not_biased_low(world):
    """In-sample scores are smaller than the scores of unseen flights; LOO removes that bias.

    Fewer training flights make the bias larger, so the check uses 60 of them.
    """
    train = world["train"].iloc[:60]
    k = world["knowledge"]
    loo = PaperMahalanobis(cv="loo").fit(train, knowledge=k, random_state=0)
    kfold = PaperMahalanobis(cv=5).fit(train, knowledge=k, random_state=0)
    in_sample = PaperMahalanobis(cv=None).fit(train, knowledge=k, random_state=0)
    assert np.all(loo.training_scores_ > in_sample.training_scores_)
    assert loo.threshold_ > in_sample.threshold_ + 0.2
    assert kfold.mu_ > in_sample.mu_
    # The same healthy model decides in all three; only the threshold differs.
    np.testing.assert_array_equal(loo.healthy_model_.mean_, in_sample.healthy_model_.mean_)
    # The out-of-sample threshold keeps the false alarms of fresh flights lower.
    fresh = world["fresh"].iloc[:1000]
    far_loo = loo.decide_table(fresh)["alarm"].mean()
    far_in = in_sample.decide_table(fresh)["alarm"].mean()
    assert far_loo < far_in


def test_paper_smoothing_detects_small_persistent_shifts(world):
    """A persistent internal leakage at 20 % of its maximal intensity (Mahalanobis ~2.4)
    is rarely seen flight by flight but is detected once Z-scores are averaged over 10
    flights; the threshold is set on equally smoothed training scores, so it is lower."""
    rng = np.random.default_rng(7)
    units = _as_units(make_healthy_table(8 * 30, rng=rng), 8, "leak")
    units[IND] = units[IND].to_numpy() + 0.2 * TRUE_A.loc["internal_leakage"].to_numpy()
    k = world["knowledge"]
    single = PaperMahalanobis().fit(world["train"], knowledge=k, random_state=0)
    smooth = PaperMahalanobis(window=10).fit(world["train"], knowledge=k, random_state=0)
    assert smooth.threshold_ < single.threshold_ - 1.0
    late = units["flight_index"].to_numpy() >= 10
    rate_single = single.decide_table(units)["alarm"].to_numpy()[late].mean()
    d = smooth.decide_table(units)
    rate_smooth = d["alarm"].to_numpy()[late].mean()
    assert rate_single < 0.35 and rate_smooth > 0.8, (rate_single, rate_smooth)
    top = np.asarray(MODE_IDS)[d[GUILT].to_numpy().argmax(axis=1)]
    assert np.mean(top[d["alarm"]] == "internal_leakage") > 0.9


def test_paper_negative_null_bias_drift_needs_symmetric_collinearity(world):
    """The null-bias drift may go either way: with the default symmetric_modes a negative
    drift is still blamed on it; with plain signed collinearity it never is."""
    rng = np.random.default_rng(3)
    t = _one_flight_units(make_healthy_table(30, rng=rng), "neg")
    t[IND] = t[IND].to_numpy() - 0.8 * TRUE_A.loc["null_bias_drift"].to_numpy()
    k = world["knowledge"]
    for symmetric, expect in ((("null_bias_drift",), True), ((), False)):
        d = PaperMahalanobis(symmetric_modes=symmetric).fit(
            world["train"], knowledge=k, random_state=0).decide_table(t)
        assert d["alarm"].all()
        top = np.asarray(MODE_IDS)[d[GUILT].to_numpy().argmax(axis=1)]
        assert bool(np.all(top == "null_bias_drift")) is expect


def test_paper_references_from_itl_match_published_signatures(world, strong_decisions):
    """references="itl" recomputes eq. 9 from the ITL with the method's own healthy std; the
    world's signatures were computed the same way, so the guilt is the same."""
    method = PaperMahalanobis(references="itl").fit(world["train"], knowledge=world["knowledge"],
                                                    random_state=0)
    d = method.decide_table(world["strong"])
    np.testing.assert_allclose(d[GUILT].to_numpy(), strong_decisions["paper"][GUILT].to_numpy(),
                               atol=1e-9)


def test_paper_guilt_is_uniform_without_signatures(world):
    method = PaperMahalanobis().fit(world["train"], knowledge=Knowledge(), random_state=0)
    d = method.decide_table(world["strong"].iloc[::20])
    assert d["alarm"].any()
    np.testing.assert_allclose(d.loc[d["alarm"], GUILT].to_numpy(), 1.0 / 7)
    assert method.references_ is None


def test_paper_handles_missing_indicators(world, fitted):
    """A missing indicator (NaN or _valid False) is scored on the others; none at all: score 0."""
    method = fitted["paper"]
    rows = world["strong"].iloc[[0, 1, 2]].copy()
    rows.loc[rows.index[0], "Hys0"] = np.nan
    rows.loc[rows.index[1], "G_in_valid"] = False
    rows.loc[rows.index[2], IND] = np.nan
    d = method.decide_table(rows)
    assert np.isfinite(d["score"]).all()
    assert d["score"].iloc[2] == 0.0 and not d["alarm"].iloc[2]
    full = method.decide_table(world["strong"].iloc[[1]])["score"].iloc[0]
    assert d["score"].iloc[1] != full  # G_in was ignored


# ----------------------------------------------------------------------------- sklearn baselines
def test_isolation_forest_false_alarm_rate_and_detection(world, fitted, fresh_decisions,
                                                         strong_decisions):
    """quantile=0.975 targets 2.5 % false alarms; over training sets the rate of this
    configuration is 2.4 % +/- 0.7 % (one sigma), and 1000 test flights add +/- 0.5 %, so
    the tolerance is [0.5 %, 5.5 %]."""
    far = fresh_decisions["iforest"]["alarm"].mean()
    assert 0.005 <= far <= 0.055, far
    table = _per_mode(strong_decisions["iforest"], world["strong"])
    # Large, multi-indicator signatures are always isolated; all modes better than chance.
    assert table.loc[["null_bias_drift", "filter_contamination"], "detected"].min() >= 0.95, table
    assert (table["detected"] > 3 * far).all(), table
    assert table["diagnosed"].mean() >= 0.9, table


@pytest.mark.parametrize("kw", [{}, {"max_samples": 0.5}, {"max_samples": 1}, {"max_samples": 2},
                                {"max_features": 0.5}, {"n_estimators": 7}],
                         ids=["default", "half", "one-sample", "two-samples", "feature-subsets", "seven-trees"])
def test_flat_forest_scores_every_row_as_score_samples_does(kw):
    """The flat forest is the forest: same bits as -score_samples on fresh rows, far outside
    the training cloud too, and on rows of float32 ties (a row equal to a threshold)."""
    from sklearn.ensemble import IsolationForest

    from fuelhm_baselines.isolation_forest import FlatForest

    rng = np.random.default_rng(7)
    x = rng.normal(size=(150, 6))
    forest = IsolationForest(random_state=3, **kw).fit(x)
    flat = FlatForest(forest)
    t = forest.estimators_[0].tree_
    node = int(np.flatnonzero(t.children_left >= 0)[0]) if (t.children_left >= 0).any() else None
    rows = np.vstack([x[:20], 5.0 * rng.normal(size=(60, 6)), np.full((1, 6), 1e6)])
    if node is not None:  # a row lying on a split threshold (the comparison is <=, in float32)
        tie = x[0].copy()
        tie[forest.estimators_features_[0][t.feature[node]]] = t.threshold[node]
        rows = np.vstack([rows, tie])
    mine = np.array([flat.score(r) for r in rows])
    np.testing.assert_array_equal(mine, -forest.score_samples(rows))
    assert FlatForest.if_exact(forest, x) is not None


def test_isolation_forest_decides_with_the_flat_forest(world):
    """decide uses the flat forest, and its scores are the forest's."""
    method = IsolationForestMethod(n_estimators=30, cv=2).fit(world["train"], knowledge=world["knowledge"],
                                                              random_state=0)
    assert method.flat_forest_ is not None
    rows = world["strong"].iloc[::25]
    d = method.decide_table(rows)
    from fuelhm_baselines._common import indicator_values
    from fuelhm_baselines.isolation_forest import _features

    expected = -method.forest_.score_samples(_features(method.healthy_model_, indicator_values(rows)))
    np.testing.assert_array_equal(d["score"].to_numpy(), expected)


def test_isolation_forest_uniform_diagnosis(world):
    method = IsolationForestMethod(n_estimators=30, diagnosis="uniform").fit(
        world["train"], knowledge=world["knowledge"], random_state=0)
    d = method.decide_table(world["strong"].iloc[::10])
    assert d["alarm"].any()
    np.testing.assert_allclose(d.loc[d["alarm"], GUILT].to_numpy(), 1.0 / 7)


def test_itl_classifier_false_alarm_rate_and_diagnosis(world, fitted, fresh_decisions,
                                                       strong_decisions):
    """false_alarm_rate=0.025 calibrated out-of-fold on 400 flights: the 2.5 % quantile of
    P(healthy) has a sampling error of about +/- 0.8 %; tolerance [0.5 %, 5.5 %]. The
    classifier is trained on exactly this kind of flight, so it detects and diagnoses
    the strong shifts (>= 95 % per mode)."""
    method = fitted["itl"]
    far = fresh_decisions["itl"]["alarm"].mean()
    assert 0.005 <= far <= 0.055, far
    assert method.threshold_ == pytest.approx(math.exp(-method.score_threshold_))
    assert set(method.modes_) == set(MODE_IDS)
    table = _per_mode(strong_decisions["itl"], world["strong"])
    assert (table["detected"] >= 0.95).all() and (table["diagnosed"] >= 0.95).all(), table
    d = fresh_decisions["itl"]
    assert np.all(d.loc[~d["alarm"], GUILT].to_numpy() == 0.0)


def test_itl_classifier_with_a_single_mode(world):
    """One non-symmetric mode gives a two-class problem (binary logistic regression)."""
    k = world["knowledge"]
    itl = k.itl[k.itl["mode"] == "internal_leakage"]
    method = ITLClassifierMethod(symmetric_modes=()).fit(
        world["train"], knowledge=Knowledge(itl=itl, max_intensity={"internal_leakage": 1.0}),
        random_state=0)
    assert method.modes_ == ("internal_leakage",) and len(method.classifier_.classes_) == 2
    strong = world["strong"]
    d = method.decide_table(strong[strong["true_mode"] == "internal_leakage"])
    assert d["alarm"].mean() >= 0.95
    np.testing.assert_allclose(d.loc[d["alarm"], "guilt_internal_leakage"], 1.0)


# ----------------------------------------------------------------------------- comparisons
def test_methods_differ(world, fitted):
    """On a mix of healthy and weakly degraded flights (10-50 % of the maximum) the five
    baselines raise different alarm sets, and every non-trivial one detects degraded
    flights far more often than it false-alarms (RandomMethod does not)."""
    rng = np.random.default_rng(11)
    weak = _degraded(rng, 25, 0.1, 0.5)
    healthy = world["fresh"].iloc[:200]
    mixed = pd.concat([healthy, weak], ignore_index=True)
    is_faulty = np.r_[np.zeros(len(healthy), bool), np.ones(len(weak), bool)]
    methods = dict(fitted)
    methods["null"] = NullMethod().fit(world["train"], random_state=0)
    methods["random"] = RandomMethod(alarm_probability=0.2).fit(world["train"], random_state=0)
    alarms = {k: m.decide_table(mixed)["alarm"].to_numpy() for k, m in methods.items()}
    names = sorted(alarms)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert not np.array_equal(alarms[a], alarms[b]), (a, b)
    assert not alarms["null"].any()
    for k in ("paper", "iforest", "itl"):
        assert alarms[k][is_faulty].mean() > alarms[k][~is_faulty].mean() + 0.3, k
    assert abs(alarms["random"][is_faulty].mean() - alarms["random"][~is_faulty].mean()) < 0.1
    # The paper's Gaussian model is the most sensitive detector on these linear shifts.
    assert alarms["paper"][is_faulty].mean() > alarms["iforest"][is_faulty].mean()


@pytest.mark.parametrize("make, seed_matters", [
    (lambda: PaperMahalanobis(), False),          # leave-one-out uses no randomness
    (lambda: PaperMahalanobis(cv=5), True),       # random folds
    (lambda: IsolationForestMethod(n_estimators=30), True),
    (lambda: ITLClassifierMethod(), True),
    (lambda: RandomMethod(alarm_probability=0.3), True),
])
def test_determinism_under_a_seed(world, make, seed_matters):
    """Same seed: identical decisions and training scores. Another seed changes the fitted
    state exactly when the method uses randomness (the decisions on a few flights may not
    change: the random folds only move the threshold a little)."""
    train, k = world["train"].iloc[:200], world["knowledge"]
    units = pd.concat([world["fresh"].iloc[:40], world["strong"].iloc[::7]], ignore_index=True)

    def run(seed):
        m = make().fit(train, knowledge=k, random_state=seed)
        evidence = getattr(m, "training_scores_", None)
        decisions = m.decide_table(units)
        return decisions, decisions["score"].to_numpy() if evidence is None else evidence

    (a, ea), (b, eb) = run(5), run(5)
    pd.testing.assert_frame_equal(a, b)
    np.testing.assert_array_equal(ea, eb)
    _, ec = run(6)
    assert (not np.array_equal(ea, ec)) is seed_matters


# ----------------------------------------------------------------------------- README
def test_readme_submission_example_passes_the_checks(monkeypatch):
    """The 'write a submission' example of baselines/README.md runs and passes check_method."""
    text = (Path(fuelhm_baselines.__file__).parent / "README.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, flags=re.S).group(1)
    module = types.ModuleType("readme_submission_example")  # importable, so pickle works
    monkeypatch.setitem(sys.modules, module.__name__, module)
    exec(compile(code, "baselines/README.md", "exec"), module.__dict__)
    check_method(module.MySubmission())


def test_leave_one_unit_out_accounts_for_unit_dispersion(world):
    """With a unit effect in the healthy data, flight-LOO keeps the unit's other flights in training:
    its threshold is biased low for a new unit; leave-one-unit-out is not."""
    from fuelhm_bench.taxonomy import INDICATOR_NAMES

    rng = np.random.default_rng(3)
    train = world["train"].iloc[:120].copy()
    train["unit_id"] = np.repeat(np.arange(12), 10)
    offsets = rng.normal(0.0, 1.0, (12, len(INDICATOR_NAMES))) * train[list(INDICATOR_NAMES)].std().to_numpy()
    train[list(INDICATOR_NAMES)] += np.repeat(offsets, 10, axis=0)
    k = world["knowledge"]
    by_unit = PaperMahalanobis(cv="units").fit(train, knowledge=k, random_state=0)
    by_flight = PaperMahalanobis(cv="loo").fit(train, knowledge=k, random_state=0)
    assert by_unit.threshold_ > by_flight.threshold_ + 0.3


# ----------------------------------------------------------------------------- scarce healthy data
def _low_data_fit_table(data: CheckData) -> pd.DataFrame:
    """Healthy flights shaped like the shipped low_data scenario's fit part (its units minus the
    calibration half, its flights per unit), drawn from the check data's healthy table."""
    from fuelhm_bench.scenarios import load_scenario

    training = load_scenario("low_data").training
    n_fit_units = training.units - max(1, training.units // 2)
    units = list(dict.fromkeys(data.healthy["unit_id"]))
    if len(units) >= n_fit_units:
        table = data.healthy[data.healthy["unit_id"].isin(units[:n_fit_units])]
        table = table[table["flight_index"] < training.flights_per_unit].reset_index(drop=True)
    else:  # more units than the check data have: the same number of flights, each relabelled as a unit
        per_unit = -(-n_fit_units * training.flights_per_unit // len(units))
        table = data.healthy[data.healthy["flight_index"] < per_unit].head(n_fit_units * training.flights_per_unit)
        table = table.reset_index(drop=True)
        table["unit_id"] = [f"{u}-{i // training.flights_per_unit}" for i, u in enumerate(table["unit_id"])]
        table["flight_index"] = np.arange(len(table)) % training.flights_per_unit
    # 5-fold cross-fitting leaves fewer flights per fold than a 10-indicator Mahalanobis model needs
    assert len(table) == n_fit_units * training.flights_per_unit
    assert len(table) - math.ceil(len(table) / 5) < len(IND) + 1
    return table


@pytest.mark.parametrize("make", [IsolationForestMethod, ITLClassifierMethod, PaperMahalanobis],
                         ids=["isolation_forest", "itl_classifier", "paper"])
def test_default_baselines_fit_on_the_low_data_training_set(make):
    """Fewer healthy flights than a full 10-indicator Mahalanobis model needs (11), cross-fitted in
    folds: the baselines fit with their default configuration and decide validly."""
    data = make_check_data(0)
    method = make(random_state=0).fit(_low_data_fit_table(data), knowledge=data.knowledge)
    table = run_table(method, data.units)
    assert np.isfinite(method.threshold_) and np.isfinite(table["score"]).all()
    assert table["alarm"].any()  # the degrading units are still seen


def test_standardisation_needs_three_flights():
    from fuelhm_baselines._common import STANDARDISATION_MIN_FLIGHTS, standardisation
    from fuelhm_bench.errors import DataFormatError

    x = np.random.default_rng(0).normal(size=(STANDARDISATION_MIN_FLIGHTS, len(IND)))
    model = standardisation(x)
    np.testing.assert_allclose(model.zscores(x).mean(axis=0), 0.0, atol=1e-12)
    with pytest.raises(DataFormatError, match="at least 3 healthy flights"):
        standardisation(x[:2])


@pytest.mark.slow
def test_every_baseline_runs_on_the_shipped_low_data_scenario(tmp_path):
    """The shipped low_data scenario itself (its 24 x 1 training flights), surrogate fidelity, small scale."""
    from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env
    from sizes import knowledge_size

    evaluation = prepare_evaluation("low_data", fidelity="surrogate", scale=0.2, knowledge_size=knowledge_size(),
                                    cache_dir=tmp_path)
    for method in (IsolationForestMethod(random_state=0), ITLClassifierMethod(random_state=0),
                   PaperMahalanobis(), NullMethod(), RandomMethod(random_state=0)):
        outcome = run_in_env(method, evaluation)
        assert outcome.ok, (type(method).__name__, outcome.message)
        assert np.isfinite(outcome.cost_kusd)
