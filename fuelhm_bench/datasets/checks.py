"""What a scenario's simulated tables must hold before anything is fitted on them.

:func:`check_training_indicators` refuses, with a message that names the scenario and what to
change, a scenario whose healthy flights yield too few valid indicators for the paper's healthy
model. The harness runs it on a scenario's training table; the knowledge builds of
:mod:`fuelhm_bench.datasets.cache` run it on their own healthy tables, so that every path to a
healthy model (``evaluate``, ``export``, ``gym.make`` at the surrogate fidelity) gives this message
rather than the healthy model's own.
"""

from __future__ import annotations

import os
import re

import pandas as pd

from fuelhm_bench.errors import ScenarioError
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES

__all__ = ["EXCITATION_FIELDS", "check_training_indicators", "scenario_label"]


def scenario_label(scenario, sc) -> str:
    """How messages name a scenario given as ``scenario`` and loaded as ``sc``: its file and id, or its id."""
    return f"{scenario} ({sc.id})" if isinstance(scenario, (str, os.PathLike)) else f"scenario {sc.id}"


#: The indicator settings of a scenario: what a message about too few valid indicators points at.
EXCITATION_FIELDS: tuple[str, ...] = ("mission.test_sweep", "mission.sweep_low_mm", "mission.sweep_high_mm",
                                      "mission.sweep_rates_mm_s", "mission.frame_rate_hz", "sensor.noise_std_um",
                                      "sensor.adc_bits", "operating.throttle_step_interval_s")


def check_training_indicators(table: pd.DataFrame, label: str, *, fidelity: str, knowledge_flights: int,
                              flight_minutes: float | None = None, flights: str = "healthy training flights") -> None:
    """Refuse a scenario whose healthy training flights yield too few valid indicators.

    The paper's healthy model of ten indicators needs ``len(INDICATOR_NAMES) + 1`` = 11 flights with
    every indicator valid (:class:`~fuelhm_bench.diagnosis.HealthyModel`), and the benchmark fits it
    on the published knowledge's healthy flights (``knowledge_flights``, 40 by default) for every
    evaluation. So each of the ten, and the ten together, must be valid in at least ``11 /
    knowledge_flights`` of the training flights (27.5 % by default): below it, the expected number of
    valid knowledge flights is under 11. At the surrogate fidelity every indicator, the extended ones
    too, must also be valid in some training flight (the surrogate learns each from healthy flights).
    Every shipped scenario has all ten valid in 100 % of its training flights, at its own flight
    length and at 2-minute flights.

    Parameters
    ----------
    table : pandas.DataFrame
        The training fleet's indicator table (with ``quality_reason``).
    label : str
        The scenario as named in the message (its file and id).
    fidelity : str
        The fidelity of the run.
    knowledge_flights : int
        Healthy flights of the published knowledge.
    flight_minutes : float or None, default=None
        The run's flight duration override, named in the message.
    flights : str, default="healthy training flights"
        What the table's flights are, in the message (the knowledge builds check their own healthy
        flights with ``knowledge_flights=len(table)``: what their healthy model needs).

    Raises
    ------
    ScenarioError
        Naming the scenario, the indicators short of valid flights and how many they have, the most
        frequent reasons and the scenario fields that set the excitation.
    """
    needed = len(INDICATOR_NAMES) + 1
    pool = max(int(knowledge_flights), needed)
    fraction = needed / pool
    n = len(table)
    valid = {name: int(table[f"{name}_valid"].astype(bool).sum()) for name in INDICATOR_NAMES}
    complete = int(table[[f"{name}_valid" for name in INDICATOR_NAMES]].astype(bool).all(axis=1).sum())
    short = {name: k for name, k in valid.items() if k * pool < needed * n}  # k / n < needed / pool, exactly
    if not short and complete * pool < needed * n:
        short = {"the ten together": complete}
    never = [name for name in EXTENDED_INDICATOR_NAMES
             if fidelity == "surrogate" and f"{name}_valid" in table and not table[f"{name}_valid"].any()]
    if n == 0 or not (short or never):
        return
    minutes = f" of {flight_minutes:g} min" if flight_minutes is not None else ""
    text = f"{label}: too few valid indicators in its {n} {flights}{minutes}."
    if short:
        text += (f" Valid in {_grouped_counts(short)} (each of the paper's ten must be valid in at least "
                 f"{100 * fraction:.3g} % of them: the published knowledge's healthy model needs {needed} of its "
                 f"{knowledge_flights} healthy flights).")
        text += _main_reasons(table, [name for name in short if name in valid] or list(INDICATOR_NAMES))
    if never:
        text += (f" At the surrogate fidelity, {', '.join(never)} must be valid in some flights (the surrogate learns "
                 f"every indicator from healthy flights; the physics fidelity does not need them).")
    raise ScenarioError(f"{text} The excitation and reading of the actuator are set by {', '.join(EXCITATION_FIELDS)}.")


def _grouped_counts(counts: dict) -> str:
    """``"0 flights: X1, Y1; in 3: Inb"`` (flights in which each indicator is valid, fewest first)."""
    groups: dict[int, list[str]] = {}
    for name, k in counts.items():
        groups.setdefault(k, []).append(name)
    return "; in ".join(f"{k}{' flights' if i == 0 else ''}: {', '.join(names)}"
                        for i, (k, names) in enumerate(sorted(groups.items())))


def _main_reasons(table: pd.DataFrame, names: list, top: int = 2) -> str:
    """`` Main reasons: '...' (400 flights); '...' (38 flights).`` from ``quality_reason`` of the flights where
    one of ``names`` is invalid (reasons differing only in their numbers count together)."""
    if "quality_reason" not in table:
        return ""
    bad = ~table[[f"{name}_valid" for name in names]].astype(bool).all(axis=1)
    counts: dict[str, list] = {}
    for text in table.loc[bad, "quality_reason"].astype(str):
        for reason in filter(None, text.split("; ")):
            entry = counts.setdefault(re.sub(r"[-+]?\d+(\.\d+)?", "#", reason), [reason, 0])
            entry[1] += 1
    best = sorted(counts.values(), key=lambda e: -e[1])[:top]
    if not best:
        return ""
    shown = "; ".join(f"'{r if len(r) <= 160 else r[:157] + '...'}' ({k} flights)" for r, k in best)
    return f" Main reasons: {shown}."
