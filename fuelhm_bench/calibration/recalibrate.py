"""Recalibration of the model on measured healthy flights (paper section IV.B, Fig. 7).

What is fitted, and why it is identifiable
------------------------------------------
The data are the current and the LVDT position only, so what can be fitted is what shapes
the velocity-gain curve ``v(i)``. The recalibration subset
(:data:`RECALIBRATION_PARAMETERS`) holds one parameter per feature of the curve:

======================================  ===================================================
parameter                               feature of the curve it moves
======================================  ===================================================
``servovalve.null_bias_a``              horizontal position (``Inb = (X1 + X2)/2``)
``servovalve.slot_width_null_m``        gain in the null region ``G_null``
``servovalve.slot_width_outer_m``       gains outside it ``G_in``, ``G_out`` and the saturated speed
``servovalve.transition_start``         first slope change (``X1``, ``X2`` about ``Inb``)
``servovalve.transition_end``           end of the change to the outer gain
``cylinder.diaphragm_diameter_m``       idle current offset ``I0 - Inb`` (cooling flow)
``load.aero_force_at_100pct_n``         extension / retraction asymmetry growing with N2^2
``servovalve.rated_current_a``          where the velocity saturates (full spool stroke)
======================================  ===================================================

Parameters left out are aliases of these, or invisible in the data. Numbers from the
Jacobian of the replay residuals on three simulated 4-minute healthy flights, one typical
change (the manufacturing dispersion) per parameter; "correlation" is the largest
correlation of the estimate with the subset's once the parameter is added to it
(``docs/calibration.md``): ``discharge_coefficient`` (-1.00 with the outer slot width:
flows scale with ``Cd w``), ``supply_rise_at_100pct_pa`` (-1.00: ``w sqrt(dP)``),
``spool_stroke_m`` (-1.00), ``driver.offset_a`` (+1.00 with the null bias: only
``(Inb - offset) / gain`` is seen), ``driver.gain`` (+1.00 with the rated current: only
``gain / I_r`` is seen); ``radial_clearance_m`` (0.005 mm/s RMS per 5 %),
``spool_time_constant_s`` (0.011 mm/s per 5 %: invisible at a 10 ms frame, and it would
compete with ``lvdt_lag``), ``spool_friction_n`` (0.035 mm/s per 10 %). The subset itself
has a condition number of about 17-19 (unit-norm columns) and its largest correlation is
-0.91 (the two ends of the transition, which share one short stretch of the curve).
:class:`CalibrationResult` reports the condition number and the correlations of the fitted
subset on the data at hand (:class:`~fuelhm_bench.calibration.fit.Identifiability`).

Per unit and fleet
------------------
Units differ by manufacturing dispersion, so the subset is fitted per unit (``unit_id``;
flights without one form a single unit); the fleet model written by ``fuelhm-bench
calibrate`` takes the mean of the unit values (the centre of the dispersion, which is what
the simulator's nominal model is: :func:`~fuelhm_bench.physics.model.manufacture` draws
units around it). The controller frame of the written model is the data's sample period.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from fuelhm_bench.calibration import replay as rp
from fuelhm_bench.calibration.curve import CurveConfig, gap
from fuelhm_bench.calibration.fit import FitParameter, JointFit, apply_values, fit_joint, identifiability
from fuelhm_bench.errors import DataFormatError, range_error

#: The recalibration subset (see the module docstring). ``typical`` is the manufacturing
#: dispersion of the parameter (one normalised unit); ``span`` the half-width of the search.
RECALIBRATION_PARAMETERS: tuple[FitParameter, ...] = (
    FitParameter("servovalve.null_bias_a", "A", 1e-4, span=1.5e-3, lower=-5e-3, upper=5e-3,
                 why="horizontal position of the curve, Inb = (X1 + X2)/2"),
    FitParameter("servovalve.slot_width_null_m", "m", 4e-5, span=2.4e-4, lower=1e-4, upper=2e-2,
                 why="velocity gain in the null region G_null"),
    FitParameter("servovalve.slot_width_outer_m", "m", 8e-5, span=4.8e-4, lower=1e-4, upper=4e-2,
                 why="gains outside the null region G_in, G_out and the saturated speed"),
    FitParameter("servovalve.transition_start", "-", 0.004, span=0.03, lower=0.0, upper=1.0,
                 why="first slope change X1, X2 (fraction of the spool stroke)"),
    FitParameter("servovalve.transition_end", "-", 0.006, span=0.03, lower=0.0, upper=1.0,
                 why="end of the change to the outer gain (fraction of the spool stroke)"),
    FitParameter("cylinder.diaphragm_diameter_m", "m", 9e-6, span=4.5e-5, lower=1e-6, upper=3e-3,
                 why="cooling flow: idle-current offset I0 - Inb"),
    FitParameter("load.aero_force_at_100pct_n", "N", 50.0, span=1500.0, lower=-2e4, upper=2e4,
                 why="extension/retraction asymmetry and idle current growing with N2^2"),
    FitParameter("servovalve.rated_current_a", "A", 1.6e-4, span=1.2e-3, lower=1e-3, upper=5e-2,
                 why="current at full spool stroke: where the velocity saturates, scale of the current axis"),
)

#: Parameters considered and left out, with the reason (reported by the docs and the CLI).
EXCLUDED_PARAMETERS: dict[str, str] = {
    "servovalve.discharge_coefficient": "flows scale with Cd w: correlation -1.00 with the outer slot width",
    "fluid.supply_rise_at_100pct_pa": "velocity ~ w sqrt(dP_s): correlation -1.00 with the outer slot width",
    "servovalve.spool_stroke_m": "scales the metering area like the slot widths: correlation -1.00",
    "driver.offset_a": "only (Inb - offset) / gain is seen: correlation +1.00 with the null bias",
    "driver.gain": "only gain / I_r is seen: correlation +1.00 with the rated current",
    "servovalve.radial_clearance_m": "0.005 mm/s RMS change per 5 % (its dispersion): not identifiable",
    "servovalve.spool_time_constant_s": "0.011 mm/s RMS change per 5 %: invisible at a 10 ms frame, aliases lvdt_lag",
    "servovalve.spool_friction_n": "0.035 mm/s RMS change per 10 % (its dispersion)",
}

#: Key of the flights that carry no ``unit_id``.
NO_UNIT = "<no unit_id>"


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of a recalibration.

    Parameters
    ----------
    replay : ReplayConfig
        Differentiator, masks and sample selection (``max_frames`` is overridden by ``fit_max_frames``
        for the fit set).
    curve : CurveConfig
        Bins of the curve and of the gap metric.
    fit_max_frames : int, default=60000
        Cap on the replayed frames used by the fit (all flights together, split evenly over units).
    max_iterations : int, default=25
        Trust-region iterations of the fit.
    seed : int, default=0
        Seed of the segment draw.
    """

    replay: rp.ReplayConfig = field(default_factory=rp.ReplayConfig)
    curve: CurveConfig = field(default_factory=CurveConfig)
    fit_max_frames: int = 60000
    max_iterations: int = 25
    seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.fit_max_frames, int) or isinstance(self.fit_max_frames, bool) or \
                self.fit_max_frames < 2000:
            raise range_error("CalibrationConfig.fit_max_frames", "an integer >= 2000", self.fit_max_frames)
        if not isinstance(self.max_iterations, int) or isinstance(self.max_iterations, bool) or \
                self.max_iterations < 1:
            raise range_error("CalibrationConfig.max_iterations", "an integer >= 1", self.max_iterations)


@dataclass(frozen=True)
class ParameterEstimate:
    """A recalibrated parameter.

    Attributes
    ----------
    path : str
        Dotted path.
    unit : str
        SI unit.
    start : float
        Value in the start model [SI].
    value : float
        Fleet value (mean over units) [SI].
    unit_values : dict
        Value per unit key [SI].
    std_error : float
        Standard error of a unit value (largest over units) [SI].
    """

    path: str
    unit: str
    start: float
    value: float
    unit_values: dict
    std_error: float


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Outcome of :func:`recalibrate`.

    Attributes
    ----------
    start_model : LoopModel
        The model before recalibration (with the data's frame).
    model : LoopModel
        Fleet model: the start model with the mean unit values.
    unit_models : dict
        Recalibrated model per unit key.
    estimates : tuple of ParameterEstimate
        Fitted parameters.
    identifiability : dict
        :class:`~fuelhm_bench.calibration.fit.Identifiability` per unit key.
    gap_before, gap_after, gap_fleet : float
        Gap metric [mm/s] on all flights: start model, per-unit models, fleet model.
    rms_before, rms_after : float
        RMS sample residual [mm/s] (start model, per-unit models).
    evaluation : ReplaySet
        The evaluated samples (for curves and plots).
    v_before, v_after, v_fleet : numpy.ndarray
        Replayed velocities of the start, per-unit and fleet models on ``evaluation`` [mm/s].
    fit : JointFit
        The underlying fit.
    frame_s : float
        Sample period of the data [s].
    n2_measured : bool
        Whether N2 came from the file.
    curve : CurveConfig
        Bins of the gap metric.
    """

    start_model: object
    model: object
    unit_models: dict
    estimates: tuple
    identifiability: dict
    gap_before: float
    gap_after: float
    gap_fleet: float
    rms_before: float
    rms_after: float
    evaluation: rp.ReplaySet
    v_before: np.ndarray
    v_after: np.ndarray
    v_fleet: np.ndarray
    fit: JointFit
    frame_s: float
    n2_measured: bool
    curve: CurveConfig

    @property
    def max_condition(self) -> float:
        """Largest condition number over units [-]."""
        return max(i.condition for i in self.identifiability.values())


def unit_key(flight) -> object:
    """Unit of a flight (its ``unit_id``, or :data:`NO_UNIT`)."""
    return NO_UNIT if flight.unit_id is None else flight.unit_id


def model_for_data(model, frame_s: float):
    """The model with its controller frame set to the data's sample period [s]."""
    if abs(model.controller.frame_s - frame_s) <= 1e-9 * frame_s:
        return model
    return model.with_parameters({"controller.frame_s": float(frame_s)})


def group_by_unit(flights) -> dict:
    """Flights per unit key, in order of first appearance."""
    out: dict = {}
    for f in flights:
        out.setdefault(unit_key(f), []).append(f)
    return out


def prepare_units(flights, model, config: CalibrationConfig, *, frame_s: float, max_frames: int | None,
                  seed: int) -> dict:
    """One :class:`ReplaySet` per unit (frames capped at ``max_frames`` over all units)."""
    groups = group_by_unit(flights)
    cap = None if max_frames is None else max(int(max_frames // max(len(groups), 1)), 1000)
    cfg = dataclasses.replace(config.replay, max_frames=cap)
    return {k: rp.prepare_replay(fs, config=cfg, stroke_m=model.cylinder.stroke_m, frame_s=frame_s, seed=seed)
            for k, fs in groups.items()}


def check_excitation(sets: dict, what: str, *, min_moving: int = 200, min_span_ma: float = 2.0) -> None:
    """Refuse data without transients: the curve needs moving samples across the current range.

    Raises
    ------
    DataFormatError
        Naming the unit, what was found and what is needed.
    """
    for k, rs in sets.items():
        mov = rs.moving & rs.scored
        n_mov = int(np.count_nonzero(mov))
        span = float(np.ptp(rs.i_ma[mov])) if n_mov else 0.0
        if n_mov < min_moving or span < min_span_ma:
            unit = "" if k == NO_UNIT else f" of unit {k!r}"
            raise DataFormatError(
                f"Not enough excitation in {what}{unit}: {n_mov} moving samples (|v| >= "
                f"{rs.config.moving_velocity_mm_s:g} mm/s or a changing current) spanning {span:.2f} mA of current. "
                f"The recalibration needs at least {min_moving} moving samples spanning at least {min_span_ma:g} mA "
                "(transients: the engine-start test sweep, throttle steps); a flight holding the actuator still "
                "only shows the idle point of the curve.")


def fleet_values(unit_values: dict, parameters: Sequence[FitParameter]) -> dict:
    """Mean of the unit values per path [SI]."""
    return {p.path: float(np.mean([v[p.path] for v in unit_values.values()])) for p in parameters}


def evaluate(models: dict, sets: dict, curve: CurveConfig) -> tuple[float, float, dict]:
    """Gap [mm/s] and RMS residual [mm/s] of per-unit models on per-unit sets, and the velocities."""
    keys = list(sets)
    vs = rp.replay_batch([models[k] for k in keys], [sets[k] for k in keys])
    merged = merge_sets([sets[k] for k in keys])
    v = np.concatenate(vs)
    r = merged.v_meas_mm_s[merged.scored] - v[merged.scored]
    return gap(merged, v, curve), float(np.sqrt(np.mean(r ** 2))), dict(zip(keys, vs))


def merge_sets(sets: Sequence[rp.ReplaySet]) -> rp.ReplaySet:
    """Concatenate replay sets (same frame and configuration)."""
    sets = list(sets)
    if len(sets) == 1:
        return sets[0]
    offsets = np.concatenate([[0], np.cumsum([s.n_frames for s in sets])[:-1]])
    flight_off = np.concatenate([[0], np.cumsum([len(s.flight_ids) for s in sets])[:-1]])

    def cat(name):
        arrays = [getattr(s, name) for s in sets]
        return None if any(a is None for a in arrays) else np.concatenate(arrays)

    return rp.ReplaySet(
        frame_s=sets[0].frame_s, current_a=cat("current_a"), position_m=cat("position_m"), n2_frac=cat("n2_frac"),
        starts=np.concatenate([s.starts + o for s, o in zip(sets, offsets)]), lengths=cat("lengths"),
        scored=cat("scored"), v_meas_mm_s=cat("v_meas_mm_s"), i_ma=cat("i_ma"), direction=cat("direction"),
        moving=cat("moving"), position_mm=cat("position_mm"),
        flight=np.concatenate([s.flight + o for s, o in zip(sets, flight_off)]), phase=cat("phase"),
        flight_ids=tuple(x for s in sets for x in s.flight_ids), unit_ids=tuple(x for s in sets for x in s.unit_ids),
        n2_measured=all(s.n2_measured for s in sets), config=sets[0].config, time_s=cat("time_s"),
        fuel_temp_degc=cat("fuel_temp_degc"),
        flight_fuel_temp_degc=(None if any(s.flight_fuel_temp_degc is None for s in sets)
                               else tuple(x for s in sets for x in s.flight_fuel_temp_degc)))


def recalibrate(flights, model=None, *, parameters: Sequence[FitParameter] = RECALIBRATION_PARAMETERS,
                config: CalibrationConfig = CalibrationConfig(),
                progress: Callable[[int], None] | None = None) -> CalibrationResult:
    """Recalibrate a model on measured healthy flights (per unit, then the fleet mean).

    Parameters
    ----------
    flights : sequence of FlightArrays
        Checked flights (:func:`fuelhm_bench.io.split_flights`), file units (s, mA, mm, %).
    model : LoopModel, optional
        Start model (default the nominal :class:`~fuelhm_bench.physics.model.LoopModel`); its
        controller frame is set to the data's sample period.
    parameters : sequence of FitParameter, default=RECALIBRATION_PARAMETERS
        The subset to fit.
    config : CalibrationConfig
        Selection, curve and fit settings.
    progress : callable, optional
        Called with 1 after each replay of the fit.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    DataFormatError
        No flight, flights at several sample rates, or not enough excitation.
    """
    from fuelhm_bench.physics.model import LoopModel

    flights = list(flights)
    if not flights:
        raise DataFormatError("No flight to recalibrate on (every flight was rejected or the file is empty).")
    frame_s = rp.estimate_frame(flights)
    start = model_for_data(model if model is not None else LoopModel(), frame_s)
    fit_sets = prepare_units(flights, start, config, frame_s=frame_s, max_frames=config.fit_max_frames,
                             seed=config.seed)
    check_excitation(fit_sets, "the flights")
    eval_sets = prepare_units(flights, start, config, frame_s=frame_s, max_frames=None, seed=config.seed)
    result = fit_joint({k: start for k in fit_sets}, fit_sets, parameters, max_iterations=config.max_iterations,
                       progress=progress)
    fleet = apply_values(start, fleet_values(result.unit_values, parameters))
    g_before, rms_before, v_before = evaluate({k: start for k in eval_sets}, eval_sets, config.curve)
    g_after, rms_after, v_after = evaluate(result.unit_models, eval_sets, config.curve)
    g_fleet, _, v_fleet = evaluate({k: fleet for k in eval_sets}, eval_sets, config.curve)
    idf = unit_identifiability(result, fit_sets)
    estimates = []
    for j, p in enumerate(parameters):
        ses = [idf[k].std_error_z[j] for k in idf]
        se_z = float(np.nanmax(ses)) if ses else math.nan
        value = float(np.mean([result.unit_values[k][p.path] for k in result.unit_values]))
        se = abs(value) * p.typical * se_z if p.log else p.typical * se_z
        estimates.append(ParameterEstimate(p.path, p.unit, float(start.get(p.path)), value,
                                           {k: v[p.path] for k, v in result.unit_values.items()}, se))
    keys = list(eval_sets)
    return CalibrationResult(
        start_model=start, model=fleet, unit_models=result.unit_models, estimates=tuple(estimates),
        identifiability=idf, gap_before=g_before, gap_after=g_after, gap_fleet=g_fleet, rms_before=rms_before,
        rms_after=rms_after, evaluation=merge_sets([eval_sets[k] for k in keys]),
        v_before=np.concatenate([v_before[k] for k in keys]), v_after=np.concatenate([v_after[k] for k in keys]),
        v_fleet=np.concatenate([v_fleet[k] for k in keys]),
        fit=result, frame_s=frame_s, n2_measured=all(s.n2_measured for s in eval_sets.values()),
        curve=config.curve)


def unit_identifiability(result: JointFit, sets: dict) -> dict:
    """Identifiability of each unit's parameters (its Jacobian block; shared parameters appended)."""
    out = {}
    row = 0
    n_u = len(result.unit_parameters)
    n_units = len(result.unit_values)
    for u, k in enumerate(result.unit_values):
        n = sets[k].n_scored
        cols = list(range(u * n_u, (u + 1) * n_u)) + list(range(n_units * n_u, result.jacobian.shape[1]))
        block = result.jacobian[row:row + n][:, cols]
        names = [p.path for p in result.unit_parameters] + [p.path for p in result.shared_parameters]
        n_eff = n / (2 * sets[k].config.half_width)
        out[k] = identifiability(block, result.unit_rss[k], n_eff, names)
        row += n
    return out
