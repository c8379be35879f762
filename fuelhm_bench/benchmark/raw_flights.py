"""The raw flights a method with ``needs_raw`` is given: the healthy training flights, one at a time.

The indicator tables the benchmark caches (:mod:`fuelhm_bench.datasets.cache`)
are extracted from full-rate flights that are not kept (150,000 samples x 5
signals, 6 MB per 25-minute flight: a training fleet of 200 flights would be
1.2 GB). Every draw of a flight is seeded per (unit, flight)
(:mod:`fuelhm_bench.flights.fleet`), so the flights behind a cached table are
flown again here, bit for bit the same, a few flights at a time (about 0.03 s
of CPU per 25-minute flight), and handed over one by one: whatever the fleet
size, at most ``batch_size`` flights are in memory. The scored flights come
the same way from the environment (``reset(options={"raw_flight": True})``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from fuelhm_bench.methods.raw import RawFlight

__all__ = ["raw_flight_from_info", "training_raw_flights"]


def training_raw_flights(scenario: Any, units: Sequence[int], *, flight_minutes: float | None = None,
                         batch_size: int = 4) -> Iterator[RawFlight]:
    """Full-rate healthy training flights of some units of a scenario's training fleet.

    Parameters
    ----------
    scenario : Scenario
        A loaded scenario (its ``training`` section).
    units : sequence of int
        Unit ids of the training fleet (the ``unit_id`` of the training
        indicator table), in the order wanted.
    flight_minutes : float or None, default=None
        Flight duration [min]; None: the scenario's.
    batch_size : int, default=4
        Flights simulated together (the memory bound).

    Yields
    ------
    RawFlight
        Unit by unit, flights in order: the very flights of
        :func:`fuelhm_bench.datasets.cache.training_indicators`.
    """
    from fuelhm_bench.flights.fleet import iter_flights

    config = scenario.training_fleet_config()
    if flight_minutes is not None:
        config = dataclasses.replace(config, mission=dataclasses.replace(
            config.mission, duration_s=60.0 * float(flight_minutes)))
    for batch in iter_flights(config, batch_size=batch_size, units=[int(u) for u in units]):
        for flight in batch:
            out, extras = flight.output, flight.inputs.extras
            n = out.time_s.size
            yield RawFlight(flight.unit_id, flight.flight_index, out.time_s, out.current_a * 1e3,
                            out.measured_position_m * 1e3, extras.get("demand_mm", np.full(n, np.nan)),
                            extras.get("n2_pct", np.full(n, np.nan)))


def raw_flight_from_info(payload: dict, unit_id: Any, flight_index: int) -> RawFlight:
    """The :class:`RawFlight` of the environment's ``info["raw_flight"]``."""
    return RawFlight(unit_id, int(flight_index), payload["time_s"], payload["current_mA"],
                     payload["position_mm"], payload["demand_mm"], payload["n2_pct"])
