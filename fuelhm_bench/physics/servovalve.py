"""Two-stage flapper-nozzle servovalve: inlet filter, spool dynamics, metering edges.

First stage (reduced). With quasi-static pilot pressures the flapper acts as a
flow source on the spool, giving a first-order spool::

    x_c   = K_sv * (i_coil - Inb0 - dInb)                 torque-motor command [m]
    e     = x_c - x_fb                                     feedback-spring error [m]
    dx_s/dt = (sqrt(beta_p) / tau_s) * dz(e, d_f)          spool velocity [m/s], |x_s| <= stroke

``x_fb`` is the feedback-spring attachment point. It follows the spool through a
play operator of width ``b`` (backlash): it moves only when ``|x_s - x_fb|``
reaches ``b/2``. ``dz`` is a dead zone of half-width ``d_f = F_c / k_d`` that
models Coulomb friction between spool and sleeve: the spool sticks while the
hydraulic drive force ``k_d * |e|`` is below the friction force ``F_c``; the drive
stiffness ``k_d = beta_p * A_end * dp_s / e_span`` scales with the pilot supply
pressure, so friction matters most at low pressure. ``beta_p`` is the pilot
supply fraction: the first (pilot) stage is fed through the inlet filter, and a
contaminated filter drops part of the supply pressure, so the pilot stage sees
``beta_p * dp_s`` (1 clean). The nozzle flows that move the spool scale with the
square root of that pressure (spool rate ``sqrt(beta_p) / tau_s``) and the force
available against friction with the pressure itself; the main stage is fed from
the supply port directly, so the metering flows do not pass the filter. The
torque-motor command is not clipped: the spool is stopped by its mechanical
stops at ``+/- stroke`` (:func:`spool_stop`). Inside one frame the command is
constant and the motion is piecewise exact (constant-rate free travel in the
play, then an exponential once engaged), see :func:`spool_advance`; the motion
within an interval is monotone, so applying the stops at its end is exact.
See docs/physics.md §2 Components and §6 Degradation modes.

Second stage. Four metering edges P->A, A->T, P->B, B->T with geometric openings
``o = +/-x_s - u`` (lap ``u``, nominal 0). A rounded land corner (radius ``r``)
starts metering before the geometric edge; far from the edge the flow area is
set by the distance between the port edge and the land, which the rounding does
not change. So the corner advances the opening by ``r`` near null and the
advance fades out over a few radii: ``o_r = o + r / (1 + (max(o, 0) / (3 r))^2)``
(:func:`rounded_opening`). Radial clearance and corner rounding
``h = clearance + corner radius`` make every edge leak near null through an
effective opening ``o_eff = h * softplus(o_r / h)`` (0.69 h at null). The
slot is dual-gain: width ``w_null`` near null, widening linearly to ``w_out``
between ``s_a`` and ``s_b`` of the spool stroke. Metering area ``A(o_eff)`` is
the integral of the width.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba

from fuelhm_bench.errors import range_error
from fuelhm_bench.physics._validation import NON_NEGATIVE, POSITIVE, UNIT_INTERVAL, check_fields


@dataclass(frozen=True)
class ServovalveParams:
    """Parameters of the two-stage flapper-nozzle servovalve.

    Parameters
    ----------
    rated_current_a : float, default=8e-3
        Rated current [A]: the current giving full spool stroke.
    null_bias_a : float, default=5e-4
        Mechanical null bias Inb0 [A]: coil current for which the control-port flows balance.
    spool_stroke_m : float, default=4e-4
        Maximum spool displacement from null [m].
    spool_time_constant_s : float, default=2.5e-3
        First-order spool time constant tau_s [s] with a clean filter.
    feedback_backlash_m : float, default=5e-7
        Play width b of the feedback-spring attachment [m].
    spool_friction_n : float, default=1.0
        Coulomb friction force between spool and sleeve F_c [N].
    spool_end_area_m2 : float, default=2.8e-5
        Spool end area on which the pilot pressure acts [m^2].
    pilot_error_span_m : float, default=4e-4
        Feedback error giving the full pilot pressure difference [m].
    slot_width_null_m : float, default=2e-3
        Metering slot width near null [m].
    slot_width_outer_m : float, default=4e-3
        Metering slot width beyond the transition [m].
    transition_start : float, default=0.19
        Start of the width transition, fraction of the spool stroke [-].
    transition_end : float, default=0.31
        End of the width transition, fraction of the spool stroke [-].
    discharge_coefficient : float, default=0.7
        Cd of the metering edges [-].
    radial_clearance_m : float, default=6e-6
        Radial clearance spool/sleeve [m].
    corner_radius_m : float, default=1e-6
        Corner radius of the spool lands [m].
    lap_m : float, default=0.0
        Lap u of the metering edges [m] (> 0 overlap, < 0 underlap).
    pilot_supply_fraction : float, default=1.0
        Pilot-stage supply pressure over the supply pressure rise, beta_p in (0, 1] (1 = clean
        inlet filter; lowered by filter contamination).
    null_bias_drift_a : float, default=0.0
        Drift of the null bias dInb [A] (degradation, added to Inb0).
    """

    rated_current_a: float = 8e-3
    null_bias_a: float = 5e-4
    spool_stroke_m: float = 4e-4
    spool_time_constant_s: float = 2.5e-3
    feedback_backlash_m: float = 5e-7
    spool_friction_n: float = 1.0
    spool_end_area_m2: float = 2.8e-5
    pilot_error_span_m: float = 4e-4
    slot_width_null_m: float = 2e-3
    slot_width_outer_m: float = 4e-3
    transition_start: float = 0.19
    transition_end: float = 0.31
    discharge_coefficient: float = 0.7
    radial_clearance_m: float = 6e-6
    corner_radius_m: float = 1e-6
    lap_m: float = 0.0
    pilot_supply_fraction: float = 1.0
    null_bias_drift_a: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, {
            "rated_current_a": POSITIVE,
            "null_bias_a": (-5e-3, 5e-3, True),
            "spool_stroke_m": POSITIVE,
            "spool_time_constant_s": (1e-5, 0.1, True),
            "feedback_backlash_m": NON_NEGATIVE,
            "spool_friction_n": NON_NEGATIVE,
            "spool_end_area_m2": POSITIVE,
            "pilot_error_span_m": POSITIVE,
            "slot_width_null_m": POSITIVE,
            "slot_width_outer_m": POSITIVE,
            "transition_start": UNIT_INTERVAL,
            "transition_end": UNIT_INTERVAL,
            "discharge_coefficient": (0.0, 1.0, False),
            "radial_clearance_m": POSITIVE,
            "corner_radius_m": NON_NEGATIVE,
            "lap_m": (-1e-4, 1e-4, True),
            "pilot_supply_fraction": (0.0, 1.0, False),
            "null_bias_drift_a": (-1e-2, 1e-2, True),
        })
        if self.transition_end < self.transition_start:
            raise range_error("ServovalveParams.transition_end",
                              f">= transition_start ({self.transition_start:g})", self.transition_end)

    @property
    def spool_gain_m_per_a(self) -> float:
        """Torque-motor gain K_sv = stroke / rated current [m/A]."""
        return self.spool_stroke_m / self.rated_current_a

    @property
    def leakage_height_m(self) -> float:
        """Effective leakage height h = radial clearance + corner radius [m]."""
        return self.radial_clearance_m + self.corner_radius_m

    @property
    def spool_rate_per_s(self) -> float:
        """Spool rate ``sqrt(beta_p) / tau_s`` [1/s] (pilot flow through the inlet filter)."""
        return math.sqrt(self.pilot_supply_fraction) / self.spool_time_constant_s

    @property
    def total_null_bias_a(self) -> float:
        """Null bias including drift, Inb0 + dInb [A]."""
        return self.null_bias_a + self.null_bias_drift_a

    def friction_dead_zone_m(self, supply_rise_pa: float) -> float:
        """Half-width of the friction dead zone on the spool error [m] at a supply rise [Pa]."""
        k_drive = (self.pilot_supply_fraction * self.spool_end_area_m2 * max(supply_rise_pa, 1e5)
                   / self.pilot_error_span_m)
        return self.spool_friction_n / k_drive


@numba.njit(cache=True, inline="always")
def slot_area(o_eff: float, w_null: float, w_out: float, o_a: float, o_b: float) -> tuple[float, float]:
    """Dual-gain slot area [m^2] and its derivative [m] for an effective opening [m]."""
    if o_eff <= o_a:
        return w_null * o_eff, w_null
    dw = w_out - w_null
    if o_eff < o_b:
        frac = (o_eff - o_a) / (o_b - o_a)
        return w_null * o_eff + 0.5 * dw * (o_eff - o_a) * frac, w_null + dw * frac
    return w_null * o_eff + dw * (0.5 * (o_b - o_a) + (o_eff - o_b)), w_out


@numba.njit(cache=True, inline="always")
def effective_opening(o: float, h: float) -> float:
    """Effective opening ``h * softplus(o / h)`` [m] (leakage through clearance near null)."""
    z = o / h
    if z > 0.0:
        return o + h * math.log1p(math.exp(-z))
    return h * math.log1p(math.exp(z))


@numba.njit(cache=True, inline="always")
def rounded_opening(o: float, r: float) -> float:
    """Geometric opening [m] advanced by a rounded land corner of radius ``r`` [m].

    ``o + r`` near and below the edge, fading to ``o`` over a few radii above it
    (monotone: the slope stays above 0.78).
    """
    if r <= 0.0:
        return o
    if o <= 0.0:
        return o + r
    z = o / (3.0 * r)
    return o + r / (1.0 + z * z)


@numba.njit(cache=True, inline="always")
def spool_stop(x_s: float, x_fb: float, half_play: float, stroke: float) -> tuple[float, float]:
    """Apply the spool's mechanical stops at +/- ``stroke`` [m]; the feedback point stays within the play."""
    if x_s > stroke:
        x_s = stroke
    elif x_s < -stroke:
        x_s = -stroke
    else:
        return x_s, x_fb
    if x_fb > x_s + half_play:
        x_fb = x_s + half_play
    elif x_fb < x_s - half_play:
        x_fb = x_s - half_play
    return x_s, x_fb


@numba.njit(cache=True)
def spool_advance(x_s: float, x_fb: float, x_c: float, dt: float, rate: float,
                  half_play: float, dead_zone: float, decay: float = -1.0) -> tuple[float, float]:
    """Advance spool and feedback point over ``dt`` with a constant command (exact).

    Parameters
    ----------
    x_s, x_fb : float
        Spool and feedback-point positions at the start [m].
    x_c : float
        Torque-motor command [m], constant over ``dt``.
    dt : float
        Duration [s].
    rate : float
        ``sqrt(beta_p) / tau_s`` [1/s].
    half_play : float
        Half of the backlash play b/2 [m].
    dead_zone : float
        Friction dead-zone half-width d_f [m].
    decay : float, optional
        Precomputed ``exp(-rate * dt)`` (used when the whole interval is engaged).

    Returns
    -------
    x_s, x_fb : float
        Positions at the end [m].
    """
    e = x_c - x_fb
    if abs(e) <= dead_zone or dt <= 0.0:
        return x_s, x_fb
    s = 1.0 if e > 0.0 else -1.0
    # Phase A: free travel inside the play at constant speed.
    gap = half_play - s * (x_s - x_fb)
    if gap > 0.0 or decay < 0.0:
        decay = -1.0
    if gap > 0.0:
        speed = rate * (abs(e) - dead_zone)
        t_a = gap / speed
        if t_a >= dt:
            return x_s + s * speed * dt, x_fb
        dt = dt - t_a
        x_s = x_fb + s * half_play
    # Phase B: engaged, exponential towards x_c + s*(b/2 - d_f).
    target = x_c + s * (half_play - dead_zone)
    if decay < 0.0:
        decay = math.exp(-rate * dt)
    x_s = target + (x_s - target) * decay
    return x_s, x_s - s * half_play
