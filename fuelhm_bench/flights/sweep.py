"""The paper's velocity-gain sweep (section IV.B): a slow open-loop current ramp.

Used to compute the velocity-gain curve of a model directly (recalibration,
indicator transformation laws) rather than from in-flight data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuelhm_bench.errors import range_error
from fuelhm_bench.physics._validation import check_fields
from fuelhm_bench.physics.simulate import FlightInputs, SimOutput, simulate


@dataclass(frozen=True)
class VelocityGainSweep:
    """The paper's velocity-gain sweep (section IV.B): a slow open-loop current ramp.

    The current ramps from the lower to the upper saturation and back (both
    directions, so that hysteresis shows), at constant engine speed, on a
    virtual bench without end stops.

    Parameters
    ----------
    current_min_a, current_max_a : float, default=-12e-3, 12e-3
        Ramp extremes [A].
    ramp_duration_s : float, default=60.0
        Duration of each one-way ramp [s].
    n2_frac : float, default=0.82
        Engine speed (sets the supply pressure; 0.82 gives about 70 bar) [-].
    frame_s : float, default=0.01
        Frame period [s].
    cycles : int, default=1
        Number of up-and-down cycles.
    """

    current_min_a: float = -12e-3
    current_max_a: float = 12e-3
    ramp_duration_s: float = 60.0
    n2_frac: float = 0.82
    frame_s: float = 0.01
    cycles: int = 1

    def __post_init__(self) -> None:
        check_fields(self, {
            "current_min_a": (-0.1, 0.1, True),
            "current_max_a": (-0.1, 0.1, True),
            "ramp_duration_s": (0.1, 1e5, True),
            "n2_frac": (0.3, 1.1, True),
            "frame_s": (1e-4, 1.0, True),
        })
        if self.current_max_a <= self.current_min_a:
            raise range_error("VelocityGainSweep.current_max_a", f"> current_min_a ({self.current_min_a:g})",
                              self.current_max_a)
        if not isinstance(self.cycles, int) or self.cycles < 1:
            raise range_error("VelocityGainSweep.cycles", "an integer >= 1", self.cycles)

    def inputs(self) -> FlightInputs:
        """The sweep as :class:`FlightInputs` (open-loop current, no end stops)."""
        n = max(int(round(self.ramp_duration_s / self.frame_s)), 2)
        up = np.linspace(self.current_min_a, self.current_max_a, n)
        one = np.concatenate([up, up[::-1]])
        current = np.tile(one, self.cycles)
        m = len(current)
        extras = {"n2_pct": np.full(m, 100.0 * self.n2_frac), "phase": np.zeros(m, dtype=np.int8)}
        return FlightInputs(np.zeros(m), np.full(m, self.n2_frac), self.frame_s, open_loop_current_a=current,
                            end_stops=False, extras=extras)


@dataclass(frozen=True)
class SweepResult:
    """Velocity-gain curve of a model from a sweep (SI units).

    Attributes
    ----------
    current_a : ndarray
        Imposed current [A].
    velocity_m_s : ndarray
        True mean rod velocity over each frame [m/s].
    increasing : ndarray of bool
        True on the up-ramp.
    output : SimOutput
        The full simulation output (LVDT position included).
    """

    current_a: np.ndarray
    velocity_m_s: np.ndarray
    increasing: np.ndarray
    output: SimOutput

    def zero_crossing_a(self, increasing: bool = True) -> float:
        """Current [A] at which the velocity crosses zero on the up- (or down-) ramp (linear interpolation)."""
        sel = self.increasing == increasing
        i, v = self.current_a[sel], self.velocity_m_s[sel]
        order = np.argsort(i)
        i, v = i[order], v[order]
        idx = np.flatnonzero(np.diff(np.sign(v)) > 0)
        if idx.size == 0:
            return float("nan")
        j = idx[len(idx) // 2]
        return float(i[j] - v[j] * (i[j + 1] - i[j]) / (v[j + 1] - v[j]))

    def velocity_at(self, current_a: float, increasing: bool = True) -> float:
        """Velocity [m/s] at a current [A] on the up- (or down-) ramp."""
        sel = self.increasing == increasing
        i, v = self.current_a[sel], self.velocity_m_s[sel]
        order = np.argsort(i)
        return float(np.interp(current_a, i[order], v[order]))


def run_sweep(model, sweep: VelocityGainSweep | None = None, *, seed: int = 0) -> SweepResult:
    """Simulate a velocity-gain sweep of ``model`` (fast path).

    The first 2 % of the ramp (start-up transient from rest) is dropped.
    """
    sweep = sweep if sweep is not None else VelocityGainSweep(frame_s=model.controller.frame_s)
    inp = sweep.inputs()
    out = simulate([model], [inp], [np.random.default_rng(seed)])[0]
    n_ramp = len(inp.open_loop_current_a) // (2 * sweep.cycles)
    inc = np.tile(np.concatenate([np.ones(n_ramp, bool), np.zeros(n_ramp, bool)]), sweep.cycles)
    keep = np.ones(len(inc), bool)
    keep[: max(n_ramp // 50, 1)] = False
    return SweepResult(inp.open_loop_current_a[keep], out.true_velocity_m_s[keep], inc[keep], out)
