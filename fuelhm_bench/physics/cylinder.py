"""Double-acting single-rod cylinder with cooling diaphragm, internal leakage and load.

Chamber 1 is the head side (area A1), chamber 2 the rod side (area A2 < A1).
Positive velocity is extension (shaft outlet). The cylinder is treated
**quasi-statically**: the hydraulic resonance (``sqrt(beta*A^2/(V*m))`` is
several hundred Hz here) is far above the 100 Hz frame, so compressibility and
inertia are dropped and, at each instant, continuity and force balance give::

    Q_PA - Q_AT - A1*v - Q_c - Q_li = 0
    Q_PB - Q_BT + A2*v + Q_c + Q_li = 0
    p1*A1 - p2*A2 = F                         (F: load + rod friction)

with the cooling flow ``Q_c = gamma*Cd_c*A_c*sqrt(2/rho)*reg_sqrt(p1 - p2)`` and
the laminar seal leakage ``Q_li = K_li*(p1 - p2)``. Eliminating ``p2`` and ``v``
leaves one equation ``r(p1) = 0`` in the head pressure, with ``r`` strictly
decreasing, solved by safeguarded Newton (:func:`velocity_direct`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba

from fuelhm_bench.errors import range_error
from fuelhm_bench.physics._validation import NON_NEGATIVE, POSITIVE, UNIT_INTERVAL, check_fields
from fuelhm_bench.physics.fluid import orifice_flow
from fuelhm_bench.physics.servovalve import effective_opening, rounded_opening, slot_area


@dataclass(frozen=True)
class CylinderParams:
    """Cylinder, cooling diaphragm and internal leakage.

    Parameters
    ----------
    bore_m : float, default=0.040
        Piston diameter [m].
    rod_m : float, default=0.020
        Rod diameter [m].
    stroke_m : float, default=0.060
        Stroke [m]; the rod position is in [0, stroke].
    diaphragm_diameter_m : float, default=3e-4
        Cooling diaphragm orifice diameter [m].
    diaphragm_discharge_coefficient : float, default=0.7
        Cd of the cooling diaphragm [-].
    diaphragm_open_fraction : float, default=1.0
        gamma in [0, 1]: 1 clean, 0 fully clogged (degradation).
    leakage_coefficient_m3_s_pa : float, default=0.0
        Laminar seal leakage K_li [m^3/(s Pa)] (0 healthy; degradation up to 1e-11).
    """

    bore_m: float = 0.040
    rod_m: float = 0.020
    stroke_m: float = 0.060
    diaphragm_diameter_m: float = 3e-4
    diaphragm_discharge_coefficient: float = 0.7
    diaphragm_open_fraction: float = 1.0
    leakage_coefficient_m3_s_pa: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, {
            "bore_m": POSITIVE,
            "rod_m": POSITIVE,
            "stroke_m": POSITIVE,
            "diaphragm_diameter_m": NON_NEGATIVE,
            "diaphragm_discharge_coefficient": (0.0, 1.0, False),
            "diaphragm_open_fraction": UNIT_INTERVAL,
            "leakage_coefficient_m3_s_pa": (0.0, 1e-9, True),
        })
        if self.rod_m >= self.bore_m:
            raise range_error("CylinderParams.rod_m", f"< bore_m ({self.bore_m:g})", self.rod_m)

    @property
    def head_area_m2(self) -> float:
        """Head-side piston area A1 [m^2]."""
        return math.pi / 4.0 * self.bore_m ** 2

    @property
    def rod_area_m2(self) -> float:
        """Rod-side annulus area A2 [m^2]."""
        return math.pi / 4.0 * (self.bore_m ** 2 - self.rod_m ** 2)

    @property
    def diaphragm_area_m2(self) -> float:
        """Cooling diaphragm orifice area [m^2]."""
        return math.pi / 4.0 * self.diaphragm_diameter_m ** 2


@dataclass(frozen=True)
class LoadParams:
    """External (aerodynamic) load on the rod.

    ``F_load = aero_force_at_100pct_n * (N2/100 %)**2`` opposing extension
    (positive force resists positive velocity).

    Parameters
    ----------
    aero_force_at_100pct_n : float, default=500.0
        Aerodynamic load at 100 % N2 [N].
    """

    aero_force_at_100pct_n: float = 500.0

    def __post_init__(self) -> None:
        check_fields(self, {"aero_force_at_100pct_n": (-2e4, 2e4, True)})


# Layout of the valve/cylinder coefficient vector used by the numba kernels.
# (Indices are internal; build the vector with physics.kernel.pack_model.)
C_W_NULL, C_W_OUT, C_O_A, C_O_B, C_H, C_LAP, C_CDV, C_ALPHA = 0, 1, 2, 3, 4, 5, 6, 7
C_A1, C_A2, C_CQC, C_KLI, C_PR, C_PCR = 8, 9, 10, 11, 12, 13
C_RC = 14  # corner radius of the spool lands [m]
C_N = 15


@numba.njit(cache=True)
def metering_coefficients(x_s: float, c) -> tuple[float, float, float, float, float, float, float, float]:
    """Flow coefficients ``alpha*Cd*A*sqrt(2/rho)`` of the four edges and their x_s-derivatives.

    ``alpha`` (``c[C_ALPHA]``) is a main-stage flow factor, 1 in every model here: the
    inlet filter feeds only the pilot stage. The derivatives neglect the slope of the
    corner-rounding advance (the quasi-static solver does not use them).

    Returns (k_pa, k_at, k_pb, k_bt, dk_pa, dk_at, dk_pb, dk_bt).
    """
    h = c[C_H]
    lap = c[C_LAP]
    kc = c[C_CDV] * c[C_ALPHA]
    rc = c[C_RC]
    r_pos = rounded_opening(x_s - lap, rc)
    r_neg = rounded_opening(-x_s - lap, rc)
    o_pos = effective_opening(r_pos, h)
    o_neg = effective_opening(r_neg, h)
    a_pos, da_pos = slot_area(o_pos, c[C_W_NULL], c[C_W_OUT], c[C_O_A], c[C_O_B])
    a_neg, da_neg = slot_area(o_neg, c[C_W_NULL], c[C_W_OUT], c[C_O_A], c[C_O_B])
    # d o_eff / d o = logistic(o/h)
    s_pos = 1.0 / (1.0 + math.exp(-r_pos / h))
    s_neg = 1.0 / (1.0 + math.exp(-r_neg / h))
    k_pos = kc * a_pos
    k_neg = kc * a_neg
    dk_pos = kc * da_pos * s_pos
    dk_neg = -kc * da_neg * s_neg
    # P->A and B->T open with +x_s; A->T and P->B with -x_s.
    return k_pos, k_neg, k_neg, k_pos, dk_pos, dk_neg, dk_neg, dk_pos


@numba.njit(cache=True)
def _residual(p1: float, k_pa: float, k_at: float, k_pb: float, k_bt: float,
              ps: float, force: float, c) -> tuple[float, float, float]:
    """r(p1) = v1 - v2, its derivative, and the velocity (v1+v2)/2 [m/s]."""
    a1 = c[C_A1]
    a2 = c[C_A2]
    pr = c[C_PR]
    pcr = c[C_PCR]
    p2 = (p1 * a1 - force) / a2
    dp2 = a1 / a2
    q_pa, g_pa = orifice_flow(k_pa, ps - p1, pcr)
    q_at, g_at = orifice_flow(k_at, p1 - pr, pcr)
    q_pb, g_pb = orifice_flow(k_pb, ps - p2, pcr)
    q_bt, g_bt = orifice_flow(k_bt, p2 - pr, pcr)
    d12 = p1 - p2
    dd12 = 1.0 - dp2
    q_c, g_c = orifice_flow(c[C_CQC], d12, pcr)
    q_l = c[C_KLI] * d12
    q_x = q_c + q_l
    g_x = (g_c + c[C_KLI]) * dd12
    v1 = (q_pa - q_at - q_x) / a1
    v2 = (q_bt - q_pb - q_x) / a2
    dv1 = (-g_pa - g_at - g_x) / a1
    dv2 = (g_bt * dp2 + g_pb * dp2 - g_x) / a2
    return v1 - v2, dv1 - dv2, 0.5 * (v1 + v2)


@numba.njit(cache=True)
def velocity_direct(x_s: float, dps: float, force: float, p1_guess: float, c) -> tuple[float, float]:
    """Quasi-static rod velocity [m/s] for a spool position, supply rise and rod force.

    Parameters
    ----------
    x_s : float
        Spool position [m].
    dps : float
        Supply pressure rise above return [Pa].
    force : float
        Force resisting extension [N] (load + friction).
    p1_guess : float
        Warm start for the head pressure [Pa]; NaN for a cold start.
    c : ndarray
        Coefficient vector (see ``pack_model``).

    Returns
    -------
    v : float
        Rod velocity [m/s].
    p1 : float
        Head pressure at the solution [Pa] (use as the next warm start).
    """
    k_pa, k_at, k_pb, k_bt, _, _, _, _ = metering_coefficients(x_s, c)
    return velocity_metered(k_pa, k_at, k_pb, k_bt, dps, force, p1_guess, c)


@numba.njit(cache=True)
def velocity_metered(k_pa: float, k_at: float, k_pb: float, k_bt: float, dps: float, force: float,
                     p1_guess: float, c) -> tuple[float, float]:
    """:func:`velocity_direct` for the metering coefficients of a spool position (``metering_coefficients``).

    Lets a caller that solves several rod forces at one spool position (the rod friction's root
    search) compute the coefficients once.
    """
    pr = c[C_PR]
    ps = pr + dps
    a1 = c[C_A1]
    a2 = c[C_A2]
    # Bracket: r is strictly decreasing in p1.
    span = dps + abs(force) / a2 + 1e5
    lo = pr - span
    hi = ps + span
    p1 = p1_guess
    if not (p1 > lo and p1 < hi):
        p1 = 0.5 * (pr + ps) + 0.5 * force / a1
    tol = 1e-7 * (dps + 1e5)
    r, dr, v = _residual(p1, k_pa, k_at, k_pb, k_bt, ps, force, c)
    for _ in range(100):
        if r > 0.0:
            lo = p1
        else:
            hi = p1
        step = -r / dr if dr < 0.0 else 0.0
        p_new = p1 + step
        if not (p_new > lo and p_new < hi) or dr >= 0.0:
            p_new = 0.5 * (lo + hi)
        if abs(p_new - p1) < tol:
            p1 = p_new
            r, dr, v = _residual(p1, k_pa, k_at, k_pb, k_bt, ps, force, c)
            break
        p1 = p_new
        r, dr, v = _residual(p1, k_pa, k_at, k_pb, k_bt, ps, force, c)
    return v, p1
