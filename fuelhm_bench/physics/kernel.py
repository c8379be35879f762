"""Fast batched integrator of the closed loop (numba), one FADEC frame per step.

Per frame ``k`` (period T), for every flight of the batch (leading axis):

1. LVDT sample ``y_k = quantize(C s_k + sigma * noise_k)``;
2. controller (PI, clamp, saturation) -> commanded current ``i_k`` (or the
   open-loop current of a sweep);
3. spool: exact piecewise motion over the frame with the command held
   (:func:`~fuelhm_bench.physics.servovalve.spool_advance`) and the mechanical
   stops (:func:`~fuelhm_bench.physics.servovalve.spool_stop`), evaluated at the
   two Gauss-Legendre points of the frame;
4. rod: ``x_{k+1} = clip(x_k + T * mean(v(gauss points)), 0, stroke)`` with the
   quasi-static velocity ``v`` of :mod:`~fuelhm_bench.physics.cylinder`; in a frame
   where the spool reaches its stop (a kink of ``v(t)``) the quadrature is split at
   that instant (found by bisection on the exact spool motion);
5. LVDT filter: exact first-order-hold update of its states.

Velocity evaluation has two modes. *Table* mode (default): at the start of a
flight, ``v / N2`` is tabulated on a (spool position x N2) grid by the direct
solver and read by bilinear interpolation (the supply rise and the aerodynamic
load both scale with N2^2, so ``v / N2`` is nearly independent of N2). *Direct*
mode solves the quasi-static equations at every Gauss point; it is used when
the rod force depends on the state (``rod_friction``, ``load_stiffness``) and
below the table's N2 range (engine start). The table-vs-direct error is tested.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from fuelhm_bench.physics import cylinder as cyl
from fuelhm_bench.physics.cylinder import metering_coefficients, velocity_direct, velocity_metered
from fuelhm_bench.physics.lvdt import lvdt_discretization
from fuelhm_bench.physics.servovalve import spool_advance, spool_stop

# Loop-vector layout.
_K_NAMES = (
    "frame", "kp", "ki", "zmax", "dead_band", "isat", "dgain", "doff", "inb", "ksv", "spool_stroke",
    "rate", "half_play", "fric_num", "ff_ratio", "w_null", "w_out", "o_a", "o_b", "dps100", "faero100",
    "kx", "xref", "fc", "fs", "vs", "bv", "stroke", "noise", "quantum", "rmin", "rmax", "lagsel",
    "direct", "endstops", "drvlag", "hyst", "fflim",
)
K = {name: i for i, name in enumerate(_K_NAMES)}
K_N = len(_K_NAMES)
(K_FRAME, K_KP, K_KI, K_ZMAX, K_DB, K_ISAT, K_DGAIN, K_DOFF, K_INB, K_KSV, K_SSTROKE, K_RATE, K_HPLAY,
 K_FRICNUM, K_FF, K_WNULL, K_WOUT, K_OA, K_OB, K_DPS100, K_FAERO100, K_KX, K_XREF, K_FC, K_FS, K_VS, K_BV,
 K_STROKE, K_NOISE, K_Q, K_RMIN, K_RMAX, K_LAGSEL, K_DIRECT, K_ENDSTOPS, K_DRVLAG, K_HYST, K_FFLIM) = range(K_N)

#: Velocity table grid: spool positions (fraction of stroke) x N2 nodes.
TABLE_NX = 801
TABLE_N2 = np.linspace(0.3, 1.1, 9)
_GAUSS = 0.5 / math.sqrt(3.0)
GAUSS_LO = 0.5 - _GAUSS
GAUSS_HI = 0.5 + _GAUSS

STATUS_OK, STATUS_NONFINITE = 0, 1

#: LLVM fast-math flags of the per-frame loop: fused multiply-add, reassociation and reciprocals,
#: but NOT "nnan"/"ninf" - the loop relies on NaN (closed-loop marker, forced-position gaps) and on
#: its non-finite guard. Deterministic on a given machine; differences to strict IEEE are at the
#: 1e-15 relative level, far inside the fast-vs-reference tolerance.
_SAFE_FASTMATH = {"contract", "reassoc", "arcp", "nsz"}


def pack_model(model, fuel_temp_degc: float = 20.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flatten a :class:`~fuelhm_bench.physics.model.LoopModel` into kernel vectors.

    ``fuel_temp_degc`` (the flight's fuel temperature) only matters with ``viscosity_temperature``.

    Returns
    -------
    c : ndarray (cyl.C_N,)
        Valve/cylinder coefficients for the quasi-static solve.
    k : ndarray (K_N,)
        Loop coefficients.
    lvdt : ndarray (3, 5)
        LVDT first-order-hold discretisation.
    """
    sv, cy, fl, ct = model.servovalve, model.cylinder, model.fluid, model.controller
    c = np.zeros(cyl.C_N)
    c[cyl.C_W_NULL] = sv.slot_width_null_m
    c[cyl.C_W_OUT] = sv.slot_width_outer_m
    c[cyl.C_O_A] = sv.transition_start * sv.spool_stroke_m
    c[cyl.C_O_B] = max(sv.transition_end * sv.spool_stroke_m, c[cyl.C_O_A] + 1e-9)
    c[cyl.C_H] = sv.leakage_height_m
    overlap = model.effect("spool_overlap")
    c[cyl.C_LAP] = sv.lap_m + (overlap.overlap_m if overlap else 0.0)
    c[cyl.C_CDV] = sv.discharge_coefficient * fl.flow_constant
    c[cyl.C_ALPHA] = 1.0  # the inlet filter feeds the pilot stage only
    c[cyl.C_A1] = cy.head_area_m2
    c[cyl.C_A2] = cy.rod_area_m2
    c[cyl.C_CQC] = (cy.diaphragm_open_fraction * cy.diaphragm_discharge_coefficient * cy.diaphragm_area_m2
                    * fl.flow_constant)
    c[cyl.C_KLI] = cy.leakage_coefficient_m3_s_pa
    vt = model.effect("viscosity_temperature")
    if vt:
        c[cyl.C_KLI] += vt.leak_coefficient(fuel_temp_degc)
    c[cyl.C_PR] = fl.return_pressure_pa
    c[cyl.C_PCR] = fl.regularisation_pressure_pa
    c[cyl.C_RC] = sv.corner_radius_m

    k = np.zeros(K_N)
    k[K_FRAME] = ct.frame_s
    k[K_KP] = ct.kp_a_per_m
    k[K_KI] = ct.ki_a_per_m_s
    k[K_ZMAX] = ct.integrator_clamp_a
    k[K_DB] = ct.dead_band_m
    k[K_ISAT] = ct.current_saturation_a
    k[K_DGAIN] = model.driver.gain
    k[K_DOFF] = model.driver.offset_a
    k[K_INB] = sv.total_null_bias_a
    k[K_KSV] = sv.spool_gain_m_per_a
    k[K_SSTROKE] = sv.spool_stroke_m
    k[K_RATE] = sv.spool_rate_per_s
    k[K_HPLAY] = 0.5 * sv.feedback_backlash_m
    k[K_FRICNUM] = sv.spool_friction_n * sv.pilot_error_span_m / (sv.spool_end_area_m2 * sv.pilot_supply_fraction)
    ff = model.effect("spool_flow_force")
    k[K_FF] = ff.stiffness_ratio if ff else 0.0
    k[K_FFLIM] = ff.command_limit_ratio * sv.spool_stroke_m if ff and ff.command_limit_ratio > 0.0 else math.inf
    k[K_WNULL] = sv.slot_width_null_m
    k[K_WOUT] = sv.slot_width_outer_m
    k[K_OA] = c[cyl.C_O_A]
    k[K_OB] = c[cyl.C_O_B]
    k[K_DPS100] = fl.supply_rise_at_100pct_pa
    k[K_FAERO100] = model.load.aero_force_at_100pct_n
    ls = model.effect("load_stiffness")
    k[K_KX] = ls.stiffness_n_m if ls else 0.0
    k[K_XREF] = ls.reference_m if ls else 0.0
    rf = model.effect("rod_friction")
    if rf:
        k[K_FC] = rf.coulomb_n
        k[K_FS] = rf.coulomb_n * rf.static_ratio
        k[K_VS] = rf.stribeck_velocity_m_s
        k[K_BV] = rf.viscous_n_s_m
    k[K_STROKE] = cy.stroke_m
    k[K_NOISE] = model.lvdt.noise_std_m
    k[K_Q] = model.lvdt.quantum_m
    k[K_RMIN] = model.lvdt.range_min_m
    k[K_RMAX] = model.lvdt.range_max_m
    lag = model.effect("lvdt_lag")
    k[K_LAGSEL] = 1.0 if lag else 0.0
    k[K_DIRECT] = 1.0 if (ls or rf or ff) else 0.0  # the flow force reads the chamber pressures
    k[K_ENDSTOPS] = 1.0
    dl = model.effect("current_driver_lag")
    k[K_DRVLAG] = dl.time_constant_s if dl else 0.0
    hy = model.effect("torque_motor_hysteresis")
    k[K_HYST] = 0.5 * hy.width_a if hy else 0.0
    lv = lvdt_discretization(model.lvdt, lag.time_constant_s if lag else 0.0, ct.frame_s)
    return c, k, lv


@numba.njit(cache=True)
def load_pressure(p1: float, f_load: float, c) -> float:
    """Chamber pressure difference ``p1 - p2`` [Pa] for a head pressure and the rod load (0 when unknown)."""
    if math.isnan(p1):
        return 0.0
    return p1 - (p1 * c[cyl.C_A1] - f_load) / c[cyl.C_A2]


@numba.njit(cache=True)
def spool_command(i_cmd: float, dps: float, k, dp12: float = 0.0) -> float:
    """Torque-motor spool command x_c [m] for a commanded current [A] (driver, null bias, flow force).

    Not clipped: the spool's stops limit the spool itself (:func:`~fuelhm_bench.physics.servovalve.spool_stop`),
    so friction and backlash do not reduce the full-stroke opening.

    The flow force (Merritt's steady flow force, a centring force proportional to the opening and to
    the pressure drop across each open metering edge) scales with the sum of the two open edges'
    drops, ``(p_s - p_r) - sgn(x_c) (p1 - p2)``: ``dp12`` is the chamber pressure difference
    ``p1 - p2`` [Pa] (the previous frame's, 0 when unknown). With the flow force on and a command
    limit (``command_limit_ratio`` > 0), the command is clipped at that limit before the flow force
    reduces it.
    """
    i_coil = k[K_DGAIN] * i_cmd + k[K_DOFF]
    x_c = k[K_KSV] * (i_coil - k[K_INB])
    if k[K_FF] > 0.0:
        # the torque motor's authority (command_limit_ratio): clipped before the flow force acts
        if x_c > k[K_FFLIM]:
            x_c = k[K_FFLIM]
        elif x_c < -k[K_FFLIM]:
            x_c = -k[K_FFLIM]
        drop = dps - dp12 if x_c >= 0.0 else dps + dp12
        if drop < 0.0:
            drop = 0.0
        ax = abs(x_c)
        if ax <= k[K_OA]:
            w = k[K_WNULL]
        elif ax >= k[K_OB]:
            w = k[K_WOUT]
        else:
            w = k[K_WNULL] + (k[K_WOUT] - k[K_WNULL]) * (ax - k[K_OA]) / (k[K_OB] - k[K_OA])
        x_c = x_c / (1.0 + k[K_FF] * (drop / 7e6) * (w / k[K_WNULL]))
    return x_c


@numba.njit(cache=True)
def friction_force(v: float, k) -> float:
    """Rod friction force [N] opposing velocity ``v`` (v != 0)."""
    fc = k[K_FC]
    mag = fc + (k[K_FS] - fc) * math.exp(-(v / k[K_VS]) ** 2)
    return (mag if v > 0.0 else -mag) + k[K_BV] * v


@numba.njit(cache=True)
def rod_velocity(x_s: float, dps: float, f_load: float, p1: float, c, k) -> tuple[float, float]:
    """Quasi-static rod velocity [m/s] including rod friction when enabled; returns (v, p1)."""
    if k[K_FC] <= 0.0:
        return velocity_direct(x_s, dps, f_load, p1, c)
    fs = k[K_FS]
    # one spool position: its metering coefficients serve every force tried
    k_pa, k_at, k_pb, k_bt, _, _, _, _ = metering_coefficients(x_s, c)
    v_up, p_up = velocity_metered(k_pa, k_at, k_pb, k_bt, dps, f_load + fs, p1, c)
    if v_up > 0.0:
        sgn = 1.0
    else:
        v_dn, p_dn = velocity_metered(k_pa, k_at, k_pb, k_bt, dps, f_load - fs, p1, c)
        if v_dn < 0.0:
            sgn = -1.0
        else:
            return 0.0, p_up
    # Root of g(v) = v - V(f_load + F(v)) between 0 and V(f_load +/- F_c) (Illinois).
    v_end, p_end = velocity_metered(k_pa, k_at, k_pb, k_bt, dps, f_load + sgn * k[K_FC], p1, c)
    a, ga = 0.0, -(v_up if sgn > 0 else v_dn)
    b = v_end
    vb, pb = velocity_metered(k_pa, k_at, k_pb, k_bt, dps, f_load + friction_force(b, k), p_end, c)
    gb = b - vb
    if gb * sgn <= 0.0:
        return b, pb
    side = 0
    p = pb
    for _ in range(60):
        m = (a * gb - b * ga) / (gb - ga)
        vm, p = velocity_metered(k_pa, k_at, k_pb, k_bt, dps, f_load + friction_force(m, k), p, c)
        gm = m - vm
        if abs(gm) < 1e-9 or abs(b - a) < 1e-10:
            return m, p
        if gm * gb > 0.0:
            b, gb = m, gm
            if side == -1:
                ga *= 0.5
            side = -1
        else:
            a, ga = m, gm
            if side == 1:
                gb *= 0.5
            side = 1
    return 0.5 * (a + b), p


@numba.njit(cache=True)
def build_velocity_table(c, k, n2_nodes, nx: int):
    """Tabulate v / N2 [m/s] on (spool position, N2) with the direct solver."""
    nn = n2_nodes.shape[0]
    table = np.empty((nx, nn))
    smax = k[K_SSTROKE]
    for j in range(nn):
        n2 = n2_nodes[j]
        dps = k[K_DPS100] * n2 * n2
        f = k[K_FAERO100] * n2 * n2
        p1 = np.nan
        for i in range(nx):
            x_s = -smax + 2.0 * smax * i / (nx - 1)
            v, p1 = velocity_direct(x_s, dps, f, p1, c)
            table[i, j] = v / n2
    return table


@numba.njit(cache=True)
def _velocity(x_s, n2, x, p1, c, k, table, use_table, n2_lo, n2_step, n2_hi):
    """Direct-mode velocity [m/s] and head pressure [Pa] (the table is read inline by the caller)."""
    dps = k[K_DPS100] * n2 * n2
    if dps <= 0.0:
        return 0.0, p1
    f_load = k[K_FAERO100] * n2 * n2 + k[K_KX] * (x - k[K_XREF])
    return rod_velocity(x_s, dps, f_load, p1, c, k)


@numba.njit(cache=True, inline="always", fastmath=_SAFE_FASTMATH)
def _table_lookup(table, x_s, j, fw, n2, smax, x_scale):
    nx = table.shape[0]
    u = min(max((x_s + smax) * x_scale, 0.0), nx - 1.0)
    i = min(int(u), nx - 2)
    fu = u - i
    t0 = table[i, j] + fu * (table[i + 1, j] - table[i, j])
    t1 = table[i, j + 1] + fu * (table[i + 1, j + 1] - table[i, j + 1])
    return (t0 + fw * (t1 - t0)) * n2


@numba.njit(cache=True, fastmath=_SAFE_FASTMATH)
def simulate_one(c, k, lv, table, use_table, n2_lo, n2_step, n2_hi, demand, n2s, noise, i_open, x_force, n,
                 x0, out_i, out_y, out_x, out_v):
    """Simulate one flight of ``n`` frames; fills the output arrays; returns a status code.

    ``i_open`` holds open-loop currents [A] (NaN: closed loop, use the controller).
    ``x_force`` holds imposed rod positions [m] at the start of each frame (NaN: free),
    used to replay measured flights (the rod state is reset, the LVDT filter is not).
    Either array may be shorter than ``n`` (e.g. length 1): it is then not used.
    """
    T = k[K_FRAME]
    t1 = T * GAUSS_LO
    t2 = T * GAUSS_HI
    stroke = k[K_STROKE]
    endstops = k[K_ENDSTOPS] > 0.5
    q = k[K_Q]
    rmin = k[K_RMIN]
    rmax = k[K_RMAX]
    x = x0
    s0 = x0
    s1 = 0.0
    s2 = x0
    x_s = 0.0
    x_fb = 0.0
    z = 0.0
    p1 = np.nan
    lag = k[K_LAGSEL] > 0.5
    top = math.floor((rmax - rmin) / q) - 1.0 if q > 0.0 else 0.0
    rate = k[K_RATE]
    hplay = k[K_HPLAY]
    d1 = math.exp(-rate * t1)
    d2 = math.exp(-rate * (t2 - t1))
    d3 = math.exp(-rate * (T - t2))
    nn = table.shape[1]
    smax = k[K_SSTROKE]
    x_scale = (table.shape[0] - 1) / (2.0 * smax)
    inv_n2_step = 1.0 / n2_step
    forced = x_force.shape[0] >= n
    open_loop = i_open.shape[0] >= n
    # optional effects current_driver_lag / torque_motor_hysteresis (states: lagged and played current)
    tdl = k[K_DRVLAG]
    edl = math.exp(-T / tdl) if tdl > 0.0 else 0.0
    i_lag = np.nan
    i_play = np.nan
    for t in range(n):
        if forced and not math.isnan(x_force[t]):
            x = x_force[t]
        # 1. sensor
        y = s2 if lag else s0
        y = y + k[K_NOISE] * noise[t]
        if q > 0.0:
            code = math.floor((y - rmin) / q + 0.5)
            if code < 0.0:
                code = 0.0
            elif code > top:
                code = top
            y = rmin + code * q
        # 2. controller
        if not open_loop or math.isnan(i_open[t]):
            e = demand[t] - y
            if abs(e) > k[K_DB]:
                z += k[K_KI] * e * T
                if z > k[K_ZMAX]:
                    z = k[K_ZMAX]
                elif z < -k[K_ZMAX]:
                    z = -k[K_ZMAX]
            i = k[K_KP] * e + z
            if i > k[K_ISAT]:
                i = k[K_ISAT]
            elif i < -k[K_ISAT]:
                i = -k[K_ISAT]
        else:
            i = i_open[t]
        n2 = n2s[t]
        dps = k[K_DPS100] * n2 * n2
        i_sv = i
        if tdl > 0.0:  # exact mean of the lagged current over the frame, then its end value
            if math.isnan(i_lag):
                i_lag = i
            i_sv = i + (i_lag - i) * tdl / T * (1.0 - edl)
            i_lag = i + (i_lag - i) * edl
        if k[K_HYST] > 0.0:
            if math.isnan(i_play):
                i_play = i_sv
            elif i_sv > i_play + k[K_HYST]:
                i_play = i_sv - k[K_HYST]
            elif i_sv < i_play - k[K_HYST]:
                i_play = i_sv + k[K_HYST]
            i_sv = i_play
        dp12 = 0.0
        if k[K_FF] > 0.0:
            dp12 = load_pressure(p1, k[K_FAERO100] * n2 * n2 + k[K_KX] * (x - k[K_XREF]), c)
        x_c = spool_command(i_sv, dps, k, dp12)
        dz = k[K_FRICNUM] / max(dps, 1e5)
        # 3. spool positions at the two Gauss-Legendre points of the frame and at its end
        xs0, xfb0 = x_s, x_fb
        xa, fa = spool_advance(x_s, x_fb, x_c, t1, rate, hplay, dz, d1)
        xa, fa = spool_stop(xa, fa, hplay, smax)
        xb, fb = spool_advance(xa, fa, x_c, t2 - t1, rate, hplay, dz, d2)
        xb, fb = spool_stop(xb, fb, hplay, smax)
        x_s, x_fb = spool_advance(xb, fb, x_c, T - t2, rate, hplay, dz, d3)
        x_s, x_fb = spool_stop(x_s, x_fb, hplay, smax)
        # 4. rod: mean velocity over the frame by Gauss-Legendre quadrature
        if use_table and n2 >= n2_lo and n2 <= n2_hi:
            w = (n2 - n2_lo) * inv_n2_step
            j = min(int(w), nn - 2)
            fw = w - j
            va = _table_lookup(table, xa, j, fw, n2, smax, x_scale)
            vb = _table_lookup(table, xb, j, fw, n2, smax, x_scale)
        else:
            va, p1 = _velocity(xa, n2, x, p1, c, k, table, False, n2_lo, n2_step, n2_hi)
            vb, p1 = _velocity(xb, n2, x, p1, c, k, table, False, n2_lo, n2_step, n2_hi)
        v_mean = 0.5 * (va + vb)
        if abs(x_s) >= smax and abs(xs0) < smax:
            # The spool reached its stop inside the frame: the velocity has a kink there, so
            # integrate the moving part and the part on the stop separately (rare frames).
            t_lo, t_hi = 0.0, T
            for _ in range(40):
                t_mid = 0.5 * (t_lo + t_hi)
                xm, _fm = spool_advance(xs0, xfb0, x_c, t_mid, rate, hplay, dz)
                if abs(xm) >= smax:
                    t_hi = t_mid
                else:
                    t_lo = t_mid
            t_hit = t_hi
            xa2, _fa = spool_advance(xs0, xfb0, x_c, t_hit * GAUSS_LO, rate, hplay, dz)
            xb2, _fb = spool_advance(xs0, xfb0, x_c, t_hit * GAUSS_HI, rate, hplay, dz)
            if use_table and n2 >= n2_lo and n2 <= n2_hi:
                va = _table_lookup(table, xa2, j, fw, n2, smax, x_scale)
                vb = _table_lookup(table, xb2, j, fw, n2, smax, x_scale)
                vs = _table_lookup(table, x_s, j, fw, n2, smax, x_scale)
            else:
                va, p1 = _velocity(xa2, n2, x, p1, c, k, table, False, n2_lo, n2_step, n2_hi)
                vb, p1 = _velocity(xb2, n2, x, p1, c, k, table, False, n2_lo, n2_step, n2_hi)
                vs, p1 = _velocity(x_s, n2, x, p1, c, k, table, False, n2_lo, n2_step, n2_hi)
            v_mean = (0.5 * t_hit * (va + vb) + (T - t_hit) * vs) / T
        x_new = x + T * v_mean
        if endstops:
            if x_new < 0.0:
                x_new = 0.0
            elif x_new > stroke:
                x_new = stroke
        if not math.isfinite(x_new) or not math.isfinite(i):
            return STATUS_NONFINITE
        out_i[t] = i
        out_y[t] = y
        out_x[t] = x
        out_v[t] = (x_new - x) / T
        # 5. LVDT filter, exact first-order-hold update
        du = (x_new - x) / T
        n0 = lv[0, 0] * s0 + lv[0, 1] * s1 + lv[0, 2] * s2 + lv[0, 3] * x + lv[0, 4] * du
        n1 = lv[1, 0] * s0 + lv[1, 1] * s1 + lv[1, 2] * s2 + lv[1, 3] * x + lv[1, 4] * du
        if lag:
            s2 = lv[2, 0] * s0 + lv[2, 1] * s1 + lv[2, 2] * s2 + lv[2, 3] * x + lv[2, 4] * du
        s0, s1 = n0, n1
        x = x_new
    return STATUS_OK


@numba.njit(cache=True)
def simulate_batch(cs, ks, lvs, tables, use_table, lengths, demand, n2s, noise, i_open, x_force, x0,
                   out_i, out_y, out_x, out_v, status):
    """Simulate a batch of flights (leading axis = flight); see :func:`simulate_one`."""
    n2_lo = TABLE_N2[0]
    n2_hi = TABLE_N2[-1]
    n2_step = TABLE_N2[1] - TABLE_N2[0]
    for b in range(cs.shape[0]):
        status[b] = simulate_one(cs[b], ks[b], lvs[b], tables[b], use_table[b], n2_lo, n2_step, n2_hi,
                                 demand[b], n2s[b], noise[b], i_open[b], x_force[b], lengths[b], x0[b],
                                 out_i[b], out_y[b], out_x[b], out_v[b])
