"""Replay measured flights through a model and compare velocities sample by sample.

Why replay
----------
A closed-loop simulation of a measured flight drifts away from it (the model's
current differs, the rod ends elsewhere), so its curve can only be compared in
aggregate. Replaying imposes what was measured: the recorded current is fed to the
servovalve open loop (``FlightInputs.open_loop_current_a``), the recorded N2 sets the
supply pressure and the load (a documented constant when the file has no ``n2_pct``),
end stops are off, and the rod position is reset to the measured position at the start
of every frame (``FlightInputs.forced_position_m``), so the rod state cannot drift. What
the model then predicts, frame by frame, is the rod's mean velocity ``v_k`` over the frame
from the measured state: a one-step-ahead prediction.

Sensor dynamics
---------------
The measured position went through the LVDT (demodulation filter, optional lag
``lvdt_lag``). The kernel's own LVDT output is not usable in replay (it filters the
*forced* position, which jumps at every frame start), so the model's sensor is applied
here, exactly: with ``E = [E_s | E_u | E_du]`` the first-order-hold discretisation of the
model's LVDT (:func:`~fuelhm_bench.physics.lvdt.lvdt_discretization`) and ``w = s - [x, 0, x]``
the deviation of the filter states from the rod position, the filter driven by the
per-frame velocities ``v_k`` is::

    w_{k+1} = E_s w_k + (E_du - [1, 0, 1] T) v_k
    d_k     = (y_{k+1} - y_k) / T = v_k + C (w_{k+1} - w_k) / T

where ``C`` reads the demodulated (or, with ``lvdt_lag``, the lagged) state. ``d_k`` is the
model's per-frame rate of the *measured* position; it goes through the same
differentiator weights as the measured rates (:mod:`~fuelhm_bench.calibration.velocity`),
so sensor effects such as ``lvdt_lag`` are compared like for like. The filter starts each
segment in steady state at its first velocity; the first ``warmup_s`` of a segment are
not scored.

Sample selection
----------------
Flights are cut into *runs* of uniform sampling (an interval differing from the frame by
more than ``frame_tolerance``, such as a gap, splits a flight).
A sample is *valid* if its differentiator window is complete, N2 is finite, the rod is
not within ``end_stop_margin_mm`` of an end stop of the model's stroke (nor within
``end_stop_dilate_s`` of such a sample), and it is not a
*stall* (current within ``current_limit_margin_ma`` of the flight's current extreme while
the rod does not move faster than ``stall_velocity_mm_s``: integrator wind-up against a stop).
A valid sample is *moving* if ``|v| >= moving_velocity_mm_s`` or its current changes
faster than ``direction_rate_ma_s``; otherwise it is *idle*. Replayed segments are the
moving runs (merged when closer than two warm-ups, padded by a warm-up on each side) cut
into blocks of at most ``max_segment_s``, plus idle blocks of ``idle_block_s`` (padded
likewise) making at most ``idle_share`` of the scored samples: an actuator is idle most of
a flight, and idle samples repeat one point of the curve. ``max_frames`` caps the replayed
frames, which bounds the cost of one model evaluation during the fits: moving segments are
then drawn (seeded) so as to cover the curve evenly (see ``_select``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numba
import numpy as np
from scipy import signal

from fuelhm_bench.calibration import velocity as vel
from fuelhm_bench.errors import DataFormatError, range_error
from fuelhm_bench.physics.lvdt import lvdt_discretization
from fuelhm_bench.physics.simulate import FlightInputs, simulate


@dataclass(frozen=True)
class ReplayConfig:
    """How measured flights are prepared for replay (differentiator, masks, selection).

    Parameters
    ----------
    half_width : int, default=2
        Half-width ``h`` of the differentiator [samples].
    n2_default_pct : float, default=85.0
        N2 used when a flight has no ``n2_pct`` column [%] (cruise; sets the supply pressure).
    end_stop_margin_mm : float, default=0.5
        Samples whose window comes within this distance of ``0`` or the model's stroke are masked [mm].
    end_stop_dilate_s : float, default=0.3
        The end-stop mask is extended by this time on both sides [s] (the rod touches the stop
        before a lagging sensor shows it, and leaves it after).
    current_limit_margin_ma : float, default=0.05
        Margin around a flight's current extremes for the stall mask [mA].
    stall_velocity_mm_s : float, default=1.0
        A sample at a current extreme moving slower than this is a stall (masked) [mm/s].
    frame_tolerance : float, default=0.05
        Relative deviation of an interval from the frame still taken as uniform [-]; a longer
        (a gap) or shorter interval splits the flight.
    direction_rate_ma_s : float, default=2.0
        Current rate separating rising / falling from steady samples [mA/s].
    moving_velocity_mm_s : float, default=2.0
        Speed from which a sample is *moving* [mm/s].
    warmup_s : float, default=0.2
        Unscored lead-in (and tail) of every replayed segment [s].
    idle_block_s : float, default=0.5
        Length of the idle blocks [s].
    max_segment_s : float, default=5.0
        Longest scored part of a moving segment [s]; longer moving runs are cut.
    idle_share : float, default=0.3
        Largest share of idle samples among the scored samples, in [0, 0.9].
    max_frames : int or None, default=None
        Cap on the replayed frames of a set (None: no cap).
    """

    half_width: int = 2
    n2_default_pct: float = 85.0
    end_stop_margin_mm: float = 0.5
    end_stop_dilate_s: float = 0.3
    current_limit_margin_ma: float = 0.05
    stall_velocity_mm_s: float = 1.0
    frame_tolerance: float = 0.05
    direction_rate_ma_s: float = 2.0
    moving_velocity_mm_s: float = 2.0
    warmup_s: float = 0.2
    idle_block_s: float = 0.5
    max_segment_s: float = 5.0
    idle_share: float = 0.3
    max_frames: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.half_width, int) or isinstance(self.half_width, bool) or not 1 <= self.half_width <= 20:
            raise range_error("ReplayConfig.half_width", "an integer in [1, 20]", self.half_width)
        for name, lo, hi in (("n2_default_pct", 30.0, 110.0), ("end_stop_margin_mm", 0.0, 10.0),
                             ("end_stop_dilate_s", 0.0, 10.0),
                             ("current_limit_margin_ma", 0.0, 5.0), ("stall_velocity_mm_s", 0.0, 50.0),
                             ("frame_tolerance", 0.0, 0.5),
                             ("direction_rate_ma_s", 0.0, 1e4), ("moving_velocity_mm_s", 0.0, 100.0),
                             ("warmup_s", 0.0, 10.0), ("idle_block_s", 0.01, 100.0),
                             ("max_segment_s", 0.05, 1e4), ("idle_share", 0.0, 0.9)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi):
                raise range_error(f"ReplayConfig.{name}", f"a number in [{lo:g}, {hi:g}]", v)
        if self.max_frames is not None and (isinstance(self.max_frames, bool) or not isinstance(self.max_frames, int)
                                            or self.max_frames < 1000):
            raise range_error("ReplayConfig.max_frames", "None or an integer >= 1000", self.max_frames)


@dataclass(frozen=True, eq=False)
class ReplaySet:
    """Measured samples prepared for replay: concatenated segments of uniformly sampled frames.

    Arrays of length ``N`` (the replayed frames) unless stated.

    Attributes
    ----------
    frame_s : float
        Frame (sample) period [s].
    current_a : numpy.ndarray
        Recorded current [A] (imposed open loop).
    position_m : numpy.ndarray
        Measured position [m] (forced at each frame start).
    n2_frac : numpy.ndarray
        Engine speed [-] (fraction of 100 %).
    starts, lengths : numpy.ndarray of int (S,)
        Segments in the concatenation.
    scored : numpy.ndarray of bool
        Samples whose velocity residual is scored (valid, complete window, past the warm-up).
    v_meas_mm_s : numpy.ndarray
        Differentiated measured position [mm/s] (NaN where the window is incomplete).
    i_ma : numpy.ndarray
        Matched current [mA].
    direction : numpy.ndarray of int8
        Current direction (:data:`~fuelhm_bench.calibration.velocity.RISING`, ...).
    moving : numpy.ndarray of bool
        Moving (as opposed to idle) samples.
    position_mm : numpy.ndarray
        Measured position [mm].
    flight : numpy.ndarray of int
        Index of the flight in ``flight_ids``.
    phase : numpy.ndarray of object or None
        Flight phase names, when the file has them.
    flight_ids, unit_ids : tuple
        Identifiers of the flights (``unit_ids`` entries may be None).
    n2_measured : bool
        Whether N2 came from the file (else ``ReplayConfig.n2_default_pct``).
    config : ReplayConfig
        The configuration used.
    time_s : numpy.ndarray or None
        Time in flight of every sample [s] (for the sparse probe of the discrepancy workflow).
    fuel_temp_degc : numpy.ndarray or None
        Fuel temperature [degC], when the file has ``fuel_temp_degC``.
    flight_fuel_temp_degc : tuple of float or None
        Mean fuel temperature of each whole flight [degC] (the simulator's per-flight value).
    """

    frame_s: float
    current_a: np.ndarray
    position_m: np.ndarray
    n2_frac: np.ndarray
    starts: np.ndarray
    lengths: np.ndarray
    scored: np.ndarray
    v_meas_mm_s: np.ndarray
    i_ma: np.ndarray
    direction: np.ndarray
    moving: np.ndarray
    position_mm: np.ndarray
    flight: np.ndarray
    phase: np.ndarray | None
    flight_ids: tuple
    unit_ids: tuple
    n2_measured: bool
    config: ReplayConfig = field(default_factory=ReplayConfig)
    time_s: np.ndarray | None = None
    fuel_temp_degc: np.ndarray | None = None
    flight_fuel_temp_degc: tuple | None = None

    @property
    def n_frames(self) -> int:
        """Number of replayed frames."""
        return int(self.current_a.shape[0])

    @property
    def n_scored(self) -> int:
        """Number of scored samples."""
        return int(np.count_nonzero(self.scored))


# --------------------------------------------------------------------------- frames
def estimate_frame(flights) -> float:
    """Common sample period of the flights: the median interval [s].

    Raises
    ------
    DataFormatError
        If a flight's median interval differs from the common one by more than 5 %
        (flights at several sample rates must be replayed separately).
    """
    medians = [float(np.median(np.diff(f.time_s))) for f in flights if f.n_samples > 1]
    if not medians:
        raise DataFormatError("No flight has two samples: the sample period cannot be determined.")
    frame = float(np.median(medians))
    for f, m in zip(flights, medians):
        if abs(m - frame) > 0.05 * frame:
            raise DataFormatError(
                f"Flight {f.flight_id!r} is sampled every {m:g} s while the other flights are sampled every "
                f"{frame:g} s; the replay needs one frame period (the FADEC frame). Split the file by sample rate.")
    return frame


def _runs(time_s: np.ndarray, frame_s: float, cfg: ReplayConfig) -> list[tuple[int, int]]:
    """(start, stop) of the runs of uniform sampling of one flight."""
    dt = np.diff(time_s)
    bad = np.abs(dt - frame_s) > cfg.frame_tolerance * frame_s
    cuts = np.flatnonzero(bad) + 1
    bounds = np.concatenate([[0], cuts, [time_s.shape[0]]])
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b - a > 2 * cfg.half_width + 1]


def _true_runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and stop (exclusive) of each run of True."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def _run_samples(flight, a: int, b: int, frame_s: float, stroke_mm: float, cfg: ReplayConfig, n2_pct: np.ndarray,
                 i_lo: float, i_hi: float) -> dict:
    """Measured quantities and masks of one uniform run ``[a, b)`` of a flight."""
    h = cfg.half_width
    pos = np.asarray(flight.position_mm[a:b], dtype=float)
    cur = np.asarray(flight.current_ma[a:b], dtype=float)
    v = vel.windowed(vel.frame_rates(pos, frame_s), h)
    i_m = vel.matched_current(cur, h)
    direction = vel.current_direction(cur, h, frame_s, cfg.direction_rate_ma_s)
    n = pos.shape[0]
    # Window extremes of the position (for the end-stop mask).
    pad = np.pad(pos, h, mode="edge")
    win = np.lib.stride_tricks.sliding_window_view(pad, 2 * h + 1)
    near_stop = (win.min(axis=1) <= cfg.end_stop_margin_mm) | (win.max(axis=1) >= stroke_mm - cfg.end_stop_margin_mm)
    k = int(math.ceil(cfg.end_stop_dilate_s / frame_s))
    if k > 0 and near_stop.any():  # the rod may touch the stop before the (lagged) measurement shows it
        # centred window of 2k+1 samples, n values even for a run shorter than the window
        near_stop = np.convolve(near_stop.astype(float), np.ones(2 * k + 1), mode="full")[k:k + n] > 0.5
    at_limit = (cur >= i_hi - cfg.current_limit_margin_ma) | (cur <= i_lo + cfg.current_limit_margin_ma)
    stall = at_limit & (np.abs(np.nan_to_num(v)) < cfg.stall_velocity_mm_s)
    n2 = n2_pct[a:b]
    valid = np.isfinite(v) & np.isfinite(i_m) & ~near_stop & ~stall & np.isfinite(n2)
    moving = valid & ((np.abs(v) >= cfg.moving_velocity_mm_s) | (direction != vel.STEADY))
    return {"pos": pos, "cur": cur, "v": v, "i_m": i_m, "dir": direction, "valid": valid, "moving": moving,
            "n2": n2, "n": n}


def _segments_of_run(valid: np.ndarray, moving: np.ndarray, warm: int, block: int,
                     max_block: int) -> tuple[list, list]:
    """Moving segments and idle blocks of one run, as (start, stop, core_start, core_stop)."""
    n = valid.shape[0]
    s, e = _true_runs(moving)
    merged: list[list[int]] = []
    for a, b in zip(s, e):
        if merged and a - merged[-1][1] < 2 * warm:
            merged[-1][1] = int(b)
        else:
            merged.append([int(a), int(b)])
    # Long moving runs (e.g. continuous idle hunting) are cut into blocks so that a frame cap
    # draws from all of them.
    pieces = []
    for a, b in merged:
        for c in range(a, b, max_block):
            pieces.append((c, min(c + max_block, b)))
    moving_segs = [(max(a - warm, 0), min(b + warm, n), a, b) for a, b in pieces]
    covered = np.zeros(n, dtype=bool)
    for a0, b0, _, _ in moving_segs:
        covered[a0:b0] = True
    idle = valid & ~moving & ~covered
    idle_segs = []
    s, e = _true_runs(idle)
    for a, b in zip(s, e):
        for c in range(int(a), int(b) - block // 2, block):
            d = min(c + block, int(b))
            idle_segs.append((max(c - warm, 0), min(d + warm, n), c, d))
    return moving_segs, idle_segs


def prepare_replay(flights, *, config: ReplayConfig = ReplayConfig(), stroke_m: float = 0.06,
                   frame_s: float | None = None, seed: int = 0) -> ReplaySet:
    """Cut measured flights into replay segments and compute the measured velocities.

    Parameters
    ----------
    flights : sequence of FlightArrays
        Checked flights (:func:`fuelhm_bench.io.split_flights`), in file units (s, mA, mm, %).
    config : ReplayConfig
        Differentiator, masks and selection.
    stroke_m : float, default=0.06
        Stroke of the model's cylinder [m] (end-stop mask).
    frame_s : float, optional
        Sample period [s]; default :func:`estimate_frame`.
    seed : int, default=0
        Seed of the segment draw when ``config.max_frames`` caps the set.

    Returns
    -------
    ReplaySet

    Raises
    ------
    DataFormatError
        If no flight has a sample left to score.
    """
    cfg = config
    flights = list(flights)
    if frame_s is None:
        frame_s = estimate_frame(flights)
    h = cfg.half_width
    warm = max(int(math.ceil(cfg.warmup_s / frame_s)), h)
    block = max(int(round(cfg.idle_block_s / frame_s)), 2 * h + 1)
    max_block = max(int(round(cfg.max_segment_s / frame_s)), block)
    stroke_mm = 1e3 * stroke_m
    n2_measured = all("n2_pct" in f.extras for f in flights)
    pieces: list[dict] = []  # one per segment
    n_intervals = n_irregular = longest_run = 0  # for the error message when nothing can be scored
    for fi, f in enumerate(flights):
        n2_pct = np.asarray(f.extras["n2_pct"], dtype=float) if n2_measured else np.full(f.n_samples,
                                                                                          cfg.n2_default_pct)
        phase = f.extras.get("phase")
        temp = f.extras.get("fuel_temp_degC")
        i_lo, i_hi = float(np.min(f.current_ma)), float(np.max(f.current_ma))
        dt = np.diff(np.asarray(f.time_s, dtype=float))
        n_intervals += dt.size
        n_irregular += int(np.count_nonzero(np.abs(dt - frame_s) > cfg.frame_tolerance * frame_s))
        for a, b in _runs(np.asarray(f.time_s), frame_s, cfg):
            longest_run = max(longest_run, b - a)
            r = _run_samples(f, a, b, frame_s, stroke_mm, cfg, n2_pct, i_lo, i_hi)
            mov, idl = _segments_of_run(r["valid"], r["moving"], warm, block, max_block)
            for kind, segs in (("moving", mov), ("idle", idl)):
                for s0, s1, c0, c1 in segs:
                    scored = np.zeros(s1 - s0, dtype=bool)
                    scored[c0 - s0:c1 - s0] = r["valid"][c0:c1]
                    # Scores need the segment's own window: drop the first/last h samples.
                    scored[:max(warm, h)] = False
                    scored[len(scored) - h:] = False
                    if not scored.any():
                        continue
                    sel = np.flatnonzero(scored) + s0
                    cells = (np.floor(r["i_m"][sel] / 0.25).astype(np.int64) * 3
                             + np.sign(np.where(np.abs(r["v"][sel]) < cfg.moving_velocity_mm_s, 0.0,
                                                r["v"][sel])).astype(np.int64) + 1)
                    pieces.append({
                        "kind": kind, "flight": fi, "scored": scored, "n_scored": int(scored.sum()), "cells": cells,
                        "cur": r["cur"][s0:s1], "pos": r["pos"][s0:s1], "n2": r["n2"][s0:s1],
                        "phase": None if phase is None else np.asarray(phase[a:b], dtype=object)[s0:s1],
                        "time": np.asarray(f.time_s, dtype=float)[a:b][s0:s1],
                        "temp": None if temp is None else np.asarray(temp[a:b], dtype=float)[s0:s1],
                    })
    if not pieces:
        need = 2 * warm + 2 * h + 1
        sampling = ""
        if n_intervals and longest_run < need:
            sampling = (f" Sampling: {100.0 * n_irregular / n_intervals:.1f} % of the intervals between samples "
                        f"differ from the frame ({frame_s:g} s, the median interval) by more than "
                        f"{100.0 * cfg.frame_tolerance:g} % (ReplayConfig.frame_tolerance), and the longest uniform "
                        f"run is {longest_run} samples: resample the flights onto a uniform time base.")
        raise DataFormatError(
            "No sample of the flights can be scored: every sample is masked (end stops, current limits, "
            "missing N2) or the flights are too short for the differentiator. The replay needs flights with "
            f"runs of at least {need} uniformly sampled frames away from the end stops.{sampling}")
    pieces = _select(pieces, cfg, frame_s, seed)
    return _assemble(pieces, flights, frame_s, cfg, n2_measured, h)


def _water_level(counts: np.ndarray, total: float) -> float:
    """Level ``t`` with ``sum(min(counts, t)) = total`` (``inf`` when everything fits)."""
    c = np.sort(counts.astype(float))
    if c.sum() <= total:
        return math.inf
    below = np.concatenate([[0.0], np.cumsum(c)])
    for j in range(c.size):
        # level between c[j-1] and c[j]: sum = below[j] + t * (size - j)
        t = (total - below[j]) / (c.size - j)
        if t <= c[j]:
            return max(t, 1.0)
    return float(c[-1])


def _select(pieces: list[dict], cfg: ReplayConfig, frame_s: float, seed: int) -> list[dict]:
    """Apply the frame cap to the moving segments (stratified over the curve) and the idle share.

    Under a cap, moving segments are drawn so as to cover the curve evenly: each scored sample
    falls in a cell (current bin of 0.25 mA x sign of the velocity); a water level ``t`` per
    cell is set so that the cells filled up to ``t`` hold the budget; segments are visited in
    a seeded random order and kept while at least half of their samples fall in cells still
    below ``t``; the rest of the budget is filled at random. Rare parts of the curve (fast
    transients, saturation) are kept whole, abundant ones (idle hunting) are thinned.
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7401]))
    moving = [p for p in pieces if p["kind"] == "moving"]
    idle = [p for p in pieces if p["kind"] == "idle"]
    n_frames = sum(len(p["cur"]) for p in moving)
    if cfg.max_frames is not None and n_frames > (1.0 - cfg.idle_share) * cfg.max_frames:
        budget = (1.0 - cfg.idle_share) * cfg.max_frames
        n_scored = sum(p["n_scored"] for p in moving)
        cells = np.concatenate([p["cells"] for p in moving])
        uniq, inverse = np.unique(cells, return_inverse=True)
        level = _water_level(np.bincount(inverse), budget * n_scored / max(n_frames, 1))
        lookup = {c: j for j, c in enumerate(uniq)}
        filled = np.zeros(uniq.size)
        order = rng.permutation(len(moving))
        kept, used = set(), 0
        for j in order:
            size = len(moving[j]["cur"])
            if used + size > budget:
                continue
            idx = np.array([lookup[c] for c in moving[j]["cells"]], dtype=np.int64)
            if idx.size and np.mean(filled[idx] < level) >= 0.5:
                np.add.at(filled, idx, 1.0)
                kept.add(int(j))
                used += size
        for j in order:
            size = len(moving[j]["cur"])
            if int(j) not in kept and used + size <= budget:
                kept.add(int(j))
                used += size
        moving = [moving[j] for j in sorted(kept)]
    n_moving_scored = sum(p["n_scored"] for p in moving)
    idle_budget = cfg.idle_share / (1.0 - cfg.idle_share) * max(n_moving_scored, 1)
    if not moving:  # only idle data: keep it all (the caller reports the lack of excitation)
        idle_budget = sum(p["n_scored"] for p in idle)
    if cfg.max_frames is not None:
        idle_budget = min(idle_budget, max(cfg.max_frames - sum(len(p["cur"]) for p in moving), 0))
    order = rng.permutation(len(idle))
    kept_idle, used = [], 0
    for j in order:
        if used + idle[j]["n_scored"] > idle_budget:
            continue
        kept_idle.append(j)
        used += idle[j]["n_scored"]
    idle = [idle[j] for j in sorted(kept_idle)]
    out = moving + idle
    out.sort(key=lambda p: p["flight"])
    return out


def _assemble(pieces: list[dict], flights, frame_s: float, cfg: ReplayConfig, n2_measured: bool, h: int) -> ReplaySet:
    lengths = np.array([len(p["cur"]) for p in pieces], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    cur = np.concatenate([p["cur"] for p in pieces])
    pos = np.concatenate([p["pos"] for p in pieces])
    n2 = np.concatenate([p["n2"] for p in pieces])
    scored = np.concatenate([p["scored"] for p in pieces])
    flight = np.concatenate([np.full(len(p["cur"]), p["flight"], dtype=np.int64) for p in pieces])
    moving = np.concatenate([np.full(len(p["cur"]), p["kind"] == "moving") for p in pieces])
    has_phase = all(p["phase"] is not None for p in pieces)
    phase = np.concatenate([p["phase"] for p in pieces]) if has_phase else None
    v = np.empty(cur.shape[0])
    i_m = np.empty(cur.shape[0])
    direction = np.empty(cur.shape[0], dtype=np.int8)
    for s, n in zip(starts, lengths):
        v[s:s + n] = vel.windowed(vel.frame_rates(pos[s:s + n], frame_s), h)
        i_m[s:s + n] = vel.matched_current(cur[s:s + n], h)
        direction[s:s + n] = vel.current_direction(cur[s:s + n], h, frame_s, cfg.direction_rate_ma_s)
    scored &= np.isfinite(v)
    return ReplaySet(
        frame_s=float(frame_s), current_a=1e-3 * cur, position_m=1e-3 * pos, n2_frac=1e-2 * n2, starts=starts,
        lengths=lengths, scored=scored, v_meas_mm_s=v, i_ma=i_m, direction=direction, moving=moving & scored,
        position_mm=pos, flight=flight, phase=phase,
        flight_ids=tuple(f.flight_id for f in flights), unit_ids=tuple(f.unit_id for f in flights),
        n2_measured=n2_measured, config=cfg, time_s=np.concatenate([p["time"] for p in pieces]),
        fuel_temp_degc=(np.concatenate([p["temp"] for p in pieces]) if all(p["temp"] is not None for p in pieces)
                        else None),
        flight_fuel_temp_degc=(tuple(float(np.nanmean(f.extras["fuel_temp_degC"])) for f in flights)
                               if all("fuel_temp_degC" in f.extras for f in flights) else None))


# --------------------------------------------------------------------------- model side
def sensor_rate_filter(model, frame_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Transfer function from the rod's per-frame velocity to the per-frame rate of the LVDT reading.

    Parameters
    ----------
    model : LoopModel
        Supplies the LVDT parameters and the optional ``lvdt_lag``.
    frame_s : float
        Frame period [s].

    Returns
    -------
    b, a : numpy.ndarray
        Numerator and denominator for :func:`scipy.signal.lfilter` (unit DC gain).
    """
    lag = model.effect("lvdt_lag")
    num, den, _ = _rate_filter(model.lvdt, lag.time_constant_s if lag else None, float(frame_s))
    return num.copy(), den.copy()


@functools.lru_cache(maxsize=512)
def _rate_filter(lvdt, lag_s: float | None, frame_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`sensor_rate_filter` by value (memoised: a fit replays the same LVDT thousands of times),
    and the normalised filter's steady-state initial conditions per unit input; read-only arrays."""
    e = lvdt_discretization(lvdt, lag_s if lag_s is not None else 0.0, frame_s)
    e_s, e_du = e[:, :3], e[:, 4]
    ones = np.array([1.0, 0.0, 1.0])
    b_vec = e_du - ones * frame_s
    c = np.array([0.0, 0.0, 1.0]) if lag_s is not None else np.array([1.0, 0.0, 0.0])
    c_out = c @ (e_s - np.eye(3)) / frame_s
    d = 1.0 + c @ b_vec / frame_s
    num, den = signal.ss2tf(e_s, b_vec.reshape(3, 1), c_out.reshape(1, 3), np.array([[d]]))
    num, den = np.asarray(num[0], dtype=float), np.asarray(den, dtype=float)
    zi0 = signal.lfilter_zi(num / den[0], den / den[0])
    for a in (num, den, zi0):
        a.flags.writeable = False
    return num, den, zi0


@functools.lru_cache(maxsize=16)
def _window_weights(half_width: int) -> np.ndarray:
    w = vel.window_weights(half_width)
    w.flags.writeable = False
    return w


@numba.njit(cache=True)
def _sensor_windowed(v_rod, starts, lengths, b, a, zi0, w, h, out):  # pragma: no cover - compiled
    """Per segment: LVDT rate filter (DF2T, steady-state start) then the differentiator window."""
    order = a.shape[0] - 1
    nw = w.shape[0]
    z = np.empty(order)
    for g in range(starts.shape[0]):
        s = starts[g]
        n = lengths[g]
        m = n - 1
        d = np.empty(m)
        u0 = v_rod[s]
        for i in range(order):
            z[i] = zi0[i] * u0
        for k in range(m):
            x = v_rod[s + k]
            y = b[0] * x + z[0]
            for i in range(order - 1):
                z[i] = b[i + 1] * x + z[i + 1] - a[i + 1] * y
            z[order - 1] = b[order] * x - a[order] * y
            d[k] = y
        for k in range(n):
            out[s + k] = np.nan
        for j in range(n - 2 * h):
            acc = 0.0
            for q in range(nw):
                acc += w[q] * d[j + q]
            out[s + h + j] = acc


def _temperature_groups(model, rs):
    """Frames of a set replayed together: all (``(None, None)``), or, with ``viscosity_temperature``
    and a fuel temperature in the data, the frames of each flight, replayed at the flight's mean
    temperature (the simulator holds one temperature per flight)."""
    if model.effect("viscosity_temperature") is None or rs.flight_fuel_temp_degc is None:
        return [(None, None)]
    out = []
    for fi in np.unique(rs.flight):
        t = rs.flight_fuel_temp_degc[fi]
        out.append((np.flatnonzero(rs.flight == fi), t if np.isfinite(t) else 20.0))
    return out


def replay_batch(models, sets) -> list[np.ndarray]:
    """Replay several (model, sample set) pairs in one simulator call.

    Parameters
    ----------
    models : sequence of LoopModel
        One model per set (each with the set's frame as controller frame).
    sets : sequence of ReplaySet
        Prepared measured samples.

    Returns
    -------
    list of numpy.ndarray
        Per set, the model's velocity at every replayed sample, differentiated like the
        measured position [mm/s] (NaN where the differentiator window is incomplete).

    Raises
    ------
    ParameterError
        If a model's controller frame differs from its set's frame.
    NumericalError
        If the simulator fails.
    """
    inputs, run_models, owners = [], [], []  # one simulator run per set, or per temperature bin of a set
    for j, (model, rs) in enumerate(zip(models, sets)):
        if abs(model.controller.frame_s - rs.frame_s) > 1e-9 * rs.frame_s:
            raise range_error("LoopModel.controller.frame_s", f"equal to the data's frame ({rs.frame_s:g} s)",
                              model.controller.frame_s)
        for idx, temp in _temperature_groups(model, rs):
            sel = slice(None) if idx is None else idx
            extras = {} if temp is None else {"fuel_temp_degC": np.array([temp])}
            inputs.append(FlightInputs(np.zeros(rs.n_frames if idx is None else idx.size), rs.n2_frac[sel],
                                       rs.frame_s, open_loop_current_a=rs.current_a[sel], end_stops=False,
                                       forced_position_m=rs.position_m[sel], extras=extras))
            run_models.append(model)
            owners.append((j, idx))
    outs = simulate(run_models, inputs, [np.random.default_rng(0) for _ in inputs],
                    labels=[f"replay of set {j}" for j, _ in owners])
    v_rods = [np.empty(rs.n_frames) for rs in sets]
    for (j, idx), out in zip(owners, outs):
        if idx is None:
            v_rods[j] = out.true_velocity_m_s
        else:
            v_rods[j][idx] = out.true_velocity_m_s
    result = []
    for model, rs, v_rod in zip(models, sets, v_rods):
        lag = model.effect("lvdt_lag")
        num, den, zi0 = _rate_filter(model.lvdt, lag.time_constant_s if lag else None, float(rs.frame_s))
        num, den = num / den[0], den / den[0]
        v = np.empty(rs.n_frames)
        _sensor_windowed(1e3 * v_rod, rs.starts, rs.lengths, num, den, zi0,
                         _window_weights(rs.config.half_width), rs.config.half_width, v)
        result.append(v)
    return result


def replay_velocity(model, rs: ReplaySet) -> np.ndarray:
    """Model's velocity at every replayed sample, differentiated like the measured position [mm/s].

    Parameters
    ----------
    model : LoopModel
        Model to replay (its frame must equal ``rs.frame_s``).
    rs : ReplaySet
        Prepared measured samples.

    Returns
    -------
    numpy.ndarray (N,)
        NaN where the differentiator window is incomplete.
    """
    return replay_batch([model], [rs])[0]


def residuals(model, rs: ReplaySet) -> np.ndarray:
    """Measured minus model velocity at the scored samples [mm/s] (order of ``np.flatnonzero(rs.scored)``)."""
    v_model = replay_velocity(model, rs)
    return rs.v_meas_mm_s[rs.scored] - v_model[rs.scored]
