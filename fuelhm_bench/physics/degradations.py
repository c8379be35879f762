"""The seven degradation modes of the paper's Table III, as physical mechanisms.

Each mode has a scalar intensity ``f`` in [0, 1] mapped to one physical
parameter of the element that degrades, relative to that unit's own healthy
value (so the manufacturing dispersion is kept). Several modes can act at once.
Mechanisms, sources and the criterion behind each maximum: docs/physics.md
§6 Degradation modes.

=========================  ================================  ===============  ==========================================
mode                       parameter                         law              healthy -> f = 1
=========================  ================================  ===============  ==========================================
``filter_contamination``   ``pilot_supply_fraction``         multiplicative   x (1 - 0.75 f): 1 -> 0.25 (spool rate / 2)
``null_bias_drift``        ``null_bias_drift_a``             additive         + 1.6 mA f (20 % of the 8 mA rated current)
``backlash``               ``feedback_backlash_m``           additive         + 30 um f
``spool_friction``         ``spool_friction_n``              additive         + 9 N f: 1 -> 10 N
``radial_clearance``       ``corner_radius_m``               additive         + 23 um f: h_eff 7 -> 30 um
``internal_leakage``       ``leakage_coefficient_m3_s_pa``   additive         + 1e-12 m^3/(s Pa) f (7 cm^3/s at 70 bar)
``diaphragm_clogging``     ``diaphragm_open_fraction``       multiplicative   x (1 - 0.75 f): 1 -> 0.25
=========================  ================================  ===============  ==========================================

Notes
-----
Filter contamination: the inlet filter feeds the pilot (first) stage only; its
clogging lowers the pilot supply pressure, which slows the spool and weakens
the force that moves it against friction, and leaves the metering flows alone.

Radial clearance: the paper models it as a decrease of the restriction
coefficient at the abraded corners of the spool lands. Erosion rounds the
corners: the rounded edge leaks more (leakage height ``h = clearance + corner
radius``) and starts metering before the geometric edge near null (an
equivalent underlap that fades out a few radii from the edge, so the
full-stroke opening and the saturation velocity are unchanged).

Internal leakage and diaphragm clogging stop at a rejection limit: a seal that
leaks as much as the cooling diaphragm passes (about 7 cm^3/s at 70 bar), and a
cooling flow reduced to a quarter.

The paper says the drift of the null bias is modelled by adding the opposite of
the drift to the control current; adding ``dInb`` to the valve's null bias is
the same equation (``i_eff = i - Inb0 - dInb``). Its sign is fixed positive here so
that the transformation laws are linear in the intensity; a negative drift is the
mirror image. The paper calls clogging "additive" on the restriction
coefficient: with a unit healthy coefficient, ``1 - 0.75 f`` is both.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from fuelhm_bench.errors import UnknownNameError, range_error
from fuelhm_bench.taxonomy import MODE_IDS


@dataclass(frozen=True)
class DegradationLaw:
    """How one mode's intensity changes one parameter.

    Parameters
    ----------
    mode : str
        Mode id.
    component : str
        Name of the component field of :class:`~fuelhm_bench.physics.model.LoopModel`.
    parameter : str
        Field of that component.
    kind : {"additive", "multiplicative"}
        ``additive``: ``p + delta * f``; ``multiplicative``: ``p * (1 + delta * f)``.
    delta : float
        Change at full intensity (SI units of the parameter, or relative for multiplicative).
    description : str
        Human-readable description.
    """

    mode: str
    component: str
    parameter: str
    kind: str
    delta: float
    description: str

    def apply(self, value: float, intensity: float) -> float:
        """Degraded parameter value for a healthy ``value`` and an ``intensity`` in [0, 1]."""
        if self.kind == "additive":
            return value + self.delta * intensity
        return value * (1.0 + self.delta * intensity)


LAWS: dict[str, DegradationLaw] = {law.mode: law for law in (
    DegradationLaw("filter_contamination", "servovalve", "pilot_supply_fraction", "multiplicative", -0.75,
                   "Inlet (pilot-stage) filter contamination: pilot supply pressure x (1 - 0.75 f), so the spool "
                   "rate halves and the force against friction falls to 1/4 at f = 1; metering flows unchanged."),
    DegradationLaw("null_bias_drift", "servovalve", "null_bias_drift_a", "additive", 1.6e-3,
                   "Null-bias drift of the torque motor: + 1.6 mA (20 % of rated current) at f = 1."),
    DegradationLaw("backlash", "servovalve", "feedback_backlash_m", "additive", 30e-6,
                   "Feedback-spring wear: play of the feedback point + 30 um at f = 1."),
    DegradationLaw("spool_friction", "servovalve", "spool_friction_n", "additive", 9.0,
                   "Spool/sleeve friction: Coulomb force + 9 N at f = 1 (1 -> 10 N)."),
    DegradationLaw("radial_clearance", "servovalve", "corner_radius_m", "additive", 23e-6,
                   "Erosion of the spool-land corners: corner radius + 23 um at f = 1, so the leakage "
                   "height grows 7 -> 30 um and the rounded edges meter up to 23 um early near null "
                   "(equivalent underlap), fading out over a few radii (full-stroke opening unchanged)."),
    DegradationLaw("internal_leakage", "cylinder", "leakage_coefficient_m3_s_pa", "additive", 1e-12,
                   "Cylinder seal wear: laminar leakage coefficient + 1e-12 m^3/(s Pa) at f = 1 (7 cm^3/s "
                   "at 70 bar, as much as the cooling diaphragm passes: the rejection limit)."),
    DegradationLaw("diaphragm_clogging", "cylinder", "diaphragm_open_fraction", "multiplicative", -0.75,
                   "Coking of the cooling diaphragm: open fraction x (1 - 0.75 f); at f = 1 a quarter of the "
                   "cooling flow is left (the rejection limit)."),
)}
assert tuple(LAWS) == MODE_IDS


def validate_intensities(intensities: Mapping[str, float], *, where: str = "intensities") -> dict[str, float]:
    """Check mode names and intensity ranges; return a clean ``{mode: float}`` dict.

    Raises
    ------
    UnknownNameError
        For an unknown mode (with a did-you-mean suggestion).
    ParameterError
        For an intensity outside [0, 1] or not a number.
    """
    import math

    from fuelhm_bench.errors import did_you_mean

    clean: dict[str, float] = {}
    for mode, value in intensities.items():
        if mode not in LAWS:
            hint = did_you_mean(str(mode), MODE_IDS)
            raise UnknownNameError(f"Unknown degradation mode '{mode}' in {where}. Allowed: {', '.join(MODE_IDS)}.{hint}")
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise range_error(f"{where}.{mode}", "a number in [0, 1]", value) from None
        if not math.isfinite(f) or not 0.0 <= f <= 1.0:
            raise range_error(f"{where}.{mode}", "in [0, 1]", value)
        clean[mode] = f
    return clean


def degrade(model, intensities: Mapping[str, float]):
    """Return a copy of ``model`` with the given degradation intensities applied.

    Parameters
    ----------
    model : LoopModel
        A healthy (possibly dispersed) unit.
    intensities : mapping of str to float
        ``{mode: intensity}``; missing modes are healthy.

    Returns
    -------
    LoopModel
    """
    clean = validate_intensities(intensities)
    changes: dict[str, dict[str, float]] = {}
    for mode, f in clean.items():
        if f == 0.0:
            continue
        law = LAWS[mode]
        comp = changes.setdefault(law.component, {})
        current = comp.get(law.parameter, getattr(getattr(model, law.component), law.parameter))
        new = law.apply(current, f)
        if law.parameter == "pilot_supply_fraction":
            new = max(new, 1e-3)
        if law.parameter == "diaphragm_open_fraction":
            new = min(max(new, 0.0), 1.0)
        comp[law.parameter] = new
    replaced = {name: dataclasses.replace(getattr(model, name), **fields) for name, fields in changes.items()}
    return dataclasses.replace(model, **replaced) if replaced else model
