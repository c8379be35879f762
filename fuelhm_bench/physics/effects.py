"""Optional physical effects that a nominal model omits (docs/physics.md §7 Optional effects).

Each effect is a frozen dataclass with its parameters (SI units in the names)
and their allowed ranges, registered under a stable id. A model holds a tuple of
enabled effects; ``LoopModel.with_effect("rod_friction", coulomb_n=200.0)``
returns a new model with the effect switched on, which is how the
model-discrepancy workflow adds one candidate effect, fits its parameters and
simulates again.

======================  =====================================================
id                      equation
======================  =====================================================
``spool_overlap``       openings ``o = +/-x_s - u``, ``u = overlap_m > 0``
``spool_flow_force``    steady flow force acts as a centring spring on the spool:
                        ``x_c <- x_c / (1 + k_r * dp_e/70 bar * w(|x_c|)/w_null)``,
                        ``dp_e = dp_s - sgn(x_c) (p1 - p2)`` the summed drops of
                        the two open metering edges (frame-start pressures);
                        ``x_c`` first clipped at +/- r x stroke when
                        ``command_limit_ratio`` r > 0
``rod_friction``        ``F = [F_c + (F_s - F_c) exp(-(v/v_s)^2)] sgn v + b v`` on the rod,
                        with stiction (the rod stays still while the available
                        force is within +/-F_s)
``lvdt_lag``            extra first-order lag ``tau`` on the measured position
``load_stiffness``      ``F_L += k_x (x - x_ref)`` position-dependent load
``current_driver_lag``  coil current lags the recorded command:
                        ``tau di_coil/dt = i_cmd - i_coil`` (the spool sees its
                        exact mean over each frame)
``torque_motor_``       play (backlash operator) of full width ``h`` between the
``hysteresis``          coil current and the torque-motor torque (magnetic
                        hysteresis of the armature): the spool command follows
                        ``i_p = clip(i_p, i - h/2, i + h/2)``
``viscosity_``          laminar cross-piston leak through the seal clearance,
``temperature``         inversely proportional to the fuel viscosity
                        ``mu(T) = mu_20 exp(-b (T - 20 degC))``:
                        ``K_li += K_20 exp(b (T - 20))``, T the flight's
                        ``fuel_temp_degC`` (20 degC when the data have none)
======================  =====================================================
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

from fuelhm_bench.errors import ParameterError, UnknownNameError, range_error
from fuelhm_bench.physics._validation import NON_NEGATIVE, check_fields
from fuelhm_bench.taxonomy import EFFECT_IDS


@dataclass(frozen=True)
class SpoolOverlap:
    """Spool lands overlap the ports at null.

    Parameters
    ----------
    overlap_m : float, default=1.5e-5
        Lap u [m], in (0, 1e-4].
    """

    id: ClassVar[str] = "spool_overlap"
    overlap_m: float = 1.5e-5

    def __post_init__(self) -> None:
        check_fields(self, {"overlap_m": (0.0, 1e-4, False)})


@dataclass(frozen=True)
class SpoolFlowForce:
    """Steady (Bernoulli) flow force on the spool, a pressure-dependent centring spring.

    The force of each open metering edge is proportional to its opening and to its own
    pressure drop (Merritt, *Hydraulic Control Systems*, chapter 5); the two open edges' drops sum
    to ``dp_s - sgn(x_c) (p1 - p2)`` (docs/physics.md §7).

    Where the torque motor's authority ends decides what the flow force does at a saturated
    current: with no command limit (the default), the command may exceed the spool stroke, and the
    reduced command still drives the spool onto its stop, so the saturation flow is unchanged; with
    ``command_limit_ratio`` = r >= 1, the command is clipped at +/- r x stroke *before* the flow force
    acts (the pilot stage cannot push the spool further than that against its feedback spring), so
    at saturation the spool stops short of the stroke and the saturation flow falls with the flow
    force too.

    Parameters
    ----------
    stiffness_ratio : float, default=0.25
        Flow-force stiffness over feedback stiffness at 70 bar of summed edge drop and null slot
        width [-], in (0, 3].
    command_limit_ratio : float, default=0.0
        Torque-motor command limit over the spool stroke [-]: 0 (no limit) or in [1, 10].
    """

    id: ClassVar[str] = "spool_flow_force"
    stiffness_ratio: float = 0.25
    command_limit_ratio: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, {"stiffness_ratio": (0.0, 3.0, False), "command_limit_ratio": (0.0, 10.0, True)})
        if 0.0 < self.command_limit_ratio < 1.0:
            raise range_error("SpoolFlowForce.command_limit_ratio", "0 (no limit) or in [1, 10]",
                              self.command_limit_ratio)


@dataclass(frozen=True)
class RodFriction:
    """Coulomb + Stribeck + viscous friction on the rod seals and linkage.

    Parameters
    ----------
    coulomb_n : float, default=150.0
        Coulomb force F_c [N], in (0, 5000].
    static_ratio : float, default=1.5
        F_s / F_c [-], in [1, 3].
    stribeck_velocity_m_s : float, default=0.002
        Stribeck velocity v_s [m/s], in (0, 0.1].
    viscous_n_s_m : float, default=0.0
        Viscous coefficient b [N s/m], in [0, 1e5].
    """

    id: ClassVar[str] = "rod_friction"
    coulomb_n: float = 150.0
    static_ratio: float = 1.5
    stribeck_velocity_m_s: float = 0.002
    viscous_n_s_m: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, {
            "coulomb_n": (0.0, 5000.0, False),
            "static_ratio": (1.0, 3.0, True),
            "stribeck_velocity_m_s": (0.0, 0.1, False),
            "viscous_n_s_m": (0.0, 1e5, True),
        })


@dataclass(frozen=True)
class LvdtLag:
    """Extra first-order lag of the LVDT demodulation.

    Parameters
    ----------
    time_constant_s : float, default=0.02
        Lag time constant tau [s], in (0, 0.5].
    """

    id: ClassVar[str] = "lvdt_lag"
    time_constant_s: float = 0.02

    def __post_init__(self) -> None:
        check_fields(self, {"time_constant_s": (0.0, 0.5, False)})


@dataclass(frozen=True)
class LoadStiffness:
    """Position-dependent (spring-like) load.

    Parameters
    ----------
    stiffness_n_m : float, default=4e4
        k_x [N/m], in [-5e5, 5e5] (positive pushes back towards ``reference_m``).
    reference_m : float, default=0.0
        Position of zero spring force [m], in [0, 1].
    """

    id: ClassVar[str] = "load_stiffness"
    stiffness_n_m: float = 4e4
    reference_m: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, {"stiffness_n_m": (-5e5, 5e5, True), "reference_m": (0.0, 1.0, True)})


@dataclass(frozen=True)
class CurrentDriverLag:
    """First-order lag of the coil current behind the commanded (recorded) current.

    The current driver (a voltage amplifier driving the coil inductance) follows the
    command with a time constant ``L / R``; the recorded current is the command.

    Parameters
    ----------
    time_constant_s : float, default=0.02
        Lag time constant tau [s], in (0, 0.5].
    """

    id: ClassVar[str] = "current_driver_lag"
    time_constant_s: float = 0.02

    def __post_init__(self) -> None:
        check_fields(self, {"time_constant_s": (0.0, 0.5, False)})


@dataclass(frozen=True)
class TorqueMotorHysteresis:
    """Magnetic hysteresis of the torque motor, as a play on the coil current.

    Parameters
    ----------
    width_a : float, default=2e-4
        Full width h of the play [A], in (0, 5e-3].
    """

    id: ClassVar[str] = "torque_motor_hysteresis"
    width_a: float = 2e-4

    def __post_init__(self) -> None:
        check_fields(self, {"width_a": (0.0, 5e-3, False)})


@dataclass(frozen=True)
class ViscosityTemperature:
    """Laminar cross-piston leak whose conductance follows the fuel viscosity with temperature.

    Parameters
    ----------
    leak_at_20c_m3_s_pa : float, default=1e-12
        Leak conductance at 20 degC K_20 [m^3/(s Pa)], in (0, 1e-9].
    slope_per_degc : float, default=0.02
        Viscosity temperature coefficient b [1/degC], in [0, 0.1] (kerosene: about 0.02).
    """

    id: ClassVar[str] = "viscosity_temperature"
    leak_at_20c_m3_s_pa: float = 1e-12
    slope_per_degc: float = 0.02

    def __post_init__(self) -> None:
        check_fields(self, {"leak_at_20c_m3_s_pa": (0.0, 1e-9, False), "slope_per_degc": (0.0, 0.1, True)})

    def leak_coefficient(self, temp_degc: float) -> float:
        """Leak conductance at a fuel temperature [m^3/(s Pa)]."""
        import math

        return self.leak_at_20c_m3_s_pa * math.exp(self.slope_per_degc * (temp_degc - 20.0))


Effect = (SpoolOverlap | SpoolFlowForce | RodFriction | LvdtLag | LoadStiffness | CurrentDriverLag
          | TorqueMotorHysteresis | ViscosityTemperature)

EFFECTS: dict[str, type] = {cls.id: cls for cls in (SpoolOverlap, SpoolFlowForce, RodFriction, LvdtLag, LoadStiffness,
                                                    CurrentDriverLag, TorqueMotorHysteresis, ViscosityTemperature)}
assert tuple(EFFECTS) == EFFECT_IDS


def _suggest(name: str, options) -> str:
    from fuelhm_bench.errors import did_you_mean

    return did_you_mean(name, options)


def make_effect(effect_id: str, **params: float) -> Effect:
    """Build an effect by id with (a subset of) its parameters.

    Parameters
    ----------
    effect_id : str
        One of :data:`fuelhm_bench.taxonomy.EFFECT_IDS`.
    **params : float
        Parameter overrides; unknown names are rejected.

    Raises
    ------
    UnknownNameError
        Unknown effect id or parameter name.
    ParameterError
        A parameter out of its range.
    """
    if effect_id not in EFFECTS:
        raise UnknownNameError(
            f"Unknown effect id '{effect_id}'. Allowed: {', '.join(EFFECT_IDS)}.{_suggest(effect_id, EFFECTS)}")
    cls = EFFECTS[effect_id]
    names = [f.name for f in dataclasses.fields(cls)]
    for key in params:
        if key not in names:
            raise UnknownNameError(
                f"Unknown parameter '{key}' for effect '{effect_id}'. Allowed: {', '.join(names)}.{_suggest(key, names)}")
    try:
        return cls(**{k: float(v) for k, v in params.items()})
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ParameterError):
            raise
        raise ParameterError(f"Effect '{effect_id}': {exc}") from None


def effect_parameters(effect: Effect) -> dict[str, float]:
    """Parameters of an effect as a plain dict."""
    return {f.name: getattr(effect, f.name) for f in dataclasses.fields(effect)}


def parse_effect_spec(spec: str) -> Effect:
    """Parse a CLI spec ``ID[:PARAM=VALUE,...]`` into an effect.

    Examples
    --------
    >>> parse_effect_spec("rod_friction:coulomb_n=200")
    RodFriction(coulomb_n=200.0, static_ratio=1.5, stribeck_velocity_m_s=0.002, viscous_n_s_m=0.0)
    """
    effect_id, _, rest = spec.partition(":")
    params: dict[str, float] = {}
    if rest:
        for item in rest.split(","):
            key, eq, value = item.partition("=")
            if not eq:
                raise ParameterError(f"Effect spec '{spec}': expected PARAM=VALUE, got '{item}'.")
            try:
                params[key.strip()] = float(value)
            except ValueError:
                raise ParameterError(
                    f"Effect spec '{spec}': the value of '{key.strip()}' must be a number. Got '{value}' instead.") from None
    return make_effect(effect_id.strip(), **params)


__all__ = ["CurrentDriverLag", "EFFECTS", "Effect", "TorqueMotorHysteresis", "ViscosityTemperature", "LoadStiffness", "LvdtLag", "RodFriction", "SpoolFlowForce", "SpoolOverlap",
           "effect_parameters", "make_effect", "parse_effect_spec", "NON_NEGATIVE"]
