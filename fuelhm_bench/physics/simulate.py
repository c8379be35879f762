"""High-level entry point of the fast path: simulate flights of given units.

:func:`simulate` takes one model per flight (a degraded, manufactured unit), the
flight's exogenous inputs (:class:`FlightInputs`) and a noise generator per flight,
and returns the recorded signals. Each flight's noise is drawn from its own
``numpy.random.Generator``, so results do not depend on how flights are batched.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fuelhm_bench.errors import NumericalError, ParameterError, range_error
from fuelhm_bench.physics import kernel

_TABLE_CACHE: OrderedDict[bytes, np.ndarray] = OrderedDict()
_TABLE_CACHE_SIZE = 256


@dataclass(frozen=True)
class FlightInputs:
    """Exogenous inputs of one flight, sampled at the controller frame.

    Parameters
    ----------
    demand_m : ndarray (n,)
        Position demand [m].
    n2_frac : ndarray (n,)
        Engine HP speed N2 as a fraction of 100 % [-].
    frame_s : float
        Frame period [s] (must equal the model's controller frame).
    open_loop_current_a : ndarray (n,) or None, default=None
        If given, the current is imposed (velocity-gain sweep) and the controller is bypassed [A].
    end_stops : bool, default=True
        If False the rod is not limited by its stroke (virtual test bench for sweeps).
    forced_position_m : ndarray (n,) or None, default=None
        If given, the rod position is reset to these values [m] at the start of each
        frame (NaN entries: free). Used to replay measured flights: with the measured
        current imposed too, each frame's simulated motion starts from the measured state.
    extras : dict, default={}
        Extra channels to carry to the flight table (e.g. ``fuel_temp_degC``, ``phase``).
    """

    demand_m: np.ndarray
    n2_frac: np.ndarray
    frame_s: float
    open_loop_current_a: np.ndarray | None = None
    end_stops: bool = True
    forced_position_m: np.ndarray | None = None
    extras: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.demand_m)
        if n < 1:
            raise range_error("FlightInputs.demand_m", "a non-empty array (duration > 0)", n)
        if len(self.n2_frac) != n:
            raise range_error("FlightInputs.n2_frac", f"of length {n} (as demand_m)", len(self.n2_frac))
        if self.open_loop_current_a is not None and len(self.open_loop_current_a) != n:
            raise range_error("FlightInputs.open_loop_current_a", f"of length {n}", len(self.open_loop_current_a))
        if self.forced_position_m is not None and len(self.forced_position_m) != n:
            raise range_error("FlightInputs.forced_position_m", f"of length {n}", len(self.forced_position_m))
        if not (self.frame_s > 0):
            raise range_error("FlightInputs.frame_s", "> 0", self.frame_s)

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return len(self.demand_m)

    @property
    def time_s(self) -> np.ndarray:
        """Sample times [s]."""
        return np.arange(self.n_frames) * self.frame_s


@dataclass(frozen=True)
class SimOutput:
    """Signals of one simulated flight (SI units).

    Attributes
    ----------
    time_s, current_a, measured_position_m, true_position_m, true_velocity_m_s : ndarray (n,)
        Sample time, commanded current, LVDT measurement, true rod position at the
        sample, mean rod velocity over the following frame.
    """

    time_s: np.ndarray
    current_a: np.ndarray
    measured_position_m: np.ndarray
    true_position_m: np.ndarray
    true_velocity_m_s: np.ndarray


def velocity_table(c: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Velocity table for packed coefficients, memoised on their bytes."""
    key = c.tobytes() + k[[kernel.K_SSTROKE, kernel.K_DPS100, kernel.K_FAERO100]].tobytes()
    table = _TABLE_CACHE.get(key)
    if table is None:
        table = kernel.build_velocity_table(c, k, kernel.TABLE_N2, kernel.TABLE_NX)
        _TABLE_CACHE[key] = table
        if len(_TABLE_CACHE) > _TABLE_CACHE_SIZE:
            _TABLE_CACHE.popitem(last=False)
    else:
        _TABLE_CACHE.move_to_end(key)
    return table


def simulate(models: Sequence, inputs: Sequence[FlightInputs], rngs: Sequence[np.random.Generator], *,
             use_table: bool = True, labels: Sequence[str] | None = None) -> list[SimOutput]:
    """Simulate a batch of flights with the fast integrator.

    Parameters
    ----------
    models : sequence of LoopModel
        One model per flight (already manufactured and degraded).
    inputs : sequence of FlightInputs
        One input set per flight.
    rngs : sequence of numpy.random.Generator
        One generator per flight for the sensor noise.
    use_table : bool, default=True
        Use the tabulated velocity where the model allows it (see :mod:`~fuelhm_bench.physics.kernel`).
    labels : sequence of str, optional
        Names of the flights for error messages (e.g. ``"unit 3, flight 12"``).

    Returns
    -------
    list of SimOutput

    Raises
    ------
    NumericalError
        If a flight produced a non-finite value (names the flight).
    """
    nb = len(models)
    if not (len(inputs) == nb and len(rngs) == nb):
        raise ParameterError(f"simulate: got {nb} models, {len(inputs)} inputs and {len(rngs)} generators; they must match.")
    if nb == 0:
        return []
    n_max = max(inp.n_frames for inp in inputs)
    cs = np.zeros((nb, kernel.cyl.C_N))
    ks = np.zeros((nb, kernel.K_N))
    lvs = np.zeros((nb, 3, 5))
    use = np.zeros(nb, dtype=np.bool_)
    tables = []
    # The kernel reads and writes frames 0 .. length - 1 of each row only: no need to zero the rows.
    demand = np.empty((nb, n_max))
    n2s = np.empty((nb, n_max))
    noise = np.empty((nb, n_max))
    # Open-loop currents and forced positions only take memory when some flight uses them.
    any_open = any(inp.open_loop_current_a is not None for inp in inputs)
    any_force = any(inp.forced_position_m is not None for inp in inputs)
    i_open = np.full((nb, n_max if any_open else 1), np.nan)
    x_force = np.full((nb, n_max if any_force else 1), np.nan)
    x0 = np.zeros(nb)
    lengths = np.zeros(nb, dtype=np.int64)
    for b, (model, inp, rng) in enumerate(zip(models, inputs, rngs)):
        if abs(inp.frame_s - model.controller.frame_s) > 1e-12:
            raise range_error("FlightInputs.frame_s", f"equal to the model's controller frame ({model.controller.frame_s:g} s)",
                              inp.frame_s)
        temp = inp.extras.get("fuel_temp_degC") if model.effect("viscosity_temperature") else None
        c, k, lv = kernel.pack_model(model, 20.0 if temp is None else float(np.mean(temp)))
        k[kernel.K_ENDSTOPS] = 1.0 if inp.end_stops else 0.0
        cs[b], ks[b], lvs[b] = c, k, lv
        n = inp.n_frames
        lengths[b] = n
        demand[b, :n] = inp.demand_m
        n2s[b, :n] = inp.n2_frac
        rng.standard_normal(out=noise[b, :n])  # same draws as standard_normal(n), without a copy
        if inp.open_loop_current_a is not None:
            i_open[b, :n] = inp.open_loop_current_a
        if inp.forced_position_m is not None:
            x_force[b, :n] = inp.forced_position_m
        x0[b] = float(inp.demand_m[0]) if inp.end_stops else 0.0
        if inp.forced_position_m is not None and np.isfinite(inp.forced_position_m[0]):
            x0[b] = float(inp.forced_position_m[0])
        use[b] = use_table and k[kernel.K_DIRECT] == 0.0
        tables.append(velocity_table(c, k) if use[b] else None)
    shape = next((t.shape for t in tables if t is not None), (2, 2))
    tab = np.zeros((nb,) + shape)
    for b, t in enumerate(tables):
        if t is not None:
            tab[b] = t
    out_i = np.empty((nb, n_max))
    out_y = np.empty((nb, n_max))
    out_x = np.empty((nb, n_max))
    out_v = np.empty((nb, n_max))
    status = np.zeros(nb, dtype=np.int64)
    kernel.simulate_batch(cs, ks, lvs, tab, use, lengths, demand, n2s, noise, i_open, x_force, x0,
                          out_i, out_y, out_x, out_v, status)
    results = []
    times: dict[tuple[int, float], np.ndarray] = {}  # one read-only time vector per (length, frame)
    for b in range(nb):
        if status[b] != kernel.STATUS_OK:
            name = labels[b] if labels is not None else f"flight {b} of the batch"
            raise NumericalError(f"The simulator produced a non-finite value for {name}; "
                                 f"check its parameters (model: {models[b]!r:.200}).")
        n = lengths[b]
        key = (int(n), float(inputs[b].frame_s))
        if key not in times:
            times[key] = inputs[b].time_s
            times[key].flags.writeable = False
        results.append(SimOutput(times[key], out_i[b, :n], out_y[b, :n], out_x[b, :n], out_v[b, :n]))
    return results
