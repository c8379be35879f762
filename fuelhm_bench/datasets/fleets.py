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

from fuelhm_bench.flights.fleet import FleetConfig, iter_flights, labels_frame


def fleet_indicators(config: FleetConfig, *, batch_size: int = 16, extraction=None,
                     progress: Callable[[int], object] | None = None,
                     workers: int = 1) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Simulate a fleet and return ``(indicators, labels)``.

    Parameters
    ----------
    config : FleetConfig
        What to simulate.
    batch_size : int, default=16
        Flights simulated together (memory bound); with several workers, the
        pieces spread over them are smaller when that gives each worker at
        least four (load balance).
    extraction : ExtractionConfig, optional
        Indicator extraction settings.
    progress : callable, optional
        Called with the number of flights done after each batch.
    workers : int, default=1
        Processes simulating batches in parallel
        (:func:`fuelhm_bench.datasets.parallel.run_ordered`); the tables are
        byte-identical for any number.

    Returns
    -------
    indicators, labels : pandas.DataFrame
    """
    from fuelhm_bench.datasets.parallel import run_ordered

    total = config.n_units * config.n_flights
    piece = batch_size if workers <= 1 else max(1, min(batch_size, -(-total // (4 * workers))))  # >= 4 per worker
    tasks = [(config, s, min(s + piece, total), piece, extraction) for s in range(0, total, piece)]
    parts = run_ordered(_fleet_part, tasks, workers=workers, sizes=[t[2] - t[1] for t in tasks], progress=progress)
    return (pd.concat([p[0] for p in parts], ignore_index=True),
            pd.concat([p[1] for p in parts], ignore_index=True))


def _fleet_part(config: FleetConfig, start: int, stop: int, batch_size: int,
                extraction) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Indicators and labels of the flights ``start .. stop - 1`` of the fleet (one piece of :func:`fleet_indicators`)."""
    from fuelhm_bench.flights.fleet import _build_unit
    from fuelhm_bench.indicators import extract_table

    hidden = ",".join(e.id for e in config.nominal.effects)
    ind_parts, lab_parts = [], []
    units = {u: _build_unit(config, u) for u in range(start // config.n_flights, (stop - 1) // config.n_flights + 1)}
    for batch in iter_flights(config, batch_size=batch_size, start=start, stop=stop, fuel_temperature=False):
        table = extract_table([f.as_flight_arrays() for f in batch], extraction, on_error="flag")
        table.insert(2, "flight_index", [f.flight_index for f in batch])
        ind_parts.append(table)
        lab_parts.append(labels_frame(batch, units, hidden))
    return pd.concat(ind_parts, ignore_index=True), pd.concat(lab_parts, ignore_index=True)
