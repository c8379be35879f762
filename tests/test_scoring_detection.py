"""Tests of Table V (detection) against the worked example of docs/scoring.md."""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.scoring import (ScoringConfig, detection_by_band, detection_table,
                                  fit_healthy_model, flight_table, score_run, threshold_table,
                                  wilson_interval)

from test_scoring_run import (DRIFT, LEAK, decisions, fleet_labels, make_labels, make_run, ramp,
                              worked_example_labels)


def worked_example_run():
    labels = worked_example_labels()
    alarm = np.zeros(len(labels), bool)
    alarm[[3, 21, 24, 25, 26, 27, 28, 29]] = True
    return make_run(labels, decisions(labels, alarm), name="worked example")


def test_worked_example_counts_and_both_rate_definitions():
    card = score_run(worked_example_run())
    row = card.detection_row("method_alarm", LEAK)
    assert (row["nfd"], row["fp"], row["fn"], row["fd"]) == (19, 1, 4, 6)
    assert (row["n_incipient"], row["n_incipient_detected"]) == (4, 1)
    assert row["fpr_standard"] == pytest.approx(1 / 20)
    assert row["fnr_standard"] == pytest.approx(4 / 10)
    assert row["fpr_paper_def"] == pytest.approx(1 / 7)
    assert row["fnr_paper_def"] == pytest.approx(4 / 23)
    assert row["balanced_accuracy"] == pytest.approx(1 - (0.05 + 0.4) / 2)
    assert row["incipient_detection_rate"] == pytest.approx(0.25)
    lo, hi = wilson_interval(1, 20)
    assert (row["fpr_standard_ci_low"], row["fpr_standard_ci_high"]) == (lo, hi)
    assert round(row["fpr_standard_ci_low"], 4) == 0.0089
    assert round(row["fpr_standard_ci_high"], 4) == 0.2361
    assert row["note"] == ""


def test_threshold_is_mu_plus_a_sigma_of_healthy_training_scores():
    model = fit_healthy_model([1.0, 2.0, 3.0, 4.0])
    assert model.mu == 2.5 and model.sigma == pytest.approx(np.sqrt(1.25))  # MLE, ddof=0
    t = threshold_table(model, (0, 2))
    assert t["threshold"].tolist() == pytest.approx([2.5, 2.5 + 2 * np.sqrt(1.25)])
    assert t["gaussian_tail_probability"].tolist() == pytest.approx([0.5, 0.02275], abs=1e-5)


def test_detection_uses_strict_threshold():
    labels = fleet_labels()
    healthy = [0.0, 2.0]  # mu = 1, sigma = 1
    score = np.where(labels["unit_id"] == "u0", 3.0, 0.0)  # healthy unit exactly at A=2
    run = make_run(labels, decisions(labels, np.zeros(len(labels)), score=score),
                   healthy_scores=healthy)
    table = detection_table(flight_table(run), fit_healthy_model(healthy))
    a2 = table[(table["operating_point"] == "thr(A=2)") & (table["mode"] == "all")].iloc[0]
    a1 = table[(table["operating_point"] == "thr(A=1)") & (table["mode"] == "all")].iloc[0]
    assert a2["fp"] == 0 and a1["fp"] == 20


def test_per_mode_population_is_healthy_plus_that_mode_only():
    labels = make_labels([{"unit": "h", "n": 10},
                          {"unit": "d", "intensity": {DRIFT: ramp(10, 0)}},
                          {"unit": "l", "intensity": {LEAK: ramp(10, 0)}},
                          {"unit": "m", "intensity": {LEAK: np.ones(4), DRIFT: np.ones(4)}}])
    card = score_run(make_run(labels, decisions(labels, labels["unit_id"] != "h")))
    t = card.detection.set_index(["operating_point", "mode"]).loc["method_alarm"]
    assert t.loc[DRIFT, "n_healthy"] == t.loc[LEAK, "n_healthy"] == 10
    assert t.loc[DRIFT, "n_detectable"] + t.loc[DRIFT, "n_incipient"] == 10
    assert t.loc["all", "n_detectable"] + t.loc["all", "n_incipient"] == 24  # incl. multiple
    assert list(t.index) == [DRIFT, LEAK, "all"]  # MODE_IDS order, then all
    assert any("several active degradations" in n for n in card.notes)


def test_incipient_flights_are_neither_fn_nor_tp():
    labels = make_labels([{"unit": "h", "n": 4},
                          {"unit": "l", "intensity": {LEAK: [0.1, 0.2, 0.5, 1.0]}}])
    for alarm_on_incipient in (False, True):
        alarm = np.array([0, 0, 0, 0, alarm_on_incipient, alarm_on_incipient, 1, 1], bool)
        row = score_run(make_run(labels, decisions(labels, alarm))).detection_row("method_alarm")
        assert (row["fn"], row["fd"], row["fp"]) == (0, 2, 0)
        assert row["n_incipient_detected"] == (2 if alarm_on_incipient else 0)
    strict = ScoringConfig(detectable_fraction=0.0)
    row = score_run(make_run(labels, decisions(labels, [0, 0, 0, 0, 0, 0, 1, 1])),
                    strict).detection_row("method_alarm")
    assert (row["fn"], row["n_incipient"]) == (2, 0)


def test_undefined_rates_are_nan_with_note():
    labels = make_labels([{"unit": "l", "intensity": {LEAK: [0.5, 1.0]}}])
    card = score_run(make_run(labels, decisions(labels, [False, False])))
    row = card.detection_row("method_alarm")
    assert np.isnan(row["fpr_standard"]) and np.isnan(row["fpr_paper_def"])
    assert row["fnr_standard"] == 1.0
    assert "fpr_standard undefined (no healthy flight)" in row["note"]
    assert "fpr_paper_def undefined (no detection: FP + FD = 0)" in row["note"]
    assert any("no healthy flight" in n for n in card.notes)


def test_detection_by_band_reports_incipient_bands():
    run = worked_example_run()
    ft = flight_table(run)
    t = detection_by_band(ft, fit_healthy_model(run.healthy_scores))
    t = t[t["operating_point"] == "method_alarm"].set_index("band")
    assert t.loc["healthy", "detection_rate"] == pytest.approx(0.05)
    assert t.loc["<12.5%", "n_flights"] == 4 and t.loc["<12.5%", "n_detected"] == 1
    assert not t.loc["<12.5%", "detectable"] and t.loc["50%", "detectable"]
    assert t.loc["50%", "n_flights"] + t.loc["100%", "n_flights"] == 10


def test_bootstrap_columns_are_reproducible():
    cfg = ScoringConfig(n_bootstrap=100, random_state=5)
    run = make_run(fleet_labels(), decisions(fleet_labels(),
                                             np.random.default_rng(2).random(70) < 0.5))
    a = score_run(run, cfg).detection
    b = score_run(run, cfg).detection
    assert "fnr_standard_boot_low" in a.columns
    np.testing.assert_array_equal(a["fnr_standard_boot_low"], b["fnr_standard_boot_low"])
    assert "fnr_standard_boot_low" not in score_run(run).detection.columns
