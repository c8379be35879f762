"""A fleet of manufactured units, each flying a sequence of flights with scheduled degradations.

Randomness is organised so that every draw comes from a generator seeded by
``(seed, stream, unit[, flight])`` through :class:`numpy.random.SeedSequence`:
a unit's manufacturing and schedule, a flight's operating conditions and its
sensor noise are each independent of how flights are batched or which other
units exist, so the same seed gives byte-identical output.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fuelhm_bench.errors import ParameterError, range_error
from fuelhm_bench.flights.mission import PHASE_NAMES, MissionProfile
from fuelhm_bench.flights.schedule import ModeSchedule, UnitSchedule, UnknownFault, draw_unit_schedule, draw_unknown_fault
from fuelhm_bench.physics.model import Dispersion, LoopModel, manufacture
from fuelhm_bench.physics.simulate import FlightInputs, SimOutput, simulate
from fuelhm_bench.taxonomy import MODE_IDS

_STREAM_UNIT, _STREAM_MISSION, _STREAM_NOISE, _STREAM_UNKNOWN = 0, 1, 2, 3


def rng_for(seed: int, stream: int, *keys: int) -> np.random.Generator:
    """Independent generator for ``(seed, stream, *keys)``."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(stream), *map(int, keys)]))


def unit_rng(seed: int, unit: int) -> np.random.Generator:
    """Generator of a unit's manufacturing and degradation schedule (as :func:`build_units` uses it)."""
    return rng_for(seed, _STREAM_UNIT, unit)


def mission_rng(seed: int, unit: int, flight: int) -> np.random.Generator:
    """Generator of a flight's operating conditions (as :func:`iter_flights` uses it)."""
    return rng_for(seed, _STREAM_MISSION, unit, flight)


def noise_rng(seed: int, unit: int, flight: int) -> np.random.Generator:
    """Generator of a flight's sensor noise (as :func:`iter_flights` uses it)."""
    return rng_for(seed, _STREAM_NOISE, unit, flight)


@dataclass(frozen=True)
class FleetConfig:
    """What to simulate.

    Parameters
    ----------
    n_units : int, default=2
        Number of units (actuation loops), >= 1.
    n_flights : int, default=5
        Flights per unit, >= 1.
    mission : MissionProfile
        Flight profile.
    nominal : LoopModel
        Nominal model around which units are manufactured (may carry optional effects).
    dispersion : Dispersion
        Manufacturing dispersion.
    schedules : tuple of ModeSchedule, default=()
        Degradation schedules (empty: a healthy fleet).
    simultaneous : bool, default=True
        Whether several modes may act in one unit.
    seed : int, default=0
        Master seed.
    unknown_faults : tuple of UnknownFault, default=()
        Faults outside the seven modes: a unit that drew no degradation mode
        develops at most one (drawn from its own stream, so the units' modes,
        onsets and manufacturing are those of the same fleet without them).
    """

    n_units: int = 2
    n_flights: int = 5
    mission: MissionProfile = field(default_factory=MissionProfile)
    nominal: LoopModel = field(default_factory=LoopModel)
    dispersion: Dispersion = field(default_factory=Dispersion)
    schedules: tuple = ()
    simultaneous: bool = True
    seed: int = 0
    unknown_faults: tuple = ()

    def __post_init__(self) -> None:
        for name in ("n_units", "n_flights"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
                raise range_error(f"FleetConfig.{name}", "an integer >= 1", v)
        if not isinstance(self.seed, (int, np.integer)) or isinstance(self.seed, bool) or self.seed < 0:
            raise range_error("FleetConfig.seed", "an integer >= 0", self.seed)
        if abs(self.mission.frame_s - self.nominal.controller.frame_s) > 1e-12:
            raise range_error("MissionProfile.frame_s",
                              f"equal to the controller frame ({self.nominal.controller.frame_s:g} s)",
                              self.mission.frame_s)
        for s in self.schedules:
            if not isinstance(s, ModeSchedule):
                raise range_error("FleetConfig.schedules", "a tuple of ModeSchedule", s)
        for f in self.unknown_faults:
            if not isinstance(f, UnknownFault):
                raise range_error("FleetConfig.unknown_faults", "a tuple of UnknownFault", f)


@dataclass(frozen=True)
class Unit:
    """A manufactured unit and its realised degradation history."""

    unit_id: int
    model: LoopModel
    schedule: UnitSchedule


@dataclass(frozen=True)
class SimulatedFlight:
    """One simulated flight with its ground truth."""

    flight_id: int
    unit_id: int
    flight_index: int
    intensities: dict
    inputs: FlightInputs
    output: SimOutput

    def as_flight_arrays(self):
        """The recorded signals at the data boundary (mA, mm; N2 in % as the extra ``n2_pct``),
        as :class:`~fuelhm_bench.io.FlightArrays`."""
        from fuelhm_bench.io import FlightArrays

        n2_pct = self.inputs.extras.get("n2_pct")  # the mission's recorded channel, 100 n2 (the same bits)
        return FlightArrays(self.flight_id, self.unit_id, self.output.time_s, self.output.current_a * 1e3,
                            self.output.measured_position_m * 1e3,
                            extras={"n2_pct": 100.0 * self.inputs.n2_frac if n2_pct is None else n2_pct})


def build_units(config: FleetConfig) -> list[Unit]:
    """Manufacture the units and draw their degradation schedules."""
    return [_build_unit(config, u) for u in range(config.n_units)]


def _build_unit(config: FleetConfig, u: int) -> Unit:
    rng = unit_rng(config.seed, u)
    model = manufacture(config.nominal, rng, config.dispersion)
    sched = draw_unit_schedule(config.schedules, rng, simultaneous=config.simultaneous)
    if config.unknown_faults and not sched.schedules:
        fault, onset = draw_unknown_fault(config.unknown_faults, rng_for(config.seed, _STREAM_UNKNOWN, u))
        sched = UnitSchedule(unknown=fault, unknown_onset=onset)
    return Unit(u, model, sched)


def iter_flights(config: FleetConfig, *, batch_size: int = 16, progress=None, start: int = 0,
                 stop: int | None = None, units=None, fuel_temperature: bool = True
                 ) -> Iterator[list[SimulatedFlight]]:
    """Simulate the fleet in batches of flights (bounded memory).

    Parameters
    ----------
    config : FleetConfig
    batch_size : int, default=16
        Flights simulated together.
    progress : callable, optional
        Called with the number of flights done after each batch.
    start, stop : int, optional
        Simulate only the flights ``start .. stop - 1`` of the fleet, in its
        order (unit by unit, flight by flight); the same flights as in the whole
        fleet, byte for byte. Default: all.
    units : sequence of int, optional
        Simulate only these units of the fleet (the same flights, bit for bit,
        as in the whole fleet: every draw is seeded per unit and flight), within
        ``start .. stop - 1``; None: all.
    fuel_temperature : bool, default=True
        False: leave the ``fuel_temp_degC`` channel out of the flights' inputs, except for a
        model that reads it (``viscosity_temperature``); every other channel and the outputs are
        the same, bit for bit (see :meth:`~fuelhm_bench.flights.mission.MissionProfile.sample`).

    Yields
    ------
    list of SimulatedFlight
    """
    nf = config.n_flights
    selected = range(config.n_units * nf)[start:stop]
    if not selected:
        return
    lo, hi = selected[0], selected[-1]
    if units is None:
        wanted = range(lo // nf, hi // nf + 1)
    else:
        wanted = [int(u) for u in units]
        bad = [u for u in wanted if not 0 <= u < config.n_units]
        if bad:
            raise ParameterError(f"The 'units' parameter of iter_flights must hold unit indices in "
                                 f"[0, {config.n_units - 1}]. Got {bad[:5]} instead.")
    fleet = [_build_unit(config, u) for u in wanted]
    todo = [(u, f) for u in fleet for f in range(nf) if lo <= u.unit_id * nf + f <= hi]
    for start in range(0, len(todo), batch_size):
        chunk = todo[start:start + batch_size]
        models, inputs, rngs, labels, intens = [], [], [], [], []
        for unit, f in chunk:
            it = unit.schedule.intensities(f)
            intens.append(it)
            model = unit.model.degraded(it)
            for effect in unit.schedule.effects(f):  # a fault outside the seven modes
                model = model.with_effect(effect)
            models.append(model)
            temperature = fuel_temperature or model.effect("viscosity_temperature") is not None
            inputs.append(config.mission.sample(mission_rng(config.seed, unit.unit_id, f),
                                                fuel_temperature=temperature))
            rngs.append(noise_rng(config.seed, unit.unit_id, f))
            labels.append(f"unit {unit.unit_id}, flight {f}")
        outs = simulate(models, inputs, rngs, labels=labels)
        batch = [SimulatedFlight(unit.unit_id * config.n_flights + f, unit.unit_id, f, it, inp, out)
                 for (unit, f), it, inp, out in zip(chunk, intens, inputs, outs)]
        if progress is not None:
            progress(len(batch))
        yield batch


def flights_frame(flights: list[SimulatedFlight]) -> pd.DataFrame:
    """Flight table in the docs/data-format.md format (mA, mm at the boundary)."""
    parts = []
    for fl in flights:
        out, ex = fl.output, fl.inputs.extras
        n = len(out.time_s)
        cols = {
            "flight_id": np.full(n, fl.flight_id, dtype=np.int64),
            "unit_id": np.full(n, fl.unit_id, dtype=np.int64),
            "time_s": out.time_s,
            "current_mA": out.current_a * 1e3,
            "position_mm": out.measured_position_m * 1e3,
        }
        if "demand_mm" in ex:
            cols["demand_mm"] = ex["demand_mm"]
        if "n2_pct" in ex:
            cols["n2_pct"] = ex["n2_pct"]
        if "fuel_temp_degC" in ex:
            cols["fuel_temp_degC"] = ex["fuel_temp_degC"]
        if "phase" in ex:
            cols["phase"] = pd.Categorical.from_codes(ex["phase"], categories=list(PHASE_NAMES))
        parts.append(pd.DataFrame(cols))
    return pd.concat(parts, ignore_index=True)


def label_row(unit: Unit, flight_index: int, intensities: dict) -> dict:
    """The ground truth of one flight of ``unit`` (the one home of a label row, whatever writes it).

    Per mode ``intensity_<mode>`` (this flight's, from ``intensities``), ``max_intensity_<mode>`` and
    ``onset_<mode>`` (the unit's schedule); then the unit's fault outside the seven modes:
    ``unknown_fault`` (its effect id, "" if none) and ``onset_unknown`` (its onset flight, -1 if none).
    """
    row = {"unit_id": unit.unit_id, "flight_index": flight_index}
    for m in MODE_IDS:
        row[f"intensity_{m}"] = float(intensities.get(m, 0.0))
        row[f"max_intensity_{m}"] = unit.schedule.max_intensity_of(m)
        row[f"onset_{m}"] = unit.schedule.onset_of(m)
    unknown = unit.schedule.unknown
    row["unknown_fault"] = "" if unknown is None else unknown.effect
    row["onset_unknown"] = unit.schedule.unknown_onset
    return row


def labels_frame(flights: list[SimulatedFlight], units: dict[int, Unit], hidden_effects: str = "") -> pd.DataFrame:
    """Ground-truth table keyed by flight_id (never mixed with the measurements)."""
    rows = [{"flight_id": fl.flight_id, **label_row(units[fl.unit_id], fl.flight_index, fl.intensities),
             "hidden_effects": hidden_effects} for fl in flights]
    return pd.DataFrame(rows)
