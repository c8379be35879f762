"""Synthetic flights on a known piecewise-linear velocity-gain curve (tests, benchmarks, docs).

This is *not* the physical simulator (``fuelhm_bench.physics``): it draws a time series whose
velocity follows a prescribed dual-gain curve exactly, so that the extracted indicators can be
compared with known values.

* :class:`DualGainCurve`: the known curve. Null region of gain ``g_null`` between
  ``X1 = Inb - null_halfwidth_ma`` and ``X2 = Inb + null_halfwidth_ma``, passing through
  ``(I0, 0)`` with ``I0 = Inb + idle_offset_ma``; inlet gain ``g_in`` below X1 and outlet gain
  ``g_out`` above X2; saturation at ``v_retract_mm_s`` and ``v_extend_mm_s``.
* :func:`synthetic_flight`: idle periods (velocity 0, current wandering around ``I0`` in
  random levels of standard deviation ``idle_current_std_ma``: the known ``Hys0``)
  alternating with excursions (current ramps from I0 to a random peak and back). During a
  ramp the velocity is ``curve(i - hysteresis_ma * sign(di/dt))``, a rate-independent
  hysteresis of half-width ``hysteresis_ma``. Current and velocity are held over each frame
  (zero-order hold, as the FADEC's current), so the position is their exact integral
  (clipped at the end stops), plus white noise, quantized by an ADC. Optional saturation
  events drive the current to its limit and the rod onto an end stop, producing the
  spurious (I_sat, v=0) points the extractor must mask.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fuelhm_bench.errors import ParameterError, parameter_error


def _err(name: str, owner: str, allowed: str, given: object) -> ParameterError:
    return parameter_error(name, owner, allowed, given)


@dataclass(frozen=True)
class DualGainCurve:
    """A known dual-gain velocity-gain curve (mA -> mm/s) with saturation.

    Parameters
    ----------
    inb_ma : float, default=0.5
        Null bias current Inb, in mA (centre of the null region).
    null_halfwidth_ma : float, default=2.0
        Half-width of the null region, in mA (``X1 = Inb - w``, ``X2 = Inb + w``).
    idle_offset_ma : float, default=0.24
        ``I0 - Inb``, in mA (3 % of an 8 mA rated current).
    g_in, g_null, g_out : float, default=11.0, 6.0, 12.5
        Velocity gains of the inlet, null and outlet segments, in mm/s/mA.
    v_retract_mm_s, v_extend_mm_s : float, default=-75.0, 87.0
        Saturated velocities, in mm/s.

    Attributes
    ----------
    x1, x2, i0 : float
        Slope changes and idle current, in mA.
    y1, y2 : float
        Velocities at X1 and X2, in mm/s.
    s_in, s_out : float
        Currents where the velocity saturates, in mA.
    """

    inb_ma: float = 0.5
    null_halfwidth_ma: float = 2.0
    idle_offset_ma: float = 0.24
    g_in: float = 11.0
    g_null: float = 6.0
    g_out: float = 12.5
    v_retract_mm_s: float = -75.0
    v_extend_mm_s: float = 87.0

    def __post_init__(self) -> None:
        for name in ("null_halfwidth_ma", "g_in", "g_null", "g_out", "v_extend_mm_s"):
            if not getattr(self, name) > 0:
                raise _err(name, "DualGainCurve", "> 0", getattr(self, name))
        if abs(self.idle_offset_ma) >= self.null_halfwidth_ma:
            raise _err("idle_offset_ma", "DualGainCurve",
                       "smaller in magnitude than null_halfwidth_ma", self.idle_offset_ma)
        if not self.v_retract_mm_s < self.y1:
            raise _err("v_retract_mm_s", "DualGainCurve", f"< Y1 = {self.y1!r}",
                       self.v_retract_mm_s)
        if not self.v_extend_mm_s > self.y2:
            raise _err("v_extend_mm_s", "DualGainCurve", f"> Y2 = {self.y2!r}",
                       self.v_extend_mm_s)

    @property
    def x1(self) -> float:
        """First slope change (inlet / null), in mA."""
        return self.inb_ma - self.null_halfwidth_ma

    @property
    def x2(self) -> float:
        """Second slope change (null / outlet), in mA."""
        return self.inb_ma + self.null_halfwidth_ma

    @property
    def i0(self) -> float:
        """Idle current (zero velocity), in mA."""
        return self.inb_ma + self.idle_offset_ma

    @property
    def y1(self) -> float:
        """Velocity at X1, in mm/s."""
        return self.g_null * (self.x1 - self.i0)

    @property
    def y2(self) -> float:
        """Velocity at X2, in mm/s."""
        return self.g_null * (self.x2 - self.i0)

    @property
    def s_in(self) -> float:
        """Current below which the retraction velocity saturates, in mA."""
        return self.x1 + (self.v_retract_mm_s - self.y1) / self.g_in

    @property
    def s_out(self) -> float:
        """Current above which the extension velocity saturates, in mA."""
        return self.x2 + (self.v_extend_mm_s - self.y2) / self.g_out

    def velocity(self, current_ma: np.ndarray) -> np.ndarray:
        """Velocity (mm/s) at the given currents (mA)."""
        i = np.asarray(current_ma, dtype=np.float64)
        v = np.where(i < self.x1, self.y1 + self.g_in * (i - self.x1),
                     np.where(i > self.x2, self.y2 + self.g_out * (i - self.x2),
                              self.g_null * (i - self.i0)))
        return np.clip(v, self.v_retract_mm_s, self.v_extend_mm_s)

    def indicators(self, hys0_ma: float = math.nan) -> dict[str, float]:
        """The ten indicators of this curve (``Hys0`` is a property of the flight, passed in)."""
        return {"X1": self.x1, "Y1": self.y1, "X2": self.x2, "Y2": self.y2,
                "Inb": self.inb_ma, "I0": self.i0, "Hys0": float(hys0_ma), "G_in": self.g_in,
                "G_out": self.g_out, "G_null": self.g_null}


@dataclass(frozen=True, eq=False)
class SyntheticFlight:
    """A synthetic flight (the attributes :func:`~fuelhm_bench.indicators.extract_table` needs).

    Attributes
    ----------
    flight_id, unit_id : object
        Identifiers.
    time_s, current_ma, position_mm : numpy.ndarray
        Recorded signals: time (s), control current (mA), measured LVDT position (mm, noisy,
        quantized).
    velocity_mm_s, true_position_mm : numpy.ndarray
        Noise-free velocity (mm/s) and position (mm).
    curve : DualGainCurve
        The curve the flight was drawn on.
    truth : dict of str to float
        The known indicators (``Hys0`` = ``idle_current_std_ma``).
    """

    flight_id: object
    unit_id: object
    time_s: np.ndarray
    current_ma: np.ndarray
    position_mm: np.ndarray
    velocity_mm_s: np.ndarray
    true_position_mm: np.ndarray
    curve: DualGainCurve
    truth: dict[str, float] = field(default_factory=dict)


def _excursion_area(curve: DualGainCurve, start: float, peak: float) -> float:
    """Integral of |v| over the current from start to peak (mm/s * mA)."""
    grid = np.linspace(start, peak, 64)
    return float(abs(np.trapezoid(np.abs(curve.velocity(grid)), grid)))


def synthetic_flight(curve: DualGainCurve | None = None, *, rate_hz: float = 100.0,
                     n_excursions: int = 300, idle_s: tuple[float, float] = (0.5, 3.0),
                     ramp_rate_ma_s: tuple[float, float] = (10.0, 40.0),
                     peak_range_ma: tuple[float, float] | None = None,
                     max_excursion_mm: float = 20.0, hysteresis_ma: float = 0.1,
                     idle_current_std_ma: float = 0.05, idle_hold_s: float = 0.2,
                     position_noise_mm: float = 0.003,
                     adc_bits: int = 12, adc_range_mm: tuple[float, float] = (-5.0, 65.0),
                     stroke_mm: tuple[float, float] = (0.0, 60.0),
                     current_limit_ma: float = 12.0, saturation_events: int = 0,
                     time_jitter_s: float = 0.0, flight_id: object = 0, unit_id: object = None,
                     seed: int = 0) -> SyntheticFlight:
    """Draw a flight whose velocity follows ``curve`` (see the module docstring).

    Parameters
    ----------
    curve : DualGainCurve, optional
        The known curve (default :class:`DualGainCurve()`).
    rate_hz : float, default=100.0
        Frame rate, in Hz.
    n_excursions : int, default=300
        Number of excursions (each preceded by an idle period).
    idle_s : tuple of float, default=(0.5, 3.0)
        Range of the idle durations (uniform), in s.
    ramp_rate_ma_s : tuple of float, default=(10.0, 40.0)
        Range of the current ramp rates (uniform), in mA/s; raised when needed so that one
        excursion moves the rod by at most ``max_excursion_mm``.
    peak_range_ma : tuple of float, optional
        Lowest and highest excursion peak current, in mA (peaks are uniform between I0 +/- 1 mA
        and these bounds). Default ``(-(current_limit_ma - 0.2), current_limit_ma - 0.2)``.
        Restricting it produces flights that never reach a region of the curve.
    max_excursion_mm : float, default=20.0
        Largest rod travel of one excursion, in mm.
    hysteresis_ma : float, default=0.1
        Half-width of the rate-independent hysteresis during ramps, in mA.
    idle_current_std_ma : float, default=0.05
        Standard deviation of the current at idle, in mA (the known ``Hys0``).
    idle_hold_s : float, default=0.2
        The idle current is a sequence of random levels, each held this long, in s (a slow
        wander within the hysteresis band, not frame-rate noise).
    position_noise_mm : float, default=0.003
        Standard deviation of the white LVDT noise, in mm.
    adc_bits : int, default=12
        ADC resolution; 0 disables quantization.
    adc_range_mm : tuple of float, default=(-5.0, 65.0)
        ADC input range, in mm (quantum ``(high - low) / 2**adc_bits``).
    stroke_mm : tuple of float, default=(0.0, 60.0)
        End stops, in mm.
    current_limit_ma : float, default=12.0
        Controller current limit (saturation events), in mA.
    saturation_events : int, default=0
        Number of excursions replaced by a saturation event: current at ``+/-current_limit_ma``
        while the rod runs onto an end stop and stays there for 1-3 s (spurious
        ``(I_sat, v=0)`` points).
    time_jitter_s : float, default=0.0
        Irregular sampling: each interval between samples is ``1/rate_hz`` plus a uniform
        draw in ``[-time_jitter_s, time_jitter_s]`` (the position is integrated over the actual
        intervals), in s; must be below half a frame.
    flight_id, unit_id : object
        Identifiers copied to the result.
    seed : int, default=0
        Seed of ``numpy.random.default_rng``.

    Returns
    -------
    SyntheticFlight
    """
    crv = DualGainCurve() if curve is None else curve
    if not rate_hz > 0:
        raise _err("rate_hz", "synthetic_flight", "> 0", rate_hz)
    if not 0 <= time_jitter_s < 0.5 / rate_hz:
        raise _err("time_jitter_s", "synthetic_flight", "in [0, half a frame)", time_jitter_s)
    if n_excursions < 0 or saturation_events < 0 or saturation_events > n_excursions:
        raise _err("saturation_events", "synthetic_flight", "in [0, n_excursions]",
                   saturation_events)
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    lim = current_limit_ma - 0.2
    peak_lo, peak_hi = (-lim, lim) if peak_range_ma is None else peak_range_ma
    mid = 0.5 * (stroke_mm[0] + stroke_mm[1])
    i0 = crv.i0
    sat_at = set(rng.choice(n_excursions, size=saturation_events, replace=False).tolist())

    currents: list[np.ndarray] = []
    velocities: list[np.ndarray] = []
    positions: list[np.ndarray] = []
    intervals: list[np.ndarray] = []
    x_next = mid  # position of the next sample

    def append(cur: np.ndarray, vel: np.ndarray, clip: bool = False) -> None:
        # Zero-order hold: sample k's current and velocity hold until sample k+1.
        nonlocal x_next
        steps_s = np.full(len(cur), dt)
        if time_jitter_s > 0:
            steps_s += rng.uniform(-time_jitter_s, time_jitter_s, len(cur))
        intervals.append(steps_s)
        pos = x_next + np.concatenate(([0.0], np.cumsum(vel[:-1] * steps_s[:-1])))
        if clip:  # the rod stops at an end stop: truncate the motion that would pass it
            ends = pos + vel * steps_s
            beyond = (ends < stroke_mm[0]) | (ends > stroke_mm[1])
            if beyond.any():
                k = int(np.argmax(beyond))
                target = stroke_mm[1] if ends[k] > stroke_mm[1] else stroke_mm[0]
                vel = vel.copy()
                vel[k] = (target - pos[k]) / steps_s[k]
                vel[k + 1:] = 0.0
                pos[k + 1:] = target
        currents.append(cur)
        velocities.append(vel)
        positions.append(pos)
        x_next = float(pos[-1] + vel[-1] * steps_s[-1])

    def idle(n_samples: int) -> np.ndarray:
        # Piecewise-constant levels around I0, each held for idle_hold_s.
        hold = max(int(round(idle_hold_s * rate_hz)), 1)
        levels = i0 + idle_current_std_ma * rng.standard_normal(-(-n_samples // hold))
        return np.repeat(levels, hold)[:n_samples]

    def ramp(start: float, stop: float, rate: float) -> tuple[np.ndarray, np.ndarray]:
        n = max(int(math.ceil(abs(stop - start) / (rate * dt))), 1)
        cur = np.linspace(start, stop, n + 1)[1:]
        sign = 1.0 if stop > start else -1.0
        return cur, crv.velocity(cur - hysteresis_ma * sign)

    direction = 1.0
    for e in range(n_excursions):
        n_idle = max(int(rate_hz * rng.uniform(*idle_s)), 1)
        append(idle(n_idle), np.zeros(n_idle))
        direction = 1.0 if x_next < mid else -1.0
        if e in sat_at:  # current limit, rod onto the end stop, hold, then back to idle
            i_sat = direction * current_limit_ma
            cur_up, vel_up = ramp(i0, i_sat, 200.0)
            append(cur_up, vel_up)
            v_sat = float(crv.velocity(np.array([i_sat]))[0])
            travel = (stroke_mm[1] if direction > 0 else stroke_mm[0]) - x_next
            n_hold = int(abs(travel) / abs(v_sat) * rate_hz) + int(rate_hz * rng.uniform(1, 3))
            append(np.full(n_hold, i_sat), np.full(n_hold, v_sat), clip=True)
            cur_dn, _ = ramp(i_sat, i0, 200.0)
            append(cur_dn, np.zeros(len(cur_dn)))  # pressed on the stop until the current is back
            continue
        if direction > 0:
            peak = rng.uniform(min(i0 + 1.0, peak_hi), peak_hi)
        else:
            peak = rng.uniform(peak_lo, max(i0 - 1.0, peak_lo))
        rate = rng.uniform(*ramp_rate_ma_s)
        rate = max(rate, 2.0 * _excursion_area(crv, i0, peak) / max_excursion_mm)
        for a, b in ((i0, peak), (peak, i0)):
            cur, vel = ramp(a, b, rate)
            append(cur, vel, clip=True)
    n_idle = max(int(rate_hz * rng.uniform(*idle_s)), 1)
    append(idle(n_idle), np.zeros(n_idle))

    current = np.concatenate(currents)
    velocity = np.concatenate(velocities)
    true_pos = np.concatenate(positions)
    n = len(current)
    steps_all = np.concatenate(intervals)
    time = np.concatenate(([0.0], np.cumsum(steps_all[:-1])))
    measured = true_pos + position_noise_mm * rng.standard_normal(n)
    if adc_bits > 0:
        lo, hi = adc_range_mm
        q = (hi - lo) / 2**adc_bits
        measured = lo + np.clip(np.round((measured - lo) / q), 0, 2**adc_bits - 1) * q
    return SyntheticFlight(
        flight_id=flight_id, unit_id=unit_id, time_s=time, current_ma=current,
        position_mm=measured, velocity_mm_s=velocity, true_position_mm=true_pos, curve=crv,
        truth=crv.indicators(idle_current_std_ma),
    )
