"""Simulated data sets as the methods and the scorer see them: indicator tables and labels.

:func:`fleet_indicators` simulates a fleet (:class:`~fuelhm_bench.flights.fleet.FleetConfig`)
in bounded-memory batches, extracts the ten on-board indicators of every flight
(:func:`fuelhm_bench.indicators.extract_table`) and returns

* the indicator table (one row per flight: ``flight_id``, ``unit_id``,
  ``flight_index``, the indicators, their validity flags, ``n_points``,
  ``quality_reason``) - what a method may see;
* the labels table (ground truth keyed by ``flight_id``) - what only the scorer sees.
"""

from __future__ import annotations

from collections.abc import Callable

import pandas as pd

from fuelhm_bench.flights.fleet import FleetConfig, build_units, iter_flights, labels_frame


def fleet_indicators(config: FleetConfig, *, batch_size: int = 16, extraction=None,
                     progress: Callable[[int], object] | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Simulate a fleet and return ``(indicators, labels)``.

    Parameters
    ----------
    config : FleetConfig
        What to simulate.
    batch_size : int, default=16
        Flights simulated together (memory bound).
    extraction : ExtractionConfig, optional
        Indicator extraction settings.
    progress : callable, optional
        Called with the number of flights done after each batch.

    Returns
    -------
    indicators, labels : pandas.DataFrame
    """
    from fuelhm_bench.indicators import extract_table

    units = {u.unit_id: u for u in build_units(config)}
    hidden = ",".join(e.id for e in config.nominal.effects)
    ind_parts, lab_parts = [], []
    for batch in iter_flights(config, batch_size=batch_size, progress=progress):
        table = extract_table([f.as_flight_arrays() for f in batch], extraction, on_error="flag")
        table.insert(2, "flight_index", [f.flight_index for f in batch])
        ind_parts.append(table)
        lab_parts.append(labels_frame(batch, units, hidden))
    return pd.concat(ind_parts, ignore_index=True), pd.concat(lab_parts, ignore_index=True)
