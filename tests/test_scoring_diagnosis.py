"""Tests of Table VI, the false classification rate, the confusion matrix and the delays."""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.errors import UnknownNameError
from fuelhm_bench.scoring import (ScoringConfig, classification_table, confusion_matrix,
                                  delay_summary, detection_delays, diagnosis_table, flight_table,
                                  headline_kpis, score_run)
from fuelhm_bench.taxonomy import MODE_IDS

from test_scoring_run import DRIFT, LEAK, decisions, fleet_labels, make_labels, make_run, ramp


def test_table_vi_mean_guilt_per_band():
    leak = [0.1, 0.25, 0.3, 0.5, 0.6, 1.0]  # bands <12.5, 25, 25, 50, 50, 100
    labels = make_labels([{"unit": "l", "intensity": {LEAK: leak}}])
    decs = decisions(labels, [1, 1, 1, 1, 1, 1])
    g = np.zeros((6, 7))
    g[:, MODE_IDS.index(LEAK)] = [0.6, 0.6, 0.8, 0.9, 0.7, 1.0]
    g[:, MODE_IDS.index(DRIFT)] = 1 - g[:, MODE_IDS.index(LEAK)]
    decs[[f"guilt_{m}" for m in MODE_IDS]] = g
    t = diagnosis_table(flight_table(make_run(labels, decs))).set_index("band")
    assert list(t.index) == ["<12.5%", "25%", "50%", "100%"]
    assert t.loc["25%", f"guilt_{LEAK}"] == pytest.approx(0.7)
    assert t.loc["25%", f"guilt_{DRIFT}"] == pytest.approx(0.3)
    assert t.loc["50%", f"guilt_{LEAK}"] == pytest.approx(0.8)
    assert t.loc["100%", "n_alarmed"] == 1 and t.loc["100%", "fcr"] == 0.0
    assert (t["true_mode"] == LEAK).all()


def test_table_vi_averages_only_alarmed_flights():
    labels = make_labels([{"unit": "l", "intensity": {LEAK: [0.5, 0.5]}}])
    decs = decisions(labels, [True, False])
    t = diagnosis_table(flight_table(make_run(labels, decs)))
    assert t.loc[0, "n_flights"] == 2 and t.loc[0, "n_alarmed"] == 1
    assert t.loc[0, "alarm_rate"] == 0.5 and t.loc[0, f"guilt_{LEAK}"] == 1.0
    none = diagnosis_table(flight_table(make_run(labels, decisions(labels, [False, False]))))
    assert np.isnan(none.loc[0, f"guilt_{LEAK}"]) and np.isnan(none.loc[0, "fcr"])


def test_false_classification_rate_counts_ties_as_false():
    labels = make_labels([{"unit": "l", "intensity": {LEAK: [0.1, 0.5, 0.6, 0.8]}}])
    decs = decisions(labels, [1, 1, 1, 1])
    decs.loc[1, [f"guilt_{m}" for m in MODE_IDS]] = np.eye(7)[MODE_IDS.index(DRIFT)]
    decs.loc[2, [f"guilt_{m}" for m in MODE_IDS]] = np.full(7, 1 / 7)
    t = classification_table(flight_table(make_run(labels, decs))).set_index("mode")
    assert t.loc[LEAK, "n_alarmed"] == 4 and t.loc[LEAK, "n_false_classification"] == 2
    assert t.loc[LEAK, "fcr"] == 0.5
    assert t.loc[LEAK, "n_alarmed_detectable"] == 3 and t.loc[LEAK, "fcr_detectable"] == 2 / 3
    assert t.loc["all", "fcr"] == 0.5


def test_confusion_matrix_counts():
    labels = fleet_labels()
    rng = np.random.default_rng(0)
    alarm = rng.random(len(labels)) < 0.6
    decs = decisions(labels, alarm, guilt_mode=LEAK)
    ft = flight_table(make_run(labels, decs))
    cm = confusion_matrix(ft)
    assert list(cm.index) == ["healthy", DRIFT, LEAK]
    assert list(cm.columns) == ["no_alarm", *MODE_IDS, "tie"]
    healthy = ft["true_mode"] == "healthy"
    assert cm.loc["healthy"].sum() == healthy.sum()
    assert cm.loc["healthy", "no_alarm"] == (~ft["alarm"] & healthy).sum()
    assert cm.loc[DRIFT, DRIFT] == 0  # all guilt on the leak
    assert cm.loc[DRIFT].sum() == ((ft["true_mode"] == DRIFT) & ft["detectable"]).sum()
    with_inc = confusion_matrix(ft, include_incipient=True)
    assert with_inc.loc[DRIFT].sum() == (ft["true_mode"] == DRIFT).sum()


def test_delays_per_event_and_undetected_reported_apart():
    labels = make_labels([{"unit": "a", "intensity": {LEAK: ramp(12, 4)}},
                          {"unit": "b", "intensity": {LEAK: ramp(12, 2)}},
                          {"unit": "c", "intensity": {DRIFT: ramp(12, 6)}}])
    alarm = np.zeros(36, bool)
    alarm[[1, 7, 9]] = True        # unit a: false alarm at 1, detection at 7 (onset 4)
    alarm[12 + 2] = True           # unit b: detection at onset
    d = detection_delays(flight_table(make_run(labels, decisions(labels, alarm))))
    d = d.set_index("unit_id")
    assert d.loc["a", "delay_from_onset"] == 3 and d.loc["a", "n_false_alarms_before_onset"] == 1
    # unit a: fraction reaches 0.25 at flight 5 (2/8), so 2 flights late once detectable
    assert d.loc["a", "detectable_index"] == 5 and d.loc["a", "delay_after_detectable"] == 2
    assert d.loc["b", "delay_from_onset"] == 0 and d.loc["b", "delay_after_detectable"] == 0
    assert not d.loc["c", "detected"] and np.isnan(d.loc["c", "delay_from_onset"])
    s = delay_summary(d.reset_index()).set_index("mode")
    assert s.loc["all", "n_events"] == 3 and s.loc["all", "n_not_detected"] == 1
    assert s.loc["all", "n_not_detected_once_detectable"] == 1
    assert s.loc["all", "delay_from_onset_mean"] == 1.5  # undetected event not averaged in
    assert s.loc[LEAK, "delay_from_onset_median"] == 1.5
    assert s.loc[LEAK, "delay_from_onset_p95"] == pytest.approx(2.85)
    assert s.loc["all", "detected_fraction"] == pytest.approx(2 / 3)


def test_event_that_never_becomes_detectable():
    labels = make_labels([{"unit": "a", "intensity": {LEAK: [0, 0.1, 0.2]}, "max": {LEAK: 1.0}}])
    d = detection_delays(flight_table(make_run(labels, decisions(labels, [0, 0, 0]))))
    assert np.isnan(d.loc[0, "detectable_index"]) and not d.loc[0, "detected"]
    s = delay_summary(d)
    assert s.loc[0, "n_never_detectable"] == 1 and s.loc[0, "n_not_detected_once_detectable"] == 0


def test_run_without_faulty_flights():
    labels = make_labels([{"unit": "h", "n": 10}])
    card = score_run(make_run(labels, decisions(labels, np.arange(10) == 3)))
    h = headline_kpis(card)
    assert h["fpr_standard_alarm"] == 0.1 and np.isnan(h["fnr_standard_alarm"])
    assert np.isnan(h["fcr"]) and np.isnan(h["summary_score"])
    assert card.classification["mode"].tolist() == ["all"]
    assert card.delays.empty and card.delay_summary.loc[0, "n_events"] == 0
    assert any("no detectable faulty flight" in n for n in card.notes)
    with pytest.raises(UnknownNameError, match="Got 'thr\\(A=7\\)' and 'all' instead"):
        card.detection_row("thr(A=7)")


def test_scorecard_tables_are_consistent():
    labels = fleet_labels()
    alarm = np.random.default_rng(4).random(len(labels)) < 0.5
    card = score_run(make_run(labels, decisions(labels, alarm)), ScoringConfig(a_values=(2.0,)))
    assert set(card.detection["operating_point"]) == {"thr(A=2)", "method_alarm"}
    cls = card.classification.set_index("mode")
    assert cls.loc["all", "n_alarmed"] == card.diagnosis["n_alarmed"].sum()
    assert set(card.tables()) == {"thresholds", "table_v_detection", "detection_by_band",
                                  "table_vi_diagnosis", "classification", "confusion", "delays",
                                  "delay_summary", "summary_components", "headline"}
