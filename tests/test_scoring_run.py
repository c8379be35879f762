"""Tests of the scorer's inputs: Run validation, ScoringConfig, per-flight table.

Also holds the small label/decision builders shared by the other scoring tests.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.errors import DataFormatError, ParameterError
from fuelhm_bench.methods import DECISION_COLUMNS
from fuelhm_bench.scoring import (LABEL_COLUMNS, Run, ScoringConfig, flight_table,
                                  null_decisions, perfect_decisions)
from fuelhm_bench.taxonomy import MODE_IDS

LEAK, DRIFT = "internal_leakage", "null_bias_drift"


def make_labels(specs):
    """Labels table from unit specs.

    Each spec: ``unit`` (id), and either ``n`` (flights; healthy unit) or
    ``intensity`` (mapping mode -> list of intensities, one per flight) with an
    optional ``max`` (mapping mode -> schedule maximum; default max of the list).
    """
    rows = []
    for spec in specs:
        inten = spec.get("intensity", {})
        n = spec["n"] if "n" in spec else len(next(iter(inten.values())))
        for k in range(n):
            row = {"flight_id": f"{spec['unit']}-{k}", "unit_id": spec["unit"], "flight_index": k}
            for m in MODE_IDS:
                values = inten.get(m)
                row[f"intensity_{m}"] = 0.0 if values is None else float(values[k])
                row[f"max_intensity_{m}"] = 0.0 if values is None else float(
                    spec.get("max", {}).get(m, max(values)))
                row[f"onset_{m}"] = -1 if values is None else int(
                    np.flatnonzero(np.asarray(values) > 0)[0])
            rows.append(row)
    return pd.DataFrame(rows)


def ramp(n, onset, top=1.0):
    """Intensities 0 before ``onset`` then a linear ramp reaching ``top`` at the last flight."""
    k = np.arange(n)
    return np.where(k >= onset, top * (k - onset + 1) / (n - onset), 0.0)


def fleet_labels():
    """Four units: healthy, a drift from flight 5, a leak from flight 10 (max 0.8), a short leak."""
    return make_labels([{"unit": "u0", "n": 20},
                        {"unit": "u1", "intensity": {DRIFT: ramp(20, 5)}},
                        {"unit": "u2", "intensity": {LEAK: ramp(20, 10, 0.8)}},
                        {"unit": "u3", "intensity": {LEAK: ramp(10, 2)}}])


def worked_example_labels():
    """The worked example of docs/scoring.md: 20 healthy flights, 4 incipient, 10 detectable."""
    leak = np.r_[np.zeros(20), np.full(4, 0.1), np.linspace(0.5, 1.0, 10)]
    return make_labels([{"unit": "A", "intensity": {LEAK: leak}, "max": {LEAK: 1.0}}])


def decisions(labels, alarm, *, guilt_mode=None, score=None):
    """Decisions with the given alarms; guilt one-hot on ``guilt_mode`` (default: true mode)."""
    alarm = np.asarray(alarm, dtype=bool)
    out = perfect_decisions(labels)
    out["alarm"] = alarm
    out["score"] = alarm.astype(float) * 10.0 if score is None else np.asarray(score, float)
    for j, m in enumerate(MODE_IDS):
        col = f"guilt_{m}"
        if guilt_mode is not None:
            out[col] = np.where(alarm, float(m == guilt_mode), 0.0)
        else:
            out[col] = np.where(alarm, out[col], 0.0)
    # alarmed healthy flights: blame the first mode
    healthy_alarm = alarm & (out[[f"guilt_{m}" for m in MODE_IDS]].sum(axis=1) == 0).to_numpy()
    out.loc[healthy_alarm, f"guilt_{MODE_IDS[0]}"] = 1.0
    return out


HEALTHY_SCORES = np.random.default_rng(0).normal(0.0, 1.0, 500)


def make_run(labels, decs, healthy_scores=HEALTHY_SCORES, name="run"):
    return Run(labels=labels, decisions=decs, healthy_scores=healthy_scores, name=name)


# ---------------------------------------------------------------- tests
def test_flight_table_categories_and_bands():
    labels = make_labels([{"unit": "u", "intensity": {LEAK: [0, 0.05, 0.125, 0.2, 0.375, 0.5, 0.75,
                                                             0.8, 1.0]}}])
    ft = flight_table(make_run(labels, null_decisions(labels)))
    assert ft["true_mode"].tolist() == ["healthy"] + [LEAK] * 8
    assert ft["band"].tolist() == ["healthy", "<12.5%", "<12.5%", "25%", "25%", "50%", "50%",
                                   "100%", "100%"]
    assert ft["detectable"].tolist() == [False, False, False, False, True, True, True, True, True]
    assert ft["incipient"].tolist() == [False, True, True, True, False, False, False, False, False]


def test_fraction_uses_unit_schedule_max_or_reference_max():
    labels = make_labels([{"unit": "u", "intensity": {LEAK: [0, 0.1, 0.2, 0.4]}}])
    run = make_run(labels, null_decisions(labels))
    np.testing.assert_allclose(flight_table(run)["fraction"], [0, 0.25, 0.5, 1.0])
    full_scale = ScoringConfig(reference_max={m: 1.0 for m in MODE_IDS})
    ft = flight_table(run, full_scale)
    np.testing.assert_allclose(ft["fraction"], [0, 0.1, 0.2, 0.4])
    assert ft["detectable"].tolist() == [False, False, False, True]


def test_multiple_faults_and_predicted_labels():
    labels = make_labels([{"unit": "u", "intensity": {LEAK: [0, 1, 1, 1], DRIFT: [0, 0, 1, 0]}}])
    decs = decisions(labels, [False, True, True, True])
    decs.loc[3, [f"guilt_{m}" for m in MODE_IDS]] = np.r_[0.5, 0.5, np.zeros(5)]
    ft = flight_table(make_run(labels, decs))
    assert ft["true_mode"].tolist() == ["healthy", LEAK, "multiple", LEAK]
    assert ft["predicted"].tolist() == ["no_alarm", LEAK, "tie", "tie"]


def test_run_rejects_bad_tables():
    labels = fleet_labels()
    decs = perfect_decisions(labels)
    with pytest.raises(DataFormatError, match=r"Missing \['onset_backlash'\]"):
        make_run(labels.drop(columns="onset_backlash"), decs)
    with pytest.raises(DataFormatError, match=r"Missing \['score'\]"):
        make_run(labels, decs.drop(columns="score"))
    with pytest.raises(DataFormatError, match="cover the same flights. Got 1 flight\\(s\\) missing "
                                              "from decisions, e.g. flight 9 of unit 'u3'"):
        make_run(labels, decs.iloc[:-1])
    bad = decs.copy()
    bad.loc[5, "score"] = np.nan
    with pytest.raises(DataFormatError, match="finite scores. Got a non-finite score at flight 5 "
                                              "of unit 'u0'"):
        make_run(labels, bad)
    bad = decs.copy()
    bad.loc[bad["alarm"].idxmax(), f"guilt_{DRIFT}"] = 0.5
    with pytest.raises(DataFormatError, match="guilt >= 0 summing to 1 on alarms"):
        make_run(labels, bad)
    bad = decs.copy()
    bad["alarm"] = bad["alarm"].astype(int)
    with pytest.raises(DataFormatError, match="bool 'alarm' column. Got dtype int64"):
        make_run(labels, bad)
    with pytest.raises(DataFormatError, match="one row per \\(unit_id, flight_index\\)"):
        make_run(pd.concat([labels, labels.iloc[:1]]), decs)
    as_text = decs.assign(unit_id=decs["unit_id"].map({"u0": 0, "u1": 1, "u2": 2, "u3": 3}))
    with pytest.raises(DataFormatError, match="must use the same key types"):
        make_run(labels, as_text)
    with pytest.raises(DataFormatError, match="at least 2 finite scores"):
        make_run(labels, decs, healthy_scores=[1.0])
    bad = labels.copy()
    bad.loc[30, f"onset_{DRIFT}"] = 7
    with pytest.raises(DataFormatError, match=f"one onset_{DRIFT} per unit"):
        make_run(bad, decs)
    bad = labels.copy()
    bad.loc[bad[f"intensity_{DRIFT}"] > 0, f"onset_{DRIFT}"] = -1
    bad.loc[bad["unit_id"] == "u1", f"onset_{DRIFT}"] = -1
    with pytest.raises(DataFormatError, match=f"onset_{DRIFT} >= 0 when intensity_{DRIFT} > 0"):
        make_run(bad, decs)


def test_zero_reference_max_is_rejected():
    labels = fleet_labels()
    labels[f"max_intensity_{LEAK}"] = 0.0
    with pytest.raises(DataFormatError, match="reference maximal intensity of mode "
                                              "'internal_leakage' must be > 0"):
        flight_table(make_run(labels, null_decisions(labels)))


def test_run_is_frozen_and_copies_scores():
    scores = np.array([0.0, 1.0, 2.0])
    run = make_run(fleet_labels(), null_decisions(fleet_labels()), healthy_scores=scores)
    scores[0] = 99.0
    assert run.healthy_scores[0] == 0.0 and not run.healthy_scores.flags.writeable
    assert list(null_decisions(fleet_labels()).columns) == list(DECISION_COLUMNS)
    assert set(LABEL_COLUMNS) <= set(fleet_labels().columns)


@pytest.mark.parametrize("kwargs, match", [
    ({"a_values": ()}, "'a_values' parameter of ScoringConfig must be a non-empty sequence"),
    ({"a_values": (1, 1)}, "distinct"),
    ({"detectable_fraction": 1.5}, r"'detectable_fraction' parameter of ScoringConfig must be a "
                                   r"float in \[0, 1\]. Got 1.5 instead."),
    ({"band_edges": (0.5, 0.2)}, "increasing"),
    ({"band_names": ("a", "b")}, "4 distinct names"),
    ({"confidence": 1.0}, r"in \(0, 1\)"),
    ({"n_bootstrap": -1}, "an int >= 0"),
    ({"reference_max": {"rust": 1.0}}, "mode ids"),
])
def test_config_validation(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        ScoringConfig(**kwargs)


def test_undefined_headline_kpis_say_why():
    """score printed 'fpr_paper_def_thr nan' with no reason when every score was equal."""
    from fuelhm_bench.scoring import headline_kpis, score_run, undefined_kpis

    labels = fleet_labels()
    card = score_run(Run(labels, null_decisions(labels), healthy_scores=[0.0, 0.0, 0.0]))
    kpis, why = headline_kpis(card), undefined_kpis(card)
    assert set(why) == {k for k, v in kpis.items() if v != v} and "fpr_paper_def_thr" in why
    assert why["fpr_paper_def_thr"].startswith("no detection: FP + FD = 0 at A = 2 (threshold mu + A sigma = 0)")
    assert "the 3 calibration scores are all equal (sigma = 0)" in why["fpr_paper_def_thr"]
    healthy = make_labels([{"unit": "u0", "n": 5}])
    card = score_run(Run(healthy, null_decisions(healthy), healthy_scores=[0.0, 1.0]))
    assert undefined_kpis(card)["summary_score"].startswith("no scored flight is faulty")
    assert undefined_kpis(card)["fnr_standard_thr"].startswith("no detectable faulty flight at A = 2")


def test_healthy_model_keeps_every_bit_of_the_direct_mean_and_std():
    """The overflow guard scales by a power of two, so ordinary scores give the direct numpy bits
    (a scale by max |score| changed mu or sigma in the last bit for most score sets: every threshold)."""
    from fuelhm_bench.scoring import fit_healthy_model

    rng = np.random.default_rng(3)
    for _ in range(200):
        s = rng.standard_normal(int(rng.integers(2, 300))) * 10.0 ** rng.uniform(-5, 5) + rng.uniform(-3, 3)
        m = fit_healthy_model(s)
        assert (m.mu, m.sigma) == (float(s.mean()), float(s.std(ddof=0)))


def test_huge_scores_are_scored_without_overflow():
    """Scores x 1e300 overflowed in the healthy model's square (a raw numpy RuntimeWarning, then NaN KPIs)."""
    import warnings

    from fuelhm_bench.scoring import fit_healthy_model, headline_kpis, score_run

    labels = fleet_labels()
    decisions = perfect_decisions(labels)
    decisions["score"] = decisions["score"] * 1e300
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = fit_healthy_model(np.linspace(0.0, 1.0, 50) * 1e300)
        card = score_run(Run(labels, decisions, healthy_scores=np.linspace(0.0, 1.0, 50) * 1e300))
    assert np.isfinite([model.mu, model.sigma]).all() and model.mu == pytest.approx(0.5e300)
    assert headline_kpis(card)["summary_score"] == 100.0
