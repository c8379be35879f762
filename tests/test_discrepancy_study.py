"""Statistical evaluation of the discrepancy workflow (slow: run with ``pytest -m slow``).

Many seeds and magnitudes: identification accuracy per hidden effect, false discoveries on
healthy data, held-out gap reduction, parameter error. The summary table is printed (``-s``)
and written to the test's temporary directory as CSV.
"""

from __future__ import annotations

import pytest

from fuelhm_bench.calibration.discrepancy import DiscrepancyConfig
from fuelhm_bench.calibration.study import cases_frame, run_study, summarize
from fuelhm_bench.taxonomy import EFFECT_IDS
from sizes import STUDY_FLIGHTS, STUDY_MINUTES, STUDY_UNITS

CONFIG = DiscrepancyConfig(n_jobs=2)


@pytest.mark.slow
def test_identification_accuracy_and_false_discoveries(tmp_path):
    cases = run_study(EFFECT_IDS + ("none",), seeds=range(300, 306), n_units=STUDY_UNITS,
                      n_flights=STUDY_FLIGHTS, minutes=STUDY_MINUTES, config=CONFIG)
    table = summarize(cases)
    cases_frame(cases).to_csv(tmp_path / "cases.csv", index=False)
    table.to_csv(tmp_path / "summary.csv", index=False)
    print("\n" + table.to_string())
    by = table.set_index("hidden")
    for effect in EFFECT_IDS:
        assert by.loc[effect, "accuracy"] >= 5 / 6, effect
        assert by.loc[effect, "median_gap_reduction"] >= 0.8, effect
        assert by.loc[effect, "median_parameter_error"] <= 0.2, effect
    assert by.loc["none", "false_discovery"] <= 1 / 6


@pytest.mark.slow
def test_magnitude_scan_down_to_the_low_end_of_the_test_ranges(tmp_path):
    # Fractions of the test range on a log scale: 0 is its low end, 1 its high end.
    cases = run_study(EFFECT_IDS, seeds=range(310, 313), fractions=[0.0, 0.5, 1.0], n_units=STUDY_UNITS,
                      n_flights=STUDY_FLIGHTS, minutes=STUDY_MINUTES, config=CONFIG)
    table = summarize(cases)
    cases_frame(cases).to_csv(tmp_path / "scan.csv", index=False)
    print("\n" + table.to_string())
    assert (table["accuracy"] >= 8 / 9).all()
    assert (table["wrong_effect"] == 0.0).all()
