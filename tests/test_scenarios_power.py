"""Statistical power of the shipped scenarios: faulty units per mode, healthy false-alarm rate at A = 2."""

from __future__ import annotations

import collections

import numpy as np
import pandas as pd
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


#: Scenarios whose point is scarce healthy data (low_data v3: 12 calibration units; a single draw of 24 units
#: spreads the rate by several points, so the 1.5-point target is not asserted on it).
SCARCE_DATA = ("low_data",)


def _unit_table(n_units, flights, rng, *, within=0.3):
    """Healthy indicator rows dominated by a per-unit offset (manufacturing dispersion), as on the physics."""
    from fuelhm_bench.taxonomy import INDICATOR_NAMES

    offsets = rng.normal(size=(n_units, len(INDICATOR_NAMES)))
    values = np.repeat(offsets, flights, axis=0) + within * rng.normal(size=(n_units * flights, len(INDICATOR_NAMES)))
    table = pd.DataFrame(values, columns=list(INDICATOR_NAMES))
    table.insert(0, "flight_index", np.tile(np.arange(flights), n_units))
    table.insert(0, "unit_id", np.repeat(np.arange(n_units), flights))
    table.insert(0, "flight_id", np.arange(n_units * flights))
    for name in INDICATOR_NAMES:
        table[f"{name}_valid"] = True
    return table


def test_split_training_holds_out_half_the_units():
    from fuelhm_bench.benchmark.harness import split_training

    table = _unit_table(9, 2, np.random.default_rng(0))
    fit, cal = split_training(table)
    assert set(cal["unit_id"]) == {5, 6, 7, 8} and set(fit["unit_id"]) == {0, 1, 2, 3, 4}
    fit1, cal1 = split_training(table[table["unit_id"] < 3])  # 3 units: 2 fit, 1 calibrates (low_data v2)
    assert set(cal1["unit_id"]) == {2} and set(fit1["unit_id"]) == {0, 1}
    # the extended indicators are optional columns; the paper's row is required
    from fuelhm_bench.errors import DataFormatError

    assert "V_in1" not in fit.columns
    with pytest.raises(DataFormatError, match=r"without \['X1_valid'\]"):
        split_training(table.drop(columns=["X1_valid"]))


def test_many_calibration_units_put_the_false_alarm_rate_near_the_gaussian_tail():
    """The calibration mechanism on rows whose spread is mostly between units: fit the paper method on the
    fit half, threshold mu + 2 sigma of the held-out half's scores, rate on 2000 new units. With the shipped
    training fleets' shape (200 units x 2 flights) the rate is within 1.5 points of 2.3 %; with 20 units x 10
    flights (the v2 fleets, the same 200 flights) it is not, because its 5 calibration units are 5 draws of
    the unit offset (measured with this seed: 2.5 % and 4.1 %)."""
    from fuelhm_baselines.paper_mahalanobis import PaperMahalanobis
    from fuelhm_bench.benchmark.harness import split_training
    from fuelhm_bench.methods import run_table
    from fuelhm_bench.scoring import fit_healthy_model

    rng = np.random.default_rng(11)
    new_units = _unit_table(2000, 1, rng)
    rates = {}
    for units, flights in ((200, 2), (20, 10)):
        fit, cal = split_training(_unit_table(units, flights, rng))
        # cv=None: the method's own threshold is not under test, the scorer's mu + A sigma of ``cal`` is
        method = PaperMahalanobis(a=2.0, cv=None).fit(fit, random_state=0)
        threshold = fit_healthy_model(run_table(method, cal)["score"]).threshold(2.0)
        # the method's score of a flight (window 1) is its healthy model's Mahalanobis distance
        scores = method.healthy_model_.global_score(new_units)
        rates[units] = float(np.mean(scores > threshold))
    assert abs(rates[200] - GAUSSIAN_FAR_A2) <= FAR_TOLERANCE, rates
    assert abs(rates[20] - GAUSSIAN_FAR_A2) > FAR_TOLERANCE, rates


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in list_scenarios() if n not in SCARCE_DATA])
def test_healthy_false_alarm_rate_at_a2_is_gaussian(name):
    """The paper method's threshold mu + 2 sigma, set on the calibration half of the healthy training units,
    gives a healthy false-alarm rate within 1.5 points of 2.3 % on new healthy units of the scored fleet's
    model (POPULATION_UNITS = 1500 units x 2 flights; without the drift for robustness_drift, whose drifted
    healthy units are meant to look abnormal), and the scored fleet's own rate is not inconsistent with that
    band: its 95 % unit-bootstrap interval overlaps 2.3 +- 1.5 %. (The scored fleet's 19-160 healthy units
    are a small sample: a 95 % interval per scenario misses a true value in about one scenario of three
    out of eight even when all are right, so the realised rate is not asked to contain 2.3 % itself.)
    python -m fuelhm_bench.benchmark.false_alarms prints both for every scenario.

    Before (v2 fleets, 20 units x 10 flights, a quarter calibrating): 7.66 % on paper_2012's scored fleet
    (95 % interval 3.2-14.5 %) with 5 calibration units. With 300 population units the measurement itself
    was too coarse (paper_2012 4.17 %, 2.50-6.00; on 1500 units 3.00 %, 2.37-3.67)."""
    from fuelhm_bench.benchmark.false_alarms import KNOWLEDGE_SIZE, healthy_false_alarm_rate

    rates = healthy_false_alarm_rate(name, a=2.0, knowledge_size=KNOWLEDGE_SIZE)
    calibrated = [r for r in rates if not r.drifted]
    assert len(calibrated) == 1
    (r,) = calibrated
    assert abs(r.population_rate - GAUSSIAN_FAR_A2) <= FAR_TOLERANCE, r
    assert r.ci_low <= GAUSSIAN_FAR_A2 + FAR_TOLERANCE and r.ci_high >= GAUSSIAN_FAR_A2 - FAR_TOLERANCE, r


def test_split_rates_measure_the_spread_over_training_fleets():
    """split_rates redraws the training fleet's units from a pool: deterministic for a seed, different draws
    differ, and on Gaussian unit-dominated rows the mean rate is near the Gaussian tail (the paper method's
    chi-like score puts it a little above 2.3 %)."""
    from fuelhm_bench.benchmark.false_alarms import split_rates
    from fuelhm_bench.errors import ParameterError
    from fuelhm_bench.scenarios import load_scenario

    import dataclasses

    sc = load_scenario("paper_2012")
    sc = dataclasses.replace(sc, training=dataclasses.replace(sc.training, units=40))  # 40 units x 2 flights
    pool = _unit_table(240, 2, np.random.default_rng(3))
    rates = split_rates(sc, n_splits=3, seed=1, pool=pool)
    assert rates.shape == (3,) and len(set(rates)) > 1
    np.testing.assert_array_equal(rates, split_rates(sc, n_splits=3, seed=1, pool=pool))
    assert 0.005 <= rates.mean() <= 0.08, rates
    with pytest.raises(ParameterError, match="more than the 40 units"):
        split_rates(sc, n_splits=1, pool=pool[pool["unit_id"] < 30])
    with pytest.raises(ParameterError, match="'n_splits' parameter of split_rates must be an int >= 1"):
        split_rates(sc, n_splits=0, pool=pool)


def test_false_alarms_cli_rejects_a_negative_number_of_splits(capsys):
    from fuelhm_bench.benchmark.false_alarms import main

    with pytest.raises(SystemExit) as info:
        main(["paper_2012", "--splits", "-1"])
    assert info.value.code == 2
    assert "--splits must be an int >= 0. Got -1 instead." in capsys.readouterr().err


def test_ideal_calibration_rate_is_set_by_the_score_shape():
    """mu + 2 sigma of a score's own sample: 2.3 % for a Gaussian, about 2.9 % for the chi distribution of
    ten Gaussian indicators' Mahalanobis distance, more for a heavier right tail (a lognormal score)."""
    from scipy import stats

    from fuelhm_bench.benchmark.false_alarms import ideal_calibration_rate
    from fuelhm_bench.errors import DataFormatError, ParameterError

    rng = np.random.default_rng(0)
    gauss = rng.standard_normal(400_000)
    chi10 = np.sqrt(rng.chisquare(10, 400_000))
    heavy = rng.lognormal(0.0, 0.6, 400_000)
    assert abs(ideal_calibration_rate(gauss) - stats.norm.sf(2.0)) < 0.001
    expected_chi = stats.chi.sf(stats.chi.mean(10) + 2 * stats.chi.std(10), 10)
    assert abs(ideal_calibration_rate(chi10) - expected_chi) < 0.001 and 0.027 < expected_chi < 0.030
    assert ideal_calibration_rate(heavy) > expected_chi + 0.005
    assert ideal_calibration_rate(gauss, a=0) > 0.49
    with pytest.raises(ParameterError, match="'a' parameter of ideal_calibration_rate must be a number >= 0"):
        ideal_calibration_rate(gauss, a=-1)
    with pytest.raises(DataFormatError, match="at least 2 finite scores"):
        ideal_calibration_rate([1.0, np.nan])


@pytest.mark.parametrize("argv, message", [
    (["paper_2012", "--splits", "3", "--design", "400"], "--design must be UNITSxFLIGHTS with 2 <= UNITS <= "),
    (["paper_2012", "--splits", "3", "--design", "400x3"], "FLIGHTS 1 or 2 (e.g. 400x1). Got '400x3' instead."),
    (["paper_2012", "--splits", "3", "--design", "1x1"], "Got '1x1' instead."),
    (["paper_2012", "--design", "400x1"], "--design needs --splits N"),
])
def test_false_alarms_cli_rejects_a_bad_design(argv, message, capsys):
    from fuelhm_bench.benchmark.false_alarms import main

    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert message in capsys.readouterr().err


def test_split_rates_refuses_more_flights_per_unit_than_the_pool_holds():
    import dataclasses

    from fuelhm_bench.benchmark.false_alarms import split_rates
    from fuelhm_bench.errors import ParameterError

    sc = load_scenario("paper_2012")
    sc = dataclasses.replace(sc, training=dataclasses.replace(sc.training, units=40, flights_per_unit=3))
    with pytest.raises(ParameterError, match="has 3 flights per unit; the 'pool' parameter of split_rates holds "
                                             "only 2 for some units"):
        split_rates(sc, n_splits=1, pool=_unit_table(240, 2, np.random.default_rng(3)))
