"""Cost under the scenario's cost model, replayed with maintenance (fuelhm_bench.scoring.cost)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.methods.tables import GUILT_COLUMNS
from fuelhm_bench.scenarios import CostSpec
from fuelhm_bench.scoring import Run, maintenance_cost, null_decisions, total_cost
from fuelhm_bench.taxonomy import MODE_IDS

COSTS = CostSpec(false_alarm_kusd=25.0, undetected_flight_kusd=2.0, failure_kusd=500.0, repair_kusd=15.0,
                 detectable_fraction=0.25, failure_fraction=1.0)


def _labels(trajectories: dict[int, dict[int, list[float]]], n_flights: int) -> pd.DataFrame:
    """Labels of units {unit: {mode index: intensity per flight}}; max intensity 1 for every mode."""
    frames = []
    for unit, modes in trajectories.items():
        data = {"unit_id": np.full(n_flights, unit), "flight_index": np.arange(n_flights)}
        for j, m in enumerate(MODE_IDS):
            data[f"intensity_{m}"] = np.asarray(modes.get(j, np.zeros(n_flights)), dtype=float)
        for m in MODE_IDS:
            data[f"max_intensity_{m}"] = np.ones(n_flights)
        for j, m in enumerate(MODE_IDS):
            inten = data[f"intensity_{m}"]
            data[f"onset_{m}"] = np.full(n_flights, int(np.argmax(inten > 0)) if (inten > 0).any() else -1)
        frames.append(pd.DataFrame(data))
    return pd.concat(frames, ignore_index=True)


def _decisions(labels: pd.DataFrame, alarm: np.ndarray, blamed: np.ndarray) -> pd.DataFrame:
    """Decisions with the given alarms, all guilt on mode index ``blamed`` (per flight) when alarmed."""
    guilt = np.zeros((len(labels), len(MODE_IDS)))
    guilt[np.flatnonzero(alarm), blamed[alarm]] = 1.0
    out = {"unit_id": labels["unit_id"].to_numpy(), "flight_index": labels["flight_index"].to_numpy(),
           "score": alarm.astype(float), "alarm": alarm.astype(bool)}
    out.update({c: guilt[:, j] for j, c in enumerate(GUILT_COLUMNS)})
    return pd.DataFrame(out)


def _oracle(labels: pd.DataFrame, costs=COSTS) -> pd.DataFrame:
    """A perfect detector: alarms exactly on detectable flights, guilt shared by the detectable modes."""
    inten = labels[[f"intensity_{m}" for m in MODE_IDS]].to_numpy(dtype=float)
    det = (inten > 0) & (inten >= costs.detectable_fraction)
    alarm = det.any(axis=1)
    dec = _decisions(labels, alarm, inten.argmax(axis=1))
    dec.loc[alarm, list(GUILT_COLUMNS)] = det[alarm] / det[alarm].sum(axis=1, keepdims=True)
    return dec


def _cost(labels, decisions, costs=COSTS) -> pd.DataFrame:
    return maintenance_cost(Run(labels=labels, decisions=decisions, healthy_scores=np.zeros(20)), costs)


# one unit, mode 0 detectable from flight 2, failing on flight 5; 8 flights
RAMP = [0.0, 0.1, 0.3, 0.5, 0.8, 1.0, 1.0, 1.0]


def test_worked_example_never_alarm_and_perfect_detector():
    """The worked example of docs/scoring.md: 4 undetected flights + a failure vs one repair."""
    labels = _labels({0: {0: RAMP}}, 8)
    never = _cost(labels, null_decisions(labels)).iloc[0]
    assert (never["undetected_flights"], never["failures"], never["inspections"]) == (4, 1, 0)
    assert never["cost_kusd"] == 4 * 2.0 + 500.0
    perfect = _cost(labels, _oracle(labels)).iloc[0]
    # repaired after flight 2: the recorded alarms of flights 3-7 are replayed (healthy unit, no healthy alarms)
    assert (perfect["repairs"], perfect["failures"], perfect["replayed_flights"]) == (1, 0, 5)
    assert perfect["cost_kusd"] == 15.0
    late = np.zeros(8, bool)
    late[4:] = True  # detects two flights late: 2 undetected flights, then one repair
    assert _cost(labels, _decisions(labels, late, np.zeros(8, int))).iloc[0]["cost_kusd"] == 2 * 2.0 + 15.0


def test_a_false_alarm_costs_an_inspection():
    labels = _labels({0: {}, 1: {}}, 8)
    base = _oracle(labels)
    extra = base.copy()
    row = (extra["unit_id"] == 1) & (extra["flight_index"] == 3)
    extra.loc[row, "alarm"] = True
    extra.loc[row, GUILT_COLUMNS[4]] = 1.0
    before, after = _cost(labels, base), _cost(labels, extra)
    assert after["cost_kusd"].sum() - before["cost_kusd"].sum() == pytest.approx(COSTS.false_alarm_kusd)
    assert after.set_index("unit_id").loc[1, "no_fault_found"] == 1
    # with a repaired unit in the fleet, it also raises the expected cost of that unit's replayed flights
    labels = _labels({0: {0: RAMP}, 1: {}}, 8)
    extra = _oracle(labels)
    extra.loc[row, "alarm"] = True
    extra.loc[row, GUILT_COLUMNS[4]] = 1.0
    after = _cost(labels, extra).set_index("unit_id")
    assert after.loc[1, "false_alarm_kusd"] == 25.0
    assert after.loc[0, "expected_false_alarm_kusd"] == pytest.approx(5 * 25.0 / 9)  # 1 alarm in 9 healthy flights


def test_an_alarm_on_a_fault_below_detectable_is_no_fault_found():
    labels = _labels({0: {0: RAMP}}, 8)
    alarm = np.zeros(8, bool)
    alarm[1] = True  # intensity 0.1 < 0.25
    row = _cost(labels, _decisions(labels, alarm, np.zeros(8, int))).iloc[0]
    assert row["no_fault_found"] == 1 and row["failures"] == 1
    assert row["cost_kusd"] == 25.0 + 4 * 2.0 + 500.0


def test_the_diagnosis_decides_what_is_replaced():
    """An alarm in time with the wrong component blamed does not prevent the failure."""
    labels = _labels({0: {0: RAMP}}, 8)
    alarm = np.zeros(8, bool)
    alarm[2] = True
    right = _cost(labels, _decisions(labels, alarm, np.zeros(8, int))).iloc[0]
    wrong = _cost(labels, _decisions(labels, alarm, np.full(8, 3))).iloc[0]
    assert right["cost_kusd"] == 15.0 and right["failures"] == 0
    assert wrong["no_fault_found"] == 1 and wrong["failures"] == 1
    assert wrong["cost_kusd"] == 25.0 + 3 * 2.0 + 500.0


def test_uniform_guilt_replaces_every_present_component():
    labels = _labels({0: {0: RAMP, 5: [0.0, 0.0, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]}}, 8)
    alarm = np.zeros(8, bool)
    alarm[2] = True
    dec = _decisions(labels, alarm, np.zeros(8, int))
    dec.loc[2, list(GUILT_COLUMNS)] = 1.0 / len(MODE_IDS)
    row = _cost(labels, dec).iloc[0]
    assert row["repairs"] == 1 and row["failures"] == 0 and row["cost_kusd"] == 15.0


def test_replayed_flights_charge_the_methods_healthy_false_alarm_rate():
    """After a repair, the recorded decisions on the still-faulty recording are replaced by the expectation."""
    healthy_units = {k: {} for k in range(1, 5)}
    labels = _labels({0: {0: RAMP}, **healthy_units}, 8)
    dec = _oracle(labels)
    # one false alarm in the 33 healthy flights (4 healthy units + flight 0 of unit 0): rate 1/33
    row = (dec["unit_id"] == 2) & (dec["flight_index"] == 6)
    dec.loc[row, "alarm"] = True
    dec.loc[row, GUILT_COLUMNS[0]] = 1.0
    table = _cost(labels, dec).set_index("unit_id")
    assert table.loc[0, "replayed_flights"] == 5
    assert table.loc[0, "expected_false_alarm_kusd"] == pytest.approx(5 * 25.0 / 33)
    assert table.loc[2, "false_alarm_kusd"] == 25.0


@pytest.mark.parametrize("seed", range(5))
def test_never_alarm_is_not_cheaper_than_a_perfect_detector_when_detection_has_value(seed):
    """Random fleets and cost models where detection has value: every fault fails if left alone, and the
    repairs of a unit (at most two faults) cost less than one failure."""
    rng = np.random.default_rng(seed)
    n = 30
    traj = {}
    for unit in range(12):
        modes = {}
        for j in rng.choice(7, size=rng.integers(0, 3), replace=False):
            onset, rate = rng.integers(0, n // 2), rng.uniform(0.1, 0.5)
            modes[int(j)] = np.clip((np.arange(n) - onset + 1) * rate, 0.0, None)
        traj[unit] = modes
    labels = _labels(traj, n)
    failure = rng.uniform(50.0, 1000.0)
    costs = CostSpec(false_alarm_kusd=rng.uniform(0, 100), undetected_flight_kusd=rng.uniform(0, 10),
                     failure_kusd=failure, repair_kusd=rng.uniform(0, failure / 2),
                     detectable_fraction=0.25, failure_fraction=1.0)
    never = _cost(labels, null_decisions(labels), costs)
    perfect = _cost(labels, _oracle(labels, costs), costs)
    assert (perfect["failures"] == 0).all() and never["failures"].sum() >= 1
    assert (perfect["cost_kusd"].to_numpy() <= never["cost_kusd"].to_numpy()).all()
    assert perfect["cost_kusd"].sum() < never["cost_kusd"].sum()


def test_never_alarm_is_cheapest_when_detection_has_no_value():
    """The protocol is not rigged: with repairs dearer than failures, acting does not pay."""
    labels = _labels({0: {0: RAMP}}, 8)
    costs = CostSpec(false_alarm_kusd=25.0, undetected_flight_kusd=0.0, failure_kusd=10.0, repair_kusd=100.0,
                     detectable_fraction=0.25, failure_fraction=1.0)
    assert _cost(labels, null_decisions(labels), costs)["cost_kusd"].sum() == 10.0
    assert total_cost(Run(labels=labels, decisions=_oracle(labels, costs), healthy_scores=np.zeros(20)),
                      costs) == 100.0


def test_a_cost_model_without_its_fields_is_refused():
    labels = _labels({0: {}}, 3)
    with pytest.raises(ParameterError, match="'costs' parameter of maintenance_cost.*failure_kusd"):
        maintenance_cost(Run(labels=labels, decisions=null_decisions(labels), healthy_scores=np.zeros(20)), object())


def _with_unknown(labels: pd.DataFrame, onsets: dict[int, int]) -> pd.DataFrame:
    """Labels with a fault outside the seven modes from flight ``onsets[unit]`` (-1 elsewhere)."""
    out = labels.copy()
    out["onset_unknown"] = out["unit_id"].map(lambda u: onsets.get(int(u), -1)).astype(np.int64)
    return out


def test_a_fault_outside_the_seven_modes_is_not_healthy_for_the_cost():
    """An unknown fault is detectable from its onset: never alarming pays every flight after it (no failure
    law, so no failure); the healthy alarm rate behind the replayed flights' expected cost ignores its flights."""
    labels = _with_unknown(_labels({0: {}, 1: {}}, 6), {0: 2})
    never = _cost(labels, null_decisions(labels)).set_index("unit_id")
    assert never.loc[0, "undetected_flights"] == 4 and never.loc[0, "failures"] == 0
    assert never.loc[0, "cost_kusd"] == 4 * COSTS.undetected_flight_kusd
    assert never.loc[1, "cost_kusd"] == 0.0
    from fuelhm_bench.scoring.cost import healthy_alarm_rate

    alarm = (labels["unit_id"] == 0).to_numpy() & (labels["flight_index"] >= 2).to_numpy()  # only on the fault
    run = Run(labels=labels, decisions=_decisions(labels, alarm, np.zeros(len(labels), dtype=int)),
              healthy_scores=np.zeros(20))
    assert healthy_alarm_rate(run) == 0.0


def test_an_unknown_fault_is_repaired_only_when_no_single_library_mode_is_named():
    """Alarm on the onset flight: a uniform guilt (no single mode) finds and repairs the fault, after which the
    recorded flights are replayed at the expected false-alarm cost; naming one mode finds no fault and the unit
    keeps flying with it."""
    labels = _with_unknown(_labels({0: {}}, 5), {0: 1})
    alarm = np.array([False, True, False, False, False])
    uniform = _decisions(labels, alarm, np.zeros(5, dtype=int))
    uniform.loc[alarm, list(GUILT_COLUMNS)] = 1.0 / len(MODE_IDS)
    row = _cost(labels, uniform).iloc[0]
    assert (row["repairs"], row["no_fault_found"], row["undetected_flights"], row["replayed_flights"]) == (1, 0, 0, 3)
    assert row["cost_kusd"] == COSTS.repair_kusd  # the run's healthy alarm rate is 0 (no healthy flight alarms)
    named = _cost(labels, _decisions(labels, alarm, np.zeros(5, dtype=int))).iloc[0]
    assert (named["repairs"], named["no_fault_found"], named["undetected_flights"]) == (0, 1, 3)
    assert named["cost_kusd"] == COSTS.false_alarm_kusd + 3 * COSTS.undetected_flight_kusd
