"""Behavioural tests of the scorer (NAB practice): properties every score must have."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.methods import RandomMethod, make_check_data, run_table
from fuelhm_bench.scoring import (HEADLINE_KPIS, Run, ScoringConfig, fit_healthy_model,
                                  headline_kpis, null_decisions, perfect_decisions, robustness,
                                  robustness_table, score_run)
from fuelhm_bench.taxonomy import MODE_IDS

from test_scoring_run import (DRIFT, HEALTHY_SCORES, LEAK, decisions, fleet_labels, make_labels,
                              make_run, ramp)

SEEDS = range(6)


def random_run(seed, p=0.4):
    labels = fleet_labels()
    rng = np.random.default_rng(seed)
    alarm = rng.random(len(labels)) < p
    decs = decisions(labels, alarm, score=rng.normal(0, 3, len(labels)))
    modes = rng.integers(0, 7, len(labels))
    decs[[f"guilt_{m}" for m in MODE_IDS]] = np.where(alarm[:, None], np.eye(7)[modes], 0.0)
    return labels, decs


def kpis(labels, decs):
    card = score_run(make_run(labels, decs))
    return card, headline_kpis(card)


def _not_worse(before, after):
    """Every headline KPI of ``after`` is at least as good as in ``before`` (NaN-tolerant)."""
    for kpi, higher in HEADLINE_KPIS.items():
        b, a = before[kpi], after[kpi]
        if np.isnan(a) or np.isnan(b):
            continue
        assert (a >= b - 1e-12) if higher else (a <= b + 1e-12), (kpi, b, a)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_false_alarm_never_improves_a_score(seed):
    labels, decs = random_run(seed)
    healthy_quiet = np.flatnonzero((labels[[f"intensity_{m}" for m in MODE_IDS]].sum(axis=1) == 0)
                                   .to_numpy() & ~decs["alarm"].to_numpy())
    i = healthy_quiet[seed % len(healthy_quiet)]
    decs.loc[i, "score"] = -1e3  # below every threshold before the change
    worse = decs.copy()
    worse.loc[i, "alarm"] = True
    worse.loc[i, f"guilt_{LEAK}"] = 1.0
    worse.loc[i, "score"] = 1e3  # also a false detection at every threshold
    card_b, before = kpis(labels, decs)
    card_a, after = kpis(labels, worse)
    _not_worse(after, before)  # the run with the false alarm is nowhere better
    assert after["fpr_standard_alarm"] > before["fpr_standard_alarm"]
    assert after["summary_score"] < before["summary_score"]
    tb, ta = card_b.detection, card_a.detection
    for col in ("fpr_standard", "fpr_paper_def", "fnr_paper_def"):
        ok = tb[col].notna() & ta[col].notna()
        assert np.all(ta.loc[ok, col] >= tb.loc[ok, col] - 1e-12), col
    assert np.all(ta["fp"] == tb["fp"] + 1)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("right_mode", [True, False])
def test_earlier_detection_is_never_worse(seed, right_mode):
    labels, decs = random_run(seed, p=0.15)
    ev = labels[labels["unit_id"] == "u1"]
    onset = int(ev[f"onset_{DRIFT}"].iloc[0])
    idx = ev.index[ev["flight_index"] >= onset]
    first = [i for i in idx if decs.loc[i, "alarm"]]
    earlier_candidates = [i for i in idx
                          if not decs.loc[i, "alarm"] and (not first or i < first[0])]
    assert earlier_candidates  # the seeds are chosen so that there is room to detect earlier
    i = earlier_candidates[seed % len(earlier_candidates)]
    earlier = decs.copy()
    earlier.loc[i, "alarm"] = True
    earlier.loc[i, [f"guilt_{m}" for m in MODE_IDS]] = np.eye(7)[
        MODE_IDS.index(DRIFT if right_mode else LEAK)]
    earlier.loc[i, "score"] = 1e3
    card_b, before = kpis(labels, decs)
    card_a, after = kpis(labels, earlier)
    db = card_b.delays.set_index("unit_id").loc["u1"]
    da = card_a.delays.set_index("unit_id").loc["u1"]
    assert da["detected"]
    assert not db["detected"] or da["delay_from_onset"] < db["delay_from_onset"]
    assert da["delay_from_onset_censored"] < db["delay_from_onset_censored"]
    assert after["summary_score"] >= before["summary_score"] - 1e-12
    for kpi in ("fnr_standard_alarm", "fnr_standard_thr", "fpr_standard_alarm"):
        assert after[kpi] <= before[kpi] + 1e-12
    if right_mode:
        _not_worse(before, after)


def test_perfect_method_scores_perfect():
    labels = fleet_labels()
    card = score_run(make_run(labels, perfect_decisions(labels)))
    h = headline_kpis(card)
    assert h["fpr_standard_alarm"] == h["fnr_standard_alarm"] == 0
    assert h["fcr"] == 0 and h["classification_accuracy"] == 1
    assert h["delay_censored_mean"] == h["delay_censored_median"] == 0
    assert (card.delays["delay_from_onset"] == 0).all()
    assert h["detected_event_fraction"] == 1 and h["summary_score"] == 100
    assert (card.delays["delay_after_detectable"] == 0).all()
    alarm_rows = card.detection[card.detection["operating_point"] == "method_alarm"]
    assert (alarm_rows["fpr_paper_def"] == 0).all() and (alarm_rows["fnr_paper_def"] == 0).all()
    assert (alarm_rows["incipient_detection_rate"] == 1).all()
    assert card.confusion.loc[LEAK, LEAK] == card.confusion.loc[LEAK].sum()


def test_null_method_scores_as_documented():
    labels = fleet_labels()
    card = score_run(make_run(labels, null_decisions(labels)))
    h = headline_kpis(card)
    assert h["fpr_standard_alarm"] == 0 and h["fnr_standard_alarm"] == 1
    assert np.isnan(h["fcr"]) and h["detected_event_fraction"] == 0
    assert h["summary_score"] == 0 and card.delays["delay_from_onset"].isna().all()
    # missed events count as their observed length: u1 20 - 5, u2 20 - 10, u3 10 - 2 flights
    assert card.delays["delay_from_onset_censored"].tolist() == [15, 10, 8]
    assert h["delay_censored_mean"] == 11
    assert h["balanced_accuracy_alarm"] == 0.5
    row = card.detection_row("method_alarm")
    assert np.isnan(row["fpr_paper_def"]) and "fpr_paper_def undefined" in row["note"]
    assert row["fnr_paper_def"] == row["fn"] / (row["fn"] + row["nfd"])
    assert any("fpr_paper_def undefined" in n for n in card.notes)
    assert card.delay_summary.set_index("mode").loc["all", "n_not_detected"] == 3


def test_random_alarms_score_near_zero_whatever_the_rate():
    labels = make_labels([{"unit": f"h{i}", "n": 200} for i in range(5)]
                         + [{"unit": f"f{i}", "intensity": {LEAK: ramp(200, 0)}} for i in range(5)])
    for p in (0.05, 0.5, 0.95):
        rng = np.random.default_rng(11)
        alarm = rng.random(len(labels)) < p
        decs = decisions(labels, alarm, guilt_mode=LEAK)
        s = score_run(make_run(labels, decs)).summary_score
        assert abs(s) < 6.0, (p, s)


def test_summary_score_worked_example():
    from test_scoring_detection import worked_example_run
    run = worked_example_run()
    assert score_run(run).summary_score == pytest.approx(55.0)
    decs = run.decisions.copy()
    decs.loc[[24, 25], [f"guilt_{m}" for m in MODE_IDS]] = np.eye(7)[0]
    wrong = Run(run.labels, decs, run.healthy_scores)
    assert score_run(wrong).summary_score == pytest.approx(100 * 0.55 * (0.5 + 0.5 * 4 / 6))
    detection_only = ScoringConfig(summary_detection_weight=1.0)
    assert score_run(wrong, detection_only).summary_score == pytest.approx(55.0)


def test_thresholds_use_only_healthy_training_scores():
    labels, decs = random_run(0)
    base = score_run(make_run(labels, decs))
    # relabelling or rescoring the evaluated flights never moves the thresholds
    shifted = decs.copy()
    shifted["score"] = shifted["score"] + 100.0
    relabelled = labels.copy()
    relabelled[f"intensity_{LEAK}"] = 0.0
    for lab, dec in ((labels, shifted), (relabelled, decs)):
        other = score_run(make_run(lab, dec))
        pd.testing.assert_frame_equal(base.thresholds, other.thresholds)
    # ... while the healthy-training scores do
    moved = score_run(make_run(labels, decs, healthy_scores=HEALTHY_SCORES * 2 + 1))
    assert not np.allclose(base.thresholds["threshold"], moved.thresholds["threshold"])
    model = fit_healthy_model(HEALTHY_SCORES)
    assert base.thresholds["threshold"].tolist() == pytest.approx(
        [model.mu + a * model.sigma for a in (0, 1, 2, 3, 5)])


def test_robustness_of_identical_and_degraded_runs():
    labels = fleet_labels()
    nominal = make_run(labels, perfect_decisions(labels), name="nominal")
    assert robustness(nominal, nominal) == 1.0
    table = robustness_table(nominal, nominal)
    assert (table["delta"].fillna(0) == 0).all() and not table["worse"].fillna(False).any()
    rng = np.random.default_rng(0)
    noisy = perfect_decisions(labels)
    flip = rng.random(len(labels)) < 0.2
    noisy.loc[flip, "score"] = 100.0 - noisy.loc[flip, "score"] * 100
    drifted = make_run(labels, noisy, name="drifted")
    r = robustness(nominal, drifted)
    nominal_ba = headline_kpis(score_run(nominal))["balanced_accuracy_thr"]
    drifted_ba = headline_kpis(score_run(drifted))["balanced_accuracy_thr"]
    assert r == pytest.approx(drifted_ba / nominal_ba) and r < 1.0
    assert robustness(score_run(nominal), score_run(drifted)) == r
    with pytest.raises(ParameterError, match="'kpi' parameter of robustness must be one of"):
        robustness(nominal, drifted, kpi="fnr_standard_thr")
    with pytest.raises(ParameterError, match="must be a Run or a Scorecard. Got DataFrame"):
        robustness(labels, drifted)


def test_scores_a_real_method_end_to_end():
    data = make_check_data(0)
    method = RandomMethod(alarm_probability=0.3).fit(data.healthy, random_state=0)
    decs = run_table(method, data.units)
    healthy_scores = run_table(method, data.healthy)["score"].to_numpy()
    onset = {"check-1": (MODE_IDS[1], 4), "check-2": (MODE_IDS[2], 4)}
    rows = []
    for _, r in data.units.iterrows():
        row = {"unit_id": r["unit_id"], "flight_index": r["flight_index"]}
        mode, o = onset.get(r["unit_id"], (None, -1))
        for m in MODE_IDS:
            on = m == mode
            row[f"intensity_{m}"] = max(0.0, (r["flight_index"] - o + 1) / 8) if on and \
                r["flight_index"] >= o else 0.0
            row[f"max_intensity_{m}"] = 1.0 if on else 0.0
            row[f"onset_{m}"] = o if on else -1
        rows.append(row)
    card = score_run(Run(pd.DataFrame(rows), decs, healthy_scores, name="random"))
    assert -100 <= card.summary_score <= 100
    assert len(card.delays) == 2
