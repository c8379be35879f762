"""Continuous piecewise-linear fit of the binned velocity-gain curve (the slope changes).

Model
-----
The healthy velocity-gain curve (docs/physics.md §6 Degradation modes, paper Fig. 3/5) is modelled as a continuous
piecewise-linear function of the current ``i`` (mA) with four breakpoints
``S_in < X1 < X2 < S_out`` and five segments::

    A  i < S_in          lower saturation (retraction), slope 0
    B  S_in <= i < X1    shaft inlet  (retraction, v < 0),  slope G_in
    C  X1 <= i < X2      null region,                       slope G_null
    D  X2 <= i < S_out   shaft outlet (extension, v > 0),   slope G_out
    E  i >= S_out        upper saturation (extension), slope 0

written with clipped-ramp basis functions, linear in ``theta = (V_low, G_in, G_null, G_out)``::

    v(i) = V_low + G_in   * (clip(i, S_in, X1)  - S_in)
                 + G_null * (clip(i, X1,  X2)   - X1)
                 + G_out  * (clip(i, X2, S_out) - X2)

so ``Y1 = v(X1) = V_low + G_in*(X1 - S_in)`` and ``Y2 = v(X2) = Y1 + G_null*(X2 - X1)``.
A saturation breakpoint placed beyond the data simply means "no saturation in this flight";
the saturation segments keep the saturated bins from biasing G_in and G_out.

Criterion
---------
Weighted least squares on the bins with moving samples (centre ``c_k``, local mean ``m_k`` of
the velocity of the samples with ``|v| > idle_velocity_mm_s``, see
:mod:`fuelhm_bench.indicators.curve`), weight ``w_k = min(n_k, weight_cap)`` with ``n_k`` the
number of moving samples in the bin. Bins with ``n_k < min_bin_count``, and bins where idle
samples outnumber the moving ones by more than ``max_idle_ratio`` (the rest region around
``I0``, whose few moving samples are mostly transitions into and out of rest, with velocities
unrelated to their current), are left out. For given breakpoints, ``theta`` is the exact weighted
least-squares solution (normal equations from per-segment prefix sums, so one evaluation costs
O(1) after an O(n_bins) set-up; a relative ridge of 1e-11 keeps empty segments solvable).

Structural constraints (a candidate violating one is rejected), which fix the labelling of
the segments when a flight does not visit the whole curve:

* the anchor, the idle current ``I0``, lies inside the null segment with a margin
  (``X1 <= I0 - min_null_halfwidth_ma`` and ``X2 >= I0 + min_null_halfwidth_ma``): the loop
  rests in its null region, which is several tenths of the rated current wide. Without the
  margin, the slightly different local slopes on the two sides of the rest point (hysteresis,
  the ``|v| > idle_velocity_mm_s`` selection) could pass for a slope change;
* every gain segment holding data has a positive slope, and the null segment is flatter than
  a neighbouring segment holding data (``G_null < G_in``, ``G_null < G_out``): the dual-gain
  shape;
* if the null segment holds data, ``Y1 < 0 < Y2``: the inlet side retracts, the outlet side
  extends.

The breakpoints minimise the weighted residual sum of squares under these constraints by:

1. an exhaustive search over all ordered 4-tuples of ``coarse_grid_size`` candidate positions
   (4 positions beyond each end of the data, starting at least ``min_null_halfwidth_ma`` from
   ``I0``, and the rest evenly spread over the midpoints between consecutive occupied bin
   centres);
2. coordinate descent over all midpoints (each breakpoint in turn scans every candidate between
   its neighbours) until no breakpoint moves;
3. continuous refinement: golden-section search of each breakpoint lying inside the data
   between its two neighbouring candidates, kept only where it lowers the criterion; sweeps
   over the four breakpoints are repeated until none moves by more than 1e-9 mA (at most 50).

Breakpoints left beyond the data mean "no such segment in this flight"; the validity rules of
:mod:`fuelhm_bench.indicators.indicators` then flag the indicators that depend on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from fuelhm_bench.indicators.config import ExtractionConfig
from fuelhm_bench.indicators.curve import VelocityGainCurve, idle_statistics

#: Segment names in model order.
SEGMENT_NAMES: tuple[str, ...] = ("lower saturation", "inlet", "null", "outlet", "upper saturation")

_N_VIRTUAL = 4  # candidate positions beyond each end of the data
_RIDGE = 1e-11
_GOLDEN = 0.3819660112501051


# --------------------------------------------------------------------------- numba core
@njit(cache=True, nogil=True)
def _add_segment(nm, rhs, p, lo, hi, a0, a1, a2, a3, j):
    """Add the normal-equation terms of bins [lo, hi) whose basis is ``a + e_j * c``."""
    if hi <= lo:
        return
    w = p[0, hi] - p[0, lo]
    c1 = p[1, hi] - p[1, lo]
    c2 = p[2, hi] - p[2, lo]
    m1 = p[3, hi] - p[3, lo]
    cm = p[4, hi] - p[4, lo]
    a = (a0, a1, a2, a3)
    for r in range(4):
        rhs[r] += m1 * a[r]
        for s in range(4):
            nm[r, s] += w * a[r] * a[s]
    if j > 0:
        for r in range(4):
            nm[r, j] += c1 * a[r]
            nm[j, r] += c1 * a[r]
        nm[j, j] += c2
        rhs[j] += cm


@njit(cache=True, nogil=True)
def _solve_sse(p, b1, b2, b3, b4, k1, k2, k3, k4, anchor, margin, nm, rhs, theta):
    """Weighted SSE of the best model with breakpoints b1..b4 (bins split at k1..k4).

    Returns inf when the model violates a structural constraint (see the module docstring).
    """
    n_bins = p.shape[1] - 1
    # The loop rests inside its null region: X1 <= I0 - margin, X2 >= I0 + margin
    # (a NaN anchor disables the constraint).
    if anchor == anchor and not (b2 <= anchor - margin and b3 >= anchor + margin):
        return np.inf
    for r in range(4):
        rhs[r] = 0.0
        for s in range(4):
            nm[r, s] = 0.0
    _add_segment(nm, rhs, p, 0, k1, 1.0, 0.0, 0.0, 0.0, 0)
    _add_segment(nm, rhs, p, k1, k2, 1.0, -b1, 0.0, 0.0, 1)
    _add_segment(nm, rhs, p, k2, k3, 1.0, b2 - b1, -b2, 0.0, 2)
    _add_segment(nm, rhs, p, k3, k4, 1.0, b2 - b1, b3 - b2, -b3, 3)
    _add_segment(nm, rhs, p, k4, n_bins, 1.0, b2 - b1, b3 - b2, b4 - b3, 0)
    return _finish_sse(p, b1, b2, b3, b4, k1, k2, k3, k4, nm, rhs, theta)


@njit(cache=True, nogil=True)
def _finish_sse(p, b1, b2, b3, b4, k1, k2, k3, k4, nm, rhs, theta):
    """The second half of :func:`_solve_sse`, once the normal equations ``nm``, ``rhs`` hold
    all five segments: solve (``theta`` receives the coefficients), check the structural
    constraints, return the weighted SSE.

    The Cholesky factorisation of the ridged normal matrix and the two substitutions are
    written out on scalars (the loops over r, s, q of the textbook algorithm, unrolled, with
    every operation in their order), so that the solve runs in registers.
    """
    n_bins = p.shape[1] - 1
    trace = nm[0, 0] + nm[1, 1] + nm[2, 2] + nm[3, 3]
    ridge = _RIDGE * 1e-3 * trace
    # Cholesky: acc = nm[r, s] (+ ridge on the diagonal) - sum_q chol[r, q] chol[s, q], then
    # chol[r, r] = sqrt(acc) or chol[r, s] = acc / chol[s, s].
    acc = nm[0, 0] + (_RIDGE * nm[0, 0] + ridge + 1e-300)
    if acc <= 0.0:
        return np.inf
    c00 = math.sqrt(acc)
    c10 = nm[1, 0] / c00
    acc = nm[1, 1] + (_RIDGE * nm[1, 1] + ridge + 1e-300)
    acc -= c10 * c10
    if acc <= 0.0:
        return np.inf
    c11 = math.sqrt(acc)
    c20 = nm[2, 0] / c00
    acc = nm[2, 1]
    acc -= c20 * c10
    c21 = acc / c11
    acc = nm[2, 2] + (_RIDGE * nm[2, 2] + ridge + 1e-300)
    acc -= c20 * c20
    acc -= c21 * c21
    if acc <= 0.0:
        return np.inf
    c22 = math.sqrt(acc)
    c30 = nm[3, 0] / c00
    acc = nm[3, 1]
    acc -= c30 * c10
    c31 = acc / c11
    acc = nm[3, 2]
    acc -= c30 * c20
    acc -= c31 * c21
    c32 = acc / c22
    acc = nm[3, 3] + (_RIDGE * nm[3, 3] + ridge + 1e-300)
    acc -= c30 * c30
    acc -= c31 * c31
    acc -= c32 * c32
    if acc <= 0.0:
        return np.inf
    c33 = math.sqrt(acc)
    # forward substitution
    t0 = rhs[0] / c00
    acc = rhs[1]
    acc -= c10 * t0
    t1 = acc / c11
    acc = rhs[2]
    acc -= c20 * t0
    acc -= c21 * t1
    t2 = acc / c22
    acc = rhs[3]
    acc -= c30 * t0
    acc -= c31 * t1
    acc -= c32 * t2
    t3 = acc / c33
    # back substitution
    t3 = t3 / c33
    acc = t2
    acc -= c32 * t3
    t2 = acc / c22
    acc = t1
    acc -= c21 * t2
    acc -= c31 * t3
    t1 = acc / c11
    acc = t0
    acc -= c10 * t1
    acc -= c20 * t2
    acc -= c30 * t3
    t0 = acc / c00
    theta[0], theta[1], theta[2], theta[3] = t0, t1, t2, t3
    # Structural constraints on the segments that hold data: positive gains, and a null
    # region flatter than its neighbours (G_null < G_in, G_null < G_out).
    has_in, has_null, has_out = k2 > k1, k3 > k2, k4 > k3
    if (has_in and not t1 > 0.0) or (has_null and not t2 > 0.0) or (has_out and not t3 > 0.0):
        return np.inf
    if has_null and ((has_in and not t1 > t2) or (has_out and not t3 > t2)):
        return np.inf
    if has_null:  # inlet side retracts (Y1 < 0), outlet side extends (Y2 > 0)
        y1 = t0 + t1 * (b2 - b1)
        y2 = y1 + t2 * (b3 - b2)
        if not (y1 < 0.0 < y2):
            return np.inf
    sse = p[5, n_bins]
    for r in range(4):
        sse -= 2.0 * theta[r] * rhs[r]
        for s in range(4):
            sse += theta[r] * nm[r, s] * theta[s]
    return sse


@njit(cache=True, nogil=True)
def _sse_at(p, centres, bp, anchor, margin, nm, rhs, theta):
    """Weighted SSE for arbitrary (continuous) breakpoints ``bp``."""
    k1 = np.searchsorted(centres, bp[0])
    k2 = np.searchsorted(centres, bp[1])
    k3 = np.searchsorted(centres, bp[2])
    k4 = np.searchsorted(centres, bp[3])
    return _solve_sse(p, bp[0], bp[1], bp[2], bp[3], k1, k2, k3, k4, anchor, margin,
                      nm, rhs, theta)


@njit(cache=True, nogil=True)
def _golden(p, centres, bp, q, lo, hi, anchor, margin, nm, rhs, theta):
    """Golden-section minimum of the SSE over breakpoint ``q`` in [lo, hi], others fixed."""
    trial = bp.copy()
    xa, xb = lo, hi
    x1 = xa + _GOLDEN * (xb - xa)
    x2 = xb - _GOLDEN * (xb - xa)
    trial[q] = x1
    f1 = _sse_at(p, centres, trial, anchor, margin, nm, rhs, theta)
    trial[q] = x2
    f2 = _sse_at(p, centres, trial, anchor, margin, nm, rhs, theta)
    for _it in range(80):
        if xb - xa < 1e-10:
            break
        if f1 <= f2:
            xb, x2, f2 = x2, x1, f1
            x1 = xa + _GOLDEN * (xb - xa)
            trial[q] = x1
            f1 = _sse_at(p, centres, trial, anchor, margin, nm, rhs, theta)
        else:
            xa, x1, f1 = x1, x2, f2
            x2 = xb - _GOLDEN * (xb - xa)
            trial[q] = x2
            f2 = _sse_at(p, centres, trial, anchor, margin, nm, rhs, theta)
    trial[q] = 0.5 * (xa + xb)
    return trial[q], _sse_at(p, centres, trial, anchor, margin, nm, rhs, theta)


@njit(cache=True, nogil=True)
def _search(p, centres, cand, cand_k, coarse, anchor, margin, n_refine_sweeps):
    """Coarse exhaustive search, coordinate descent, golden-section refinement.

    Returns the breakpoints (4,), theta (4,) and the weighted SSE (inf: no admissible model).
    """
    nm = np.zeros((4, 4))
    rhs = np.zeros(4)
    theta = np.zeros(4)
    n_c = coarse.shape[0]
    best = np.inf
    idx = np.zeros(4, dtype=np.int64)
    # 1. exhaustive coarse search over ordered 4-tuples. The same sums as _solve_sse for each
    # tuple, in the same order, but the terms of the segments left of the inner loops' breakpoints
    # are added once per outer loop (nm_ab: segments A, B; nm_abc: + C) and copied, and a tuple
    # the anchor rejects (X1 = b2, X2 = b3) is skipped before its inner loops: the same SSEs.
    nm_ab = np.zeros((4, 4))
    rhs_ab = np.zeros(4)
    nm_abc = np.zeros((4, 4))
    rhs_abc = np.zeros(4)
    n_bins = p.shape[1] - 1
    check_anchor = anchor == anchor  # a NaN anchor disables the constraint
    for a in range(n_c):
        ga = coarse[a]
        b1, k1 = cand[ga], cand_k[ga]
        for b in range(a + 1, n_c):
            gb = coarse[b]
            b2, k2 = cand[gb], cand_k[gb]
            if check_anchor and not b2 <= anchor - margin:
                continue
            for r in range(4):
                rhs_ab[r] = 0.0
                for s in range(4):
                    nm_ab[r, s] = 0.0
            _add_segment(nm_ab, rhs_ab, p, 0, k1, 1.0, 0.0, 0.0, 0.0, 0)
            _add_segment(nm_ab, rhs_ab, p, k1, k2, 1.0, -b1, 0.0, 0.0, 1)
            for c in range(b + 1, n_c):
                gc = coarse[c]
                b3, k3 = cand[gc], cand_k[gc]
                if check_anchor and not b3 >= anchor + margin:
                    continue
                nm_abc[:, :] = nm_ab
                rhs_abc[:] = rhs_ab
                _add_segment(nm_abc, rhs_abc, p, k2, k3, 1.0, b2 - b1, -b2, 0.0, 2)
                for d in range(c + 1, n_c):
                    gd = coarse[d]
                    b4, k4 = cand[gd], cand_k[gd]
                    nm[:, :] = nm_abc
                    rhs[:] = rhs_abc
                    _add_segment(nm, rhs, p, k3, k4, 1.0, b2 - b1, b3 - b2, -b3, 3)
                    _add_segment(nm, rhs, p, k4, n_bins, 1.0, b2 - b1, b3 - b2, b4 - b3, 0)
                    sse = _finish_sse(p, b1, b2, b3, b4, k1, k2, k3, k4, nm, rhs, theta)
                    if sse < best:
                        best = sse
                        idx[0], idx[1], idx[2], idx[3] = ga, gb, gc, gd
    if best == np.inf:  # no admissible model
        return np.full(4, np.nan), np.full(4, np.nan), np.inf
    # 2. coordinate descent on the full candidate grid
    n_cand = cand.shape[0]
    trial = idx.copy()
    for _sweep in range(50):
        moved = False
        for q in range(4):
            lo = idx[q - 1] + 1 if q > 0 else 0
            hi = idx[q + 1] if q < 3 else n_cand
            for g in range(lo, hi):
                if g == idx[q]:
                    continue
                trial[:] = idx
                trial[q] = g
                sse = _solve_sse(p, cand[trial[0]], cand[trial[1]], cand[trial[2]],
                                 cand[trial[3]], cand_k[trial[0]], cand_k[trial[1]],
                                 cand_k[trial[2]], cand_k[trial[3]], anchor, margin,
                                 nm, rhs, theta)
                if sse < best * (1.0 - 1e-13):
                    best = sse
                    idx[q] = g
                    moved = True
        if not moved:
            break
    bp = np.empty(4)
    for q in range(4):
        bp[q] = cand[idx[q]]
    # 3. continuous golden-section refinement of the breakpoints inside the data
    first, last = centres[0], centres[-1]
    for _sweep in range(n_refine_sweeps):
        moved_by = 0.0
        for q in range(4):
            if not (first < bp[q] < last):
                continue
            lo = cand[idx[q] - 1] if idx[q] > 0 else bp[q]
            hi = cand[idx[q] + 1] if idx[q] + 1 < n_cand else bp[q]
            if q > 0 and lo < bp[q - 1]:
                lo = bp[q - 1]
            if q < 3 and hi > bp[q + 1]:
                hi = bp[q + 1]
            xm, fm = _golden(p, centres, bp, q, lo, hi, anchor, margin, nm, rhs, theta)
            if fm < best:
                best = fm
                moved_by = max(moved_by, abs(xm - bp[q]))
                bp[q] = xm
        if moved_by < 1e-9:
            break
    best = _sse_at(p, centres, bp, anchor, margin, nm, rhs, theta)
    return bp, theta.copy(), best


@njit(cache=True, nogil=True)
def _profile_interval(p, centres, bp, q, lo, hi, step, threshold, anchor, margin):
    """Range of breakpoint ``q`` over [lo, hi] (grid ``step``) where SSE <= threshold."""
    nm = np.zeros((4, 4))
    rhs = np.zeros(4)
    theta = np.zeros(4)
    trial = bp.copy()
    first = np.inf
    last = -np.inf
    n_steps = int((hi - lo) / step) + 1
    for j in range(n_steps + 1):
        value = min(lo + j * step, hi)
        trial[q] = value
        if _sse_at(p, centres, trial, anchor, margin, nm, rhs, theta) <= threshold:
            first = min(first, value)
            last = max(last, value)
    if first > last:  # not even the optimum passes (rounding): a point interval
        return bp[q], bp[q]
    return first, last


# --------------------------------------------------------------------------- Python API
@dataclass(frozen=True)
class CurveFit:
    """Result of the piecewise-linear fit of one binned velocity-gain curve.

    Attributes
    ----------
    s_in_ma, x1_ma, x2_ma, s_out_ma : float
        Breakpoints, in mA. ``s_in_ma`` / ``s_out_ma`` beyond the data mean that the flight
        shows no saturation on that side.
    v_low_mm_s : float
        Model value below ``s_in_ma`` (lower saturation velocity), in mm/s.
    g_in, g_null, g_out : float
        Segment slopes (velocity gains), in mm/s/mA.
    y1_mm_s, y2_mm_s : float
        Model values at X1 and X2, in mm/s.
    segment_points : tuple of int
        Moving samples in each segment (A..E, see :data:`SEGMENT_NAMES`).
    segment_bins : tuple of int
        Occupied bins in each segment.
    segment_span_ma : tuple of float
        Current span covered by the occupied bins of each segment, in mA
        (last centre - first centre + bin width; 0 for an empty segment).
    rms_residual_mm_s : float
        Weighted RMS residual of the fit, in mm/s.
    data_range_ma : tuple of float
        Centres of the first and last bins used by the fit, in mA.
    x1_interval_ma, x2_interval_ma : tuple of float
        Approximate 95 % profile intervals of X1 and X2, in mA: the positions of the
        breakpoint (on a grid of a fifth of a bin, between its neighbours and within the data,
        the other breakpoints fixed) where the weighted SSE stays within
        ``3.84 * SSE_min / (n_bins - 8)`` of its minimum.
    """

    s_in_ma: float
    x1_ma: float
    x2_ma: float
    s_out_ma: float
    v_low_mm_s: float
    g_in: float
    g_null: float
    g_out: float
    segment_points: tuple[int, ...]
    segment_bins: tuple[int, ...]
    segment_span_ma: tuple[float, ...]
    rms_residual_mm_s: float
    data_range_ma: tuple[float, float] = (float("-inf"), float("inf"))
    x1_interval_ma: tuple[float, float] = (float("nan"), float("nan"))
    x2_interval_ma: tuple[float, float] = (float("nan"), float("nan"))

    @property
    def y1_mm_s(self) -> float:
        """Model velocity at X1, in mm/s."""
        return self.v_low_mm_s + self.g_in * (self.x1_ma - self.s_in_ma)

    @property
    def y2_mm_s(self) -> float:
        """Model velocity at X2, in mm/s."""
        return self.y1_mm_s + self.g_null * (self.x2_ma - self.x1_ma)

    def evaluate(self, current_ma: np.ndarray) -> np.ndarray:
        """Fitted velocity (mm/s) at the given currents (mA)."""
        i = np.asarray(current_ma, dtype=np.float64)
        return (self.v_low_mm_s
                + self.g_in * (np.clip(i, self.s_in_ma, self.x1_ma) - self.s_in_ma)
                + self.g_null * (np.clip(i, self.x1_ma, self.x2_ma) - self.x1_ma)
                + self.g_out * (np.clip(i, self.x2_ma, self.s_out_ma) - self.x2_ma))


def _candidates(centres: np.ndarray, width: float, anchor: float, margin: float) -> np.ndarray:
    """Candidate breakpoint positions: 4 below the data, midpoints, 4 above the data.

    The positions beyond the data start no closer to the anchor than ``margin``, so that a
    slope change the data do not reach can always be placed beyond them.
    """
    low_start = centres[0] - 0.5 * width
    high_start = centres[-1] + 0.5 * width
    if np.isfinite(anchor):
        low_start = min(low_start, anchor - margin)
        high_start = max(high_start, anchor + margin)
    below = low_start - 2.0 * width * np.arange(_N_VIRTUAL)[::-1]
    above = high_start + 2.0 * width * np.arange(_N_VIRTUAL)
    mids = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([below, mids, above])


def fit_curve(curve: VelocityGainCurve, config: ExtractionConfig | None = None, *,
              anchor_ma: float | None = None) -> CurveFit | None:
    """Fit the five-segment continuous piecewise-linear model to a binned curve.

    Parameters
    ----------
    curve : VelocityGainCurve
        Binned curve (from the batch or the streaming extractor).
    config : ExtractionConfig, optional
        Fit settings (``min_bin_count``, ``weight_cap``, ``coarse_grid_size``); defaults to
        the curve's own configuration.
    anchor_ma : float, optional
        Current that must lie between X1 and X2, at least ``min_null_halfwidth_ma`` from
        each, in mA. Default: the idle current
        (mean current of the idle samples, see
        :func:`~fuelhm_bench.indicators.curve.idle_statistics`); NaN disables the constraint.

    Returns
    -------
    CurveFit or None
        None when fewer than 4 bins hold moving samples or no model satisfies the
        constraints.
    """
    cfg = curve.config if config is None else config
    count = curve.moving_count
    used = (count >= cfg.min_bin_count) & (curve.idle_count <= cfg.max_idle_ratio * count)
    if int(used.sum()) < 4:
        return None
    centres = np.ascontiguousarray(curve.bin_centres_ma[used])
    n = count[used]
    mean = curve.moving_mean_velocity_mm_s[used]
    w = np.minimum(n, float(cfg.weight_cap))
    moments = np.stack([w, w * centres, w * centres**2, w * mean, w * centres * mean,
                        w * mean**2])
    prefix = np.zeros((6, len(centres) + 1))
    np.cumsum(moments, axis=1, out=prefix[:, 1:])
    i0 = idle_statistics(curve, cfg)[0] if anchor_ma is None else float(anchor_ma)
    margin = float(cfg.min_null_halfwidth_ma)
    cand = _candidates(centres, cfg.bin_width_ma, i0, margin)
    cand_k = np.searchsorted(centres, cand).astype(np.int64)
    n_cand = len(cand)
    n_inner = max(cfg.coarse_grid_size - 2 * _N_VIRTUAL, 2)
    inner = np.unique(np.round(np.linspace(_N_VIRTUAL, n_cand - _N_VIRTUAL - 1, n_inner)))
    coarse = np.concatenate([np.arange(_N_VIRTUAL), inner.astype(np.int64),
                             np.arange(n_cand - _N_VIRTUAL, n_cand)]).astype(np.int64)
    coarse = np.unique(coarse)
    bp, theta, sse = _search(prefix, centres, cand, cand_k, coarse, i0, margin, 50)
    if not np.isfinite(sse):
        return None
    seg = np.searchsorted(centres, bp)  # bins [0,seg0) A, [seg0,seg1) B, ...
    bounds = np.concatenate([[0], seg, [len(centres)]])
    points, bins, spans = [], [], []
    for s in range(5):
        lo, hi = int(bounds[s]), int(bounds[s + 1])
        points.append(int(n[lo:hi].sum()) if hi > lo else 0)
        bins.append(max(hi - lo, 0))
        spans.append(float(centres[hi - 1] - centres[lo] + cfg.bin_width_ma) if hi > lo else 0.0)
    rms = float(np.sqrt(max(sse, 0.0) / w.sum()))
    threshold = sse + 3.84 * max(sse, 0.0) / max(len(centres) - 8, 1)
    intervals = []
    for q in (1, 2):
        lo = max(bp[q - 1], centres[0])
        hi = min(bp[q + 1], centres[-1])
        if lo < bp[q] < hi:
            intervals.append(tuple(float(v) for v in _profile_interval(
                prefix, centres, bp, q, lo, hi, 0.2 * cfg.bin_width_ma, threshold, i0, margin)))
        else:
            intervals.append((float("nan"), float("nan")))
    return CurveFit(
        s_in_ma=float(bp[0]), x1_ma=float(bp[1]), x2_ma=float(bp[2]), s_out_ma=float(bp[3]),
        v_low_mm_s=float(theta[0]), g_in=float(theta[1]), g_null=float(theta[2]),
        g_out=float(theta[3]), segment_points=tuple(points), segment_bins=tuple(bins),
        segment_span_ma=tuple(spans), rms_residual_mm_s=rms,
        data_range_ma=(float(centres[0]), float(centres[-1])),
        x1_interval_ma=intervals[0], x2_interval_ma=intervals[1],
    )
