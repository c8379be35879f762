"""Reference integrator: the same equations as the fast path, solved by ``scipy.integrate.solve_ivp``.

Between two controller frames the current is held (zero-order hold) and the
continuous states ``[x_s, x_fb, x, y, y', y_lag]`` (spool, feedback point, rod,
LVDT filter) are integrated, segment by segment between the spool's mode changes
(play taken up, spool on its stop, located by events), with an implicit method (Radau by default) at tight
tolerances and a small maximum step. The right-hand side uses the same physics
functions as the fast path (spool command, friction dead zone, play operator,
quasi-static rod velocity from the direct solver, LVDT filter matrices), but
none of the fast path's discretisation (no exact piecewise spool update, no
Gauss points, no velocity table, no first-order-hold filter update). The
controller and the ADC run at the frame boundaries exactly as in the fast path.
This path is slow (about a second of wall time per simulated second): use it
on short segments to validate :func:`~fuelhm_bench.physics.simulate.simulate`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from fuelhm_bench.errors import NumericalError
from fuelhm_bench.physics import kernel
from fuelhm_bench.physics.lvdt import lvdt_state_matrix
from fuelhm_bench.physics.simulate import FlightInputs, SimOutput


def simulate_reference(model, inputs: FlightInputs, rng: np.random.Generator, *, method: str = "Radau",
                       rtol: float = 1e-8, atol_m: float = 1e-11, max_step_s: float | None = None) -> SimOutput:
    """Simulate one flight with the reference solver.

    Parameters
    ----------
    model : LoopModel
        The unit.
    inputs : FlightInputs
        Its inputs.
    rng : numpy.random.Generator
        Noise generator (draws exactly as the fast path does).
    method : str, default="Radau"
        Implicit ``solve_ivp`` method ("Radau" or "BDF").
    rtol : float, default=1e-8
        Relative tolerance.
    atol_m : float, default=1e-11
        Absolute tolerance on positions [m] (velocities: ``atol_m * 1e3``).
    max_step_s : float, optional
        Maximum step [s]; default ``frame / 40`` (0.25 ms at 100 Hz).

    Returns
    -------
    SimOutput
    """
    c, k, _ = kernel.pack_model(model)
    lag = model.effect("lvdt_lag")
    a_mat, b_vec = lvdt_state_matrix(model.lvdt, lag.time_constant_s if lag else 0.0)
    T = inputs.frame_s
    n = inputs.n_frames
    max_step = max_step_s if max_step_s is not None else T / 40.0
    noise = rng.standard_normal(n)
    stroke = model.cylinder.stroke_m
    end_stops = inputs.end_stops
    q = model.lvdt.quantum_m
    rmin, rmax = model.lvdt.range_min_m, model.lvdt.range_max_m
    top = math.floor((rmax - rmin) / q) - 1.0 if q > 0 else 0.0
    rate, half_play = k[kernel.K_RATE], k[kernel.K_HPLAY]
    spool_stroke = k[kernel.K_SSTROKE]
    state = {"p1": float("nan")}

    x0 = float(inputs.demand_m[0]) if end_stops else 0.0
    s = np.array([0.0, 0.0, x0, x0, 0.0, x0])
    z = 0.0
    out_i = np.zeros(n)
    out_y = np.zeros(n)
    out_x = np.zeros(n)
    out_v = np.zeros(n)
    atol = np.array([atol_m, atol_m, atol_m, atol_m, atol_m * 1e3, atol_m])
    for t in range(n):
        y = (s[5] if lag else s[3]) + k[kernel.K_NOISE] * noise[t]
        if q > 0:
            code = min(max(math.floor((y - rmin) / q + 0.5), 0.0), top)
            y = rmin + code * q
        i_open = None if inputs.open_loop_current_a is None else inputs.open_loop_current_a[t]
        if i_open is None or math.isnan(i_open):
            e = inputs.demand_m[t] - y
            if abs(e) > k[kernel.K_DB]:
                z = min(max(z + k[kernel.K_KI] * e * T, -k[kernel.K_ZMAX]), k[kernel.K_ZMAX])
            i = min(max(k[kernel.K_KP] * e + z, -k[kernel.K_ISAT]), k[kernel.K_ISAT])
        else:
            i = float(i_open)
        n2 = float(inputs.n2_frac[t])
        dps = k[kernel.K_DPS100] * n2 * n2
        f_aero = k[kernel.K_FAERO100] * n2 * n2
        dp12 = 0.0  # the flow force reads the chamber pressures of the frame start (as the fast path)
        if k[kernel.K_FF] > 0.0:
            dp12 = kernel.load_pressure(state["p1"], f_aero + k[kernel.K_KX] * (s[2] - k[kernel.K_XREF]), c)
        x_c = kernel.spool_command(i, dps, k, dp12)
        dz = k[kernel.K_FRICNUM] / max(dps, 1e5)

        # Spool mode over this frame (x_c held): stuck, free travel in the play, engaged, at its stop.
        e0 = x_c - s[1]
        sgn = 1.0 if e0 > 0.0 else -1.0

        def rhs(_t, st, x_c=x_c, dz=dz, dps=dps, f_aero=f_aero, mode="stuck", e0=e0, sgn=sgn):
            x_s, x_fb, x = st[0], st[1], st[2]
            if mode in ("stuck", "stop"):
                vs = 0.0
                vfb = 0.0
            elif mode == "free":
                vs = rate * (e0 - sgn * dz)
                vfb = 0.0
            else:
                vs = rate * (x_c + sgn * (half_play - dz) - x_s)
                vfb = vs
            if dps <= 0.0:
                v = 0.0
            else:
                f_load = f_aero + k[kernel.K_KX] * (x - k[kernel.K_XREF])
                v, state["p1"] = kernel.rod_velocity(x_s, dps, f_load, state["p1"], c, k)
            if end_stops and ((x <= 0.0 and v < 0.0) or (x >= stroke and v > 0.0)):
                v = 0.0
            ds = a_mat @ st[3:] + b_vec * x
            return np.array([vs, vfb, v, ds[0], ds[1], ds[2]])

        def hit_play(_t, st, sgn=sgn):
            return sgn * (st[0] - st[1]) - half_play

        def hit_stop(_t, st, sgn=sgn):
            return sgn * st[0] - spool_stroke

        hit_play.terminal = hit_stop.terminal = True
        hit_play.direction = hit_stop.direction = 1.0
        t0, cur = 0.0, s
        # the first segment's mode from the state; later ones are set by the event ending the previous one
        if abs(e0) <= dz:
            mode = "stuck"
        elif sgn * cur[0] >= spool_stroke:
            mode = "stop"
        elif sgn * (cur[0] - cur[1]) < half_play:
            mode = "free"
        else:
            mode = "engaged"
        for _ in range(4):  # at most stuck | free -> engaged -> stop
            events = {"free": [hit_play, hit_stop], "engaged": [hit_stop]}.get(mode)

            def rhs_mode(tt, st, mode=mode):
                return rhs(tt, st, mode=mode)

            with np.errstate(over="ignore"):  # scipy's Jacobian step-factor growth may overflow harmlessly
                sol = solve_ivp(rhs_mode, (t0, T), cur, method=method, rtol=rtol, atol=atol, max_step=max_step,
                                events=events)
            if not (sol.success and sol.status == 1):
                cur = sol.y[:, -1].copy()
                break
            t0 = float(sol.t[-1])
            cur = sol.y[:, -1].copy()
            if sol.t_events[0].size and mode == "free":  # play taken up: engaged from here
                cur[1] = cur[0] - sgn * half_play
                mode = "engaged"
            else:  # spool on its stop
                cur[0] = sgn * spool_stroke
                cur[1] = min(max(cur[1], cur[0] - half_play), cur[0] + half_play)
                mode = "stop"
            if t0 >= T:
                break
        if not sol.success or not np.all(np.isfinite(cur)):
            raise NumericalError(f"Reference solver failed at frame {t} (t = {t * T:.3f} s): {sol.message}")
        new = cur.copy()
        if end_stops:
            new[2] = min(max(new[2], 0.0), stroke)
        out_i[t] = i
        out_y[t] = y
        out_x[t] = s[2]
        out_v[t] = (new[2] - s[2]) / T
        s = new
    return SimOutput(inputs.time_s, out_i, out_y, out_x, out_v)
