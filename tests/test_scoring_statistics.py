"""Unit-bootstrap intervals, ranks / Friedman / critical difference, guilt calibration."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from fuelhm_bench.errors import DataFormatError, ParameterError
from fuelhm_bench.methods import GUILT_COLUMNS
from fuelhm_bench.scoring import (Run, fit_healthy_model, headline_kpis, null_decisions,
                                  perfect_decisions, score_run)
from fuelhm_bench.scoring.bootstrap import INTERVAL_KPIS, kpi_intervals, scorecard_intervals
from fuelhm_bench.scoring.calibration import brier_score, guilt_calibration, reliability_table
from fuelhm_bench.scoring.ranking import (cd_diagram, critical_difference, friedman_test,
                                          mean_ranks, rank_matrix, wilcoxon_holm)
from fuelhm_bench.taxonomy import MODE_IDS


def _labels(n_units=6, n_flights=10, seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for u in range(n_units):
        mode = MODE_IDS[u % 3] if u % 4 else None
        onset = int(rng.integers(2, 6))
        for k in range(n_flights):
            row = {"unit_id": u, "flight_index": k}
            for m in MODE_IDS:
                active = m == mode
                row[f"intensity_{m}"] = max(0.0, (k - onset + 1) / 4) if active and k >= onset else 0.0
                row[f"max_intensity_{m}"] = 1.0 if active else 0.0
                row[f"onset_{m}"] = onset if active else -1
            rows.append(row)
    return pd.DataFrame(rows)


def _noisy(labels, seed=1, flip=0.2):
    rng = np.random.default_rng(seed)
    d = perfect_decisions(labels)
    flips = rng.random(len(d)) < flip
    d.loc[flips, "alarm"] = ~d.loc[flips, "alarm"]
    g = rng.dirichlet(np.ones(7), size=len(d))
    d.loc[:, list(GUILT_COLUMNS)] = np.where(d["alarm"].to_numpy()[:, None],
                                             np.where(flips[:, None], g,
                                                      d[list(GUILT_COLUMNS)].to_numpy()), 0.0)
    wrong = d["alarm"] & (d[list(GUILT_COLUMNS)].sum(axis=1) == 0)
    d.loc[wrong, list(GUILT_COLUMNS)] = 1.0 / 7
    d["score"] = d["score"] + rng.normal(0, 0.1, len(d))
    return d


# ------------------------------------------------------------------ bootstrap
def test_point_values_equal_headline_kpis():
    labels = _labels()
    card = score_run(Run(labels, _noisy(labels), healthy_scores=[0.0, 0.1, 0.05, -0.05]))
    t = scorecard_intervals(card, n_resamples=300).set_index("kpi")
    head = headline_kpis(card)
    for kpi in INTERVAL_KPIS:
        assert t.loc[kpi, "value"] == pytest.approx(head[kpi], nan_ok=True), kpi
        if np.isfinite(t.loc[kpi, "value"]):
            assert t.loc[kpi, "ci_low"] <= t.loc[kpi, "value"] + 1e-12 <= t.loc[kpi, "ci_high"] + 2e-12


def test_perfect_run_has_degenerate_interval_and_seed_reproduces():
    labels = _labels()
    card = score_run(Run(labels, perfect_decisions(labels), healthy_scores=[0.0, 0.1]))
    t = scorecard_intervals(card, n_resamples=200).set_index("kpi")
    assert t.loc["summary_score", ["value", "ci_low", "ci_high"]].tolist() == [100.0] * 3
    assert t.loc["fpr_standard_alarm", "ci_high"] == 0.0
    again = scorecard_intervals(card, n_resamples=200)
    pd.testing.assert_frame_equal(t.reset_index(), again)


def test_interval_resamples_units_not_flights():
    # worked example of the module docstring: per-unit FPR 1/2 and 0/2 -> bounds 0 and 1/2
    flights = pd.DataFrame({"unit_id": [1, 1, 2, 2], "flight_index": [0, 1, 0, 1],
                            "true_mode": ["healthy"] * 4, "detectable": [False] * 4,
                            "score": [0.0] * 4, "alarm": [True, False, False, False],
                            "predicted": ["tie", "no_alarm", "no_alarm", "no_alarm"]})
    t = kpi_intervals(flights, fit_healthy_model([0.0, 1.0]), n_resamples=500).set_index("kpi")
    assert t.loc["fpr_standard_alarm", ["value", "ci_low", "ci_high"]].tolist() == [0.25, 0.0, 0.5]
    assert np.isnan(t.loc["summary_score", "value"])  # no faulty flight


def test_more_units_narrow_the_interval():
    widths = []
    for n_units in (6, 30):
        labels = _labels(n_units=n_units)
        card = score_run(Run(labels, _noisy(labels), healthy_scores=[0.0, 0.1]))
        t = scorecard_intervals(card, n_resamples=200).set_index("kpi")
        widths.append(t.loc["summary_score", "ci_high"] - t.loc["summary_score", "ci_low"])
    assert widths[1] < widths[0]


@pytest.mark.parametrize("kw, match", [({"n_resamples": 0}, "n_resamples"),
                                       ({"confidence": 1.0}, "confidence")])
def test_bootstrap_bad_parameters(kw, match):
    labels = _labels()
    card = score_run(Run(labels, null_decisions(labels), healthy_scores=[0.0, 0.1]))
    with pytest.raises(ParameterError, match=match):
        scorecard_intervals(card, **kw)


# ------------------------------------------------------------------ ranks
def _results():
    # 3 methods x 5 scenarios; "a" best everywhere, "b" second, "c" last, one tie
    rows = []
    for i, sc in enumerate(["s1", "s2", "s3", "s4", "s5"]):
        for m, v in (("a", 50 + i), ("b", 20 + i), ("c", 5.0 if i else 20 + i)):
            rows.append({"method": m, "scenario": sc, "seed": None, "summary_score": v})
    return pd.DataFrame(rows)


def test_mean_ranks_worked_values():
    r = mean_ranks(_results())
    # s1: a 1, b and c tie at 2.5; s2-s5: a 1, b 2, c 3
    assert r["method"].tolist() == ["a", "b", "c"]
    np.testing.assert_allclose(r["mean_rank"], [1.0, (2.5 + 8) / 5, (2.5 + 12) / 5])
    assert (r["n_blocks"] == 5).all()


def test_failed_entries_drop_their_block():
    res = _results()
    res.loc[(res["method"] == "c") & (res["scenario"] == "s5"), "summary_score"] = np.nan
    assert rank_matrix(res).shape == (4, 3)


def test_duplicate_entry_is_refused():
    res = pd.concat([_results(), _results().iloc[[0]]])
    with pytest.raises(DataFormatError, match="one row per method and block"):
        rank_matrix(res)


def test_friedman_matches_scipy():
    res = _results()
    out = friedman_test(res)
    wide = res.pivot(index="scenario", columns="method", values="summary_score")
    ref = stats.friedmanchisquare(*[-wide[c] for c in wide.columns])
    assert out["statistic"] == pytest.approx(ref.statistic)
    assert out["pvalue"] == pytest.approx(ref.pvalue) and out["pvalue"] < 0.05
    assert np.isnan(friedman_test(res[res["method"] != "c"])["pvalue"])


def test_critical_difference_matches_demsar_table():
    # Demšar (2006), Table 5(a): q_0.05 for k = 2..10
    q = [1.960, 2.343, 2.569, 2.728, 2.850, 2.949, 3.031, 3.102, 3.164]
    for k, qk in zip(range(2, 11), q):
        assert critical_difference(k, 1) / np.sqrt(k * (k + 1) / 6) == pytest.approx(qk, abs=1.5e-3)
    assert critical_difference(4, 14) == pytest.approx(1.254, abs=5e-4)
    with pytest.raises(ParameterError, match="n_methods"):
        critical_difference(1, 5)


def test_wilcoxon_holm():
    rng = np.random.default_rng(0)
    rows = [{"method": m, "scenario": f"s{i}", "summary_score": base + rng.normal(0, 1)}
            for i in range(12) for m, base in (("a", 10), ("b", 0), ("c", 0.1))]
    out = wilcoxon_holm(pd.DataFrame(rows)).set_index(["method_a", "method_b"])
    assert out.loc[("a", "b"), "significant"] and not out.loc[("b", "c"), "significant"]
    assert (out["pvalue_holm"] >= out["pvalue"]).all()


def test_cd_diagram_svg():
    r = mean_ranks(_results())
    svg = cd_diagram(r, critical_difference(3, 5), title="summary score")
    assert svg.startswith("<svg") and svg.endswith("</svg>") and "http" not in svg.replace(
        'xmlns="http://www.w3.org/2000/svg"', "")
    assert svg.count('class="cd-method"') == 3
    # mean ranks 1.0, 2.1, 2.9 and CD = 1.48: cliques {a, b} and {b, c}, but a and c differ
    assert svg.count('class="cd-clique"') == 2


# ------------------------------------------------------------------ calibration
def _flights(guilt, true_mode):
    f = pd.DataFrame(np.asarray(guilt, float), columns=list(GUILT_COLUMNS))
    return f.assign(true_mode=true_mode, alarm=True)


def test_brier_worked_values():
    g = np.zeros((2, 7))
    g[0, MODE_IDS.index("backlash")] = 1.0
    g[1, MODE_IDS.index("internal_leakage")] = 1.0
    assert brier_score(_flights(g, "backlash")) == 1.0
    assert brier_score(_flights(np.full((3, 7), 1 / 7), "backlash")) == pytest.approx(6 / 7)
    healthy = _flights(g, "healthy")
    assert np.isnan(brier_score(healthy))


def test_reliability_of_a_calibrated_method():
    rng = np.random.default_rng(0)
    n = 20000
    p = rng.dirichlet(np.ones(7), size=n)
    true = np.array([MODE_IDS[rng.choice(7, p=row)] for row in p])
    out = guilt_calibration(_flights(p, true), n_bins=5)
    t = out["reliability"]
    ok = t["count"] > 500
    np.testing.assert_allclose(t.loc[ok, "observed_frequency"], t.loc[ok, "mean_predicted"],
                               atol=0.02)
    assert out["ece"] < 0.02 and out["n_flights"] == n
    over = guilt_calibration(_flights(np.eye(7)[rng.integers(0, 7, n)], true), n_bins=5)
    assert over["ece"] > 0.2 and over["brier"] > out["brier"]


def test_reliability_bad_bins():
    with pytest.raises(ParameterError, match="n_bins"):
        reliability_table(_flights(np.full((1, 7), 1 / 7), "backlash"), n_bins=0)
