"""Tests of the healthy Gaussian model (paper eqs. 6-7, global Mahalanobis score)."""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from scipy.spatial.distance import mahalanobis
from sklearn.base import clone

from fuelhm_bench.diagnosis import HealthyModel, NotFittedError, chi2_equivalent
from fuelhm_bench.testing.diagnosis import DEFAULT_MEAN, DEFAULT_STD, make_healthy_table
from fuelhm_bench.errors import DataFormatError, FuelHMError, ParameterError, UnknownNameError
from fuelhm_bench.taxonomy import INDICATOR_NAMES

P = len(INDICATOR_NAMES)
MU = np.array([DEFAULT_MEAN[f] for f in INDICATOR_NAMES])
SD = np.array([DEFAULT_STD[f] for f in INDICATOR_NAMES])


def random_cov(rng: np.random.Generator) -> np.ndarray:
    """A well-conditioned covariance with the default standard deviations."""
    a = rng.standard_normal((P, P))
    m = a @ a.T + P * np.eye(P)
    d = np.sqrt(np.diag(m))
    return m / np.outer(d, d) * np.outer(SD, SD)


def gaussian_table(n: int, rng: np.random.Generator, cov: np.ndarray) -> pd.DataFrame:
    """Healthy table drawn from N(MU, cov)."""
    x = rng.multivariate_normal(MU, cov, size=n)
    table = pd.DataFrame(x, columns=list(INDICATOR_NAMES))
    table.insert(0, "flight_id", np.arange(n))
    return table


# ------------------------------------------------------------- estimation
def test_recovers_mean_and_covariance_of_a_known_gaussian():
    rng = np.random.default_rng(0)
    cov = random_cov(rng)
    n = 20_000
    model = HealthyModel(shrinkage=0.0).fit(gaussian_table(n, rng, cov))
    se_mean = SD / np.sqrt(n)
    assert np.all(np.abs(model.mean_ - MU) < 5 * se_mean)
    np.testing.assert_allclose(model.std_, SD, rtol=0.03)
    # Sample covariance entries have standard error about sd_i sd_j sqrt(2 / n).
    np.testing.assert_allclose(model.cov_, cov, atol=5 * np.sqrt(2 / n) * np.outer(SD, SD).max())
    np.testing.assert_allclose(model.precision_ @ model.cov_, np.eye(P), atol=1e-8)
    assert model.n_samples_ == n and model.n_complete_ == n and model.features_ == INDICATOR_NAMES
    assert model.rank_ == P and model.shrinkage_ == 0.0


def test_auto_shrinkage_is_small_with_plenty_of_data_and_keeps_the_covariance():
    rng = np.random.default_rng(1)
    cov = random_cov(rng)
    model = HealthyModel().fit(gaussian_table(20_000, rng, cov))
    assert 0.0 < model.shrinkage_ < 0.01
    np.testing.assert_allclose(model.cov_, cov, atol=0.05 * np.outer(SD, SD).max())


def test_mahalanobis_matches_scipy_on_a_well_conditioned_case():
    rng = np.random.default_rng(2)
    cov = random_cov(rng)
    table = gaussian_table(200, rng, cov)
    model = HealthyModel(shrinkage=0.0).fit(table)
    x = table[list(INDICATOR_NAMES)].to_numpy()
    vi = np.linalg.inv(np.cov(x, rowvar=False, ddof=1))
    assert np.linalg.cond(vi) < 1e3
    new = MU + 3 * SD * rng.standard_normal((25, P))
    expected = [mahalanobis(row, x.mean(axis=0), vi) for row in new]
    np.testing.assert_allclose(model.global_score(new), expected, rtol=1e-9)


def test_zscores_follow_eq_7_and_keep_the_index():
    rng = np.random.default_rng(3)
    table = make_healthy_table(50, rng=rng)
    model = HealthyModel().fit(table)
    probe = table.iloc[[3, 7, 11]]
    z = model.zscores(probe)
    x = table[list(INDICATOR_NAMES)].to_numpy()
    expected = (probe[list(INDICATOR_NAMES)].to_numpy() - x.mean(axis=0)) / x.std(axis=0, ddof=1)
    assert list(z.index) == [3, 7, 11] and list(z.columns) == list(INDICATOR_NAMES)
    np.testing.assert_allclose(z.to_numpy(), expected, rtol=1e-12)
    np.testing.assert_allclose(model.zscores(probe[list(INDICATOR_NAMES)].to_numpy()), expected, rtol=1e-12)


def test_full_shrinkage_gives_the_euclidean_norm_of_the_zscores():
    rng = np.random.default_rng(4)
    table = make_healthy_table(100, rng=rng, correlation=0.8)
    model = HealthyModel(shrinkage=1.0).fit(table)
    np.testing.assert_allclose(model.correlation_, np.eye(P))
    z = model.zscores(table).to_numpy()
    np.testing.assert_allclose(model.global_score(table), np.linalg.norm(z, axis=1), rtol=1e-12)


def test_global_score_uses_the_shrunk_correlation():
    rng = np.random.default_rng(5)
    table = make_healthy_table(80, rng=rng, correlation=0.6)
    model = HealthyModel(shrinkage=0.3).fit(table)
    z = model.zscores(table).to_numpy()
    sample = np.corrcoef(table[list(INDICATOR_NAMES)].to_numpy(), rowvar=False)
    shrunk = 0.7 * sample + 0.3 * np.eye(P)
    np.testing.assert_allclose(model.correlation_, shrunk, atol=1e-12)
    expected = np.sqrt(np.einsum("ij,jk,ik->i", z, np.linalg.inv(shrunk), z))
    np.testing.assert_allclose(model.global_score(table), expected, rtol=1e-9)
    # The score on Z-scores equals the score on the indicator vector with cov_.
    d = table[list(INDICATOR_NAMES)].to_numpy() - model.mean_
    np.testing.assert_allclose(model.global_score(table), np.sqrt(np.einsum("ij,jk,ik->i", d, model.precision_, d)), rtol=1e-9)


# ------------------------------------------------------- singular covariance
def degenerate_table(rng: np.random.Generator) -> pd.DataFrame:
    table = make_healthy_table(60, rng=rng)
    table["Inb"] = (table["X1"] + table["X2"]) / 2  # exact linear dependency (Table I)
    table["G_out"] = table["G_in"]  # duplicated column
    table["Hys0"] = 0.1  # constant column (0.1 is not exact in binary: a rounding-error spread)
    return table


@pytest.mark.parametrize("shrinkage", ["auto", 0.0])
def test_singular_covariance_gives_finite_scores_without_warnings(shrinkage):
    rng = np.random.default_rng(6)
    table = degenerate_table(rng)
    probe = degenerate_table(rng)
    probe.loc[:4, "Hys0"] = 0.2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = HealthyModel(shrinkage=shrinkage).fit(table)
        scores = model.global_score(probe)
        z = model.zscores(probe)
    assert np.all(np.isfinite(scores)) and np.all(np.isfinite(z.to_numpy()))
    assert np.all(np.isfinite(model.cov_)) and np.all(np.isfinite(model.precision_))
    j = INDICATOR_NAMES.index("Hys0")
    assert model.std_[j] == pytest.approx(1e-6)  # the stated floor, std_floor * max(|mean|, 1)
    assert np.all(model.correlation_[j, np.arange(P) != j] == 0.0)
    assert np.all(scores[:5] > 1e3)  # a constant indicator that moves is flagged
    if shrinkage == 0.0:
        assert model.rank_ == P - 2  # Inb and G_out add no direction
    else:
        assert model.shrinkage_ > 0 and model.rank_ == P


def test_shrinkage_keeps_a_penalty_on_breaking_a_healthy_linear_dependency():
    rng = np.random.default_rng(7)
    table = degenerate_table(rng)  # G_out == G_in on every healthy flight
    i, o = INDICATOR_NAMES.index("G_in"), INDICATOR_NAMES.index("G_out")
    for model in (HealthyModel().fit(table), HealthyModel(shrinkage=0.0).fit(table)):
        both = model.mean_.copy()
        both[[i, o]] += 2 * model.std_[[i, o]]  # move together, as healthy flights do
        broken = model.mean_.copy()
        broken[o] += 2 * model.std_[o]  # move G_out alone: never seen in healthy data
        score_both, score_broken = model.global_score(np.vstack([both, broken]))
        # u = (e_o - e_i)/sqrt(2) is an eigenvector of the shrunk correlation with eigenvalue
        # shrinkage_; "broken" is half of "both" plus sqrt(2) u, so its squared score is
        # score_both^2 / 4 + 2 / shrinkage_ -- and the pseudo-inverse (shrinkage 0) drops the u term.
        penalty = 2 / model.shrinkage_ if model.shrinkage_ > 0 else 0.0
        assert score_broken**2 == pytest.approx(score_both**2 / 4 + penalty, rel=1e-9)
    assert HealthyModel().fit(table).shrinkage_ > 0


def test_zero_variance_at_zero_mean_uses_the_absolute_floor():
    rng = np.random.default_rng(8)
    table = make_healthy_table(30, rng=rng)
    table["Inb"] = 0.0
    model = HealthyModel(std_floor=1e-4).fit(table)
    assert model.std_[INDICATOR_NAMES.index("Inb")] == pytest.approx(1e-4)


# ---------------------------------------------------------------- NaN policy
def test_fit_uses_available_values_per_indicator_and_complete_cases_for_correlation():
    rng = np.random.default_rng(9)
    table = make_healthy_table(200, rng=rng)
    table.loc[::4, "G_null"] = np.nan
    table.loc[1::5, "Y1_valid"] = False  # a False validity flag means "missing"
    model = HealthyModel(shrinkage=0.0).fit(table)
    g = INDICATOR_NAMES.index("G_null")
    y = INDICATOR_NAMES.index("Y1")
    assert model.mean_[g] == pytest.approx(table["G_null"].mean())  # pandas skips NaN
    assert model.mean_[y] == pytest.approx(table.loc[table["Y1_valid"], "Y1"].mean())
    complete = table["G_null"].notna() & table["Y1_valid"]
    assert model.n_complete_ == int(complete.sum()) and model.n_samples_ == 200
    expected_corr = np.corrcoef(table.loc[complete, list(INDICATOR_NAMES)].to_numpy(), rowvar=False)
    np.testing.assert_allclose(model.correlation_, expected_corr, atol=1e-12)


def test_missing_indicators_are_scored_on_the_marginal_and_mapped_to_p_dof():
    rng = np.random.default_rng(10)
    table = make_healthy_table(300, rng=rng)
    model = HealthyModel().fit(table)
    probe = make_healthy_table(5, rng=rng)
    probe.loc[:, ["Y1", "G_in", "G_null"]] = np.nan
    z = model.zscores(probe).to_numpy()
    keep = ~np.isnan(z[0])
    sub = model.correlation_[np.ix_(keep, keep)]
    d2 = np.einsum("ij,jk,ik->i", z[:, keep], np.linalg.inv(sub), z[:, keep])
    expected = np.sqrt(stats.chi2.isf(stats.chi2.sf(d2, keep.sum()), P))
    np.testing.assert_allclose(model.global_score(probe), expected, rtol=1e-8)


def test_rows_without_any_indicator_score_nan_and_others_are_unaffected():
    rng = np.random.default_rng(11)
    table = make_healthy_table(100, rng=rng)
    model = HealthyModel().fit(table)
    probe = table.head(4).copy()
    probe.loc[1, list(INDICATOR_NAMES)] = np.nan
    scores = model.global_score(probe)
    assert np.isnan(scores[1])
    np.testing.assert_allclose(scores[[0, 2, 3]], model.global_score(table.head(4))[[0, 2, 3]])


def test_false_alarm_rate_does_not_depend_on_which_indicators_are_missing():
    rng = np.random.default_rng(12)
    model = HealthyModel(shrinkage=0.0).fit(make_healthy_table(5000, rng=rng))
    threshold = np.sqrt(stats.chi2.ppf(0.95, P))
    probe = make_healthy_table(20_000, rng=rng)
    full_rate = np.mean(model.global_score(probe) > threshold)
    probe.loc[: 9_999, ["X1", "Y2", "Hys0", "G_in", "G_out", "G_null"]] = np.nan
    probe.loc[10_000:, "I0"] = np.nan
    scores = model.global_score(probe)
    for rows in (slice(0, 10_000), slice(10_000, None)):
        assert abs(np.mean(scores[rows] > threshold) - 0.05) < 0.01
    assert abs(full_rate - 0.05) < 0.01


def test_chi2_equivalent_is_exact_monotone_and_finite_in_the_far_tail():
    d2 = np.array([0.0, 0.5, 3.84, 30.0, 200.0])
    for k in (1, 4, 9):
        np.testing.assert_allclose(chi2_equivalent(d2, k, 10), stats.chi2.isf(stats.chi2.sf(d2, k), 10), rtol=1e-9)
    np.testing.assert_array_equal(chi2_equivalent(d2, 10, 10), d2)
    grid = np.linspace(1.0, 1e5, 20_001)
    for k in (1, 3, 9):
        mapped = chi2_equivalent(grid, k, 10)
        assert np.all(np.isfinite(mapped)) and np.all(np.diff(mapped) > 0)
        assert np.all(mapped >= grid)  # fewer indicators: the same tail needs a larger p-dof value


# -------------------------------------------------------------------- errors
def test_too_few_healthy_flights_names_the_needed_count():
    table = make_healthy_table(7, rng=np.random.default_rng(13))
    with pytest.raises(DataFormatError, match=r"at least 11 healthy flights.*Got 7"):
        HealthyModel().fit(table)
    with pytest.raises(DataFormatError, match=r"at least 8 healthy flights"):
        HealthyModel(min_flights=8).fit(table)
    HealthyModel(min_flights=5).fit(table)  # explicitly allowed
    HealthyModel(features=["X1", "X2"]).fit(table)  # needs 3


def test_too_few_valid_values_of_one_indicator_names_it():
    table = make_healthy_table(30, rng=np.random.default_rng(14))
    table.loc[5:, "G_null"] = np.nan
    with pytest.raises(DataFormatError, match=r"at least 11 .*'G_null' \(5\)"):
        HealthyModel().fit(table)
    model = HealthyModel(features=[f for f in INDICATOR_NAMES if f != "G_null"]).fit(table)
    assert model.features_ == tuple(f for f in INDICATOR_NAMES if f != "G_null")


def test_too_few_complete_flights_is_an_error():
    table = make_healthy_table(30, rng=np.random.default_rng(15))
    table.loc[:14, "X1"] = np.nan
    table.loc[15:, "Y1"] = np.nan
    with pytest.raises(DataFormatError, match=r"all 10 indicators available.*Got 0 complete"):
        HealthyModel().fit(table)


def test_missing_column_is_named():
    table = make_healthy_table(30, rng=np.random.default_rng(16)).drop(columns=["Hys0"])
    with pytest.raises(DataFormatError, match=r"missing required column 'Hys0'"):
        HealthyModel().fit(table)
    model = HealthyModel().fit(make_healthy_table(30, rng=np.random.default_rng(16)))
    with pytest.raises(DataFormatError, match=r"'Hys0'"):
        model.global_score(table)


@pytest.mark.parametrize(
    ("params", "name"),
    [
        ({"shrinkage": 1.5}, "shrinkage"),
        ({"shrinkage": "oas"}, "shrinkage"),
        ({"std_floor": 0.0}, "std_floor"),
        ({"min_flights": 1}, "min_flights"),
        ({"min_flights": 2.5}, "min_flights"),
        ({"features": []}, "features"),
        ({"features": ["X1", "X1"]}, "features"),
    ],
)
def test_bad_hyperparameters_follow_the_error_template(params, name):
    table = make_healthy_table(30, rng=np.random.default_rng(17))
    with pytest.raises(ParameterError, match=rf"^The '{name}' parameter of HealthyModel must be .*\. Got .* instead\.$"):
        HealthyModel(**params).fit(table)


def test_unknown_feature_name_and_bad_data_are_rejected():
    table = make_healthy_table(30, rng=np.random.default_rng(18))
    with pytest.raises(UnknownNameError, match="X3"):
        HealthyModel(features=["X1", "X3"]).fit(table)
    bad = table.copy()
    bad.loc[3, "Y2"] = np.inf
    with pytest.raises(DataFormatError, match=r"infinite value in indicator 'Y2'"):
        HealthyModel().fit(bad)
    with pytest.raises(DataFormatError, match=r"shape \(n_rows, 10\)"):
        HealthyModel().fit(np.zeros((30, 9)))


def test_not_fitted_error_is_a_fuelhm_error():
    with pytest.raises(NotFittedError, match="not fitted") as info:
        HealthyModel().global_score(np.zeros((1, P)))
    assert isinstance(info.value, FuelHMError)


# ------------------------------------------------------ estimator conventions
def test_scikit_learn_conventions():
    with pytest.raises(TypeError):
        HealthyModel("auto")  # hyperparameters are keyword-only
    model = HealthyModel(shrinkage=0.2, features=("X1", "Y1", "I0"))
    assert model.get_params() == {"features": ("X1", "Y1", "I0"), "min_flights": None, "shrinkage": 0.2, "std_floor": 1e-6}
    assert not hasattr(model, "mean_")  # the constructor stores hyperparameters only
    table = make_healthy_table(40, rng=np.random.default_rng(19))
    before = table.copy()
    fitted = model.fit(table)
    assert fitted is model
    pd.testing.assert_frame_equal(table, before)  # input not mutated
    assert not hasattr(clone(model), "mean_")
    restored = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(restored.global_score(table), model.global_score(table))
    refit = clone(model).fit(table)
    np.testing.assert_array_equal(refit.global_score(table), model.global_score(table))


def test_fit_rejects_degraded_rows_and_accepts_nullable_validity_flags():
    rng = np.random.default_rng(20)
    table = make_healthy_table(30, rng=rng).assign(mode="healthy")
    HealthyModel().fit(table)
    table.loc[3, "mode"] = "backlash"
    with pytest.raises(DataFormatError, match=r"healthy flights only.*\['backlash'\]"):
        HealthyModel().fit(table)
    nullable = make_healthy_table(30, rng=rng)
    nullable["X1_valid"] = pd.array([True] * 29 + [pd.NA], dtype="boolean")
    model = HealthyModel().fit(nullable)
    assert model.n_complete_ == 29  # <NA> validity counts as missing
    with pytest.raises(DataFormatError, match="'X1_valid' .* must be boolean"):
        HealthyModel().fit(nullable.assign(X1_valid=1))
