"""The scenario schema (``schema_version: 1``) as typed frozen dataclasses.

A scenario says everything needed to reproduce a benchmark run: the scored
(test) fleet and its degradation schedule, the flights, the sensor, hidden
physical effects of the simulated truth, nominal-parameter drift of the scored
units, the healthy training set, the seeds, the default simulation fidelity and
the cost model behind rewards. YAML is only its storage
(:mod:`fuelhm_bench.scenarios.loader`); these classes are the schema, and the
JSON Schema for editors is generated from them
(:func:`fuelhm_bench.scenarios.jsonschema.scenario_json_schema`).

Keys in YAML are the field names below, one section per class. Units are in
the field names (``_min``, ``_hz``, ``_s``, ``_mm``, ``_um``, ``_degc``,
``_kusd``); fields without a unit are dimensionless.

Versioning
----------
``version`` works like a Gymnasium ``-vN`` suffix: any change to a scenario
that alters simulated data or scores (a number, a mode, a seed, a cost) must
increment it; only comments and ``description`` may change without a bump.
``schema_version`` is the version of this file format, not of the scenario.

Rules
-----
* Degradation onsets are 0-based flight indices and the window
  ``[onset_min, onset_max]`` must lie within the unit's flights
  (``onset_max <= flights_per_unit - 1``).
* ``simultaneous: false`` (at most one mode per unit): the modes'
  probabilities plus ``healthy_probability`` must sum to 1.
  ``simultaneous: true`` (each mode occurs independently with its own
  probability, so a unit is healthy with probability ``prod(1 - p)``):
  ``healthy_probability`` must be omitted.
* ``drift`` changes the nominal model of the scored fleet only (never the
  training fleet), before manufacturing dispersion; it may not touch a
  parameter that a degradation mode acts on (that would be an unlabelled
  fault), nor the controller frame or the ADC resolution (set by ``mission``
  and ``sensor``).
* The training and test fleets must have different seeds (otherwise their
  units would be manufactured identically).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fuelhm_bench.errors import FuelHMError, ParameterError, ScenarioError
from fuelhm_bench.flights.fleet import FleetConfig
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.flights.schedule import GROWTH_LAWS, ModeSchedule, UnknownFault
from fuelhm_bench.physics.degradations import LAWS
from fuelhm_bench.physics.effects import EFFECTS, make_effect
from fuelhm_bench.physics.lvdt import MAX_NOISE_STD_M, LvdtParams
from fuelhm_bench.physics.model import (COMPONENTS, DISPERSION_TRUNCATION, MAX_DISPERSION_SCALE, Dispersion, LoopModel,
                                        dispersion_error, max_dispersion_scale)
from fuelhm_bench.scenarios._fields import Problem, Spec, option, parameter_docs, show, suggest, unknown_key
from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.taxonomy import EFFECT_IDS, MODE_IDS

#: File-format versions this package reads.
SUPPORTED_SCHEMA_VERSIONS: tuple[int, ...] = (1,)
#: Simulation fidelities a scenario may ask for by default.
FIDELITIES: tuple[str, ...] = ("physics", "surrogate")
#: Kinds of nominal-parameter drift.
DRIFT_CHANGES: tuple[str, ...] = ("relative", "absolute")
#: Upper bound of the units of a fleet (scored or training).
MAX_UNITS: int = 10_000
#: Upper bound of the flights per unit of a fleet.
MAX_FLIGHTS_PER_UNIT: int = 10_000
#: Upper bound of a flight's duration [min] (24 h).
MAX_DURATION_MIN: float = 1440.0
#: Largest seed (a signed 64-bit integer: seeds are stored in the SQLite results store).
MAX_SEED: int = 2**63 - 1
#: Run budget without an explicit opt-in [flight-hours, training + scored fleets]; the largest
#: shipped scenario needs about 470.
DEFAULT_RUN_BUDGET_FLIGHT_HOURS: float = 2000.0
#: Environment variable that raises (or lowers) the default run budget [flight-hours].
RUN_BUDGET_ENV: str = "FUELHM_RUN_BUDGET_FLIGHT_HOURS"
#: Simulation time per flight-hour at 100 Hz on one core [s], the fast path's benchmark
#: (``tests/bench_physics.py``: 35.8-36.5 ms per flight-hour, see the README); used only to
#: print an order of magnitude of a run's cost. It scales with the frame rate.
SECONDS_PER_FLIGHT_HOUR_100HZ: float = 0.036
#: Upper bound of every cost of a scenario's cost model [kUSD]: one billion US dollars, the order of the
#: loss of an aircraft, far above any cost of one actuator event (the shipped failure cost is 500); a run's
#: total then stays a finite number of kUSD (a cost of 1e308 overflowed to inf).
MAX_COST_KUSD: int = 1_000_000
#: Scenario names: lowercase identifiers (the ``-vN`` suffix is reserved for versions).
NAME_PATTERN = r"[a-z][a-z0-9_]*"

_MP = MissionProfile()
_LVDT = LvdtParams()
_MODE_DEFAULTS = {f.name: f.default for f in dataclasses.fields(ModeSchedule)}
_PARAM_MSG = re.compile(r"^The '(?P<name>[^']+)' parameter must be (?P<allowed>.*)\. Got (?P<given>.*) instead\.$",
                        re.S)

#: Model parameters that ``drift`` may not change, with the reason.
_DRIFT_EXCLUDED: dict[str, str] = {
    "controller.frame_s": "it is set by mission.frame_rate_hz",
    "lvdt.adc_bits": "it is set by sensor.adc_bits",
    **{f"{law.component}.{law.parameter}": f"degradation mode {law.mode} acts on it (drift would be an unlabelled fault)"
       for law in LAWS.values()},
}


#: A drift keeps a parameter within this factor of its nominal value (new / nominal in [1/2, 2], i.e. a
#: relative value in [-0.5, 1]): a shift of the population, not another design.
MAX_DRIFT_FACTOR: float = 2.0
#: Parameters that add to the parameter of a degradation mode (the same physical quantity) -> that mode.
DRIFT_TWINS: dict[str, str] = {
    "servovalve.null_bias_a": "null_bias_drift",  # total null bias = null_bias_a + null_bias_drift_a
    "driver.offset_a": "null_bias_drift",  # coil current = gain x command + offset_a: the same shift of the null
    "servovalve.radial_clearance_m": "radial_clearance",  # leakage height = radial clearance + corner radius
}
#: A twin (:data:`DRIFT_TWINS`) may drift by at most its mode's change at this intensity (the scorer's default
#: detectable fraction, :class:`~fuelhm_bench.scoring.config.ScoringConfig`): more is the fault, unlabelled.
MAX_TWIN_DRIFT_INTENSITY: float = 0.25


def drift_range(parameter: str, nominal: float) -> tuple[float, float, str]:
    """The values a drift may give ``parameter``, whose nominal value is ``nominal``, and why.

    The one rule of scenario ``drift`` entries and of ``drift-sweep`` (besides the physics' own
    bounds, checked by applying the drift): within :data:`MAX_DRIFT_FACTOR` of the nominal, and, for a
    parameter that adds to a degradation mode's (:data:`DRIFT_TWINS`), within that mode's change at
    intensity :data:`MAX_TWIN_DRIFT_INTENSITY`.

    Parameters
    ----------
    parameter : str
        Dotted parameter path (``"servovalve.null_bias_a"``).
    nominal : float
        Its value before the drift (SI units).

    Returns
    -------
    low, high : float
        Bounds of the drifted value (infinite when ``nominal`` is 0 and no mode bounds it).
    why : str
        The rule, for messages.

    Examples
    --------
    >>> drift_range("fluid.supply_rise_at_100pct_pa", 1.03e7)[:2]
    (5150000.0, 20600000.0)
    >>> low, high, why = drift_range("servovalve.null_bias_a", 5e-4)
    >>> round(low, 6), round(high, 6)  # a factor 2 below, 0.25 x 1.6 mA (null-bias drift) above
    (0.00025, 0.0009)
    """
    low, high = sorted((nominal / MAX_DRIFT_FACTOR, nominal * MAX_DRIFT_FACTOR)) if nominal else (-math.inf, math.inf)
    why = (f"within a factor {MAX_DRIFT_FACTOR:g} of its nominal value {nominal:g} (a drift shifts the population; "
           f"it is not another design)")
    mode = DRIFT_TWINS.get(parameter)
    if mode is not None:
        law = LAWS[mode]
        step = MAX_TWIN_DRIFT_INTENSITY * abs(law.delta)
        if nominal - step > low or nominal + step < high:
            low, high = max(low, nominal - step), min(high, nominal + step)
            why = (f"within a factor {MAX_DRIFT_FACTOR:g} of its nominal value {nominal:g} and within {step:g} of it: "
                   f"it adds to {law.component}.{law.parameter}, so a larger drift is the {mode} fault beyond "
                   f"intensity {MAX_TWIN_DRIFT_INTENSITY:g} ({law.delta:g} at 1), unlabelled")
    return low, high, why


def drift_value_problem(parameter: str, change: str, value: float, nominal: float, field: str) -> Problem | None:
    """The :class:`Problem` of a drift that leaves :func:`drift_range`, or None.

    ``field`` is the scenario field blamed (``"drift[0].value"``); the allowed range is given in the
    units of ``value`` (a fraction for ``relative``, SI units for ``absolute``).
    """
    new = nominal * (1.0 + value) if change == "relative" else nominal + value
    low, high, why = drift_range(parameter, nominal)
    slack = 1e-12 * max(abs(low), abs(high), abs(nominal)) if math.isfinite(low) and math.isfinite(high) else 0.0
    if low - slack <= new <= high + slack:
        return None
    if change == "relative":
        a, b = sorted((low / nominal - 1.0, high / nominal - 1.0))
    else:
        a, b = low - nominal, high - nominal
    return Problem(field, f"in [{a:.4g}, {b:.4g}] ({change} drift of {parameter}), to keep it {why}", show(value),
                   f"It would set {parameter} from {nominal:g} to {new:g}.")


def _physics_problem(exc: FuelHMError, field: str, given: object, context: str = "", *,
                     same_units: bool = False) -> Problem:
    """Turn a physics validation error into a :class:`Problem` on a scenario field.

    Parameters
    ----------
    exc : FuelHMError
        The error raised by a physics dataclass (message template of
        :func:`fuelhm_bench.errors.range_error` when possible).
    field : str
        Scenario field path the error is attributed to.
    given : object
        The scenario value of that field.
    context : str, default=""
        Sentence added as a hint (e.g. what the value would set).
    same_units : bool, default=False
        The scenario field is the physics parameter itself (same value and
        units), so the physics range applies to it directly.
    """
    m = _PARAM_MSG.match(str(exc))
    if m and same_units:
        allowed = f"{m.group('allowed')} ({m.group('name')})"
    elif m:
        allowed = f"such that {m.group('name')} is {m.group('allowed')} (got {m.group('given')})"
    else:
        allowed = f"accepted by the physics model ({exc})"
    return Problem(field, allowed, show(given), context)


def drift_parameter_paths(effect_ids: Iterable[str] = ()) -> tuple[str, ...]:
    """Model parameter paths that ``drift`` entries may change.

    Parameters
    ----------
    effect_ids : iterable of str, default=()
        Hidden effects enabled in the scenario; their parameters
        (``effect.<id>.<field>``) may drift too.

    Returns
    -------
    tuple of str
        ``component.field`` paths of :class:`~fuelhm_bench.physics.model.LoopModel`
        minus the excluded ones, then the effect paths.
    """
    paths = [f"{comp}.{f.name}" for comp, cls in COMPONENTS.items() for f in dataclasses.fields(cls)]
    paths += [f"effect.{eid}.{f.name}" for eid in effect_ids for f in dataclasses.fields(EFFECTS[eid])]
    return tuple(p for p in paths if p not in _DRIFT_EXCLUDED)


@dataclass(frozen=True)
class RunCost:
    """Estimated cost of a scenario run.

    Parameters
    ----------
    flight_hours : float
        Simulated flight time of the training and scored fleets [h].
    frame_rate_hz : float
        Simulation frame rate [Hz].
    """

    flight_hours: float
    frame_rate_hz: float

    @property
    def seconds(self) -> float:
        """Approximate simulation time on one core [s] (indicators and methods come on top)."""
        return self.flight_hours * SECONDS_PER_FLIGHT_HOUR_100HZ * self.frame_rate_hz / 100.0

    def describe(self) -> str:
        """``"about 3.2 h of simulation on one core"``."""
        s = self.seconds
        text = f"{s:.0f} s" if s < 120 else f"{s / 60:.0f} min" if s < 7200 else (
            f"{s / 3600:.1f} h" if s < 172800 else f"{s / 86400:.0f} days")
        return f"about {text} of simulation on one core at {self.frame_rate_hz:g} Hz"


def run_budget(declared: float | None = None) -> tuple[float, str]:
    """The run budget [flight-hours] and where it comes from.

    Parameters
    ----------
    declared : float or None, default=None
        A scenario's ``run_budget_flight_hours``.

    Returns
    -------
    budget : float
    origin : str
        ``"run_budget_flight_hours"``, the environment variable or ``"the default"``.

    Raises
    ------
    ScenarioError
        If the environment variable is set but is not a number > 0.
    """
    if declared is not None:
        return float(declared), "run_budget_flight_hours in the file"
    text = os.environ.get(RUN_BUDGET_ENV, "").strip()
    if not text:
        return DEFAULT_RUN_BUDGET_FLIGHT_HOURS, "the default"
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        raise ScenarioError(f"The environment variable {RUN_BUDGET_ENV} must be a number of flight-hours > 0. "
                            f"Got {show(text)} instead.")
    return value, f"{RUN_BUDGET_ENV}={text}"


# ----------------------------------------------------------------------------- sections
@dataclass(frozen=True, kw_only=True)
class FleetSpec(Spec):
    """The scored (test) fleet.

    Parameters
    ----------
    units : int
        Number of units (actuation loops) in the scored fleet, in [1, 10000].
    flights_per_unit : int
        Flights flown by each unit, in [1, 10000]; degradation onsets are indices into them.
    dispersion_scale : float, default=1.0
        Multiplies every standard deviation of the manufacturing dispersion
        (:class:`~fuelhm_bench.physics.model.Dispersion`), in [0, 3]; 0 gives
        identical units. Also used for the training fleet. The draws are truncated
        at 3 standard deviations: at 3 the most dispersed parameters (10 %) move by
        up to 90 %, and every unit so manufactured must be a valid model (a drift
        that brings a parameter near its physical bound lowers the limit).
    """

    units: int = option(ge=1, le=MAX_UNITS)
    flights_per_unit: int = option(ge=1, le=MAX_FLIGHTS_PER_UNIT)
    dispersion_scale: float = option(Dispersion().scale, ge=0.0, le=MAX_DISPERSION_SCALE)


@dataclass(frozen=True, kw_only=True)
class MissionSpec(Spec):
    """Structure of a flight (maps onto :class:`~fuelhm_bench.flights.mission.MissionProfile`).

    Parameters
    ----------
    duration_min : float, default=60.0
        Flight duration [min], at least ``(start_duration_s + 60) / 60``, at most 1440 (24 h).
    frame_rate_hz : float, default=100.0
        FADEC frame (and recording) rate [Hz], in [20, 10000]; sets the
        controller frame of the model too. (Below about 12 Hz the on-board
        extraction finds no idle samples and no moving current bins: measured
        on 20-minute flights, none valid at 7 and 9 Hz, every one at 12 Hz.)
    start_duration_s : float, default=60.0
        Engine start, including the actuator test sweep [s], in [20, 600].
    test_sweep : bool, default=true
        Whether the FADEC strokes the actuator end to end during engine start.
    sweep_rates_mm_s : list of float, default=[8, 15, 30, 50, 70, 90, 110]
        Demand ramp rates of the test sweep [mm/s], each in (0, 1000]: one ramp up
        and down per rate, cut short if the sweep does not fit in start_duration_s.
    sweep_low_mm : float, default=3.0
        Low end of the test sweep and of the N2 demand schedule [mm], >= 0.
    sweep_high_mm : float, default=57.0
        High end of the test sweep and of the N2 demand schedule [mm], > sweep_low_mm
        and below the nominal model's stroke (60 mm): a demand beyond the stroke
        holds the rod on its end stop.
    schedule_n2_low : float, default=0.55
        N2 (fraction of 100 %) at which the scheduled demand starts to open [-], in [0, 1.2].
    schedule_n2_high : float, default=1.0
        N2 at which the scheduled demand is fully open [-], in [0, 1.2], > schedule_n2_low.
    engine_time_constant_s : float, default=3.0
        First-order lag of N2 towards each phase's set point [s], > 0.
    """

    #: scenario field -> (MissionProfile field, conversion to SI)
    PHYSICS: ClassVar[dict] = {
        "duration_min": ("duration_s", lambda v: 60.0 * v),
        "frame_rate_hz": ("frame_s", lambda v: 1.0 / v),
        "start_duration_s": ("start_duration_s", float),
        "test_sweep": ("test_sweep", bool),
        "sweep_rates_mm_s": ("sweep_rates_m_s", lambda v: tuple(1e-3 * r for r in v)),
        "sweep_low_mm": ("sweep_low_m", lambda v: 1e-3 * v),
        "sweep_high_mm": ("sweep_high_m", lambda v: 1e-3 * v),
        "schedule_n2_low": ("schedule_n2_low", float),
        "schedule_n2_high": ("schedule_n2_high", float),
        "engine_time_constant_s": ("engine_time_constant_s", float),
    }

    duration_min: float = option(_MP.duration_s / 60.0, gt=0.0, le=MAX_DURATION_MIN)
    frame_rate_hz: float = option(1.0 / _MP.frame_s, ge=20.0, le=1e4)
    start_duration_s: float = option(_MP.start_duration_s, ge=20.0, le=600.0)
    test_sweep: bool = option(_MP.test_sweep)
    sweep_rates_mm_s: tuple[float, ...] = option(tuple(1e3 * r for r in _MP.sweep_rates_m_s), gt=0.0, le=1000.0,
                                                 min_items=1)
    sweep_low_mm: float = option(1e3 * _MP.sweep_low_m, ge=0.0)
    sweep_high_mm: float = option(1e3 * _MP.sweep_high_m, gt=0.0)
    schedule_n2_low: float = option(_MP.schedule_n2_low, ge=0.0, le=1.2)
    schedule_n2_high: float = option(_MP.schedule_n2_high, ge=0.0, le=1.2)
    engine_time_constant_s: float = option(_MP.engine_time_constant_s, gt=0.0)

    def _checks(self) -> Iterable[Problem]:
        shortest = (self.start_duration_s + 60.0) / 60.0
        if self.duration_min < shortest:
            yield Problem("duration_min", f">= (start_duration_s + 60 s) / 60 = {shortest:g} min",
                          show(self.duration_min))
        if self.sweep_high_mm <= self.sweep_low_mm:
            yield Problem("sweep_high_mm", f"> sweep_low_mm ({self.sweep_low_mm:g} mm)", show(self.sweep_high_mm))
        if self.schedule_n2_high <= self.schedule_n2_low:
            yield Problem("schedule_n2_high", f"> schedule_n2_low ({self.schedule_n2_low:g})",
                          show(self.schedule_n2_high))


@dataclass(frozen=True, kw_only=True)
class OperatingSpec(Spec):
    """Operating variability from flight to flight (maps onto ``MissionProfile``).

    Parameters
    ----------
    throttle_step_std : float, default=0.025
        Standard deviation of random throttle steps around each phase's N2 set point [-], in [0, 0.2].
    throttle_step_interval_s : float, default=90.0
        Mean interval between throttle steps [s], > 0.
    n2_noise_std : float, default=0.002
        Standard deviation of the slow band-limited fluctuation of the N2 demand [-], in [0, 0.05].
    fuel_temp_start_degc : float, default=15.0
        Mean fuel temperature at the start of a flight [degC], in [-60, 150] (each flight draws around it).
    fuel_temp_end_degc : float, default=70.0
        Mean fuel temperature at the end of a flight [degC], in [-60, 150].
    """

    PHYSICS: ClassVar[dict] = {
        "throttle_step_std": ("throttle_step_std", float),
        "throttle_step_interval_s": ("throttle_step_interval_s", float),
        "n2_noise_std": ("n2_noise_std", float),
        "fuel_temp_start_degc": ("fuel_temp_start_degc", float),
        "fuel_temp_end_degc": ("fuel_temp_end_degc", float),
    }

    throttle_step_std: float = option(_MP.throttle_step_std, ge=0.0, le=0.2)
    throttle_step_interval_s: float = option(_MP.throttle_step_interval_s, gt=0.0)
    n2_noise_std: float = option(_MP.n2_noise_std, ge=0.0, le=0.05)
    fuel_temp_start_degc: float = option(_MP.fuel_temp_start_degc, ge=-60.0, le=150.0)
    fuel_temp_end_degc: float = option(_MP.fuel_temp_end_degc, ge=-60.0, le=150.0)


@dataclass(frozen=True, kw_only=True)
class SensorSpec(Spec):
    """The LVDT acquisition chain.

    Parameters
    ----------
    noise_std_um : float, default=3.0
        Standard deviation of the additive white position noise [um], in [0, 10000] (the LVDT's
        ``MAX_NOISE_STD_M``).
    adc_bits : int, default=12
        ADC resolution over the LVDT range [bits], in [0, 24]; 0 disables quantization.
    """

    noise_std_um: float = option(1e6 * _LVDT.noise_std_m, ge=0.0, le=1e6 * MAX_NOISE_STD_M)
    adc_bits: int = option(_LVDT.adc_bits, ge=0, le=24)


@dataclass(frozen=True, kw_only=True)
class DegradationSpec(Spec):
    """One degradation mode of the schedule (maps onto :class:`~fuelhm_bench.flights.schedule.ModeSchedule`).

    Parameters
    ----------
    mode : str
        Degradation mode id (paper Table III).
    probability : float
        Probability that a unit of the scored fleet develops this mode, in [0, 1].
    onset_min : int
        Earliest onset flight (0-based index), >= 0.
    onset_max : int
        Latest onset flight (0-based), in [onset_min, flights_per_unit - 1]; each
        unit draws its onset uniformly in [onset_min, onset_max].
    growth : str
        Growth law from the onset: step (maximum at once), linear (reaches the
        maximum after ramp_flights flights) or exponential (from e^-5 of the
        maximum, reaching it after ramp_flights flights).
    ramp_flights : int, default=20
        Flights from onset to maximum intensity for linear and exponential growth, >= 1.
    max_intensity : float, default=1.0
        Maximum intensity, in (0, 1] (1 is the Table III maximum of the mode).
    """

    mode: str = option(choices=MODE_IDS)
    probability: float = option(ge=0.0, le=1.0)
    onset_min: int = option(ge=0)
    onset_max: int = option(ge=0)
    growth: str = option(choices=GROWTH_LAWS)
    ramp_flights: int = option(_MODE_DEFAULTS["ramp_flights"], ge=1)
    max_intensity: float = option(_MODE_DEFAULTS["max_intensity"], gt=0.0, le=1.0)

    def _checks(self) -> Iterable[Problem]:
        if self.onset_max < self.onset_min:
            yield Problem("onset_max", f">= onset_min ({self.onset_min})", show(self.onset_max))

    def schedule(self) -> ModeSchedule:
        """The simulator's :class:`~fuelhm_bench.flights.schedule.ModeSchedule`."""
        return ModeSchedule(self.mode, self.probability, self.onset_min, self.onset_max, self.growth,
                            self.ramp_flights, self.max_intensity)


@dataclass(frozen=True, kw_only=True)
class HiddenEffectSpec(Spec):
    """An optional physical effect switched on in the simulated truth (methods are not told).

    Parameters
    ----------
    effect : str
        Effect id (docs/physics.md §7 Optional effects).
    parameters : mapping of str to float, default={}
        Parameter overrides of the effect, SI units as in the parameter names
        (e.g. coulomb_n for rod_friction); omitted ones take the effect's defaults.
    """

    effect: str = option(choices=EFFECT_IDS)
    parameters: tuple[tuple[str, float], ...] = option(default=(), number_map=True)

    def _checks(self) -> Iterable[Problem]:
        names = [f.name for f in dataclasses.fields(EFFECTS[self.effect])]
        seen = set()
        for key, value in self.parameters:
            if key not in names:
                yield unknown_key(f"parameters.{key}", key, names)
            elif key in seen:
                yield Problem(f"parameters.{key}", "given once", show(value))
            seen.add(key)
        if any(k not in names for k, _ in self.parameters):
            return
        try:
            make_effect(self.effect, **dict(self.parameters))
        except FuelHMError as exc:
            m = _PARAM_MSG.match(str(exc))
            key = m.group("name").rpartition(".")[2] if m else ""
            field = f"parameters.{key}" if key in names else "parameters"
            yield _physics_problem(exc, field, dict(self.parameters).get(key, dict(self.parameters)),
                                   same_units=field != "parameters")

    def build(self):
        """The effect instance (see :func:`fuelhm_bench.physics.effects.make_effect`)."""
        return make_effect(self.effect, **dict(self.parameters))

    @classmethod
    def json_schema_extra(cls) -> dict:
        """Per-effect parameter names, ranges and docs for editors (``if``/``then`` on ``effect``)."""
        branches = []
        for eid, ecls in EFFECTS.items():
            docs = parameter_docs(ecls)
            props = {f.name: {"type": "number", "description": docs.get(f.name, ""), "default": f.default}
                     for f in dataclasses.fields(ecls)}
            branches.append({"if": {"properties": {"effect": {"const": eid}}, "required": ["effect"]},
                             "then": {"properties": {"parameters": {"type": "object", "properties": props,
                                                                    "additionalProperties": False}}}})
        return {"allOf": branches}


@dataclass(frozen=True, kw_only=True)
class UnknownFaultSpec(HiddenEffectSpec):
    """A fault outside the seven modes: an optional physical effect a scored unit acquires at an onset flight.

    Methods are told neither that it exists nor what it does. A scored unit
    that drew no degradation mode develops at most one unknown fault; its
    flights from the onset on are faulty with the true mode "unknown"
    (detection counts them; no mode of the library is the right diagnosis).

    Parameters
    ----------
    effect : str
        Effect id (docs/physics.md §7 Optional effects); not one of hidden_effects.
    parameters : mapping of str to float, default={}
        Parameter overrides of the effect, SI units as in the parameter names
        (e.g. width_a for torque_motor_hysteresis); omitted ones take the effect's defaults.
    probability : float
        Probability that a scored unit without any degradation mode develops
        this fault, in [0, 1]; the unknown faults' probabilities sum to at most 1.
    onset_min : int
        Earliest onset flight (0-based index), >= 0.
    onset_max : int
        Latest onset flight (0-based), in [onset_min, flights_per_unit - 1]; the
        effect stays on from the onset to the unit's last flight.
    """

    probability: float = option(ge=0.0, le=1.0)
    onset_min: int = option(ge=0)
    onset_max: int = option(ge=0)

    def _checks(self) -> Iterable[Problem]:
        yield from super()._checks()
        if self.onset_max < self.onset_min:
            yield Problem("onset_max", f">= onset_min ({self.onset_min})", show(self.onset_max))

    def schedule(self) -> UnknownFault:
        """The simulator's :class:`~fuelhm_bench.flights.schedule.UnknownFault`."""
        return UnknownFault(self.effect, self.probability, self.onset_min, self.onset_max, tuple(self.parameters))


@dataclass(frozen=True, kw_only=True)
class DriftSpec(Spec):
    """A change of one nominal model parameter in the scored fleet (robustness).

    Parameters
    ----------
    parameter : str
        Dotted parameter path of the model, component.field (e.g.
        servovalve.spool_time_constant_s) or effect.<id>.<field> for a hidden
        effect; see LoopModel.with_parameters.
    change : str
        relative (new = nominal * (1 + value)) or absolute (new = nominal + value,
        SI units of the parameter).
    value : float
        Size of the change: a fraction > -1 for relative, SI units for absolute.
    """

    parameter: str = option()
    change: str = option(choices=DRIFT_CHANGES)
    value: float = option()

    def _checks(self) -> Iterable[Problem]:
        if self.change == "relative" and self.value <= -1.0:
            yield Problem("value", "> -1 for a relative change", show(self.value))

    def apply(self, model: LoopModel) -> LoopModel:
        """Return ``model`` with this drift applied (validated by the physics)."""
        nominal = model.get(self.parameter)
        new = nominal * (1.0 + self.value) if self.change == "relative" else nominal + self.value
        return model.with_parameters({self.parameter: new})

    @classmethod
    def json_schema_extra(cls) -> dict:
        """Parameter paths for editors' autocompletion."""
        effect_pattern = r"^effect\.(" + "|".join(EFFECT_IDS) + r")\.[a-z0-9_]+$"
        return {"properties": {"parameter": {"anyOf": [{"enum": list(drift_parameter_paths())},
                                                       {"pattern": effect_pattern}]}}}


@dataclass(frozen=True, kw_only=True)
class TrainingSpec(Spec):
    """The healthy training set methods may learn from (no degradation, no drift).

    Parameters
    ----------
    units : int
        Number of healthy training units, in [2, 10000] (manufactured with the training seed). At
        least two: the harness fits methods on the first half of the units and calibrates their
        thresholds on the others (:func:`~fuelhm_bench.benchmark.harness.split_training`), never on
        the units they were fitted on.
    flights_per_unit : int
        Healthy flights per training unit, in [1, 10000].
    """

    units: int = option(ge=2, le=MAX_UNITS)
    flights_per_unit: int = option(ge=1, le=MAX_FLIGHTS_PER_UNIT)

    @property
    def n_flights(self) -> int:
        """Total number of healthy training flights."""
        return self.units * self.flights_per_unit


@dataclass(frozen=True, kw_only=True)
class SeedSpec(Spec):
    """Seeds of a run.

    Parameters
    ----------
    master : int
        Master seed, >= 0: seeds any other random choice of a run and derives
        the fleet seeds that are not given.
    training : int or None, default=null
        Seed of the training fleet, >= 0; null derives it from master
        (SeedSequence([master, 1])).
    test : int or None, default=null
        Seed of the scored fleet, >= 0; null derives it from master
        (SeedSequence([master, 2])).
    """

    master: int = option(ge=0, le=MAX_SEED)
    training: int | None = option(None, ge=0, le=MAX_SEED)
    test: int | None = option(None, ge=0, le=MAX_SEED)

    def _checks(self) -> Iterable[Problem]:
        if self.training_seed == self.test_seed:
            yield Problem("test", f"different from the training seed ({self.training_seed}), or the two fleets "
                                  f"would be manufactured identically", show(self.test), near=("training", "master"))

    @staticmethod
    def _derive(master: int, stream: int) -> int:
        return int(np.random.SeedSequence([master, stream]).generate_state(1)[0])

    @property
    def training_seed(self) -> int:
        """Seed of the training fleet (given or derived)."""
        return self.training if self.training is not None else self._derive(self.master, 1)

    @property
    def test_seed(self) -> int:
        """Seed of the scored (test) fleet (given or derived)."""
        return self.test if self.test is not None else self._derive(self.master, 2)


@dataclass(frozen=True, kw_only=True)
class CostSpec(Spec):
    """Cost model behind rewards, in thousands of US dollars (kUSD).

    The defaults are illustrative orders of magnitude, not airline data. Every
    cost is in [0, :data:`MAX_COST_KUSD`] (one billion US dollars).
    Intensity fractions refer to each mode's max_intensity in the scenario
    (the published maximal intensity), as in the scorer.

    Parameters
    ----------
    false_alarm_kusd : float, default=25.0
        Cost of a removal of a unit that has no detectable fault (no fault found) [kUSD], in [0, 1000000].
    undetected_flight_kusd : float, default=2.0
        Cost of each flight flown with a detectable fault that has not been
        acted upon (risk exposure) [kUSD], in [0, 1000000].
    failure_kusd : float, default=500.0
        Cost of an in-flight failure, when a degradation reaches failure_fraction [kUSD], in [0, 1000000].
    repair_kusd : float, default=15.0
        Cost of a correct maintenance action that repairs a faulty unit [kUSD], in [0, 1000000].
    detectable_fraction : float, default=0.25
        A fault is detectable from this fraction of its maximal intensity on,
        in (0, 1] (same default as the scorer's detectable_fraction).
    failure_fraction : float, default=1.0
        A fault causes an in-flight failure at this fraction of its maximal
        intensity, in (0, 1], > detectable_fraction.
    """

    false_alarm_kusd: float = option(25.0, ge=0.0, le=MAX_COST_KUSD)
    undetected_flight_kusd: float = option(2.0, ge=0.0, le=MAX_COST_KUSD)
    failure_kusd: float = option(500.0, ge=0.0, le=MAX_COST_KUSD)
    repair_kusd: float = option(15.0, ge=0.0, le=MAX_COST_KUSD)
    detectable_fraction: float = option(ScoringConfig().detectable_fraction, gt=0.0, le=1.0)
    failure_fraction: float = option(1.0, gt=0.0, le=1.0)

    def _checks(self) -> Iterable[Problem]:
        if self.failure_fraction <= self.detectable_fraction:
            yield Problem("failure_fraction", f"> detectable_fraction ({self.detectable_fraction:g})",
                          show(self.failure_fraction), near=("detectable_fraction",))


# ----------------------------------------------------------------------------- scenario
@dataclass(frozen=True, kw_only=True)
class Scenario(Spec):
    """A benchmark scenario (file format ``schema_version: 1``).

    Build one with :func:`fuelhm_bench.scenarios.load_scenario` (shipped name or
    YAML path) or directly in Python; either way every field is validated and
    the simulator objects are built once to check them.

    Parameters
    ----------
    schema_version : int
        Version of the scenario file format; only 1 exists.
    name : str
        Scenario name, a lowercase identifier; a scenario file is <name>.yaml (the loader checks it).
    version : int
        Scenario version, >= 1: increment it for any change that alters simulated
        data or scores (the id is <name>-v<version>).
    description : str
        What the scenario tests.
    fleet : FleetSpec
        The scored (test) fleet: units, flights per unit, manufacturing dispersion.
    mission : MissionSpec, default=MissionSpec()
        Structure of every flight (duration, frame rate, engine-start test sweep, N2 schedule).
    operating : OperatingSpec, default=OperatingSpec()
        Operating variability (throttle steps, N2 noise, fuel temperature).
    sensor : SensorSpec, default=SensorSpec()
        LVDT noise and ADC resolution.
    simultaneous : bool, default=true
        Whether several degradation modes may act in one unit.
    healthy_probability : float or None, default=null
        Probability that a scored unit stays healthy, in [0, 1]; required when
        simultaneous is false (then it and the modes' probabilities sum to 1),
        omitted when simultaneous is true.
    degradations : list of DegradationSpec, default=[]
        Degradation schedule of the scored fleet (each mode at most once).
    hidden_effects : list of HiddenEffectSpec, default=[]
        Optional physical effects of the simulated truth (training and scored
        fleets), not disclosed to methods (each effect at most once).
    drift : list of DriftSpec, default=[]
        Nominal-parameter changes applied to the scored fleet only, in order
        (each parameter at most once).
    unknown_faults : list of UnknownFaultSpec, default=[]
        Faults outside the seven modes in the scored fleet (each effect at
        most once, none of hidden_effects): a unit without any degradation mode
        develops at most one; scored as faulty with the true mode "unknown".
    training : TrainingSpec
        The healthy training set (units and flights per unit).
    seeds : SeedSpec
        Master seed and the training and test fleet seeds.
    fidelity : str, default="physics"
        Default simulation fidelity of a run: physics (the numba simulator) or
        surrogate (a faster approximation, where a runner provides one).
    costs : CostSpec, default=CostSpec()
        Cost model behind rewards (kUSD).
    run_budget_flight_hours : float or None, default=null
        Opt-in for a large run [flight-hours], > 0: a scenario whose estimated
        cost (flight-hours of the training and scored fleets) exceeds the run
        budget is refused with its estimate; the budget is this value when
        given, else the FUELHM_RUN_BUDGET_FLIGHT_HOURS environment variable,
        else 2000. It does not change simulated data or scores.

    Examples
    --------
    >>> from fuelhm_bench.scenarios import load_scenario
    >>> s = load_scenario("paper_2012")
    >>> s.id
    'paper_2012-v3'
    >>> s.test_fleet_config().n_units == s.fleet.units
    True
    """

    schema_version: int = option(choices=SUPPORTED_SCHEMA_VERSIONS)
    name: str = option(pattern=NAME_PATTERN)
    version: int = option(ge=1)
    description: str = option()
    fleet: FleetSpec = option()
    mission: MissionSpec = option(default_factory=MissionSpec)
    operating: OperatingSpec = option(default_factory=OperatingSpec)
    sensor: SensorSpec = option(default_factory=SensorSpec)
    simultaneous: bool = option(True)
    healthy_probability: float | None = option(None, ge=0.0, le=1.0)
    degradations: tuple[DegradationSpec, ...] = option(())
    hidden_effects: tuple[HiddenEffectSpec, ...] = option(())
    drift: tuple[DriftSpec, ...] = option(())
    unknown_faults: tuple[UnknownFaultSpec, ...] = option(())
    training: TrainingSpec = option()
    seeds: SeedSpec = option()
    fidelity: str = option("physics", choices=FIDELITIES)
    costs: CostSpec = option(default_factory=CostSpec)
    run_budget_flight_hours: float | None = option(None, gt=0.0)

    # ------------------------------------------------------------------ identity
    @property
    def id(self) -> str:
        """``<name>-v<version>``, e.g. ``"all_modes-v1"``."""
        return f"{self.name}-v{self.version}"

    # -------------------------------------------------------------- simulator objects
    def mission_profile(self) -> MissionProfile:
        """The flight profile of every flight (training and scored)."""
        kwargs = {}
        for section in (self.mission, self.operating):
            for name, (phys, convert) in type(section).PHYSICS.items():
                kwargs[phys] = convert(getattr(section, name))
        return MissionProfile(**kwargs)

    def published_model(self) -> LoopModel:
        """The nominal model methods may be told about: frame rate and sensor, no hidden effect, no drift."""
        return LoopModel().with_parameters({
            "controller.frame_s": 1.0 / self.mission.frame_rate_hz,
            "lvdt.noise_std_m": 1e-6 * self.sensor.noise_std_um,
            "lvdt.adc_bits": self.sensor.adc_bits,
        })

    def truth_model(self) -> LoopModel:
        """The simulated truth: :meth:`published_model` with the hidden effects switched on."""
        model = self.published_model()
        for spec in self.hidden_effects:
            model = model.with_effect(spec.build())
        return model

    def drifted_model(self) -> LoopModel:
        """The scored fleet's nominal model: :meth:`truth_model` with the drift applied in order."""
        model = self.truth_model()
        for spec in self.drift:
            model = spec.apply(model)
        return model

    def dispersion(self) -> Dispersion:
        """Manufacturing dispersion of both fleets."""
        return dataclasses.replace(Dispersion(), scale=self.fleet.dispersion_scale)

    def mode_schedules(self) -> tuple[ModeSchedule, ...]:
        """Degradation schedules of the scored fleet."""
        return tuple(d.schedule() for d in self.degradations)

    def training_fleet_config(self) -> FleetConfig:
        """The healthy training fleet: truth model (hidden effects, no drift), no degradation, training seed."""
        return FleetConfig(n_units=self.training.units, n_flights=self.training.flights_per_unit,
                           mission=self.mission_profile(), nominal=self.truth_model(), dispersion=self.dispersion(),
                           schedules=(), simultaneous=True, seed=self.seeds.training_seed)

    def test_fleet_config(self) -> FleetConfig:
        """The scored fleet: drifted truth model, degradation schedule, test seed."""
        return FleetConfig(n_units=self.fleet.units, n_flights=self.fleet.flights_per_unit,
                           mission=self.mission_profile(), nominal=self.drifted_model(), dispersion=self.dispersion(),
                           schedules=self.mode_schedules(), simultaneous=self.simultaneous,
                           seed=self.seeds.test_seed,
                           unknown_faults=tuple(u.schedule() for u in self.unknown_faults))

    # ------------------------------------------------------------------ checks
    def run_cost(self) -> RunCost:
        """Estimated cost of a run of this scenario (both fleets simulated once)."""
        return RunCost(
            flight_hours=(self.fleet.units * self.fleet.flights_per_unit
                          + self.training.units * self.training.flights_per_unit) * self.mission.duration_min / 60.0,
            frame_rate_hz=self.mission.frame_rate_hz)

    def _budget_checks(self) -> Iterator[Problem]:
        cost = self.run_cost()
        budget, origin = run_budget(self.run_budget_flight_hours)
        if cost.flight_hours <= budget:
            return
        fleets = (f"scored fleet {self.fleet.units} units x {self.fleet.flights_per_unit} flights + training "
                  f"{self.training.units} x {self.training.flights_per_unit}, {self.mission.duration_min:g} min each")
        yield Problem("fleet", f"a run within the budget of {budget:g} flight-hours ({origin})",
                      f"{cost.flight_hours:.4g} flight-hours ({fleets}; {cost.describe()})",
                      f"To allow it, set run_budget_flight_hours: {math.ceil(cost.flight_hours)} in the file or "
                      f"the environment variable {RUN_BUDGET_ENV}.",
                      near=("fleet.units", "training.units"))

    def _checks(self) -> Iterable[Problem]:
        problems = list(self._schedule_checks()) + list(self._effect_checks()) + list(self._budget_checks())
        if not problems:
            problems += self._drift_checks()
        if not problems:
            problems += self._physics_checks()
        return problems

    def _schedule_checks(self) -> Iterator[Problem]:
        last = self.fleet.flights_per_unit - 1
        seen: dict[str, int] = {}
        for i, d in enumerate(self.degradations):
            where = f"degradations[{i}]"
            if d.mode in seen:
                yield Problem(f"{where}.mode", f"a mode not already scheduled (degradations[{seen[d.mode]}] "
                                               f"is {d.mode})", show(d.mode))
            seen.setdefault(d.mode, i)
            if d.onset_min > last:
                yield Problem(f"{where}.onset_min", f"<= the last flight index, flights_per_unit - 1 = {last} "
                                                    f"(onsets are 0-based)", show(d.onset_min))
            elif d.onset_max > last:
                yield Problem(f"{where}.onset_max", f"<= the last flight index, flights_per_unit - 1 = {last} "
                                                    f"(onsets are 0-based)", show(d.onset_max))
        if self.simultaneous:
            if self.healthy_probability is not None:
                yield Problem("healthy_probability", "omitted when simultaneous is true (each mode then occurs "
                                                     "independently; a unit is healthy with probability prod(1 - p))",
                              show(self.healthy_probability))
            return
        if self.healthy_probability is None:
            yield Problem("healthy_probability", "given when simultaneous is false (a number in [0, 1] such that it "
                                                 "and the degradation probabilities sum to 1)",
                          show(self.healthy_probability), near=("simultaneous",))
            return
        probs = [d.probability for d in self.degradations]
        total = math.fsum(probs) + self.healthy_probability
        if not math.isclose(total, 1.0, rel_tol=0.0, abs_tol=1e-9):
            yield self._probability_sum_problem(probs, total)

    def _probability_sum_problem(self, probs: list[float], total: float) -> Problem:
        """Blame the field the user changed for a probability sum that is not 1.

        Against the shipped scenario of the same name (when there is one), the
        changed probability is blamed; otherwise ``healthy_probability`` when the
        degradations alone leave room for it, else the largest degradation
        probability. The message lists every term by its field.
        """
        fields = [f"degradations[{i}].probability" for i in range(len(probs))] + ["healthy_probability"]
        values = probs + [self.healthy_probability]
        terms = " + ".join(f"{v:g}" for v in values) + f" = {total:g}: " + " + ".join(fields)
        shipped = _shipped_probabilities(self.name)
        blamed = None
        if shipped is not None:
            mine = {d.mode: d.probability for d in self.degradations}
            mine["healthy_probability"] = self.healthy_probability
            changed = [k for k in mine if k in shipped and not math.isclose(mine[k], shipped[k], abs_tol=1e-12)]
            if changed:
                key = changed[0]
                blamed = ("healthy_probability" if key == "healthy_probability" else
                          fields[[d.mode for d in self.degradations].index(key)])
                others = 1.0 - (total - mine[key])
                hint = (f"{blamed} was {shipped[key]:g} in the shipped {self.name}; "
                        + (f"{others:g} would make the sum 1." if 0.0 <= others <= 1.0 else
                           "the other probabilities alone leave no room for it."))
        rest = 1.0 - math.fsum(probs)
        if blamed is None and rest >= 0.0:
            blamed, hint = "healthy_probability", f"healthy_probability: {rest:g} would make them sum to 1."
        elif blamed is None:
            i = max(range(len(probs)), key=probs.__getitem__)
            blamed = fields[i]
            hint = (f"The degradation probabilities alone sum to {1.0 - rest:g} > 1; lower one of them "
                    f"({blamed} is the largest).")
        given = values[fields.index(blamed)]
        return Problem(blamed, f"such that the degradation probabilities plus healthy_probability sum to 1 when "
                               f"simultaneous is false ({terms})",
                       show(given), hint, near=("simultaneous",))

    def _effect_checks(self) -> Iterator[Problem]:
        seen: dict[str, int] = {}
        for i, e in enumerate(self.hidden_effects):
            if e.effect in seen:
                yield Problem(f"hidden_effects[{i}].effect", f"an effect not already enabled (hidden_effects"
                                                             f"[{seen[e.effect]}] is {e.effect})", show(e.effect))
            seen.setdefault(e.effect, i)
        last = self.fleet.flights_per_unit - 1
        mine: dict[str, int] = {}
        for i, u in enumerate(self.unknown_faults):
            where = f"unknown_faults[{i}]"
            if u.effect in seen:
                yield Problem(f"{where}.effect", f"an effect outside hidden_effects (hidden_effects[{seen[u.effect]}] "
                                                 f"is {u.effect}: every unit already has it)", show(u.effect))
            elif u.effect in mine:
                yield Problem(f"{where}.effect", f"an effect not already scheduled (unknown_faults[{mine[u.effect]}] "
                                                 f"is {u.effect})", show(u.effect))
            mine.setdefault(u.effect, i)
            if u.onset_min > last:
                yield Problem(f"{where}.onset_min", f"<= the last flight index, flights_per_unit - 1 = {last} "
                                                    f"(onsets are 0-based)", show(u.onset_min))
            elif u.onset_max > last:
                yield Problem(f"{where}.onset_max", f"<= the last flight index, flights_per_unit - 1 = {last} "
                                                    f"(onsets are 0-based)", show(u.onset_max))
        total = math.fsum(u.probability for u in self.unknown_faults)
        if total > 1.0 + 1e-9:
            terms = " + ".join(f"unknown_faults[{i}].probability = {u.probability:g}"
                               for i, u in enumerate(self.unknown_faults))
            yield Problem(f"unknown_faults[{len(self.unknown_faults) - 1}].probability",
                          f"such that the unknown faults' probabilities sum to at most 1 ({terms} = {total:g})",
                          show(self.unknown_faults[-1].probability))

    def _drift_checks(self) -> list[Problem]:
        problems: list[Problem] = []
        effect_ids = [e.effect for e in self.hidden_effects]
        allowed = drift_parameter_paths(effect_ids)
        seen: dict[str, int] = {}
        for i, d in enumerate(self.drift):
            field = f"drift[{i}].parameter"
            if d.parameter in _DRIFT_EXCLUDED:
                problems.append(Problem(field, f"a parameter that drift may change; not {d.parameter}, because "
                                               f"{_DRIFT_EXCLUDED[d.parameter]}", show(d.parameter)))
            elif d.parameter not in allowed:
                problems.append(Problem(field, _drift_allowed_text(d.parameter, effect_ids), show(d.parameter),
                                        suggest(d.parameter, allowed)))
            elif d.parameter in seen:
                problems.append(Problem(field, f"a parameter not already drifted (drift[{seen[d.parameter]}])",
                                        show(d.parameter)))
            seen.setdefault(d.parameter, i)
        if problems:
            return problems
        model = self.truth_model()
        for i, d in enumerate(self.drift):
            nominal = model.get(d.parameter)
            if d.change == "relative" and nominal == 0.0:
                problems.append(Problem(f"drift[{i}].change", f"absolute for {d.parameter}, whose nominal value is 0 "
                                                              f"(a relative change would do nothing)", show(d.change)))
                continue
            try:
                model = d.apply(model)
            except FuelHMError as exc:
                new = nominal * (1.0 + d.value) if d.change == "relative" else nominal + d.value
                problems.append(_physics_problem(exc, f"drift[{i}].value", d.value,
                                                 f"It would set {d.parameter} from {nominal:g} to {new:g}."))
                continue
            problem = drift_value_problem(d.parameter, d.change, d.value, nominal, f"drift[{i}].value")
            if problem is not None:
                problems.append(problem)
        return problems

    def _physics_checks(self) -> list[Problem]:
        problems: list[Problem] = []
        stroke_mm = 1e3 * self.truth_model().cylinder.stroke_m
        if self.mission.sweep_high_mm >= stroke_mm:
            problems.append(Problem("mission.sweep_high_mm", f"< the model's stroke ({stroke_mm:g} mm): a demand beyond "
                                    f"it holds the rod on its end stop", show(self.mission.sweep_high_mm)))
            return problems
        try:
            self.mission_profile()
        except ParameterError as exc:
            problems.append(self._mission_problem(exc))
        if problems:
            return problems
        for label, build in (("training", self.training_fleet_config), ("fleet", self.test_fleet_config)):
            try:
                build()
            except FuelHMError as exc:
                problems.append(_physics_problem(exc, label, getattr(self, label).to_dict()))
        return problems or self._dispersion_checks()

    def _dispersion_checks(self) -> list[Problem]:
        """Every unit the dispersion can manufacture (draws at their truncation) is a valid model, in both fleets."""
        dispersion = self.dispersion()
        for model, fleet in ((self.truth_model(), "the training and scored fleets"),
                             (self.drifted_model(), "the drifted scored fleet (lower the dispersion or the drift)")):
            exc = dispersion_error(model, dispersion)
            if exc is None:
                continue
            m = _PARAM_MSG.match(str(exc))
            detail = (f"{m.group('name')} must be {m.group('allowed')} and would reach {m.group('given')}" if m
                      else str(exc))
            return [Problem("fleet.dispersion_scale",
                            f"in [0, {max_dispersion_scale(model, dispersion):g}] here: every unit it can manufacture "
                            f"must be a valid model", show(self.fleet.dispersion_scale),
                            f"At {DISPERSION_TRUNCATION:g} standard deviations (where the draws are truncated), "
                            f"{detail} in {fleet}.")]
        return []

    def _mission_problem(self, exc: ParameterError) -> Problem:
        m = _PARAM_MSG.match(str(exc))
        phys = m.group("name").rpartition(".")[2] if m else ""
        for section, name in ((self.mission, "mission"), (self.operating, "operating")):
            for field, (target, _) in type(section).PHYSICS.items():
                if target == phys:
                    return _physics_problem(exc, f"{name}.{field}", getattr(section, field))
        return _physics_problem(exc, "mission", self.mission.to_dict())


def _shipped_probabilities(name: str) -> dict[str, float] | None:
    """``{mode: probability, "healthy_probability": p}`` of the shipped scenario ``name``, read raw (no validation)."""
    import yaml

    from fuelhm_bench.scenarios.registry import shipped_scenario_files

    try:
        entry = shipped_scenario_files().get(name)
        raw = yaml.safe_load(entry.read_text(encoding="utf-8")) if entry is not None else None
        out = {d["mode"]: float(d["probability"]) for d in raw.get("degradations") or []}
        if raw.get("healthy_probability") is not None:
            out["healthy_probability"] = float(raw["healthy_probability"])
        return out
    except Exception:  # no shipped baseline to compare with: blame by the rule
        return None


def _drift_allowed_text(path: str, effect_ids: list[str]) -> str:
    comp, _, _ = path.partition(".")
    if comp in COMPONENTS:
        fields = [f.name for f in dataclasses.fields(COMPONENTS[comp]) if f"{comp}.{f.name}" not in _DRIFT_EXCLUDED]
        return f"a parameter path of the model; for {comp}: {comp}.{{{', '.join(fields)}}}"
    if comp == "effect":
        parts = path.split(".")
        if len(parts) == 3 and parts[1] in EFFECTS and parts[1] not in effect_ids:
            return (f"a parameter of an enabled hidden effect (enabled: {', '.join(effect_ids) or 'none'}; "
                    f"add {parts[1]} to hidden_effects first)")
        return f"effect.<id>.<field> with <id> an enabled hidden effect ({', '.join(effect_ids) or 'none enabled'})"
    extra = " or effect.<id>.<field> for an enabled hidden effect"
    return f"a parameter path component.field with component one of {', '.join(COMPONENTS)}{extra}"
