"""Candidate effects for the model-discrepancy workflow: what is fitted, where the search starts.

Each candidate is an optional effect of :mod:`fuelhm_bench.physics.effects` with the
parameters the workflow fits (shared by all units, bounded by the effect's documented
range), the parameters it holds, and a grid of start points spanning the range (the
multi-start: every grid point is scored with the recalibrated units, the fit starts from
the best one).

=====================  ==========================================  ==============================================
effect                 fitted [range]                               held
=====================  ==========================================  ==============================================
``spool_overlap``      ``overlap_m`` (log) [1e-7, 1e-4] m,          --
                       ``servovalve.radial_clearance_m`` (log)
                       [5e-7, 3e-5] m
``spool_flow_force``   ``stiffness_ratio`` (log) [1e-3, 3],         --
                       ``command_limit_ratio`` [1, 3]
``rod_friction``       ``coulomb_n`` (log) [1, 5000] N,             ``stribeck_velocity_m_s`` = 2 mm/s,
                       ``static_ratio`` [1, 3]                      ``viscous_n_s_m`` = 0
``lvdt_lag``           ``time_constant_s`` (log) [1e-4, 0.5] s      --
``load_stiffness``     ``stiffness_n_m`` [-5e5, 5e5] N/m,           --
                       ``reference_m`` [0, stroke] m
``current_driver_lag`` ``time_constant_s`` (log) [1e-4, 0.5] s      --
``torque_motor_        ``width_a`` (log) [1e-6, 5e-3] A              --
hysteresis``
``viscosity_           ``leak_at_20c_m3_s_pa`` (log) [1e-15, 1e-9]  ``slope_per_degc`` = 0.02 /degC (kerosene;
temperature``                                                       the flights' temperatures rarely separate it)
=====================  ==========================================  ==============================================

The overlap is fitted with the radial clearance of the spool, fleet-wide: across an overlapped
land the only flow is the leakage through that clearance, and the model's leakage law (the
``softplus`` effective opening, :func:`~fuelhm_bench.physics.servovalve.effective_opening`)
is one of several plausible ones (a laminar leak that does not depend on the lap is another).
With the clearance held at nominal, the lap alone had to reproduce both the dead band and
another simulator's leakage through it, and was fitted 22-30 % short on the second
simulator's laps (issue 14, sixteenth round); freeing the leakage's scale leaves the lap to
the dead band's width. On healthy data (no lap) the clearance is not identifiable and the
candidate earns nothing (docs/discrepancy.md).

Held parameters: the Stribeck velocity shapes the friction below a few mm/s, where the
velocity quantum of the differentiated position (``q / (10 T)`` = 0.17 mm/s at 12 bit and
100 Hz, but the idle hunting spans a few mm/s) leaves it unidentifiable; the viscous term
``b v`` is a velocity-proportional force, aliased with the slot widths that the
recalibration fits per unit. The lower ends of the log ranges (the documented ranges are
open at 0) are far below any visible magnitude. The reference of ``load_stiffness`` is
searched over the stroke (a reference beyond it is a constant force, which the
recalibrated load already holds). The flow force's command limit only acts where the
command exceeds it (at a saturated current, about 1.5 x stroke for the nominal valve):
above that its gradient is zero, so every stiffness start is tried with a limit near the
stroke (1.05) and with one beyond any command (2.5); the starts lie inside the bounds
(a start on a bound left the trust-region fit where it began).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fuelhm_bench.calibration.fit import FitParameter
from fuelhm_bench.errors import UnknownNameError
from fuelhm_bench.taxonomy import EFFECT_IDS


@dataclass(frozen=True)
class EffectCandidate:
    """One candidate effect of the discrepancy search.

    Parameters
    ----------
    effect : str
        Effect id.
    parameters : tuple of FitParameter
        Fitted (fleet-wide) parameters: the effect's, paths ``effect.<id>.<field>``, and model
        parameters its law depends on (dotted model paths, e.g. the clearance of an overlap's leakage).
    fixed : dict
        Parameters held at these values [SI].
    grid : tuple of dict
        Start points (values of the effect's fitted parameters, by field name) [SI]; the other
        fitted parameters start at the model's values.
    """

    effect: str
    parameters: tuple
    fixed: dict
    grid: tuple

    def start_values(self, point: dict) -> dict:
        """Effect parameters (fixed + a grid point) by field name [SI]."""
        return {**self.fixed, **point}

    def apply(self, model, values: dict):
        """``model`` with the effect on, ``values`` keyed by :func:`parameter_key` (effect fields by
        field name, model parameters by dotted path) [SI]."""
        out = model.with_effect(self.effect, **{k: v for k, v in values.items() if "." not in k})
        paths = {k: v for k, v in values.items() if "." in k}
        return out.with_parameters(paths) if paths else out

    def is_off(self, values: dict) -> bool:
        """Whether a fit with these values (keyed by :func:`parameter_key`) has its effect switched off:
        every log-scaled effect parameter within one typical change of the lower end of its range
        (those ends lie far below any visible magnitude). Such a fit explains the data through the
        other parameters it fits (an overlap's clearance) or not at all, so it cannot name the effect.
        An effect without a log-scaled parameter is never off."""
        mags = [p for p in self.parameters if p.log and p.path.startswith("effect.")]
        return bool(mags) and all(parameter_key(p.path) in values and
                                  values[parameter_key(p.path)] <= p.lower * math.exp(p.typical) for p in mags)


def parameter_key(path: str) -> str:
    """Report key of a candidate's fitted parameter: the field name of an effect parameter
    (``effect.<id>.<field>``), the dotted path of a model parameter."""
    return path.rsplit(".", 1)[-1] if path.startswith("effect.") else path


def _p(effect: str, name: str, unit: str, typical: float, lower: float, upper: float,
       log: bool = False) -> FitParameter:
    return FitParameter(f"effect.{effect}.{name}", unit, typical, lower=lower, upper=upper, log=log)


def candidates(stroke_m: float = 0.06) -> dict[str, EffectCandidate]:
    """The candidate library, keyed by effect id (see the module docstring).

    Parameters
    ----------
    stroke_m : float, default=0.06
        Cylinder stroke [m] (search range of the load-stiffness reference).
    """
    mid = 0.5 * stroke_m
    return {
        "spool_overlap": EffectCandidate(
            "spool_overlap", (_p("spool_overlap", "overlap_m", "m", 0.3, 1e-7, 1e-4, log=True),
                              FitParameter("servovalve.radial_clearance_m", "m", 0.3, lower=5e-7, upper=3e-5,
                                           log=True)), {},
            tuple({"overlap_m": v} for v in (2e-6, 8e-6, 3e-5))),
        "spool_flow_force": EffectCandidate(
            "spool_flow_force", (_p("spool_flow_force", "stiffness_ratio", "-", 0.3, 1e-3, 3.0, log=True),
                                 _p("spool_flow_force", "command_limit_ratio", "-", 0.1, 1.0, 3.0)), {},
            tuple({"stiffness_ratio": v, "command_limit_ratio": r} for r in (1.05, 2.5) for v in (0.03, 0.15, 0.6))),
        "rod_friction": EffectCandidate(
            "rod_friction", (_p("rod_friction", "coulomb_n", "N", 0.3, 1.0, 5000.0, log=True),
                             _p("rod_friction", "static_ratio", "-", 0.1, 1.0, 3.0)),
            {"stribeck_velocity_m_s": 0.002, "viscous_n_s_m": 0.0},
            tuple({"coulomb_n": v, "static_ratio": 1.5} for v in (40.0, 150.0, 500.0))),
        "lvdt_lag": EffectCandidate(
            "lvdt_lag", (_p("lvdt_lag", "time_constant_s", "s", 0.3, 1e-4, 0.5, log=True),), {},
            tuple({"time_constant_s": v} for v in (0.003, 0.012, 0.05))),
        "load_stiffness": EffectCandidate(
            "load_stiffness", (_p("load_stiffness", "stiffness_n_m", "N/m", 1e4, -5e5, 5e5),
                               _p("load_stiffness", "reference_m", "m", 0.005, 0.0, stroke_m)), {},
            tuple({"stiffness_n_m": v, "reference_m": mid} for v in (-8e4, -2e4, 2e4, 8e4))),
        "current_driver_lag": EffectCandidate(
            "current_driver_lag", (_p("current_driver_lag", "time_constant_s", "s", 0.3, 1e-4, 0.5, log=True),), {},
            tuple({"time_constant_s": v} for v in (0.003, 0.012, 0.05))),
        "torque_motor_hysteresis": EffectCandidate(
            "torque_motor_hysteresis", (_p("torque_motor_hysteresis", "width_a", "A", 0.3, 1e-6, 5e-3, log=True),), {},
            tuple({"width_a": v} for v in (3e-5, 1.5e-4, 6e-4))),
        "viscosity_temperature": EffectCandidate(
            "viscosity_temperature", (_p("viscosity_temperature", "leak_at_20c_m3_s_pa", "m3/(s Pa)", 0.3, 1e-15,
                                         1e-9, log=True),), {"slope_per_degc": 0.02},
            tuple({"leak_at_20c_m3_s_pa": v} for v in (1e-13, 1e-12, 1e-11))),
    }


def get_candidates(ids, stroke_m: float = 0.06) -> list[EffectCandidate]:
    """Candidates by id, in the given order.

    Raises
    ------
    UnknownNameError
        An unknown effect id.
    """
    lib = candidates(stroke_m)
    out = []
    for i in ids:
        if i not in lib:
            raise UnknownNameError(f"Unknown candidate effect '{i}'. Allowed: {', '.join(EFFECT_IDS)}.")
        out.append(lib[i])
    return out


assert set(candidates()) == set(EFFECT_IDS), "every effect of the library is a candidate"
