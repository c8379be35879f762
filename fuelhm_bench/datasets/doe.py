"""Design of experiments for the indicator transformation laws (paper section V).

For each of ``n_units`` manufactured units, one flight profile and one noise
realisation are drawn; the unit then flies that same flight healthy and with each
degradation mode at each intensity. Indicator changes are therefore paired: the
unit's dispersion, the operating conditions and the sensor noise cancel in
``dI = I(unit, mode, intensity) - I(unit, healthy)``, which is what
:func:`~fuelhm_bench.diagnosis.itl.fit_itl` regresses on the intensity.

Two extensions serve the surrogate fidelity (:mod:`fuelhm_bench.envs.surrogate`):
``missions > 1`` flies every case of a unit under several flight profiles and
noise realisations (column ``replicate``), so that the flight-to-flight variation
of a unit's response is observed; ``pairs`` adds flights with two modes at once
(``mode`` ``"a+b"``, intensities in ``intensity`` and ``intensity_2``), so that
the interaction of simultaneous modes is observed; ``faults`` adds, per unit and
mission, one flight with each fault outside the seven modes
(:class:`~fuelhm_bench.flights.schedule.UnknownFault`: the effect with its declared
parameters, at full strength; ``mode`` :func:`fault_case`, ``intensity`` 1), so
that the response to it is observed like a mode's. With the defaults (one
mission, no pair, no fault) the table is that of the published DOE, unchanged.

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

#: Prefix of the ``mode`` of a DOE flight with a fault outside the seven modes (:func:`fault_case`).
FAULT_PREFIX = "unknown:"


def fault_case(fault) -> str:
    """The ``mode`` label of a DOE flight with the fault outside the seven modes ``fault``.

    ``"unknown:<effect>"``, followed by ``"@name=value,..."`` when the fault sets parameters
    (values exact: ``repr`` of the float, without a ``+``, which separates the modes of a pair).
    Two faults with the same effect and parameters share a label (the same physics), whatever
    their probability and onsets.

    Examples
    --------
    >>> from fuelhm_bench.flights.schedule import UnknownFault
    >>> fault_case(UnknownFault("torque_motor_hysteresis", parameters=(("width_a", 0.0005),)))
    'unknown:torque_motor_hysteresis@width_a=0.0005'
    """
    params = ",".join(f"{k}={repr(float(v)).replace('+', '')}" for k, v in fault.parameters)
    return FAULT_PREFIX + fault.effect + (f"@{params}" if params else "")


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
    missions : int, default=1
        Flight profiles (with their noise realisations) each unit flies every case
        on, >= 1; mission 0 is the one of a one-mission design.
    pairs : tuple of (str, str), default=()
        Pairs of modes flown together, each at every combination of ``pair_intensities``.
    pair_intensities : tuple of float, default=()
        Intensities of each mode of a pair, in (0, 1] (required when ``pairs`` is given).
    faults : tuple of UnknownFault, default=()
        Faults outside the seven modes, each flown at full strength (its effect with its
        parameters) on every unit and mission, after the other cases (``mode`` :func:`fault_case`).
    """

    n_units: int = 8
    intensities: tuple = (0.25, 0.5, 0.75, 1.0)
    modes: tuple = MODE_IDS
    mission: MissionProfile = field(default_factory=lambda: MissionProfile(duration_s=900.0))
    nominal: LoopModel = field(default_factory=LoopModel)
    dispersion: Dispersion = field(default_factory=Dispersion)
    seed: int = 0
    missions: int = 1
    pairs: tuple = ()
    pair_intensities: tuple = ()
    faults: tuple = field(default=(), metadata={"key": "omit-default"})  # keys of older recipes kept

    def __post_init__(self) -> None:
        if not isinstance(self.n_units, int) or self.n_units < 1:
            raise range_error("DesignOfExperiments.n_units", "an integer >= 1", self.n_units)
        if not self.intensities or any(not 0.0 < float(f) <= 1.0 for f in self.intensities):
            raise range_error("DesignOfExperiments.intensities", "a non-empty tuple of values in (0, 1]",
                              self.intensities)
        validate_intensities({m: 0.0 for m in self.modes}, where="DesignOfExperiments.modes")
        if isinstance(self.missions, bool) or not isinstance(self.missions, int) or self.missions < 1:
            raise range_error("DesignOfExperiments.missions", "an integer >= 1", self.missions)
        pairs = tuple(tuple(map(str, pr)) for pr in self.pairs)
        if any(len(pr) != 2 or pr[0] == pr[1] for pr in pairs):
            raise range_error("DesignOfExperiments.pairs", "a tuple of pairs of two different modes", self.pairs)
        for pr in pairs:
            validate_intensities({m: 0.0 for m in pr}, where="DesignOfExperiments.pairs")
        if pairs and (not self.pair_intensities
                      or any(not 0.0 < float(f) <= 1.0 for f in self.pair_intensities)):
            raise range_error("DesignOfExperiments.pair_intensities", "a non-empty tuple of values in (0, 1] "
                              "when pairs are given", self.pair_intensities)
        object.__setattr__(self, "pairs", pairs)
        faults = tuple(self.faults)
        if any(not (hasattr(f, "effect") and hasattr(f, "parameters") and callable(getattr(f, "build", None)))
               for f in faults):
            raise range_error("DesignOfExperiments.faults", "a tuple of UnknownFault", self.faults)
        labels = [fault_case(f) for f in faults]
        if len(set(labels)) != len(labels):
            raise range_error("DesignOfExperiments.faults", "faults with different effects or parameters", labels)
        object.__setattr__(self, "faults", faults)

    @property
    def n_flights(self) -> int:
        """Number of simulated flights."""
        return self.n_units * self.missions * len(self.cases())

    def cases(self) -> list[tuple[str, float]]:
        """``(mode, intensity)`` of every flight of a unit on one mission, healthy first.

        A pair's case is ``("a+b", (f_a, f_b))``; a fault's ``(fault_case(fault), 1.0)``.
        """
        return ([("healthy", 0.0)] + [(m, float(f)) for m in self.modes for f in self.intensities]
                + [(f"{a}+{b}", (float(fa), float(fb))) for a, b in self.pairs
                   for fa in self.pair_intensities for fb in self.pair_intensities]
                + [(fault_case(f), 1.0) for f in self.faults])


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
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise range_error("run_doe batch_size", "an integer >= 1 or None", batch_size)
    tasks = [(doe, s, min(s + batch_size, total), extraction) for s in range(0, total, batch_size)]
    parts = run_ordered(_doe_part, tasks, workers=workers, sizes=[t[2] - t[1] for t in tasks], progress=progress)
    return pd.concat(parts, ignore_index=True)


def _doe_part(doe: DesignOfExperiments, start: int, stop: int, extraction) -> pd.DataFrame:
    """Indicators of the flights ``start .. stop - 1`` of the design (one piece of :func:`run_doe`)."""
    from fuelhm_bench.indicators import extract_table

    cases = doe.cases()
    faults = {fault_case(f): f for f in doe.faults}
    per_block = len(cases)  # one unit on one mission
    chunk = []
    for block in range(start // per_block, (stop - 1) // per_block + 1):
        u, r = divmod(block, doe.missions)
        keys = (u,) if r == 0 else (u, r)  # mission 0: the one-mission design's streams
        unit = manufacture(doe.nominal, rng_for(doe.seed, _STREAM_DOE_UNIT, u), doe.dispersion)
        inputs = doe.mission.sample(rng_for(doe.seed, _STREAM_DOE_MISSION, *keys))
        for c, (mode, f) in enumerate(cases):
            flight_id = block * per_block + c
            if start <= flight_id < stop:
                if mode == "healthy":
                    model = unit
                elif mode in faults:  # the effect with its parameters, at full strength
                    model = unit.with_effect(faults[mode].build())
                elif "+" in mode:
                    model = unit.degraded(dict(zip(mode.split("+"), f)))
                else:
                    model = unit.degraded({mode: f})
                chunk.append((flight_id, u, mode, f, model, inputs, r, keys))
    outs = simulate([j[4] for j in chunk], [j[5] for j in chunk],
                    [rng_for(doe.seed, _STREAM_DOE_NOISE, *j[7]) for j in chunk],
                    labels=[f"DOE unit {j[1]} mission {j[6]}, {j[2]} at {j[3]}" for j in chunk])
    flights = [_Flight(j[0], j[1], o.time_s, o.current_a * 1e3, o.measured_position_m * 1e3,
                       100.0 * j[5].n2_frac)
               for j, o in zip(chunk, outs)]
    table = extract_table(flights, extraction, on_error="flag")
    table.insert(2, "mode", [j[2] for j in chunk])
    table.insert(3, "intensity", np.array([j[3][0] if isinstance(j[3], tuple) else j[3] for j in chunk]))
    if doe.pairs:
        table.insert(4, "intensity_2", np.array([j[3][1] if isinstance(j[3], tuple) else 0.0 for j in chunk]))
    if doe.missions > 1:
        table.insert(2, "replicate", np.array([j[6] for j in chunk], dtype=np.int64))
    return table


@dataclass(frozen=True)
class _Flight:
    flight_id: int
    unit_id: int
    time_s: np.ndarray
    current_ma: np.ndarray
    position_mm: np.ndarray
    n2_pct: np.ndarray
