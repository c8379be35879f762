"""Statistical power of the shipped scenarios: faulty units per mode, healthy false-alarm rate at A = 2."""

from __future__ import annotations

import collections

import pytest

from fuelhm_bench.flights.fleet import build_units
from fuelhm_bench.scenarios import list_scenarios, load_scenario
from fuelhm_bench.taxonomy import MODE_IDS

#: The Gaussian tail beyond mu + 2 sigma, and the tolerance of issue 11 on the healthy false-alarm rate.
GAUSSIAN_FAR_A2 = 0.02275
FAR_TOLERANCE = 0.015


def test_all_modes_has_at_least_15_faulty_units_per_mode():
    units = build_units(load_scenario("all_modes").test_fleet_config())
    per_mode = collections.Counter(s.mode for u in units for s in u.schedule.schedules)
    assert set(per_mode) == set(MODE_IDS)
    assert min(per_mode.values()) >= 15, per_mode
    healthy = sum(1 for u in units if not u.schedule.schedules)
    assert healthy >= 15


#: Scenarios whose point is scarce healthy data (their calibration split is one unit by design).
SCARCE_DATA = ("low_data",)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in list_scenarios() if n not in SCARCE_DATA])
def test_healthy_false_alarm_rate_at_a2_is_gaussian(name):
    """The paper method's threshold mu + 2 sigma, set on the calibration split of the healthy training
    flights, gives a healthy false-alarm rate within 1.5 points of 2.3 % on the scored fleet (full size).

    Measured on paper_2012 with the release physics (training units x flights, calibration flights):
    5.86 % (20 x 10, 50), 4.05 % (40 x 10, 100), 5.41 % (60 x 10, 150), 9.23 % (80 x 5, 100). Not monotone
    in the calibration size: the scored fleet's healthy flights cluster in 30 units (8 healthy), so the
    measured rate carries unit-level sampling noise of several points; this test fails on paper_2012
    with the release physics."""
    from fuelhm_baselines.paper_mahalanobis import PaperMahalanobis
    from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env
    from fuelhm_bench.datasets.cache import KnowledgeSize
    from fuelhm_bench.scoring import headline_kpis

    evaluation = prepare_evaluation(name, fidelity="physics", robustness=False,
                                    knowledge_size=KnowledgeSize(doe_units=2))
    outcome = run_in_env(PaperMahalanobis(a=2.0), evaluation, random_state=0, timeout_s=3000)
    assert outcome.ok, outcome.message
    card = outcome.score()
    far = headline_kpis(card)["fpr_standard_thr"]
    assert abs(far - GAUSSIAN_FAR_A2) <= FAR_TOLERANCE, f"{name}: healthy false-alarm rate at A=2 is {far:.4f}"
