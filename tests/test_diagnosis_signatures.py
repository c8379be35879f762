"""Tests of the signature matrix (eq. 9, Table IV) and the collinearity diagnosis."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread

from fuelhm_bench.diagnosis import (
    ITL,
    HealthyModel,
    NotFittedError,
    collinearity_guilt,
    fit_itl,
    plot_signature_heatmap,
    signature_from_csv,
    signature_matrix,
    signature_to_csv,
    signature_to_markdown,
)
from fuelhm_bench.testing.diagnosis import DEFAULT_STD, make_doe_table, make_healthy_table
from fuelhm_bench.errors import DataFormatError, OutputPathError, ParameterError, UnknownNameError
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

#: Table IV of the paper (the two modes it studied).
TABLE_IV = pd.DataFrame(
    [[24, 0, 26, 0, 28, 24, 0, 0, 0, 0], [0, 4, 0, 11, 0, 1, 0, 0, 0, 0]],
    index=["null_bias_drift", "internal_leakage"],
    columns=list(INDICATOR_NAMES),
    dtype=float,
)


@pytest.fixture(scope="module")
def fitted():
    """A healthy model and ITL with known laws (7 modes x 10 indicators)."""
    rng = np.random.default_rng(0)
    sd = np.array([DEFAULT_STD[f] for f in INDICATOR_NAMES])
    coef = pd.DataFrame(rng.normal(scale=10.0, size=(7, 10)) * sd, index=list(MODE_IDS), columns=list(INDICATOR_NAMES))
    itl = fit_itl(make_doe_table(coef, rng=rng, n_units=3))
    model = HealthyModel().fit(make_healthy_table(200, rng=rng))
    return itl, model


# ----------------------------------------------------------------- matrix
def test_signature_matrix_is_a_times_max_intensity_over_sigma(fitted):
    itl, model = fitted
    sig = signature_matrix(itl, model)
    assert sig.shape == (7, 10) and tuple(sig.index) == MODE_IDS and tuple(sig.columns) == INDICATOR_NAMES
    assert sig.index.name == "mode" and sig.columns.name == "indicator"
    np.testing.assert_allclose(sig.to_numpy(), itl.matrix().to_numpy() / model.std_, rtol=1e-12)
    maxima = dict(zip(MODE_IDS, np.linspace(0.3, 1.0, 7)))
    scaled = signature_matrix(itl, model, max_intensity=maxima)
    np.testing.assert_allclose(scaled.to_numpy(), sig.to_numpy() * np.linspace(0.3, 1.0, 7)[:, None], rtol=1e-12)


def test_signature_matrix_equals_zscores_of_itl_degraded_mean_eq_9(fitted):
    itl, model = fitted
    sig = signature_matrix(itl, model, max_intensity=0.8)
    for mode in MODE_IDS:
        degraded = itl.apply(model.mean_[None, :], mode, 0.8)  # eq. 4 from the healthy mean
        np.testing.assert_allclose(model.zscores(degraded)[0], sig.loc[mode].to_numpy(), atol=1e-9)


def test_signature_matrix_errors(fitted):
    itl, model = fitted
    with pytest.raises(NotFittedError):
        signature_matrix(itl, HealthyModel())
    with pytest.raises(ParameterError, match=r"^The 'max_intensity' parameter of signature_matrix must be"):
        signature_matrix(itl, model, max_intensity=0.0)
    with pytest.raises(ParameterError, match=r"missing \['diaphragm_clogging'\]"):
        signature_matrix(itl, model, max_intensity={m: 1.0 for m in MODE_IDS[:-1]})
    partial = ITL(itl.table[itl.table["indicator"] != "G_null"])
    with pytest.raises(DataFormatError, match=r"no law for indicator\(s\) \['G_null'\]"):
        signature_matrix(partial, model)
    restricted = HealthyModel(features=INDICATOR_NAMES[:9]).fit(make_healthy_table(50, rng=np.random.default_rng(1)))
    assert signature_matrix(partial, restricted).shape == (7, 9)


# --------------------------------------------------------------- outputs
def test_csv_round_trip_and_markdown(tmp_path):
    sig = TABLE_IV.copy()
    sig.loc["internal_leakage", "G_null"] = np.nan
    back = signature_from_csv(signature_to_csv(sig, tmp_path / "sig.csv"))
    pd.testing.assert_frame_equal(back, sig, check_names=False)
    text = signature_to_markdown(sig, decimals=0)
    lines = text.splitlines()
    assert lines[0] == "| mode | X1 | Y1 | X2 | Y2 | Inb | I0 | Hys0 | G_in | G_out | G_null |"
    assert lines[1] == "|---|" + "---:|" * 10
    assert lines[2] == "| null_bias_drift | 24 | 0 | 26 | 0 | 28 | 24 | 0 | 0 | 0 | 0 |"
    assert lines[3] == "| internal_leakage | 0 | 4 | 0 | 11 | 0 | 1 | 0 | 0 | 0 | - |"
    assert "| 24.00 |" in signature_to_markdown(sig, decimals=2)
    with pytest.raises(ParameterError, match="'decimals' parameter of signature_to_markdown"):
        signature_to_markdown(sig, decimals=-1)
    with pytest.raises(DataFormatError, match="numbers only"):
        signature_to_markdown(sig.assign(X1="a"))


def test_heatmap_is_written(tmp_path):
    sig = TABLE_IV.copy()
    sig.loc["internal_leakage", "Y1"] = np.nan
    image = imread(plot_signature_heatmap(sig, tmp_path / "sig.png"))
    assert image.ndim == 3 and image[..., :3].std() > 0.05
    with pytest.raises(OutputPathError):
        plot_signature_heatmap(sig, tmp_path / "nope" / "sig.png")


# ------------------------------------------------------------- collinearity
def test_guilt_reproduces_the_paper_drift_row():
    guilt = collinearity_guilt(TABLE_IV.loc["null_bias_drift"], TABLE_IV)
    assert isinstance(guilt, pd.Series) and list(guilt.index) == list(TABLE_IV.index)
    # Table VI gives 0.94 / 0.06 with noisy flights; the noise-free value is 1 / (1 + cos) = 0.96.
    assert guilt["null_bias_drift"] == pytest.approx(0.96, abs=0.005)


def test_guilt_picks_the_right_mode_for_noisy_scaled_signatures(fitted):
    itl, model = fitted
    refs = signature_matrix(itl, model)
    rng = np.random.default_rng(2)
    n = 700
    truth = rng.integers(0, 7, size=n)
    scale = rng.uniform(0.5, 1.0, size=n)
    observed = scale[:, None] * refs.to_numpy()[truth] + rng.standard_normal((n, 10))
    guilt = collinearity_guilt(observed, refs.to_numpy())
    assert guilt.shape == (n, 7)
    assert np.all(guilt >= 0) and np.allclose(guilt.sum(axis=1), 1.0)
    assert np.mean(guilt.argmax(axis=1) == truth) > 0.95
    # Batched result equals row-by-row results.
    np.testing.assert_allclose(guilt[:5], [collinearity_guilt(row, refs.to_numpy()) for row in observed[:5]])


def test_guilt_is_scale_invariant_and_signed():
    refs = np.array([[1.0, 0.0, 2.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    s = np.array([2.0, 0.5, 3.0])
    np.testing.assert_allclose(collinearity_guilt(5 * s, refs), collinearity_guilt(s, refs))
    cos = refs @ s / (np.linalg.norm(refs, axis=1) * np.linalg.norm(s))
    np.testing.assert_allclose(collinearity_guilt(s, refs), cos / cos.sum())
    # The opposite direction is not evidence for a mode with a signed signature ...
    flipped = -refs[0] + np.array([0.0, 0.5, 0.0])
    assert collinearity_guilt(flipped, refs)[0] == 0.0
    assert collinearity_guilt(flipped, refs)[1] == 1.0
    # ... unless that mode is declared symmetric (e.g. a null-bias drift of either sign).
    assert collinearity_guilt(flipped, refs, symmetric=[0])[0] > 0.8
    np.testing.assert_allclose(collinearity_guilt(-s, refs, symmetric=True), collinearity_guilt(s, refs, symmetric=True))


def test_guilt_drops_nan_indicators_from_both_vectors():
    rng = np.random.default_rng(3)
    refs = rng.uniform(size=(4, 6))
    refs[2, 1] = np.nan
    s = rng.uniform(size=6)
    s[4] = np.nan
    guilt = collinearity_guilt(s, refs)
    scores = []
    for r in refs:
        keep = np.isfinite(r) & np.isfinite(s)
        c = s[keep] @ r[keep] / (np.linalg.norm(s[keep]) * np.linalg.norm(r[keep]))
        scores.append(c)
    assert min(scores) > 0
    np.testing.assert_allclose(guilt, np.array(scores) / np.sum(scores))


def test_guilt_falls_back_to_uniform_without_evidence():
    refs = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    batch = np.array([[0.0, 0.0], [np.nan, np.nan], [-1.0, -1.0]])
    np.testing.assert_allclose(collinearity_guilt(batch, refs), np.full((3, 3), 1 / 3))


def test_guilt_matches_indicators_by_name_and_keeps_the_index():
    refs = TABLE_IV
    flights = pd.DataFrame(
        [TABLE_IV.loc["internal_leakage"].to_numpy(), TABLE_IV.loc["null_bias_drift"].to_numpy()],
        columns=list(INDICATOR_NAMES),
        index=["f1", "f2"],
    )
    shuffled = flights[list(reversed(INDICATOR_NAMES))].assign(extra=1.0)
    guilt = collinearity_guilt(shuffled, refs)
    assert list(guilt.index) == ["f1", "f2"] and list(guilt.columns) == list(refs.index)
    np.testing.assert_allclose(guilt.to_numpy(), collinearity_guilt(flights.to_numpy(), refs.to_numpy()))
    assert guilt.loc["f1"].idxmax() == "internal_leakage" and guilt.loc["f2"].idxmax() == "null_bias_drift"


def test_guilt_input_errors():
    refs = TABLE_IV
    with pytest.raises(DataFormatError, match=r"shape \(10,\) or \(n_flights, 10\)"):
        collinearity_guilt(np.zeros(9), refs)
    with pytest.raises(DataFormatError, match=r"lack indicator\(s\) \['G_null'\]"):
        collinearity_guilt(pd.DataFrame(np.zeros((1, 9)), columns=list(INDICATOR_NAMES[:9])), refs)
    with pytest.raises(UnknownNameError, match="backlash"):
        collinearity_guilt(np.zeros(10), refs, symmetric=["backlash"])
    with pytest.raises(ParameterError, match="'symmetric' parameter of collinearity_guilt"):
        collinearity_guilt(np.zeros(10), refs, symmetric="null_bias_drift")
    with pytest.raises(DataFormatError, match="shape \\(n_modes, n_indicators\\)"):
        collinearity_guilt(np.zeros(10), np.zeros(10))
