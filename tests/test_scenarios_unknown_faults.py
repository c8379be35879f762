"""Faults outside the seven modes (issue 11 §7): schema, simulation, labels, scoring."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.errors import ScenarioError
from fuelhm_bench.flights.fleet import FleetConfig, build_units
from fuelhm_bench.flights.schedule import UnknownFault
from fuelhm_bench.scenarios import load_scenario, parse_scenario
from fuelhm_bench.scenarios.registry import shipped_scenario_files
from fuelhm_bench.scoring import Run, flight_table, headline_kpis, score_run, summary_components
from fuelhm_bench.scoring.run import UNKNOWN
from fuelhm_bench.taxonomy import MODE_IDS
from tests.sizes import FLIGHT_MINUTES

PAPER = shipped_scenario_files()["paper_2012"].read_text()
FAULT = ("unknown_faults:\n"
         "  - effect: torque_motor_hysteresis\n"
         "    parameters: {width_a: 0.0005}\n"
         "    probability: 0.5\n"
         "    onset_min: 5\n"
         "    onset_max: 15\n")


def _with_faults(block: str) -> str:
    text = re.sub(r"^unknown_faults: \[\].*\n", "", PAPER, flags=re.M)
    return text.replace("\ntraining:", "\n" + block + "\ntraining:", 1)


def test_unknown_faults_parse_into_the_scored_fleet_only():
    sc = parse_scenario(_with_faults(FAULT), "s.yaml")
    (fault,) = sc.test_fleet_config().unknown_faults
    assert fault == UnknownFault("torque_motor_hysteresis", 0.5, 5, 15, (("width_a", 0.0005),))
    assert sc.training_fleet_config().unknown_faults == ()


@pytest.mark.parametrize("old, new, field, allowed", [
    ("effect: torque_motor_hysteresis", "effect: torque_hysteresis", "unknown_faults[0].effect", "one of"),
    ("{width_a: 0.0005}", "{width_a: 0.5}", "unknown_faults[0].parameters.width_a", "in (0, 0.005]"),
    ("{width_a: 0.0005}", "{width: 0.0005}", "unknown_faults[0].parameters.width", "width_a"),
    ("probability: 0.5", "probability: 1.5", "unknown_faults[0].probability", "in [0, 1]"),
    ("onset_max: 15", "onset_max: 30", "unknown_faults[0].onset_max",
     "<= the last flight index, flights_per_unit - 1 = 29"),
    ("onset_max: 15", "onset_max: 4", "unknown_faults[0].onset_max", ">= onset_min (5)"),
])
def test_bad_unknown_fault_names_file_field_and_range(old, new, field, allowed):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(_with_faults(FAULT.replace(old, new)), "s.yaml")
    message = str(info.value)
    assert re.search(rf"s\.yaml:\d+: {re.escape(field)}\b", message), message
    assert allowed in message, message


def test_unknown_fault_probabilities_sum_and_overlaps_are_refused():
    twice = FAULT + FAULT.replace("unknown_faults:\n", "").replace("torque_motor_hysteresis", "lvdt_lag").replace(
        "{width_a: 0.0005}", "{time_constant_s: 0.05}").replace("probability: 0.5", "probability: 0.6")
    with pytest.raises(ScenarioError, match=r"unknown_faults\[1\]\.probability must be such that the unknown "
                                            r"faults' probabilities sum to at most 1"):
        parse_scenario(_with_faults(twice), "s.yaml")
    same = FAULT + FAULT.replace("unknown_faults:\n", "")
    with pytest.raises(ScenarioError, match=r"unknown_faults\[1\]\.effect must be an effect not already scheduled"):
        parse_scenario(_with_faults(same), "s.yaml")
    hidden = _with_faults(FAULT).replace("hidden_effects: []", "hidden_effects: [{effect: torque_motor_hysteresis}]")
    with pytest.raises(ScenarioError, match=r"unknown_faults\[0\]\.effect must be an effect outside hidden_effects"):
        parse_scenario(hidden, "s.yaml")


def test_robustness_drift_has_unknown_faults_and_keeps_its_pairing_with_paper_2012():
    drift, paper = load_scenario("robustness_drift"), load_scenario("paper_2012")
    assert {u.effect for u in drift.unknown_faults} and not ({u.effect for u in drift.unknown_faults} & set(MODE_IDS))
    units = build_units(drift.test_fleet_config())
    plain = build_units(dataclasses.replace(drift.test_fleet_config(), unknown_faults=()))
    paired = build_units(paper.test_fleet_config())
    with_unknown = [u for u in units if u.schedule.unknown is not None]
    assert len(with_unknown) >= 3
    for u, p, q in zip(units, plain, paired):
        # the unknown faults go to units without a mode and change nothing else
        assert (u.schedule.schedules, u.schedule.onsets) == (p.schedule.schedules, p.schedule.onsets)
        assert (u.schedule.schedules, u.schedule.onsets) == (q.schedule.schedules, q.schedule.onsets)
        if u.schedule.unknown is not None:
            assert u.schedule.schedules == () and 5 <= u.schedule.unknown_onset <= 15


def test_a_unit_with_an_unknown_fault_is_simulated_with_it_and_labelled():
    from fuelhm_bench.datasets.fleets import fleet_indicators

    sc = load_scenario("paper_2012")
    base = sc.training_fleet_config()
    mission = dataclasses.replace(base.mission, duration_s=60.0 * FLIGHT_MINUTES)
    fault = UnknownFault("torque_motor_hysteresis", 1.0, 1, 1, (("width_a", 0.003),))
    config = FleetConfig(n_units=1, n_flights=2, mission=mission, nominal=base.nominal, dispersion=base.dispersion,
                         seed=3, unknown_faults=(fault,))
    table, labels = fleet_indicators(config)
    assert labels["unknown_fault"].tolist() == ["torque_motor_hysteresis"] * 2
    assert labels["onset_unknown"].tolist() == [1, 1]
    assert (labels[[f"intensity_{m}" for m in MODE_IDS]].to_numpy() == 0).all()
    # the same flights without the fault: only the flight from the onset on differs
    clean, _ = fleet_indicators(dataclasses.replace(config, unknown_faults=()))
    assert table.loc[0, "Hys0"] == clean.loc[0, "Hys0"]
    # 3 mA of torque-motor play widens the idle hysteresis (measured 0.04 -> 0.50 mA on these flights)
    assert table.loc[1, "Hys0"] > 5 * clean.loc[1, "Hys0"]


# --------------------------------------------------------------------------- scoring
def _labels() -> pd.DataFrame:
    """Three units x 4 flights: healthy, leaking from flight 2, unknown fault from flight 1."""
    rows = []
    for unit in range(3):
        for f in range(4):
            row = {"unit_id": unit, "flight_index": f}
            for m in MODE_IDS:
                leak = m == "internal_leakage" and unit == 1
                row[f"intensity_{m}"] = 1.0 if leak and f >= 2 else 0.0
                row[f"max_intensity_{m}"] = 1.0 if leak else 0.0
                row[f"onset_{m}"] = 2 if leak else -1
            row["unknown_fault"] = "lvdt_lag" if unit == 2 else ""
            row["onset_unknown"] = 1 if unit == 2 else -1
            rows.append(row)
    return pd.DataFrame(rows)


def _decisions(labels: pd.DataFrame, alarm_unknown: bool, guilt_unknown: np.ndarray) -> pd.DataFrame:
    leak = labels["intensity_internal_leakage"].to_numpy() > 0
    unknown = (labels["onset_unknown"] >= 0).to_numpy() & (labels["flight_index"] >= labels["onset_unknown"]).to_numpy()
    alarm = leak | (unknown & alarm_unknown)
    guilt = np.zeros((len(labels), len(MODE_IDS)))
    guilt[leak, MODE_IDS.index("internal_leakage")] = 1.0
    guilt[unknown & alarm_unknown] = guilt_unknown
    out = labels[["unit_id", "flight_index"]].assign(score=alarm.astype(float), alarm=alarm)
    return out.assign(**{f"guilt_{m}": guilt[:, j] for j, m in enumerate(MODE_IDS)})


def test_scorer_counts_unknown_fault_flights_as_faulty():
    labels = _labels()
    table = flight_table(Run(labels, _decisions(labels, False, np.zeros(7)), np.array([0.0, 1.0])))
    unknown = table[table["true_mode"] == UNKNOWN]
    assert list(zip(unknown["unit_id"], unknown["flight_index"])) == [(2, 1), (2, 2), (2, 3)]
    assert unknown["detectable"].all()
    assert (table.loc[table["unit_id"] == 2, "true_mode"].iloc[0]) == "healthy"  # before its onset
    # labels without the optional column: the same flights are healthy (backward compatible)
    old = flight_table(Run(labels.drop(columns=["unknown_fault", "onset_unknown"]),
                           _decisions(labels, False, np.zeros(7)), np.array([0.0, 1.0])))
    assert UNKNOWN not in set(old["true_mode"])


def test_library_only_classifier_gets_no_diagnosis_credit_on_unknown_faults():
    labels = _labels()
    healthy_scores = np.array([0.0, 0.1, 0.2])
    runs = {
        "blind": _decisions(labels, False, np.zeros(7)),                      # alarms on its library only
        "names_a_mode": _decisions(labels, True, np.eye(7)[0]),               # alarms, blames filter contamination
        "says_unknown": _decisions(labels, True, np.full(7, 1 / 7)),          # alarms, names no single mode
    }
    cards = {k: score_run(Run(labels, d, healthy_scores, name=k)) for k, d in runs.items()}
    kpis = {k: headline_kpis(c) for k, c in cards.items()}
    terms = {k: summary_components(c.flights).set_index("mode").loc[UNKNOWN] for k, c in cards.items()}
    # detection: an alarm on an unknown fault is a true positive, a missed one a false negative
    assert kpis["blind"]["fnr_standard_alarm"] == pytest.approx(3 / 5)
    assert kpis["names_a_mode"]["fnr_standard_alarm"] == 0.0
    assert terms["blind"]["tpr"] == 0.0 and terms["names_a_mode"]["tpr"] == 1.0
    # diagnosis: naming one of the seven modes is wrong, naming none is right
    assert terms["names_a_mode"]["accuracy"] == 0.0 and terms["says_unknown"]["accuracy"] == 1.0
    assert kpis["says_unknown"]["summary_score"] == pytest.approx(100.0)
    from fuelhm_bench.scoring import perfect_decisions  # the oracle anchor names no mode on an unknown fault

    perfect = headline_kpis(score_run(Run(labels, perfect_decisions(labels), healthy_scores)))
    assert perfect["summary_score"] == pytest.approx(100.0) and perfect["fnr_standard_alarm"] == 0.0
    assert kpis["blind"]["summary_score"] == pytest.approx(50.0)   # perfect on the leak, nothing on the unknown
    assert kpis["blind"]["summary_score"] < kpis["names_a_mode"]["summary_score"] < kpis["says_unknown"][
        "summary_score"]


# --------------------------------------------------------------------------- environment
def _env_with_certain_fault():
    """paper_2012 with torque-motor play in every unit that draws no mode, from flight 1, on short flights."""
    from fuelhm_bench.envs.actuation_loop import ActuationLoopEnv

    block = FAULT.replace("probability: 0.5", "probability: 1.0").replace("onset_min: 5", "onset_min: 1") \
                 .replace("onset_max: 15", "onset_max: 1").replace("width_a: 0.0005", "width_a: 0.003")
    sc = parse_scenario(_with_faults(block))
    return ActuationLoopEnv(scenario=sc, fidelity="physics", maintenance=True, flight_minutes=FLIGHT_MINUTES)


def test_drawn_units_get_unknown_faults_and_the_rewards_charge_them():
    """A drawn (not replayed) unit without a mode gets the scenario's unknown fault, like a scored-fleet unit.
    Its flights are faulty for the rewards: flying it without an alarm costs an undetected flight, an alarm is a
    correct maintenance that removes it (the next flight is flown without the fault, whose torque-motor play
    widens Hys0)."""
    from fuelhm_bench.taxonomy import INDICATOR_NAMES

    env = _env_with_certain_fault()
    costs = env.scenario.costs
    drawn = []
    for seed in range(12):
        env.reset(seed=seed)
        drawn.append((seed, env._schedule))
    without_mode = [(s, sch) for s, sch in drawn if not sch.schedules]
    assert without_mode, "no drawn unit without a mode in 12 seeds (30 % each)"
    assert all(sch.unknown is not None and sch.unknown.effect == "torque_motor_hysteresis"
               and sch.unknown_onset == 1 for _, sch in without_mode)
    assert all(sch.unknown is None for _, sch in drawn if sch.schedules)
    hys0 = INDICATOR_NAMES.index("Hys0")
    obs0, _ = env.reset(seed=without_mode[0][0])
    no_alarm = {"alarm": 0, "guilt": np.zeros(len(MODE_IDS), dtype=np.float32)}
    obs1, r0, *_ = env.step(no_alarm)                     # decision on flight 0: healthy
    _, r1, *_ = env.step(no_alarm)                        # flight 1: the fault, not seen
    obs3, r2, *_ = env.step({**no_alarm, "alarm": 1})     # flight 2: alarm, correct maintenance
    _, r3, *_ = env.step(no_alarm)                        # flight 3: repaired, healthy again
    assert (r0, r1, r2, r3) == (0.0, -costs.undetected_flight_kusd, -costs.repair_kusd, 0.0)
    hys = [float(o["indicators"][hys0]) for o in (obs0, obs1, obs3)]
    assert hys[1] > 3 * hys[0] and hys[2] < 2 * hys[0], hys
    truth = env.episode_truth()
    assert truth["detectable"].tolist() == [False, True, True, False]
    assert truth["repaired"].tolist() == [False, False, True, False]
    assert truth["unknown_fault"] == "torque_motor_hysteresis"
