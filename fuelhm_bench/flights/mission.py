"""Mission profile: engine speed, position demand, temperature and phases of a flight.

A flight is: engine start (recording starts at ground idle; the FADEC then
strokes the actuator end to end with demand ramps at increasing rates, the
*test sweep*, the fastest ramp faster than the actuator can follow so that the
current sweeps through the velocity saturation), taxi, take-off, climb, cruise,
descent, approach, landing (with reverse thrust) and taxi-in.

Engine speed is the output of engine dynamics, never of per-frame noise. The
*speed demand* is each phase's set point plus random throttle steps (operating
variability) plus a slow band-limited fluctuation (a first-order Gauss-Markov
process with correlation time ``n2_noise_time_constant_s``: gusts, fuel-control
and bleed changes). The HP spool follows that demand through a first-order lag
(``engine_time_constant_s``), so N2 is twice low-pass filtered and carries no
power above a few tenths of a hertz (docs/physics.md §5 Mission and excitation).
The variable-geometry demand is the VSV schedule of that N2 (closed at low
speed, open at high speed), so the actuator moves mostly in transients. The
supply pressure follows N2 inside the physics (see
:class:`~fuelhm_bench.physics.fluid.FluidParams`). Fuel temperature drifts over
the flight (recorded; the nominal model has no temperature effect).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from numba import njit

from fuelhm_bench.errors import range_error
from fuelhm_bench.physics._validation import NON_NEGATIVE, POSITIVE, check_fields
from fuelhm_bench.physics.simulate import FlightInputs

#: Phase names, their share of the time after engine start, and their N2 set point [-].
PHASES: tuple[tuple[str, float, float], ...] = (
    ("taxi", 0.05, 0.62),
    ("take_off", 0.02, 1.00),
    ("climb", 0.15, 0.95),
    ("cruise", 0.50, 0.85),
    ("descent", 0.12, 0.66),
    ("approach", 0.08, 0.74),
    ("landing", 0.03, 0.60),
    ("taxi_in", 0.05, 0.60),
)
PHASE_NAMES: tuple[str, ...] = ("engine_start",) + tuple(p[0] for p in PHASES)


@njit(cache=True, nogil=True)
def first_order_filter(x: np.ndarray, gain: float, pole: float, z0: float) -> np.ndarray:
    """``scipy.signal.lfilter([gain], [1, -pole], x, zi=[z0])[0]``, bit for bit, without its overheads.

    The transposed direct form II recursion of ``lfilter`` with the same operations in the same
    order (``y = z + gain x``, then ``z = 0 x - (-pole) y``; compiled without fast-math, so
    nothing is contracted or reordered): ``y[k] = pole y[k-1] + gain x[k]``.
    """
    y = np.empty(x.shape[0])
    _first_order_filter_into(x, gain, pole, z0, y, False)
    return y


@njit(cache=True, nogil=True)
def _first_order_filter_into(x: np.ndarray, gain: float, pole: float, z0: float, out: np.ndarray,
                             accumulate: bool) -> None:
    """``out[:] = first_order_filter(...)``, or ``out += first_order_filter(...)`` with ``accumulate``, in one pass."""
    a1 = -pole
    z = z0
    for k in range(x.shape[0]):
        xk = x[k]
        yk = z + gain * xk
        z = 0.0 * xk - a1 * yk
        if accumulate:
            out[k] = out[k] + yk
        else:
            out[k] = yk


@njit(cache=True, nogil=True)
def _flight_channels(target, n_start, drive, b, start, a, n2_max, n2_low, n2_span, low_m, span_m, sweep):
    """N2 [-], demand [m], ``100 n2`` [%] and ``1e3 demand`` [mm] of a flight, in one compiled pass.

    Bit for bit the three steps of :meth:`MissionProfile.sample` it replaces, each with the same
    operations in the same order (compiled without fast-math):
    ``_first_order_filter_into(drive, 1.0, b, start, target[n_start:], True)`` (the speed demand's
    Gauss-Markov fluctuation; skipped when ``drive`` is empty), then
    ``first_order_filter(target, 1 - a, a, a * target[0])`` (the HP spool's lag; its recursion runs
    on the unclipped output), then the clip of N2 to [0, ``n2_max``], the demand of
    :meth:`MissionProfile.demand_from_n2` (``low + clip((n2 - a) / (b - a), 0, 1) * (high - low)``)
    with its first ``len(sweep)`` samples replaced by the test sweep, and the recorded channels. One
    pass instead of three: the two recursions interleave, and the arrays are read and written once.
    """
    n = target.shape[0]
    m = sweep.shape[0]
    n2 = np.empty(n)
    demand = np.empty(n)
    n2_pct = np.empty(n)
    demand_mm = np.empty(n)
    noisy = drive.shape[0] > 0
    a1_noise = -b
    z_noise = start
    gain = 1.0 - a
    a1 = -a
    z = 0.0
    for k in range(n):
        tk = target[k]
        if noisy and k >= n_start:
            xk = drive[k - n_start]
            yk = z_noise + 1.0 * xk
            z_noise = 0.0 * xk - a1_noise * yk
            tk = tk + yk
        if k == 0:
            z = a * tk
        y = z + gain * tk
        z = 0.0 * tk - a1 * y
        v = y
        if v < 0.0:
            v = 0.0
        elif v > n2_max:
            v = n2_max
        n2[k] = v
        if k < m:
            d = sweep[k]
        else:
            u = (v - n2_low) / n2_span
            if u < 0.0:
                u = 0.0
            elif u > 1.0:
                u = 1.0
            d = u * span_m + low_m
        demand[k] = d
        n2_pct[k] = 100.0 * v
        demand_mm[k] = 1e3 * d
    return n2, demand, n2_pct, demand_mm


@functools.lru_cache(maxsize=16)
def _test_sweep(T: float, lo: float, hi: float, rates: tuple, n_start: int) -> np.ndarray:
    """Demand [m] of the engine-start test sweep (ramps up and down at each rate ``rates`` [m/s] between
    ``lo`` and ``hi`` [m], then hold) over ``n_start`` frames of ``T`` [s]: the same for every flight
    of a profile, so made once and read-only."""
    parts = [np.full(int(2.0 / T), lo)]
    for rate in rates:
        m = max(int(round((hi - lo) / rate / T)), 1)
        ramp = np.linspace(lo, hi, m + 1)[1:]
        parts += [ramp, np.full(int(1.0 / T), hi), ramp[::-1], np.full(int(1.0 / T), lo)]
    seq = np.concatenate(parts)
    out = np.full(n_start, lo)
    out[: min(n_start, seq.size)] = seq[:n_start]
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class MissionProfile:
    """Parameters of the flight profile.

    Parameters
    ----------
    duration_s : float, default=3600.0
        Flight duration [s], at least ``start_duration_s + 60``, at most 86400 (one day).
    frame_s : float, default=0.01
        Sample (controller frame) period [s].
    start_duration_s : float, default=60.0
        Engine start including the actuator test sweep [s].
    test_sweep : bool, default=True
        Whether the FADEC strokes the actuator end to end during engine start.
    sweep_rates_m_s : tuple of float, default=(0.008, 0.015, 0.03, 0.05, 0.07, 0.09, 0.11)
        Demand ramp rates of the test sweep [m/s], each ramp up then down; the sweep is
        cut short if it does not fit in ``start_duration_s``.
    sweep_low_m, sweep_high_m : float, default=0.003, 0.057
        Demand extremes of the test sweep and of the N2 schedule [m].
    schedule_n2_low, schedule_n2_high : float, default=0.55, 1.0
        N2 range over which the demand moves from low to high [-].
    engine_time_constant_s : float, default=3.0
        First-order lag of the HP spool speed N2 behind its demand [s].
    throttle_step_std : float, default=0.025
        Standard deviation of random throttle steps around the set point [-].
    throttle_step_interval_s : float, default=90.0
        Mean interval between throttle steps [s].
    n2_noise_std : float, default=0.002
        Standard deviation of the slow band-limited fluctuation of the speed demand [-]
        (stationary std of the Gauss-Markov process, before the engine lag).
    n2_noise_time_constant_s : float, default=5.0
        Correlation time of that fluctuation [s].
    fuel_temp_start_degc, fuel_temp_end_degc : float, default=15.0, 70.0
        Mean fuel temperature at start and end [degC] (each flight draws around them).
    """

    duration_s: float = 3600.0
    frame_s: float = 0.01
    start_duration_s: float = 60.0
    test_sweep: bool = True
    sweep_rates_m_s: tuple = (0.008, 0.015, 0.03, 0.05, 0.07, 0.09, 0.11)
    sweep_low_m: float = 0.003
    sweep_high_m: float = 0.057
    schedule_n2_low: float = 0.55
    schedule_n2_high: float = 1.0
    engine_time_constant_s: float = 3.0
    throttle_step_std: float = 0.025
    throttle_step_interval_s: float = 90.0
    n2_noise_std: float = 0.002
    n2_noise_time_constant_s: float = 5.0
    fuel_temp_start_degc: float = 15.0
    fuel_temp_end_degc: float = 70.0

    def __post_init__(self) -> None:
        check_fields(self, {
            "duration_s": (0.0, 86400.0, False),  # at most one day (a scenario's duration_min <= 1440)
            "frame_s": (1e-4, 1.0, True),
            "start_duration_s": (20.0, 600.0, True),
            "sweep_low_m": NON_NEGATIVE,
            "sweep_high_m": POSITIVE,
            "schedule_n2_low": (0.0, 1.2, True),
            "schedule_n2_high": (0.0, 1.2, True),
            "engine_time_constant_s": POSITIVE,
            "throttle_step_std": (0.0, 0.2, True),
            "throttle_step_interval_s": POSITIVE,
            "n2_noise_std": (0.0, 0.05, True),
            "n2_noise_time_constant_s": (0.5, 600.0, True),
            "fuel_temp_start_degc": (-60.0, 150.0, True),
            "fuel_temp_end_degc": (-60.0, 150.0, True),
        })
        if self.duration_s < self.start_duration_s + 60.0:
            raise range_error("MissionProfile.duration_s", f">= start_duration_s + 60 ({self.start_duration_s + 60:g} s)",
                              self.duration_s)
        rates = self.sweep_rates_m_s
        if not isinstance(rates, tuple) or not rates or not all(
                isinstance(r, (int, float)) and 0.0 < r <= 1.0 for r in rates):
            raise range_error("MissionProfile.sweep_rates_m_s", "a non-empty tuple of rates in (0, 1] m/s", rates)
        if self.sweep_high_m <= self.sweep_low_m:
            raise range_error("MissionProfile.sweep_high_m", f"> sweep_low_m ({self.sweep_low_m:g})", self.sweep_high_m)
        if self.schedule_n2_high <= self.schedule_n2_low:
            raise range_error("MissionProfile.schedule_n2_high", f"> schedule_n2_low ({self.schedule_n2_low:g})",
                              self.schedule_n2_high)

    @property
    def n_frames(self) -> int:
        """Number of frames in a flight."""
        return int(round(self.duration_s / self.frame_s))

    def demand_from_n2(self, n2: np.ndarray) -> np.ndarray:
        """Scheduled position demand [m] for engine speed ``n2`` [-]."""
        # One buffer, updated in place (the same operations in the same order as
        # ``low + clip((n2 - a) / (b - a), 0, 1) * (high - low)``: bit for bit, without temporaries).
        out = np.asarray(np.subtract(n2, self.schedule_n2_low))  # a new array (0-d for a scalar)
        np.divide(out, self.schedule_n2_high - self.schedule_n2_low, out=out)
        np.clip(out, 0.0, 1.0, out=out)
        np.multiply(out, self.sweep_high_m - self.sweep_low_m, out=out)
        np.add(out, self.sweep_low_m, out=out)
        return out[()] if out.ndim == 0 else out

    def sample(self, rng: np.random.Generator, *, fuel_temperature: bool = True) -> FlightInputs:
        """Draw one flight's inputs.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of the operating variability.
        fuel_temperature : bool, default=True
            Compute the ``fuel_temp_degC`` channel. Its draws are made either way, so every
            other channel is the same, bit for bit; False leaves it out for callers that keep
            only the indicators of a model without ``viscosity_temperature`` (a flight-long
            ``exp``: about a tenth of the sampling time).

        Returns
        -------
        FlightInputs
            With extras ``n2_pct``, ``fuel_temp_degC`` (unless ``fuel_temperature`` is False),
            ``phase`` (phase index into :data:`PHASE_NAMES`) and ``demand_mm``.
        """
        T = self.frame_s
        n = self.n_frames
        n_start = min(int(round(self.start_duration_s / T)), n)
        # Phase set points after the start, with durations jittered by +/-20 %.
        shares = np.array([p[1] for p in PHASES]) * rng.uniform(0.8, 1.2, len(PHASES))
        shares /= shares.sum()
        bounds = n_start + np.round(np.cumsum(np.concatenate([[0.0], shares])) * (n - n_start)).astype(int)
        bounds[-1] = n
        target = np.empty(n)
        phase = np.zeros(n, dtype=np.int8)
        idle = 0.6 + rng.normal(0.0, 0.01)
        target[:n_start] = idle
        for j, (_, _, n2_set) in enumerate(PHASES):
            target[bounds[j]:bounds[j + 1]] = n2_set + rng.normal(0.0, 0.01)
            phase[bounds[j]:bounds[j + 1]] = j + 1
        # Throttle steps (operating variability) after the start.
        n_steps = rng.poisson((n - n_start) * T / self.throttle_step_interval_s)
        if n_steps:
            starts = np.sort(rng.integers(n_start, n, n_steps))
            lengths = rng.integers(int(5 / T), int(60 / T) + 1, n_steps)
            amps = rng.normal(0.0, self.throttle_step_std, n_steps)
            for s, ln, a in zip(starts, lengths, amps):
                target[s:s + ln] += a
        # Reverse thrust burst at landing.
        land = bounds[PHASE_NAMES.index("landing") - 1]
        target[land + int(3 / T): land + int(15 / T)] = 0.85
        # Slow band-limited fluctuation of the speed demand after the start: first-order
        # Gauss-Markov process (exact discrete update, stationary std n2_noise_std).
        b, start, drive = 0.0, 0.0, np.empty(0)
        if self.n2_noise_std > 0.0 and n > n_start:
            b = np.exp(-T / self.n2_noise_time_constant_s)
            drive = rng.normal(0.0, self.n2_noise_std * np.sqrt(1.0 - b * b), n - n_start)
            start = b * rng.normal(0.0, self.n2_noise_std)  # stationary initial state
        # HP spool: first-order lag behind the speed demand (exact discrete update); N2 clipped to
        # [0, 1.15], the scheduled demand (test sweep first) and the recorded channels: one compiled pass
        # (_flight_channels: the fluctuation added to the demand, then the lag, then the schedule).
        a = np.exp(-T / self.engine_time_constant_s)
        sweep = (_test_sweep(T, self.sweep_low_m, self.sweep_high_m, self.sweep_rates_m_s, n_start)
                 if self.test_sweep and n_start > 0 else np.empty(0))
        n2, demand, n2_pct, demand_mm = _flight_channels(
            target, n_start, drive, float(b), float(start), float(a), 1.15, float(self.schedule_n2_low),
            float(self.schedule_n2_high - self.schedule_n2_low), float(self.sweep_low_m),
            float(self.sweep_high_m - self.sweep_low_m), sweep)
        temp0 = self.fuel_temp_start_degc + rng.normal(0.0, 8.0)
        temp1 = self.fuel_temp_end_degc + rng.normal(0.0, 8.0)
        extras = {"n2_pct": n2_pct}
        if fuel_temperature:
            tau = 0.3 * self.duration_s
            # temp1 + (temp0 - temp1) * exp(-t / tau) with t = k T, in one buffer (same operations, same bits).
            fuel_temp = np.arange(n, dtype=np.float64)  # exact integers, as np.arange(n) converted for the product
            np.multiply(fuel_temp, T, out=fuel_temp)
            np.negative(fuel_temp, out=fuel_temp)
            np.divide(fuel_temp, tau, out=fuel_temp)
            np.exp(fuel_temp, out=fuel_temp)
            np.multiply(fuel_temp, temp0 - temp1, out=fuel_temp)
            np.add(fuel_temp, temp1, out=fuel_temp)
            extras["fuel_temp_degC"] = fuel_temp
        extras.update(phase=phase, demand_mm=demand_mm)
        return FlightInputs(demand, n2, T, extras=extras)
