"""Design of experiments for the indicator transformation laws (paper section V).

For each of ``n_units`` manufactured units, one flight profile and one noise
realisation are drawn; the unit then flies that same flight healthy and with each
degradation mode at each intensity. Indicator changes are therefore paired: the
unit's dispersion, the operating conditions and the sensor noise cancel in
``dI = I(unit, mode, intensity) - I(unit, healthy)``, which is what
:func:`~fuelhm_bench.diagnosis.itl.fit_itl` regresses on the intensity.

The ITL is *published knowledge*: it is computed on the nominal model the
benchmark publishes (no hidden effects), with the scenario's mission and sensor.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fuelhm_bench.errors import range_error
from fuelhm_bench.flights.fleet import rng_for
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.physics.degradations import validate_intensities
from fuelhm_bench.physics.model import Dispersion, LoopModel, manufacture
from fuelhm_bench.physics.simulate import simulate
from fuelhm_bench.taxonomy import MODE_IDS

_STREAM_DOE_UNIT, _STREAM_DOE_MISSION, _STREAM_DOE_NOISE = 10, 11, 12


@dataclass(frozen=True)
class DesignOfExperiments:
    """Which simulations the ITL is computed from.

    Parameters
    ----------
    n_units : int, default=8
        Manufactured units (each flies all the cases).
    intensities : tuple of float, default=(0.25, 0.5, 0.75, 1.0)
        Intensities of each mode, in (0, 1].
    modes : tuple of str, default=MODE_IDS
        Degradation modes.
    mission : MissionProfile, default=15-minute flights
        Flight profile.
    nominal : LoopModel
        Published nominal model.
    dispersion : Dispersion
        Manufacturing dispersion of the units.
    seed : int, default=0
        Master seed.
    """

    n_units: int = 8
    intensities: tuple = (0.25, 0.5, 0.75, 1.0)
    modes: tuple = MODE_IDS
    mission: MissionProfile = field(default_factory=lambda: MissionProfile(duration_s=900.0))
    nominal: LoopModel = field(default_factory=LoopModel)
    dispersion: Dispersion = field(default_factory=Dispersion)
    seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.n_units, int) or self.n_units < 1:
            raise range_error("DesignOfExperiments.n_units", "an integer >= 1", self.n_units)
        if not self.intensities or any(not 0.0 < float(f) <= 1.0 for f in self.intensities):
            raise range_error("DesignOfExperiments.intensities", "a non-empty tuple of values in (0, 1]",
                              self.intensities)
        validate_intensities({m: 0.0 for m in self.modes}, where="DesignOfExperiments.modes")

    @property
    def n_flights(self) -> int:
        """Number of simulated flights."""
        return self.n_units * (1 + len(self.modes) * len(self.intensities))

    def cases(self) -> list[tuple[str, float]]:
        """``(mode, intensity)`` of every flight of a unit, healthy first."""
        return [("healthy", 0.0)] + [(m, float(f)) for m in self.modes for f in self.intensities]


def run_doe(doe: DesignOfExperiments, *, batch_size: int | None = None, extraction=None,
            progress: Callable[[int], object] | None = None, workers: int = 1) -> pd.DataFrame:
    """Simulate the design and extract the indicators of every flight.

    Parameters
    ----------
    doe : DesignOfExperiments
    batch_size : int or None, default=None
        Flights simulated together; None: one unit's cases (29 with the seven
        modes at four intensities), at most 29. The pieces spread over the workers.
    extraction : ExtractionConfig, optional
    progress : callable, optional
        Called with the number of flights done after each batch.
    workers : int, default=1
        Processes simulating batches in parallel
        (:func:`fuelhm_bench.datasets.parallel.run_ordered`); the table is
        byte-identical for any number.

    Returns
    -------
    pandas.DataFrame
        The indicator table (see :func:`fuelhm_bench.indicators.extract_table`)
        with ``mode`` (a mode id or ``"healthy"``) and ``intensity`` columns: the
        DOE table :func:`~fuelhm_bench.diagnosis.itl.fit_itl` expects.
    """
    from fuelhm_bench.datasets.parallel import run_ordered

    total = doe.n_flights
    batch_size = min(len(doe.cases()), 29) if batch_size is None else batch_size  # memory bound as in 0.1
    tasks = [(doe, s, min(s + batch_size, total), extraction) for s in range(0, total, batch_size)]
    parts = run_ordered(_doe_part, tasks, workers=workers, sizes=[t[2] - t[1] for t in tasks], progress=progress)
    return pd.concat(parts, ignore_index=True)


def _doe_part(doe: DesignOfExperiments, start: int, stop: int, extraction) -> pd.DataFrame:
    """Indicators of the flights ``start .. stop - 1`` of the design (one piece of :func:`run_doe`)."""
    from fuelhm_bench.indicators import extract_table

    per_unit = len(doe.cases())
    chunk = []
    for u in range(start // per_unit, (stop - 1) // per_unit + 1):
        unit = manufacture(doe.nominal, rng_for(doe.seed, _STREAM_DOE_UNIT, u), doe.dispersion)
        inputs = doe.mission.sample(rng_for(doe.seed, _STREAM_DOE_MISSION, u))
        for c, (mode, f) in enumerate(doe.cases()):
            flight_id = u * per_unit + c
            if start <= flight_id < stop:
                model = unit if mode == "healthy" else unit.degraded({mode: f})
                chunk.append((flight_id, u, mode, f, model, inputs))
    outs = simulate([j[4] for j in chunk], [j[5] for j in chunk],
                    [rng_for(doe.seed, _STREAM_DOE_NOISE, j[1]) for j in chunk],
                    labels=[f"DOE unit {j[1]}, {j[2]} at {j[3]:g}" for j in chunk])
    flights = [_Flight(j[0], j[1], o.time_s, o.current_a * 1e3, o.measured_position_m * 1e3,
                       100.0 * j[5].n2_frac)
               for j, o in zip(chunk, outs)]
    table = extract_table(flights, extraction, on_error="flag")
    table.insert(2, "mode", [j[2] for j in chunk])
    table.insert(3, "intensity", np.array([j[3] for j in chunk]))
    return table


@dataclass(frozen=True)
class _Flight:
    flight_id: int
    unit_id: int
    time_s: np.ndarray
    current_ma: np.ndarray
    position_mm: np.ndarray
    n2_pct: np.ndarray
