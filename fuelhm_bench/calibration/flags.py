"""Recalibrated parameters that likely absorb a missing effect.

A unit's recalibrated value far outside the population's manufacturing dispersion
(:class:`~fuelhm_bench.physics.model.Dispersion`) is not a manufacturing offset: the fit
bent that parameter to mimic something the model lacks (a flow force narrowing the outer
slot width, a supply droop inflating the aerodynamic load, ...). A health tracker reading
such a value would report a degradation that is not there. :func:`absorbing_parameters`
flags every (unit, parameter) whose deviation from the input model exceeds ``z_max``
standard deviations of the dispersion (3 by default: the dispersion is truncated there).
Parameters without a dispersion (the width transition) are never flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fuelhm_bench.physics.model import Dispersion

#: Deviation [dispersion sigmas] beyond which a recalibrated value is flagged.
Z_MAX = 3.0

#: Additive dispersions that shift the same feature of the curve as the parameter (the driver's
#: offset moves the null bias seen from the recorded current).
_ALIASED_ADDITIVE = {"servovalve.null_bias_a": ("driver.offset_a",)}


@dataclass(frozen=True)
class ParameterFlag:
    """One recalibrated value outside the manufacturing dispersion.

    Attributes
    ----------
    unit : object
        Unit key.
    path : str
        Parameter path.
    value, nominal : float
        Recalibrated and input-model values [SI].
    sigma : float
        Dispersion standard deviation at the nominal value [SI].
    z : float
        ``(value - nominal) / sigma`` [-].
    """

    unit: object
    path: str
    value: float
    nominal: float
    sigma: float
    z: float

    def as_json(self) -> dict:
        """JSON-ready summary."""
        return {"unit": self.unit, "parameter": self.path, "value": self.value, "nominal": self.nominal,
                "sigma": self.sigma, "z": self.z, "reading": "likely absorbing a missing effect"}


def dispersion_sigma(model, path: str, dispersion: Dispersion = Dispersion()) -> float | None:
    """Standard deviation of ``path`` over the manufactured population [SI] (None: not dispersed)."""
    rel = dict(dispersion.relative)
    add = dict(dispersion.additive)
    if path in rel:
        return abs(model.get(path)) * rel[path] * dispersion.scale
    if path in add:
        var = add[path] ** 2 + sum(add.get(a, 0.0) ** 2 for a in _ALIASED_ADDITIVE.get(path, ()))
        return math.sqrt(var) * dispersion.scale
    return None


def absorbing_parameters(unit_values: dict, nominal_model, *, dispersion: Dispersion = Dispersion(),
                         z_max: float = Z_MAX) -> tuple[ParameterFlag, ...]:
    """Flag the recalibrated values outside ``z_max`` dispersion sigmas of the input model.

    Parameters
    ----------
    unit_values : dict
        Unit key -> {parameter path: recalibrated value} [SI].
    nominal_model : LoopModel
        The input model (the population's centre).
    dispersion : Dispersion
        Manufacturing dispersion of the population.
    z_max : float, default=3.0
        Threshold [sigmas].

    Returns
    -------
    tuple of ParameterFlag
        By decreasing ``|z|``.
    """
    flags = []
    for unit, values in unit_values.items():
        for path, value in values.items():
            sigma = dispersion_sigma(nominal_model, path, dispersion)
            if not sigma:
                continue
            nominal = nominal_model.get(path)
            z = (float(value) - nominal) / sigma
            if abs(z) > z_max:
                flags.append(ParameterFlag(unit, path, float(value), nominal, sigma, z))
    return tuple(sorted(flags, key=lambda f: -abs(f.z)))


#: Units of a fleet (at most all of them) whose values of one parameter must lie beyond the threshold
#: for :func:`fleet_wide` to keep that parameter's flags.
MIN_FLAGGED_UNITS = 2


def fleet_wide(flags, n_units: int, min_units: int = MIN_FLAGGED_UNITS) -> tuple[ParameterFlag, ...]:
    """The flags of the parameters flagged in at least ``min(min_units, n_units)`` units.

    A missing effect acts on every unit of the fleet, so the parameter that absorbs it moves in
    most units (a flow force narrows every unit's outer slot; a supply droop inflates every unit's
    load). One unit's value beyond the threshold is that unit's oddity: a manufacturing outlier or
    an estimate from little data, more likely the more units and parameters are fitted (12 units
    of one flight: 96 values). Such a flag stays a flag; it is not evidence of a fleet-wide
    disagreement. With one unit, its flags are kept.

    Parameters
    ----------
    flags : sequence of ParameterFlag
        From :func:`absorbing_parameters`.
    n_units : int
        Units of the fit.
    min_units : int, default=MIN_FLAGGED_UNITS
        Units needed per parameter.

    Returns
    -------
    tuple of ParameterFlag
        The kept flags, in their order.
    """
    need = max(1, min(int(min_units), int(n_units)))
    units_by_path: dict = {}
    for f in flags:
        units_by_path.setdefault(f.path, set()).add(f.unit)
    return tuple(f for f in flags if len(units_by_path[f.path]) >= need)


def within_dispersion(parameters, nominal_model, z: float, *, dispersion: Dispersion = Dispersion()) -> tuple:
    """The fit parameters with their limits narrowed to ``z`` dispersion sigmas around the input model.

    A fit with these parameters cannot absorb a missing effect into values that no manufactured
    unit has (the *plausible* recalibration); parameters without a dispersion keep their limits.

    Parameters
    ----------
    parameters : sequence of FitParameter
        Fit parameters (their ``lower``/``upper`` are intersected with the dispersion band).
    nominal_model : LoopModel
        The input model (the population's centre).
    z : float
        Half-width of the band [sigmas], > 0.
    dispersion : Dispersion
        Manufacturing dispersion of the population.
    """
    import dataclasses

    from fuelhm_bench.errors import range_error

    if not (isinstance(z, (int, float)) and math.isfinite(z) and z > 0):
        raise range_error("within_dispersion z", "a finite number of sigmas > 0", z)
    out = []
    for p in parameters:
        sigma = dispersion_sigma(nominal_model, p.path, dispersion)
        if not sigma:
            out.append(p)
            continue
        centre = float(nominal_model.get(p.path))
        lo, hi = max(p.lower, centre - z * sigma), min(p.upper, centre + z * sigma)
        if p.log:
            lo = max(lo, p.lower, 1e-300)
        out.append(dataclasses.replace(p, lower=lo, upper=hi))
    return tuple(out)


def at_limit(unit_values: dict, parameters, *, rel: float = 1e-3) -> tuple:
    """(unit, path) pairs whose value sits at a limit of its (narrowed) fit parameter."""
    hits = []
    for unit, values in unit_values.items():
        for p in parameters:
            if p.path not in values or not (math.isfinite(p.lower) and math.isfinite(p.upper)):
                continue
            tol = rel * (p.upper - p.lower)
            v = float(values[p.path])
            if v <= p.lower + tol or v >= p.upper - tol:
                hits.append((unit, p.path))
    return tuple(hits)


__all__ = ["MIN_FLAGGED_UNITS", "ParameterFlag", "Z_MAX", "absorbing_parameters", "at_limit", "dispersion_sigma",
           "fleet_wide", "within_dispersion"]
