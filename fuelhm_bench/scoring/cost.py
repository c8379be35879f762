"""Cost of a method's decisions under a scenario's cost model, with maintenance.

The scored fleet is simulated once, without maintenance (faults evolve as
scheduled whatever a method says), so that every method sees the same flights.
The cost is then obtained by *replaying* each unit's life under the maintenance
protocol the cost model describes:

1. after each flight the method decides; an **alarm** sends the unit to an
   inspection;
2. the **diagnosis decides what is replaced**: the blamed modes are those with
   the largest guilt (all tied modes; a uniform guilt blames every mode);
3. if a blamed mode has a *detectable* fault on that flight (intensity >=
   ``detectable_fraction`` x its maximal intensity), the maintenance is correct:
   ``repair_kusd``, and every blamed mode that is present is removed for the
   rest of the unit's life; otherwise the removal finds no fault
   (``false_alarm_kusd``) and the unit returns unchanged;
4. each flight flown without an alarm while a detectable, not yet removed fault
   is present costs ``undetected_flight_kusd``;
5. a flight on which a not yet removed fault reaches ``failure_fraction`` x its
   maximal intensity costs ``failure_kusd`` (an in-flight failure; the alarm of
   that flight comes too late to prevent it), after which the unit is overhauled:
   every present mode is removed.

A fault outside the seven modes (labels ``onset_unknown`` >= 0, the scenario's
``unknown_faults``) acts at full strength from its onset: it is present and
detectable on every flight from then on and, with no failure law, never fails.
No guilt column names it, so an inspection finds it when the diagnosis does not
name a single library mode (several tied modes, or a uniform guilt: "something is
wrong, not one of the seven"), the rule by which the scorer judges its diagnosis;
it is then repaired and removed like a mode. An inspection that names one mode
repairs that mode if it is detectable and otherwise finds no fault.

A removed mode still shows in the recorded flights, so the method's recorded
decision on a later flight does not tell what it would have said on the
repaired unit. On such *replayed* flights (a removed mode is still present in
the recording and no remaining mode is detectable) the replayed unit is healthy
for the cost model, and the flight is charged the method's **expected**
false-alarm cost: ``false_alarm_kusd`` times the method's alarm rate on the
run's healthy flights (no mode present). On replayed flights where a remaining
mode is detectable, the recorded decision is used as in 3-4.

Under this protocol a method that never alarms pays every detectable flight and
every failure, whereas a perfect detector pays one repair per fault: never
alarming is cheaper only when detection has no value (``repair_kusd`` larger
than what a fault costs when left alone). Worked examples: ``docs/scoring.md``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fuelhm_bench.methods.tables import GUILT_COLUMNS
from fuelhm_bench.scoring.run import INTENSITY_COLUMNS, MAX_INTENSITY_COLUMNS, UNKNOWN_ONSET_COLUMN, Run

__all__ = ["COST_COLUMNS", "COST_FIELDS", "maintenance_cost", "total_cost"]

#: Attributes a cost model must have (those of ``fuelhm_bench.scenarios.CostSpec``).
COST_FIELDS: tuple[str, ...] = ("false_alarm_kusd", "undetected_flight_kusd", "failure_kusd", "repair_kusd",
                                "detectable_fraction", "failure_fraction")

#: Columns of :func:`maintenance_cost`.
COST_COLUMNS: tuple[str, ...] = ("unit_id", "flights", "inspections", "repairs", "no_fault_found",
                                 "undetected_flights", "failures", "replayed_flights", "repair_kusd",
                                 "false_alarm_kusd", "undetected_kusd", "failure_kusd",
                                 "expected_false_alarm_kusd", "cost_kusd")


def _model(costs) -> dict[str, float]:
    missing = [f for f in COST_FIELDS if not hasattr(costs, f)]
    if missing:
        from fuelhm_bench.errors import ParameterError

        raise ParameterError(f"The 'costs' parameter of maintenance_cost must be a cost model with the fields "
                             f"{', '.join(COST_FIELDS)} (a scenario's CostSpec). Got {type(costs).__name__} "
                             f"without {', '.join(missing)} instead.")
    return {f: float(getattr(costs, f)) for f in COST_FIELDS}


def _unknown_present(labels: pd.DataFrame) -> np.ndarray:
    """Flights carrying a fault outside the seven modes (from its onset on; all False without the column)."""
    if UNKNOWN_ONSET_COLUMN not in labels.columns:
        return np.zeros(len(labels), dtype=bool)
    onset = labels[UNKNOWN_ONSET_COLUMN].to_numpy(dtype=float)
    return (onset >= 0) & (labels["flight_index"].to_numpy(dtype=float) >= onset)


def healthy_alarm_rate(run: Run) -> float:
    """Alarm rate of the run's method on its healthy flights (no mode and no fault outside the seven
    present; 0 when there are none)."""
    extra = [UNKNOWN_ONSET_COLUMN] if UNKNOWN_ONSET_COLUMN in run.labels.columns else []
    merged = run.labels[["unit_id", "flight_index", *INTENSITY_COLUMNS, *extra]].merge(
        run.decisions[["unit_id", "flight_index", "alarm"]], on=["unit_id", "flight_index"])
    healthy = (merged[list(INTENSITY_COLUMNS)].to_numpy(dtype=float) <= 0).all(axis=1) & ~_unknown_present(merged)
    return float(merged["alarm"].to_numpy(dtype=bool)[healthy].mean()) if healthy.any() else 0.0


def maintenance_cost(run: Run, costs) -> pd.DataFrame:
    """Replay each unit's life under the maintenance protocol and cost it (module docstring).

    Parameters
    ----------
    run : Run
        Labels and decisions of one method on one scored fleet.
    costs : CostSpec
        The scenario's cost model (any object with the attributes of
        :data:`COST_FIELDS`).

    Returns
    -------
    pandas.DataFrame
        One row per unit, columns :data:`COST_COLUMNS`: counts of inspections
        (alarms judged), correct repairs, no-fault-found removals, undetected
        flights, failures and replayed flights, the cost of each kind [kUSD] and
        their sum ``cost_kusd``.

    Examples
    --------
    One unit, one mode that is detectable from flight 1 and fails on flight 3:

    >>> import numpy as np, pandas as pd
    >>> from types import SimpleNamespace
    >>> from fuelhm_bench.scoring import Run, null_decisions
    >>> from fuelhm_bench.taxonomy import MODE_IDS
    >>> labels = pd.DataFrame({"unit_id": 0, "flight_index": np.arange(5)})
    >>> for m in MODE_IDS:
    ...     labels[f"intensity_{m}"] = 0.0
    ...     labels[f"max_intensity_{m}"] = 1.0
    ...     labels[f"onset_{m}"] = -1
    >>> labels[f"intensity_{MODE_IDS[0]}"] = [0.0, 0.4, 0.7, 1.0, 1.0]
    >>> labels[f"onset_{MODE_IDS[0]}"] = 1
    >>> costs = SimpleNamespace(false_alarm_kusd=25.0, undetected_flight_kusd=2.0, failure_kusd=500.0,
    ...                         repair_kusd=15.0, detectable_fraction=0.25, failure_fraction=1.0)
    >>> never = Run(labels=labels, decisions=null_decisions(labels), healthy_scores=np.zeros(20))
    >>> float(maintenance_cost(never, costs)["cost_kusd"].sum())  # 3 undetected flights + 1 failure
    506.0
    """
    c = _model(costs)
    labels = run.labels.sort_values(["unit_id", "flight_index"], kind="stable")
    keys = ["unit_id", "flight_index"]
    decisions = labels[keys].merge(run.decisions, on=keys, how="left")
    p_fa = healthy_alarm_rate(run)
    inten = labels[list(INTENSITY_COLUMNS)].to_numpy(dtype=float)
    mx = labels[list(MAX_INTENSITY_COLUMNS)].to_numpy(dtype=float)
    alarm = decisions["alarm"].to_numpy(dtype=bool)
    guilt = decisions[list(GUILT_COLUMNS)].to_numpy(dtype=float)
    unknown = _unknown_present(labels)
    rows = [_replay_unit(unit, inten[idx], mx[idx], alarm[idx], guilt[idx], c, p_fa, unknown[idx])
            for unit, idx in labels.groupby("unit_id", sort=False).indices.items()]
    return pd.DataFrame(rows, columns=list(COST_COLUMNS))


def _replay_unit(unit, inten: np.ndarray, mx: np.ndarray, alarm: np.ndarray, guilt: np.ndarray,
                 c: dict[str, float], p_fa: float, unknown: np.ndarray) -> dict:
    removed = np.zeros(inten.shape[1], dtype=bool)
    unknown_removed = False
    n = {"inspections": 0, "repairs": 0, "no_fault_found": 0, "undetected_flights": 0, "failures": 0,
         "replayed_flights": 0}
    expected_fa = 0.0
    for t in range(inten.shape[0]):
        present = (inten[t] > 0) & ~removed
        detectable = present & (inten[t] >= c["detectable_fraction"] * mx[t])
        failing = present & (inten[t] >= c["failure_fraction"] * mx[t])
        outside = bool(unknown[t]) and not unknown_removed  # present and detectable from its onset
        replayed = (bool(((inten[t] > 0) & removed).any()) or (bool(unknown[t]) and unknown_removed)) and not (
            detectable.any() or outside)
        if replayed:
            n["replayed_flights"] += 1
            expected_fa += p_fa * c["false_alarm_kusd"]
        elif alarm[t]:
            n["inspections"] += 1
            blamed = guilt[t] >= guilt[t].max()
            found_outside = outside and int(blamed.sum()) != 1  # no single library mode named
            if (blamed & detectable).any() or found_outside:
                n["repairs"] += 1
                removed |= blamed & present
                unknown_removed = unknown_removed or found_outside
            else:
                n["no_fault_found"] += 1
        elif detectable.any() or outside:
            n["undetected_flights"] += 1
        if failing.any():
            n["failures"] += 1
            removed |= present
            unknown_removed = unknown_removed or outside  # the overhaul removes it too
    out = {"unit_id": unit, "flights": int(inten.shape[0]), **n,
           "repair_kusd": n["repairs"] * c["repair_kusd"],
           "false_alarm_kusd": n["no_fault_found"] * c["false_alarm_kusd"],
           "undetected_kusd": n["undetected_flights"] * c["undetected_flight_kusd"],
           "failure_kusd": n["failures"] * c["failure_kusd"],
           "expected_false_alarm_kusd": expected_fa}
    out["cost_kusd"] = (out["repair_kusd"] + out["false_alarm_kusd"] + out["undetected_kusd"]
                        + out["failure_kusd"] + expected_fa)
    return out


def total_cost(run: Run, costs) -> float:
    """Total cost of the run's decisions over its fleet [kUSD]: ``maintenance_cost(run, costs)["cost_kusd"].sum()``."""
    return float(maintenance_cost(run, costs)["cost_kusd"].sum())
