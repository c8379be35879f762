"""Tests of the indicator transformation laws (paper eqs. 2-5)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread

from fuelhm_bench.diagnosis import ITL, ITL_COLUMNS, fit_itl, fit_through_origin, paired_deltas, plot_itl
from fuelhm_bench.testing.diagnosis import DEFAULT_STD, make_doe_table
from fuelhm_bench.errors import DataFormatError, OutputPathError, ParameterError, UnknownNameError
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

SD = np.array([DEFAULT_STD[f] for f in INDICATOR_NAMES])
LEVELS = (0.2, 0.4, 0.6, 0.8, 1.0)


def true_coef(rng: np.random.Generator) -> pd.DataFrame:
    """Known ITL coefficients, 2 to 8 healthy standard deviations per unit intensity, random sign."""
    shape = (len(MODE_IDS), len(INDICATOR_NAMES))
    return pd.DataFrame(
        rng.choice([-1.0, 1.0], size=shape) * rng.uniform(2.0, 8.0, size=shape) * SD,
        index=list(MODE_IDS),
        columns=list(INDICATOR_NAMES),
    )


def tiny_doe() -> pd.DataFrame:
    """Two units, hand-computable: unit 1 has two healthy flights."""
    return pd.DataFrame(
        {
            "unit_id": [0, 0, 0, 1, 1, 1, 1],
            "mode": ["healthy", "backlash", "backlash", "healthy", "healthy", "backlash", "backlash"],
            "intensity": [0.0, 0.5, 1.0, 0.0, 0.0, 0.5, 1.0],
            "X1": [1.0, 2.0, 3.1, 10.0, 12.0, 12.0, 13.0],
            "Y1": [5.0, 5.0, 5.0, 7.0, 7.0, 7.0, 7.0],
        }
    )


# ------------------------------------------------------------------- fitting
def test_recovers_known_linear_coefficients_despite_unit_dispersion():
    rng = np.random.default_rng(0)
    coef = true_coef(rng)
    n_units, noise = 6, 0.02
    # Unit offsets of 30 healthy sigmas: without pairing by unit they would swamp the laws.
    doe = make_doe_table(coef, rng=rng, n_units=n_units, intensities=LEVELS, unit_std=30.0, noise_std=noise)
    itl = fit_itl(doe)
    assert list(itl.table.columns) == list(ITL_COLUMNS) and len(itl.table) == 70
    assert itl.modes == MODE_IDS and itl.indicators == INDICATOR_NAMES
    assert (itl.table["n"] == n_units * len(LEVELS)).all()
    # Standard error of A: noise of the difference (sqrt(2) sigma) over sqrt(n_units * sum(s^2)).
    se = np.sqrt(2) * noise * SD / np.sqrt(n_units * np.sum(np.square(LEVELS)))
    error = (itl.matrix("A") - coef).to_numpy()
    assert np.all(np.abs(error) < 5 * se)
    assert (itl.matrix("r2").to_numpy() > 0.99).all()
    np.testing.assert_allclose(itl.matrix("residual_std").to_numpy(), np.tile(np.sqrt(2) * noise * SD, (7, 1)), rtol=0.5)


def test_r2_reveals_quadratic_and_saturating_laws():
    rng = np.random.default_rng(1)
    coef = true_coef(rng)
    laws = {
        ("backlash", "Hys0"): lambda s: s**2,
        ("filter_contamination", "G_in"): lambda s: (1 - np.exp(-5 * s)) / (1 - np.exp(-5)),
    }
    doe = make_doe_table(coef, rng=rng, n_units=5, intensities=LEVELS, noise_std=0.02, laws=laws)
    r2 = fit_itl(doe).matrix("r2")
    linear = r2.to_numpy().copy()
    linear[MODE_IDS.index("backlash"), INDICATOR_NAMES.index("Hys0")] = np.nan
    linear[MODE_IDS.index("filter_contamination"), INDICATOR_NAMES.index("G_in")] = np.nan
    assert np.nanmin(linear) > 0.99
    assert r2.loc["backlash", "Hys0"] < 0.9
    assert r2.loc["filter_contamination", "G_in"] < 0.0


def test_fit_through_origin_formulas_and_conventions():
    s = np.array([0.25, 0.5, 0.75, 1.0])
    d = np.column_stack([3 * s, s**2, 1 - np.exp(-5 * s), np.zeros(4), np.full(4, 2.0), [1.0, np.nan, np.nan, np.nan]])
    fit = fit_through_origin(s, d)
    a_quad = np.sum(s**3) / np.sum(s**2)
    resid = s**2 - a_quad * s
    np.testing.assert_allclose(fit["A"][:2], [3.0, a_quad])
    assert fit["r2"][0] == pytest.approx(1.0)
    assert fit["r2"][1] == pytest.approx(1 - np.sum(resid**2) / np.sum((s**2 - np.mean(s**2)) ** 2))
    assert fit["r2"][1] == pytest.approx(0.84, abs=0.005)  # the values quoted in the docstring
    assert fit["r2"][2] == pytest.approx(-5.32, abs=0.01)
    assert fit["residual_std"][1] == pytest.approx(np.sqrt(np.sum(resid**2) / 3))
    assert fit["A"][3] == 0.0 and fit["r2"][3] == 1.0  # insensitive indicator: exact zero law
    assert fit["r2"][4] == -np.inf  # constant offset: no spread to explain, law wrong
    assert fit["n"].tolist() == [4, 4, 4, 4, 4, 1]
    assert np.isnan(fit["r2"][5]) and np.isnan(fit["residual_std"][5]) and fit["A"][5] == 4.0
    with pytest.raises(DataFormatError, match=r"Got \(4,\) and \(3, 6\)"):
        fit_through_origin(s, d[:3])


def test_paired_deltas_use_each_units_mean_healthy_flight():
    deltas = paired_deltas(tiny_doe(), features=["X1", "Y1"])
    assert list(deltas.index) == [1, 2, 5, 6]
    assert list(deltas.columns) == ["unit_id", "mode", "intensity", "X1", "Y1"]
    np.testing.assert_allclose(deltas["X1"], [1.0, 2.1, 1.0, 2.0])
    np.testing.assert_allclose(deltas["Y1"], 0.0)
    itl = fit_itl(tiny_doe(), features=["X1", "Y1"])
    assert itl.matrix().loc["backlash", "X1"] == pytest.approx((0.5 * 1 + 2.1 + 0.5 * 1 + 2) / 2.5)


def test_missing_indicator_values_are_dropped_law_by_law():
    rng = np.random.default_rng(2)
    doe = make_doe_table(true_coef(rng).iloc[:2], rng=rng, n_units=3, intensities=LEVELS)
    degraded = doe.index[doe["mode"] == MODE_IDS[0]]
    doe.loc[degraded[0], "X1"] = np.nan
    doe.loc[degraded[1], "Y1_valid"] = False
    doe.loc[doe.index[(doe["mode"] == "healthy") & (doe["unit_id"] == 2)], "G_null"] = np.nan
    n = fit_itl(doe).matrix("n")
    assert n.loc[MODE_IDS[0], "X1"] == 14 and n.loc[MODE_IDS[0], "Y1"] == 14
    assert n.loc[MODE_IDS[0], "G_null"] == 10 and n.loc[MODE_IDS[1], "G_null"] == 10  # unit 2 has no reference
    assert n.loc[MODE_IDS[1], "X1"] == 15


# --------------------------------------------------------------------- apply
def test_apply_implements_eq_4():
    rng = np.random.default_rng(3)
    itl = fit_itl(make_doe_table(true_coef(rng), rng=rng, n_units=3))
    a = itl.matrix().loc["internal_leakage"].to_numpy()
    healthy = make_doe_table(true_coef(rng).iloc[:1], rng=rng, n_units=4)
    healthy = healthy[healthy["mode"] == "healthy"]
    before = healthy.copy()
    s = np.array([0.0, 0.3, 0.6, 1.0])
    out = itl.apply(healthy, "internal_leakage", s)
    pd.testing.assert_frame_equal(healthy, before)  # input not mutated
    expected = healthy[list(INDICATOR_NAMES)].to_numpy() + np.outer(s, a)
    np.testing.assert_allclose(out[list(INDICATOR_NAMES)].to_numpy(), expected)
    pd.testing.assert_frame_equal(out.drop(columns=list(INDICATOR_NAMES)), healthy.drop(columns=list(INDICATOR_NAMES)))
    vector = healthy[list(INDICATOR_NAMES)].to_numpy()[0]
    np.testing.assert_allclose(itl.apply(vector, "internal_leakage", 0.5), vector + 0.5 * a)
    np.testing.assert_allclose(itl.apply(vector, "internal_leakage", s), vector + np.outer(s, a))
    series = healthy.iloc[1]
    np.testing.assert_allclose(itl.apply(series, "internal_leakage", 1.0)[list(INDICATOR_NAMES)].to_numpy(dtype=float), series[list(INDICATOR_NAMES)].to_numpy(dtype=float) + a)
    np.testing.assert_array_equal(itl.apply(vector, "internal_leakage", 0.0), vector)


def test_apply_rejects_bad_inputs():
    rng = np.random.default_rng(4)
    itl = fit_itl(make_doe_table(true_coef(rng).iloc[:2], rng=rng, n_units=2))
    vector = np.zeros(10)
    with pytest.raises(UnknownNameError, match="'backlash'"):
        itl.apply(vector, "backlash", 0.5)
    with pytest.raises(ParameterError, match=r"^The 'intensity' parameter of ITL.apply must be .* Got 1.5 instead\.$"):
        itl.apply(vector, MODE_IDS[0], 1.5)
    with pytest.raises(ParameterError, match="intensity"):
        itl.apply(np.zeros((3, 10)), MODE_IDS[0], [0.1, 0.2])
    with pytest.raises(DataFormatError, match=r"lack indicator\(s\) \['G_null'\]"):
        itl.apply(pd.DataFrame(np.zeros((2, 9)), columns=list(INDICATOR_NAMES[:9])), MODE_IDS[0], 0.5)
    with pytest.raises(DataFormatError, match=r"shape \(10,\)"):
        itl.apply(np.zeros(9), MODE_IDS[0], 0.5)


# ------------------------------------------------------------ table and I/O
def test_csv_round_trip(tmp_path):
    rng = np.random.default_rng(5)
    doe = make_doe_table(true_coef(rng), rng=rng, n_units=3)
    doe.loc[doe["mode"] == "backlash", "Hys0"] = np.nan  # a law without data: NaN A, n = 0
    itl = fit_itl(doe)
    assert itl.table.loc[(itl.table["mode"] == "backlash") & (itl.table["indicator"] == "Hys0"), "n"].item() == 0
    path = itl.to_csv(tmp_path / "itl.csv")
    back = ITL.from_csv(path)
    pd.testing.assert_frame_equal(back.table, itl.table, check_exact=False, rtol=1e-12)
    assert back.table["n"].dtype == np.int64


def test_itl_table_is_validated_and_sorted():
    rows = pd.DataFrame(
        {"mode": ["backlash", "null_bias_drift"], "indicator": ["Y1", "X1"], "A": [1.0, 2.0],
         "r2": [1.0, 0.5], "residual_std": [0.1, 0.2], "n": [4, 4]}
    )
    itl = ITL(rows)
    assert itl.table["mode"].tolist() == ["null_bias_drift", "backlash"]  # MODE_IDS order
    assert itl.modes == ("null_bias_drift", "backlash") and itl.indicators == ("X1", "Y1")
    assert np.isnan(itl.matrix().loc["backlash", "X1"])
    with pytest.raises(DataFormatError, match="missing required column 'r2'"):
        ITL(rows.drop(columns="r2"))
    with pytest.raises(DataFormatError, match=r"unknown value\(s\) \['leak'\]"):
        ITL(rows.assign(mode=["leak", "backlash"]))
    with pytest.raises(DataFormatError, match="more than one law"):
        ITL(pd.concat([rows, rows.iloc[:1]]))
    with pytest.raises(DataFormatError, match="unexpected column"):
        ITL(rows.assign(extra=1))
    with pytest.raises(DataFormatError, match="non-negative integers"):
        ITL(rows.assign(n=[4, 2.5]))
    with pytest.raises(ParameterError, match="'value' parameter of ITL.matrix"):
        itl.matrix("slope")


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.drop(columns="unit_id"), "missing required column 'unit_id'"),
        (lambda d: d.drop(columns="Y1"), "missing required column 'Y1'"),
        (lambda d: d.assign(mode=d["mode"].replace("backlash", "wear")), r"unknown value\(s\) \['wear'\]"),
        (lambda d: d.assign(intensity=d["intensity"].replace(1.0, 1.2)), r"in \[0, 1\]. Got 1.2"),
        (lambda d: d.assign(intensity=d["intensity"].where(d["mode"] != "healthy", 0.1)), "intensity 0"),
        (lambda d: d[d["unit_id"] != 1].assign(mode="healthy", intensity=0.0), "no degraded flight"),
        (lambda d: d.drop(index=[3, 4]), r"units \[1\] have none"),
        (lambda d: d.assign(unit_id=d["unit_id"].astype(float).where(d.index != 2)), "'unit_id' .* missing"),
    ],
)
def test_bad_doe_tables_give_clear_errors(mutate, message):
    with pytest.raises(DataFormatError, match=message):
        fit_itl(mutate(tiny_doe()), features=["X1", "Y1"])


def test_from_csv_of_a_missing_file():
    with pytest.raises(DataFormatError, match="does not exist"):
        ITL.from_csv("/nonexistent/itl.csv")


# ----------------------------------------------------------------------- plot
def test_plot_itl_writes_one_panel_per_law(tmp_path):
    rng = np.random.default_rng(6)
    coef = true_coef(rng).loc[["backlash", "internal_leakage"]]
    doe = make_doe_table(coef, rng=rng, n_units=3, laws={("backlash", "Hys0"): np.square})
    small = fit_itl(doe, features=["X1", "Hys0", "G_in"])  # 2 x 3 panels keep the test fast
    image = imread(plot_itl(small, doe, tmp_path / "small.png"))
    assert image[..., :3].std() > 0.05  # not blank
    wide = fit_itl(doe, features=["X1", "Y1", "X2", "Y2", "Hys0", "G_in"])
    image_wide = imread(plot_itl(wide, doe, tmp_path / "wide.png"))
    assert image_wide.shape[0] == image.shape[0] and image_wide.shape[1] > 1.6 * image.shape[1]
    with pytest.raises(OutputPathError, match="does not exist"):
        plot_itl(small, doe, tmp_path / "missing" / "itl.png")
