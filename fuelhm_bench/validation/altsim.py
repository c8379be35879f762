"""A second, structurally different simulator of the actuation loop ("altsim").

Its flights are written in the measured-data format (``docs/data-format.md``: ``flight_id``,
``unit_id``, ``time_s``, ``current_mA``, ``position_mm``, ``demand_mm``, ``n2_pct``,
``fuel_temp_degC``), so they feed the calibration and discrepancy workflows exactly like
measured flights. It shares no equation and no code with :mod:`fuelhm_bench.physics`; it is
the "plausible model that is not exactly yours" against which the discrepancy thresholds are
calibrated. Structural differences from the project's model:

==========================  ===================================  =====================================
part                        project model                        altsim
==========================  ===================================  =====================================
spool                       first order, play, friction dead     second order (``w_n``, ``zeta``), no
                            zone                                 play, no dead zone
flow force (optional)       centring spring on the command ~     stiffness on the spool's position in
                            open edges' drops (frame start)      its 2nd-order dynamics ~ edge drops
                                                                 (command clipped at the stroke first)
metering edges              softplus opening, piecewise-linear   sharp edges + *laminar* clearance leak
                            width transition                     per edge, logistic width transition
cylinder                    quasi-static (no compressibility)    dynamic: chamber pressures with bulk
                                                                 modulus and dead volumes, rod mass,
                                                                 viscous damping
rod friction (optional)     Coulomb + Stribeck with stiction     ``F_c tanh(v / v_t)`` (no stiction),
                                                                 linearised-implicit in the sub-step
LVDT                        3-state filter                       second-order low-pass (+ optional lag)
==========================  ===================================  =====================================

Optional effects (:class:`AltEffects`): the five of the project's library under these different
laws (spool overlap, flow force, rod friction, LVDT lag, load stiffness), the three new ones
(current-driver lag, torque-motor hysteresis as a play on the coil current, a
temperature-dependent laminar cross-piston leak) and two that no library holds: a supply
pressure droop under flow and a constant coil-current offset that drifts with time in flight.

The integration is explicit (semi-implicit Euler for the rod) on sub-steps of at most
0.25 ms, compiled with numba; a 20-minute flight at 100 Hz takes about 0.1 s.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numba
import numpy as np
import pandas as pd

from fuelhm_bench.errors import ParameterError, range_error


@dataclass(frozen=True)
class AltEffects:
    """Optional effects of the altsim (all off by default).

    Parameters
    ----------
    overlap_m : float
        Spool lap [m] (openings ``|x_s| - u``).
    flow_force_ratio : float
        Bernoulli flow-force stiffness at 70 bar total edge drop and null width, over the
        spool's centring stiffness [-].
    coulomb_n : float
        Rod friction ``F_c tanh(v / 1 mm/s)`` [N].
    lvdt_lag_s : float
        Extra first-order lag of the position sensor [s].
    load_stiffness_n_m : float
        Spring load ``k (x - x_ref)`` [N/m].
    load_reference_m : float
        ``x_ref`` [m].
    driver_lag_s : float
        First-order lag of the coil current behind the recorded command [s].
    hysteresis_a : float
        Full width of the play between coil current and torque-motor torque [A].
    leak_m3_s_pa_at_20c : float
        Laminar cross-piston leak at 20 degC [m^3/(s Pa)], scaled by the fuel viscosity
        ``mu(T) = mu_20 exp(-viscosity_slope (T - 20))``.
    viscosity_slope_per_degc : float
        Viscosity temperature coefficient [1/degC].
    supply_droop_pa_s_m3 : float
        Supply pressure drop per supply flow [Pa s/m^3] (outside every library).
    current_drift_a_per_h : float
        Coil-current offset growing with time in flight [A/h] (outside every library).
    """

    overlap_m: float = 0.0
    flow_force_ratio: float = 0.0
    coulomb_n: float = 0.0
    lvdt_lag_s: float = 0.0
    load_stiffness_n_m: float = 0.0
    load_reference_m: float = 0.03
    driver_lag_s: float = 0.0
    hysteresis_a: float = 0.0
    leak_m3_s_pa_at_20c: float = 0.0
    viscosity_slope_per_degc: float = 0.02
    supply_droop_pa_s_m3: float = 0.0
    current_drift_a_per_h: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise range_error(f"AltEffects.{f.name}", "a finite number", v)
        for name in ("overlap_m", "flow_force_ratio", "coulomb_n", "lvdt_lag_s", "driver_lag_s", "hysteresis_a",
                     "leak_m3_s_pa_at_20c", "supply_droop_pa_s_m3"):
            if getattr(self, name) < 0:
                raise range_error(f"AltEffects.{name}", ">= 0", getattr(self, name))


@dataclass(frozen=True)
class AltParams:
    """Nominal parameters of the altsim loop (SI units).

    The values are chosen so that the velocity-gain curve is close to, but not the same
    as, the project's nominal model: same rated current, null bias, slot widths and
    supply law; different spool, edge, cylinder and sensor dynamics.
    """

    density_kg_m3: float = 800.0
    return_pressure_pa: float = 2e5
    supply_rise_at_100pct_pa: float = 1.03e7
    rated_current_a: float = 8e-3
    null_bias_a: float = 5e-4
    spool_stroke_m: float = 4e-4
    spool_natural_hz: float = 110.0
    spool_damping: float = 0.8
    slot_width_null_m: float = 2e-3
    slot_width_outer_m: float = 4e-3
    transition_mid: float = 0.25
    transition_width: float = 0.025
    discharge_coefficient: float = 0.68
    edge_leak_m3_s_pa: float = 1.5e-13
    bore_m: float = 0.040
    rod_m: float = 0.020
    stroke_m: float = 0.060
    dead_volume_m3: float = 3e-5
    bulk_modulus_pa: float = 2.5e8
    rod_mass_kg: float = 3.0
    viscous_n_s_m: float = 300.0
    diaphragm_diameter_m: float = 3e-4
    diaphragm_cd: float = 0.7
    aero_force_at_100pct_n: float = 500.0
    kp_a_per_m: float = 2.0
    ki_a_per_m_s: float = 6.0
    integrator_clamp_a: float = 8e-3
    dead_band_m: float = 2e-5
    current_saturation_a: float = 12e-3
    lvdt_hz: float = 150.0
    lvdt_damping: float = 0.7
    noise_std_m: float = 3e-6
    adc_bits: int = 12
    range_min_m: float = -0.005
    range_max_m: float = 0.065
    effects: AltEffects = field(default_factory=AltEffects)


#: Manufacturing dispersion of the altsim units: (field, relative std) and (field, additive std).
ALT_DISPERSION_RELATIVE = (("slot_width_null_m", 0.02), ("slot_width_outer_m", 0.02), ("rated_current_a", 0.02),
                           ("diaphragm_diameter_m", 0.03), ("aero_force_at_100pct_n", 0.10),
                           ("discharge_coefficient", 0.02), ("spool_natural_hz", 0.05))
ALT_DISPERSION_ADDITIVE = (("null_bias_a", 1e-4),)


def manufacture_alt(params: AltParams, rng: np.random.Generator, scale: float = 1.0) -> AltParams:
    """Draw one altsim unit (truncated normal at 3 sigma, seeded)."""
    z = np.clip(rng.standard_normal(len(ALT_DISPERSION_RELATIVE) + len(ALT_DISPERSION_ADDITIVE)), -3, 3) * scale
    values = {}
    for (name, std), zz in zip(ALT_DISPERSION_RELATIVE, z):
        values[name] = getattr(params, name) * (1.0 + std * zz)
    for (name, std), zz in zip(ALT_DISPERSION_ADDITIVE, z[len(ALT_DISPERSION_RELATIVE):]):
        values[name] = getattr(params, name) + std * zz
    return dataclasses.replace(params, **values)


def _pack(p: AltParams) -> np.ndarray:
    e = p.effects
    a1 = math.pi / 4 * p.bore_m ** 2
    a2 = a1 - math.pi / 4 * p.rod_m ** 2
    vals = [
        p.density_kg_m3, p.return_pressure_pa, p.supply_rise_at_100pct_pa, p.spool_stroke_m / p.rated_current_a,
        p.null_bias_a, p.spool_stroke_m, 2 * math.pi * p.spool_natural_hz, p.spool_damping, p.slot_width_null_m,
        p.slot_width_outer_m, p.transition_mid * p.spool_stroke_m, p.transition_width * p.spool_stroke_m,
        p.discharge_coefficient, p.edge_leak_m3_s_pa, a1, a2, p.stroke_m, p.dead_volume_m3, p.bulk_modulus_pa,
        p.rod_mass_kg, p.viscous_n_s_m, math.pi / 4 * p.diaphragm_diameter_m ** 2 * p.diaphragm_cd,
        p.aero_force_at_100pct_n, p.kp_a_per_m, p.ki_a_per_m_s, p.integrator_clamp_a, p.dead_band_m,
        p.current_saturation_a, 2 * math.pi * p.lvdt_hz, p.lvdt_damping, p.noise_std_m,
        (p.range_max_m - p.range_min_m) / 2 ** p.adc_bits, p.range_min_m, p.range_max_m,
        e.overlap_m, e.flow_force_ratio, e.coulomb_n, e.lvdt_lag_s, e.load_stiffness_n_m, e.load_reference_m,
        e.driver_lag_s, e.hysteresis_a, e.leak_m3_s_pa_at_20c, e.viscosity_slope_per_degc, e.supply_droop_pa_s_m3,
        e.current_drift_a_per_h,
    ]
    return np.array(vals, dtype=float)


@numba.njit(cache=True)
def _sqrt_flow(dp, kq):
    """Turbulent orifice flow ``kq sqrt(|dp|) sgn(dp)``, linear below 0.3 bar."""
    p_reg = 3e4
    a = abs(dp)
    if a < p_reg:
        return kq * dp / math.sqrt(p_reg)
    return kq * math.sqrt(a) * (1.0 if dp > 0 else -1.0)


@numba.njit(cache=True)
def _area(o, w0, w1, om, ow):
    """Metering area of an opening ``o`` [m]: width w0 -> w1 through a logistic centred at om."""
    if o <= 0.0:
        return 0.0
    # integral of w0 + (w1 - w0) * sigmoid((s - om) / ow) ds from 0 to o
    sp1 = ow * math.log1p(math.exp((o - om) / ow)) if (o - om) / ow < 30 else (o - om)
    sp0 = ow * math.log1p(math.exp(-om / ow))
    return w0 * o + (w1 - w0) * (sp1 - sp0)


@numba.njit(cache=True)
def _run(q, demand, n2, temp, noise, frame, out_i, out_y, max_dt=2.5e-4):  # pragma: no cover - compiled
    (rho, pr, dps100, ksv, inb, smax, wn, zeta, w0, w1, om, ow, cd, cleak, a1, a2, stroke, v0, beta, mass, bvisc,
     acd, faero, kp, ki, zmax, db, isat, wl, zl, nstd, qz, rmin, rmax, lap, kff, fc, tlag, kx, xref, tdrv, hyst,
     kleak20, vslope, droop, drift) = (q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7], q[8], q[9], q[10], q[11],
                                       q[12], q[13], q[14], q[15], q[16], q[17], q[18], q[19], q[20], q[21], q[22],
                                       q[23], q[24], q[25], q[26], q[27], q[28], q[29], q[30], q[31], q[32], q[33],
                                       q[34], q[35], q[36], q[37], q[38], q[39], q[40], q[41], q[42], q[43], q[44],
                                       q[45])
    n = demand.shape[0]
    nsub = max(int(math.ceil(frame / max_dt)), 1)
    dt = frame / nsub
    kq = cd * math.sqrt(2.0 / rho)
    kc = acd * math.sqrt(2.0 / rho)
    x = demand[0]
    v = 0.0
    ps0 = pr + dps100 * n2[0] ** 2
    p1 = 0.5 * (ps0 + pr)
    p2 = p1 * a1 / a2
    xs = 0.0
    vs = 0.0
    i_coil = 0.0
    i_play = 0.0
    yl = x
    yl_d = 0.0
    ylag = x
    z = 0.0
    qsup = 0.0
    top = math.floor((rmax - rmin) / qz) - 1.0
    for t in range(n):
        # sensor (value at the frame start)
        y = ylag + nstd * noise[t]
        code = math.floor((y - rmin) / qz + 0.5)
        code = min(max(code, 0.0), top)
        y = rmin + code * qz
        e = demand[t] - y
        if abs(e) > db:
            z = min(max(z + ki * e * frame, -zmax), zmax)
        i = min(max(kp * e + z, -isat), isat)
        out_i[t] = i
        out_y[t] = y
        ps_nom = pr + dps100 * n2[t] ** 2
        hours = t * frame / 3600.0
        if kleak20 > 0.0:
            kleak = kleak20 * math.exp(vslope * (temp[t] - 20.0))
        else:
            kleak = 0.0
        f_aero = faero * n2[t] ** 2
        for _ in range(nsub):
            # coil current: driver lag, slow drift; torque motor play (hysteresis)
            if tdrv > 0.0:
                i_coil += (i - i_coil) * (1.0 - math.exp(-dt / tdrv))
            else:
                i_coil = i
            i_eff = i_coil + drift * hours
            if hyst > 0.0:
                h = 0.5 * hyst
                if i_eff > i_play + h:
                    i_play = i_eff - h
                elif i_eff < i_play - h:
                    i_play = i_eff + h
            else:
                i_play = i_eff
            x_cmd = min(max(ksv * (i_play - inb), -smax), smax)
            ps = max(ps_nom - droop * qsup, pr + 1e4)
            # openings (positive spool: P->A and B->T open)
            oa = xs - lap
            ob = -xs - lap
            apa = _area(oa, w0, w1, om, ow)
            apb = _area(ob, w0, w1, om, ow)
            qpa = kq * apa * _sqrt_flow(ps - p1, 1.0) + cleak * (ps - p1)
            qat = kq * apb * _sqrt_flow(p1 - pr, 1.0) + cleak * (p1 - pr)
            qpb = kq * apb * _sqrt_flow(ps - p2, 1.0) + cleak * (ps - p2)
            qbt = kq * apa * _sqrt_flow(p2 - pr, 1.0) + cleak * (p2 - pr)
            qsup = max(qpa + qpb, 0.0)
            qc = kc * _sqrt_flow(p1 - p2, 1.0) + kleak * (p1 - p2)
            # spool: second order; Bernoulli force on the open edges as an extra centring stiffness
            kf = 0.0
            if kff > 0.0:
                ax = abs(xs)
                wx = w0 + (w1 - w0) / (1.0 + math.exp(-(ax - om) / ow))
                drop = (ps - p1) + (p2 - pr) if xs > 0 else (ps - p2) + (p1 - pr)
                kf = kff * max(drop, 0.0) / 7e6 * wx / w0
            acc_s = wn * wn * (x_cmd - xs * (1.0 + kf)) - 2.0 * zeta * wn * vs
            vs += acc_s * dt
            xs += vs * dt
            # cylinder chambers
            v1 = v0 + a1 * x
            v2 = v0 + a2 * (stroke - x)
            p1 += beta / v1 * (qpa - qat - a1 * v - qc) * dt
            p2 += beta / v2 * (qpb - qbt + a2 * v + qc) * dt
            p1 = max(p1, 1e4)
            p2 = max(p2, 1e4)
            f = p1 * a1 - p2 * a2 - f_aero - kx * (x - xref) - bvisc * v
            if fc > 0.0:
                # friction linearised about v and taken implicitly (its slope fc / 1 mm/s makes the
                # explicit update unstable below a few mm/s: the velocity chattered around zero there
                # and the mean friction vanished)
                th = math.tanh(v / 1e-3)
                f -= fc * th
                v += f / mass * dt / (1.0 + fc * (1.0 - th * th) / 1e-3 * dt / mass)
            else:
                v += f / mass * dt
            x += v * dt
            if x < 0.0:
                x = 0.0
                v = max(v, 0.0)
            elif x > stroke:
                x = stroke
                v = min(v, 0.0)
            # LVDT: second-order demodulation, then optional lag
            yl_d += (wl * wl * (x - yl) - 2.0 * zl * wl * yl_d) * dt
            yl += yl_d * dt
            if tlag > 0.0:
                ylag += (yl - ylag) * (1.0 - math.exp(-dt / tlag))
            else:
                ylag = yl
        if not (math.isfinite(x) and math.isfinite(p1) and math.isfinite(p2)):
            return 1
    return 0


def mission(duration_s: float, frame_s: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Demand [m], N2 [-] and fuel temperature [degC] of one flight (seeded).

    Engine start (N2 0.2 -> 0.62 in 40 s) with a full-stroke test sweep at ground idle, then
    phases at ground idle, take-off, climb, cruise, descent and approach; the demand follows a
    scheduled position plus random steps and ramps (fast moves saturate the current);
    the fuel warms from about 15 to 55 degC.
    """
    n = int(round(duration_s / frame_s))
    t = np.arange(n) * frame_s
    frac = t / duration_s
    knots = np.array([0.0, 40.0, 60.0, 0.12 * duration_s, 0.17 * duration_s, 0.3 * duration_s, 0.75 * duration_s,
                      0.9 * duration_s, duration_s])
    levels = np.array([0.2, 0.62, 0.62, 0.64, 0.97, 0.9, 0.86, 0.66, 0.74])
    n2 = np.interp(t, knots, levels) + 0.01 * np.sin(2 * np.pi * t / 37.0)
    base = 0.012 + 0.03 * (n2 - 0.2) / 0.8
    demand = base.copy()
    # test sweep at ground idle: 45-58 s, ramps to both ends
    sweep = (t >= 45.0) & (t < 58.0)
    demand[sweep] = 0.03 + 0.026 * np.sin(2 * np.pi * (t[sweep] - 45.0) / 6.5)
    # random moves after the start
    k = int(60.0 / frame_s)
    offset = np.zeros(n)
    while k < n:
        hold = int(rng.uniform(2.0, 12.0) / frame_s)
        target = rng.uniform(-0.012, 0.02)
        ramp = int(rng.choice([0.0, 0.0, 0.5, 2.0, 6.0]) / frame_s)
        prev = offset[k - 1]
        seg = np.full(min(hold, n - k), target)
        if ramp > 0:
            r = min(ramp, seg.size)
            seg[:r] = prev + (target - prev) * (np.arange(1, r + 1) / r)
        offset[k:k + seg.size] = seg
        k += seg.size
    demand = np.clip(demand + offset, 0.002, 0.058)
    demand[sweep] = 0.03 + 0.026 * np.sin(2 * np.pi * (t[sweep] - 45.0) / 6.5)
    temp = 15.0 + 40.0 * (1.0 - np.exp(-3.0 * frac)) + rng.normal(0.0, 0.5) + 0.3 * np.sin(2 * np.pi * t / 300.0)
    return demand, n2, temp


def simulate_flights(effects: AltEffects = AltEffects(), *, n_units: int = 2, n_flights: int = 2,
                     minutes: float = 4.0, frame_s: float = 0.01, noise_std_m: float = 3e-6,
                     dispersion: float = 1.0, seed: int = 0, substep_s: float = 2.5e-4) -> pd.DataFrame:
    """Simulate a fleet with the altsim, in the measured-data format.

    Parameters
    ----------
    effects : AltEffects
        Effects present in every unit (the "truth").
    n_units, n_flights : int
        Units and flights per unit.
    minutes : float
        Flight duration [min], >= 2.
    frame_s : float
        Sample period [s].
    noise_std_m : float
        LVDT noise [m].
    dispersion : float
        Scale of the manufacturing dispersion.
    seed : int
        Master seed.
    substep_s : float, default=2.5e-4
        Largest integration sub-step [s] (smaller: a convergence check).

    Returns
    -------
    pandas.DataFrame
        Columns ``flight_id, unit_id, time_s, current_mA, position_mm, demand_mm, n2_pct, fuel_temp_degC``.
    """
    if minutes < 2.0:
        raise range_error("minutes", ">= 2", minutes)
    if not (frame_s > 0 and frame_s <= 0.05):
        raise range_error("frame_s", "in (0, 0.05]", frame_s)
    if not (substep_s > 0 and substep_s <= 2.5e-4):
        raise range_error("substep_s", "in (0, 2.5e-4]", substep_s)
    nominal = AltParams(noise_std_m=noise_std_m, effects=effects)
    root = np.random.SeedSequence([int(seed), 4242])
    unit_seqs = root.spawn(n_units)
    parts = []
    fid = 0
    for u, us in enumerate(unit_seqs):
        rng_u = np.random.default_rng(us)
        unit = manufacture_alt(nominal, rng_u, dispersion)
        q = _pack(unit)
        for _ in range(n_flights):
            demand, n2, temp = mission(60.0 * minutes, frame_s, rng_u)
            noise = rng_u.standard_normal(demand.size)
            out_i = np.zeros(demand.size)
            out_y = np.zeros(demand.size)
            status = _run(q, demand, n2, temp, noise, float(frame_s), out_i, out_y, float(substep_s))
            if status != 0:
                raise ParameterError(f"altsim: non-finite state in unit {u}, flight {fid}; check the effects {effects}.")
            parts.append(pd.DataFrame({
                "flight_id": np.full(demand.size, fid, dtype=np.int64), "unit_id": np.full(demand.size, u, dtype=np.int64),
                "time_s": np.arange(demand.size) * frame_s, "current_mA": 1e3 * out_i, "position_mm": 1e3 * out_y,
                "demand_mm": 1e3 * demand, "n2_pct": 100.0 * n2, "fuel_temp_degC": temp}))
            fid += 1
    return pd.concat(parts, ignore_index=True)


__all__ = ["ALT_DISPERSION_ADDITIVE", "ALT_DISPERSION_RELATIVE", "AltEffects", "AltParams", "manufacture_alt",
           "mission", "simulate_flights"]
