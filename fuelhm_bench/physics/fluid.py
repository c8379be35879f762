"""Fuel (the hydraulic fluid), the hydraulic supply, and orifice flow.

The orifice law is the turbulent (Merritt) law with a regularised square root,
so its slope is finite at zero pressure drop:

    Q = Cd * A * sqrt(2 / rho) * dp / (dp**2 + p_cr**2) ** (1/4)        [m^3/s]

which tends to ``Cd*A*sqrt(2|dp|/rho)*sign(dp)`` for ``|dp| >> p_cr``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba

from fuelhm_bench.physics._validation import NON_NEGATIVE, POSITIVE, check_fields


@dataclass(frozen=True)
class FluidParams:
    """Fuel properties and the hydraulic supply of the actuation loop.

    Parameters
    ----------
    density_kg_m3 : float, default=800.0
        Fuel density [kg/m^3] (Jet A-1: 775-840).
    return_pressure_pa : float, default=2e5
        Return (tank) pressure [Pa].
    supply_rise_at_100pct_pa : float, default=1.03e7
        Supply pressure rise above return at 100 % N2 [Pa]. The HP pump makes
        the rise scale with the square of engine speed:
        ``dp_s = supply_rise_at_100pct_pa * (N2 / 100 %)**2`` (17 bar at 40 %
        relight speed, 70 bar at 82 % cruise, 103 bar at 100 % take-off).
    regularisation_pressure_pa : float, default=5e4
        ``p_cr`` of the regularised square root of the orifice law [Pa].
    """

    density_kg_m3: float = 800.0
    return_pressure_pa: float = 2e5
    supply_rise_at_100pct_pa: float = 1.03e7
    regularisation_pressure_pa: float = 5e4

    def __post_init__(self) -> None:
        check_fields(self, {
            "density_kg_m3": POSITIVE,
            "return_pressure_pa": NON_NEGATIVE,
            "supply_rise_at_100pct_pa": POSITIVE,
            "regularisation_pressure_pa": POSITIVE,
        })

    @property
    def flow_constant(self) -> float:
        """``sqrt(2 / rho)`` [m^1.5 kg^-0.5]."""
        return math.sqrt(2.0 / self.density_kg_m3)

    def supply_rise_pa(self, n2_frac: float) -> float:
        """Supply pressure rise above return [Pa] at engine speed ``n2_frac`` (1.0 = 100 %)."""
        return self.supply_rise_at_100pct_pa * n2_frac * n2_frac


@numba.njit(cache=True, inline="always")
def orifice_flow(coef_area: float, dp: float, p_cr: float) -> tuple[float, float]:
    """Regularised turbulent orifice flow and its derivative.

    Parameters
    ----------
    coef_area : float
        ``Cd * A * sqrt(2/rho)`` [m^3/s per sqrt(Pa)].
    dp : float
        Pressure drop across the orifice [Pa] (positive: flow in the positive direction).
    p_cr : float
        Regularisation pressure [Pa].

    Returns
    -------
    q : float
        Flow [m^3/s].
    dq_ddp : float
        Derivative of the flow with respect to ``dp`` [m^3/(s Pa)].
    """
    s = dp * dp + p_cr * p_cr
    r = s ** -0.25
    q = coef_area * dp * r
    dq = coef_area * r * (0.5 * dp * dp + p_cr * p_cr) / s
    return q, dq
