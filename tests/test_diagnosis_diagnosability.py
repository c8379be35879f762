"""The diagnosability report on small synthetic designs with known laws."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.diagnosis.diagnosability import diagnosability_report, fit_power_law
from fuelhm_bench.testing.diagnosis import DEFAULT_STD, make_doe_table, make_healthy_table
from fuelhm_bench.errors import ParameterError


def test_power_law_recovers_known_exponents_and_beats_the_line_on_a_step():
    s = np.repeat([0.25, 0.5, 0.75, 1.0], 3)
    step = np.where(s > 0, 2.0, 0.0)
    fit = fit_power_law(s, np.column_stack([3 * s, 3 * s**2.5, step]))
    assert fit["p"][0] == 1.0 and fit["c"][0] == pytest.approx(3.0)
    assert fit["p"][1] == pytest.approx(2.5, rel=0.03) and fit["r2"][1] > 0.999
    # A step (constant change at every intensity) has zero spread: the line is worse than a
    # constant (r2 = -inf by the centred convention), the monotone law reproduces it almost.
    assert fit["p"][2] <= 0.06 and fit["c"][2] == pytest.approx(2.0, rel=0.1)
    with pytest.raises(ParameterError, match="intensity"):
        fit_power_law(np.array([0.0, 1.0]), np.ones((2, 1)))


def test_power_law_ignores_missing_values_and_needs_two_rows():
    s = np.array([0.5, 1.0, 1.0])
    fit = fit_power_law(s, np.array([[1.0, np.nan], [2.0, 5.0], [2.0, np.nan]]))
    assert fit["n"].tolist() == [3, 1]
    assert fit["c"][0] == pytest.approx(2.0) and np.isnan(fit["c"][1])


@pytest.fixture(scope="module")
def report():
    rng = np.random.default_rng(3)
    coef = pd.DataFrame(0.0, index=["null_bias_drift", "filter_contamination", "backlash", "radial_clearance"],
                        columns=["X1", "X2", "Hys0", "G_null"])
    coef.loc["null_bias_drift", ["X1", "X2"]] = 0.4          # Z = 0.4 / 0.05 = 8 on X1 and X2
    coef.loc["filter_contamination", ["X1", "X2"]] = 0.8     # same direction: cosine 1
    coef.loc["backlash", "Hys0"] = 0.6                        # Z = 0.6 / 0.2 = 3: below target
    coef.loc["radial_clearance", "G_null"] = 2.0              # a saturating law
    doe = make_doe_table(coef, rng=rng, n_units=4,
                         laws={("radial_clearance", "G_null"): lambda s: 1.0 - np.exp(-5.0 * s)})
    healthy = make_healthy_table(4000, rng=rng)
    return diagnosability_report(doe, healthy, max_intensity={"null_bias_drift": 1.0, "filter_contamination": 1.0,
                                                             "backlash": 1.0, "radial_clearance": 0.5})


def test_report_largest_z_per_mode(report):
    m = report.modes.set_index("mode")
    assert list(m.index) == ["filter_contamination", "null_bias_drift", "backlash", "radial_clearance"]
    assert m.loc["null_bias_drift", "z_max"] == pytest.approx(0.4 / DEFAULT_STD["X1"], rel=0.06)
    assert m.loc["null_bias_drift", "z_max_indicator"] in ("X1", "X2")
    assert m.loc["backlash", "z_max"] == pytest.approx(0.6 / DEFAULT_STD["Hys0"], rel=0.06)
    assert not m.loc["backlash", "visible"] and m.loc["null_bias_drift", "visible"]
    assert not report.all_visible
    # The saturating law has done most of its change at half intensity: the monotone law follows it
    # (true Z = 2 (1 - e^-2.5) / 0.2 = 9.2), the line through the origin misses it.
    true_z = 2.0 * (1.0 - np.exp(-2.5)) / DEFAULT_STD["G_null"]
    assert m.loc["radial_clearance", "z_max"] == pytest.approx(true_z, rel=0.08)
    assert m.loc["radial_clearance", "z_max_linear"] < 0.8 * true_z
    assert m.loc["radial_clearance", "p_at_z_max"] < 0.5 and m.loc["radial_clearance", "r2_power_at_z_max"] > 0.85
    assert m.loc["null_bias_drift", "r2_linear_at_z_max"] > 0.99


def test_report_r2_of_each_law_form(report):
    laws = report.laws.set_index(["mode", "indicator"])
    assert len(report.laws) == 4 * 10
    assert laws.loc[("null_bias_drift", "X1"), "r2_linear"] > 0.99
    assert laws.loc[("radial_clearance", "G_null"), "r2_power"] > 0.85
    assert laws.loc[("radial_clearance", "G_null"), "r2_linear"] < 0.0


def test_report_cosine_flags_collinear_signatures(report):
    c = report.cosine
    assert c.shape == (4, 4) and np.allclose(np.diag(c), 1.0)
    assert c.loc["null_bias_drift", "filter_contamination"] > 0.99
    assert abs(c.loc["null_bias_drift", "backlash"]) < 0.2
    pairs = report.similar_pairs()
    assert [(a, b) for a, b, _ in pairs] == [("filter_contamination", "null_bias_drift")]
    m = report.modes.set_index("mode")
    assert not m.loc["null_bias_drift", "distinguishable"] and m.loc["backlash", "distinguishable"]


def test_report_files(report, tmp_path):
    paths = report.write(tmp_path)
    assert [p.name for p in paths] == ["diagnosability_paper.md", "diagnosability_paper.json",
                                       "diagnosability_paper_laws.csv"]
    data = json.loads(paths[1].read_text())
    assert data["all_visible"] is False and len(data["modes"]) == 4
    assert data["similar_pairs"][0][:2] == ["filter_contamination", "null_bias_drift"]
    md = paths[0].read_text()
    assert "| backlash | 1 | 3." in md and "**no**" in md and "exponent p" in md
    assert len(pd.read_csv(paths[2])) == 40
