"""The surrogate fidelity: indicator draws learnt from physics flights.

The surrogate replaces the simulation and the extraction of a flight by a draw
whose law is learnt, once, from two indicator tables simulated by the physics
(:func:`fit_surrogate`, a pure function of the tables; the cached call site is
:func:`fuelhm_bench.datasets.cache.surrogate_knowledge`):

* a **healthy table** of many units flying several flights each (``unit_id``
  column), with the scored fleet's truth model (hidden effects, drift);
* a **design of experiments** (:func:`fuelhm_bench.datasets.doe.run_doe`): each
  DOE unit flies one flight healthy and with each mode at each intensity, the
  same mission and noise every time, so that ``I(unit, mode, f) - I(unit, healthy)``
  is the unit's own response to the degradation.

Both tables may carry each unit's **manufacturing coordinates** ``z`` (columns
``unit_z:<parameter path>``): the standardised draws of
:func:`~fuelhm_bench.physics.model.manufacture` that made the unit
(:func:`~fuelhm_bench.physics.model.dispersion_coordinates`). On physics v2 a
unit's healthy indicators are dominated by who the unit is (unit share 0.7 to
1 of the variance) and are close to linear in ``z`` (a unit-mean regression on
the 12 coordinates explains 95 to 100 % of the unit-to-unit variance of the ten
Table I indicators on ``paper_2012``). The environment hands the surrogate the
coordinates of the very unit the physics would fly (the scored fleet's units
are manufactured from the same seeds, which costs nothing), so the scored
fleet's unit-to-unit spread, a random realisation that decides the healthy
false alarms of every method, is the physics' own.

The indicators are every column ``c`` of the tables that has a ``c_valid``
companion (the ten of Table I, and any extended indicator the extractor adds:
all are learnt and drawn alike). A unit's flights are then drawn as::

    I[flight] = mean + A z + u + r[flight] + sum_m [D_m(f_m[flight]; z) + d_m[flight](f_m[flight])]
                + sum_{a<b} X_ab(f_a[flight], f_b[flight]) + sum_k present_k[flight] [F_k(z) + e_k[flight]]

1. ``mean + A z``: the unit mean at its coordinates, a ridge regression of the
   physics units' means on ``[1, z]`` (intercept not penalised). Without
   coordinates (or too few units for them), ``A = 0``.
2. ``u ~ N(0, B)``, drawn once per unit: the unit-to-unit part the coordinates
   do not explain. ``B`` is the covariance of the regression residuals of the
   unit means (divided by the residual degrees of freedom) minus the part due
   to the flight-to-flight noise of a mean, with negative eigenvalues set to 0.
   Its small directions are those of the physics: an exact relation of the
   indicators (``Inb = (X1 + X2) / 2``) holds for every unit mean and every
   fitted value, so ``B`` and ``A`` have no variance across it.
3. ``r``: a flight-to-flight residual *resampled* from the physics: a row of
   the pooled within-unit residuals ``x - unit mean`` (inflated by
   ``sqrt(n_u / (n_u - 1))`` so that their variance is unbiased), drawn with
   replacement, together with its pattern of invalid indicators. The full
   flight-to-flight covariance, its small directions, its non-Gaussian tails
   and the joint patterns of invalid indicators are those of real flights,
   not of a fitted Gaussian.
4. ``D_m(f; z)``: the response of mode ``m`` at intensity ``f``, piecewise linear
   between the DOE intensities (0 at 0, the last segment continued beyond
   the largest). At each intensity it is regressed on the DOE units'
   coordinates like the unit means (its dependence on who the unit is), plus
   the unexplained part of a DOE unit drawn once per unit and mode (inflated
   for the fitted degrees of freedom): the curvature of the laws and their
   unit-to-unit spread are those of the DOE. A DOE flight
   that made an indicator invalid makes it invalid in the surrogate (between
   two DOE intensities the nearer one's pattern is used with a probability
   given by the distance). A mode the DOE did not fly (the cached DOE flies
   the scenario's modes only) is not learnt: an intensity of it is refused
   (:attr:`SurrogateModel.learnt`). When the DOE flew each unit on several
   missions (column ``replicate``), ``D_m`` is regressed on a unit's mean
   response over its missions.
5. ``d_m[flight]``: the flight-to-flight part of a response. Each DOE unit's
   response on one mission minus its mean over its missions (inflated by
   ``sqrt(n / (n - 1))``) forms a pool (:attr:`SurrogateModel.response_flight`);
   every degraded flight draws one row of it per active mode, piecewise linear
   in the intensity like ``D_m``.
6. ``X_ab``: the interaction of two simultaneous modes, from DOE flights of the
   pair (mode ``"a+b"``, intensities ``intensity`` and ``intensity_2``):
   ``I(a+b) - I(a) - I(b) + I(healthy)`` of a DOE unit on one mission (the
   single responses interpolated between knots), averaged over missions,
   kept per DOE unit (the one drawn for ``a``); bilinear between the pair
   intensities, 0 when either mode is at 0, held beyond the largest. Three or
   more modes add their pairs' interactions.
7. ``F_k + e_k``: the response to a fault ``k`` outside the seven modes (a
   scenario's ``unknown_faults``) on the flights where it is present, from DOE
   flights of each unit with the fault at full strength (mode
   :func:`~fuelhm_bench.datasets.doe.fault_case`): learnt as a mode at its one
   intensity (``F_k`` regressed on the coordinates plus a DOE unit's own
   residual, ``e_k`` a row of its pool of mission deviations, its lost
   indicators lost) and held whatever the flight (:attr:`SurrogateModel.faults`).

Estimation error. Everything is estimated from a finite physics sample, and
the fitted surrogate says how much (:attr:`SurrogateModel.fit_info`,
:meth:`SurrogateModel.describe`): the number of units and residual rows, and
a unit-bootstrap standard error of every indicator's healthy standard
deviation and unit share (the tables are resampled by unit, the estimators
refitted). The residual pool reuses physics rows: a surrogate fleet of ``n``
flights repeats each of the ``R`` pooled rows about ``n / R`` times (the
residuals are combined with fresh unit effects and responses, so whole
flights are not repeated).

What the surrogate does not reproduce: interactions of three or more modes
beyond their pairs', indicators lost only when two modes act together, the
link between a flight's healthy residual and its response deviation (drawn
independently; the physics flies both on one mission), non-linear dependence
of the unit mean or of a response on the coordinates, correlation between
consecutive flights of a unit beyond the shared unit effect, a Gaussian
shape for the unexplained unit part (its covariance is kept, its shape is not),
and a fault outside the seven modes at another strength than the declared one
or together with a mode.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fuelhm_bench.datasets.cache import COORDINATE_PREFIX
from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.physics.model import dispersion_coordinates, manufacturing_draws

__all__ = ["SurrogateModel", "coordinate_columns", "fit_surrogate", "indicator_columns"]


def indicator_columns(table: pd.DataFrame) -> tuple[str, ...]:
    """Indicator columns of a table: every ``c`` with a ``c_valid`` companion, in table order.

    Examples
    --------
    >>> indicator_columns(pd.DataFrame(columns=["unit_id", "X1", "X1_valid", "G_in", "G_in_valid"]))
    ('X1', 'G_in')
    """
    cols = set(map(str, table.columns))
    return tuple(str(c) for c in table.columns if f"{c}_valid" in cols and not str(c).endswith("_valid"))


def _values(table: pd.DataFrame, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Values (NaN where invalid) and validity of the indicator columns."""
    x = np.column_stack([pd.to_numeric(table[n], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
                         for n in names]) if names else np.empty((len(table), 0))
    valid = np.column_stack([table[f"{n}_valid"].to_numpy(dtype=bool) for n in names]) if names else x.astype(bool)
    valid &= np.isfinite(x)
    return np.where(valid, x, np.nan), valid


def _psd(matrix: np.ndarray) -> np.ndarray:
    """Nearest (Frobenius) symmetric positive semi-definite matrix: negative eigenvalues set to 0."""
    w, v = np.linalg.eigh(0.5 * (matrix + matrix.T))
    return (v * np.clip(w, 0.0, None)) @ v.T


def _factor(matrix: np.ndarray) -> np.ndarray:
    """``L`` with ``L L^T = matrix`` (symmetric PSD); eigenvalues below rounding (1e-12 of the largest) are 0."""
    w, v = np.linalg.eigh(0.5 * (matrix + matrix.T))
    w = np.where(w > 1e-12 * max(float(w.max(initial=0.0)), 0.0), w, 0.0)
    return v * np.sqrt(w)


def coordinate_columns(table: pd.DataFrame) -> tuple[str, ...]:
    """Unit-coordinate columns of a table: every ``unit_z:<parameter path>`` column, in table order.

    Examples
    --------
    >>> coordinate_columns(pd.DataFrame(columns=["unit_id", "unit_z:driver.gain", "X1", "X1_valid"]))
    ('driver.gain',)
    """
    return tuple(str(c)[len(COORDINATE_PREFIX):] for c in table.columns if str(c).startswith(COORDINATE_PREFIX))


def _unit_rows(table: pd.DataFrame, coords: tuple[str, ...]):
    """Per row: unit index; per unit: its coordinates (first row of the unit), shape (k, c)."""
    labels, inverse = np.unique(table["unit_id"].to_numpy(), return_inverse=True)
    first = np.zeros(len(labels), dtype=np.intp)
    first[inverse[::-1]] = np.arange(len(inverse))[::-1]
    z = np.column_stack([pd.to_numeric(table[COORDINATE_PREFIX + c], errors="coerce").to_numpy(np.float64)[first]
                         for c in coords]) if coords else np.zeros((len(labels), 0))
    if not np.all(np.isfinite(z)):
        raise DataFormatError("The unit-coordinate columns (unit_z:...) of the surrogate's tables must be finite.")
    return labels, inverse, z


_PENALTIES = (0.0, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 1e3, 1e4)


def _ridge(z: np.ndarray, y: np.ndarray, penalty: float | None):
    """Ridge fit of ``y`` (k, p) on ``[1, z]`` (intercept not penalised): coefficients (1 + c, p), hat trace, penalty.

    ``penalty`` None: chosen among :data:`_PENALTIES` by generalised cross-validation (one penalty for every
    column, each column scaled by its standard deviation, so that exact linear relations between the
    columns hold for the fitted values too).
    """
    design = np.column_stack([np.ones(len(z)), z])
    k = len(z)
    scale = y.std(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    best = None
    for lam in (_PENALTIES if penalty is None else (float(penalty),)):
        reg = lam * np.eye(design.shape[1])
        reg[0, 0] = 0.0
        gram_inv = np.linalg.pinv(design.T @ design + reg)
        coef = gram_inv @ design.T @ y
        dof = float(np.trace(design @ gram_inv @ design.T))
        if k - dof < 0.5 and penalty is None:
            continue
        gcv = k * float((((y - design @ coef) / scale) ** 2).sum()) / max(k - dof, 1e-9) ** 2
        if best is None or gcv < best[0]:
            best = (gcv, coef, dof, lam)
    if best is None:  # no penalty leaves a residual degree of freedom: the strongest one
        return _ridge(z, y, _PENALTIES[-1])
    return best[1], best[2], best[3]


def _healthy_parts(x: np.ndarray, valid: np.ndarray, units: np.ndarray, z: np.ndarray, penalty: float):
    """Intercept, coordinate map, residual between-unit covariance, pooled residuals and their validity.

    ``z`` (k, c): coordinates of the units in ``np.unique(units)`` order (c may be 0).
    """
    p = x.shape[1]
    labels, inverse = np.unique(units, return_inverse=True)
    k = len(labels)
    counts = np.zeros((k, p))
    np.add.at(counts, inverse, valid.astype(np.float64))
    sums = np.zeros((k, p))
    np.add.at(sums, inverse, np.where(valid, x, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        unit_mean = sums / counts
    resid = np.where(valid, x - unit_mean[inverse], 0.0)
    n_row = counts[inverse]
    with np.errstate(invalid="ignore", divide="ignore"):
        inflate = np.where(n_row > 1, np.sqrt(n_row / np.maximum(n_row - 1, 1)), 0.0)
    resid = resid * inflate
    keep = (n_row > 1).any(axis=1)  # residual rows that carry information: the unit flew more than one flight
    rows, rvalid = resid[keep], valid[keep]
    full = rows[rvalid.all(axis=1)]
    within = full.T @ full / max(len(full), 1)
    # Unit means regressed on the unit coordinates (units with every indicator valid at least once).
    complete = (counts > 0).all(axis=1)
    c = z.shape[1]
    if complete.sum() < c + 3:
        z, c = z[:, :0], 0
    mean = np.full(p, np.nan)
    lam = 0.0
    coef_map = np.zeros((p, c))
    between = np.zeros((p, p))
    if complete.any():
        coef, dof, lam = _ridge(z[complete], unit_mean[complete], penalty)
        mean, coef_map = coef[0], coef[1:].T
        e = unit_mean[complete] - np.column_stack([np.ones(complete.sum()), z[complete]]) @ coef
        kc = int(complete.sum())
        if kc - dof >= 1.0:
            # flight-to-flight noise of a unit mean: W_ij / max(n_i, n_j) (flights valid on both), averaged
            n = counts[complete]
            noise = within * np.mean(1.0 / np.maximum(n[:, :, None], n[:, None, :]), axis=0)
            between = _psd(e.T @ e / (kc - dof) - noise)
    # an indicator never valid on a complete unit: its plain mean
    n_valid = valid.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        plain = np.where(n_valid > 0, np.where(valid, x, 0.0).sum(axis=0) / n_valid, np.nan)
    mean = np.where(np.isfinite(mean), mean, plain)
    return mean, coef_map, between, rows, rvalid, z.shape[1], lam


def _responses(doe: pd.DataFrame, names: tuple[str, ...], modes: tuple[str, ...], coords: tuple[str, ...],
               penalty: float):
    """Knots, per-mode learnt flags, mean responses, coordinate maps, per-DOE-unit residual responses, invalidity.

    The response of DOE unit ``a`` to mode ``b`` at knot ``c`` is ``I(a, b, f_c) - I(a, healthy)``; it is
    regressed on the unit's coordinates (ridge, as the healthy unit means); what the coordinates do not
    explain is kept per DOE unit (inflated for the fitted degrees of freedom) and drawn with the unit.
    """
    x, valid = _values(doe, names)
    mode = doe["mode"].astype(str).to_numpy()
    intensity = pd.to_numeric(doe["intensity"], errors="coerce").to_numpy(dtype=np.float64)
    units = doe["unit_id"].to_numpy()
    labels, inverse, z_all = _unit_rows(doe, coords)
    deg = mode != "healthy"
    knots = np.unique(intensity[deg & np.isin(mode, modes)])
    knots = knots[np.isfinite(knots) & (knots > 0)]
    unit_index = [a for a, u in enumerate(labels) if ((units == u) & (mode == "healthy")).any()]
    k, m, q, p = len(unit_index), len(modes), len(knots), len(names)
    z = z_all[unit_index]
    replicate = (doe["replicate"].to_numpy(dtype=np.int64) if "replicate" in doe.columns
                 else np.zeros(len(doe), dtype=np.int64))
    reps = np.unique(replicate)
    # per replicate (a mission of the unit: same profile and noise for all its cases), the paired response
    per = np.full((k, len(reps), m, q + 1, p), np.nan)
    per[:, :, :, 0, :] = 0.0
    invalid = np.zeros((k, m, q + 1, p), dtype=bool)
    healthy_rows = {}
    for a, ui in enumerate(unit_index):
        u = labels[ui]
        first = True
        for e, rep_id in enumerate(reps):
            hs = np.flatnonzero((units == u) & (mode == "healthy") & (replicate == rep_id))
            if not len(hs):
                continue
            h = hs[0]
            healthy_rows[a, e] = h
            for b, md in enumerate(modes):
                for c, f in enumerate(knots):
                    rows = np.flatnonzero((units == u) & (mode == md) & np.isclose(intensity, f)
                                          & (replicate == rep_id))
                    if not len(rows):
                        continue
                    r = rows[0]
                    per[a, e, b, c + 1] = np.where(valid[r] & valid[h], x[r] - x[h], np.nan)
                    if first:  # the invalid patterns: the unit's first mission
                        invalid[a, b, c + 1] = valid[h] & ~valid[r]
            first = False
    n_rep = np.isfinite(per).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        resp = np.where(n_rep > 0, np.nansum(per, axis=1) / n_rep, np.nan)
        # flight-to-flight part of a unit's response: deviation of each mission from the unit's mean response,
        # inflated so that its variance is unbiased; 0 where a unit has one valid mission
        inflate = np.where(n_rep > 1, np.sqrt(n_rep / np.maximum(n_rep - 1, 1)), 0.0)
        dev = np.nan_to_num((per - resp[:, None]) * inflate[:, None])
    flight = dev.reshape(k * len(reps), m, q + 1, p) if len(reps) > 1 else np.zeros((1, m, q + 1, p))
    learnt = np.array([bool(np.isin(mode, [md]).any()) for md in modes], dtype=bool)
    # A response that is unknown (invalid flight, missing case) takes the mean of the other DOE units; else 0.
    known = np.isfinite(resp)
    with np.errstate(invalid="ignore", divide="ignore"):
        fill = np.where(known, resp, 0.0).sum(axis=0) / known.sum(axis=0)
    fill = np.where(np.isfinite(fill), fill, 0.0)
    resp = np.where(np.isfinite(resp), resp, fill[None])
    c = z.shape[1] if k >= z.shape[1] + 3 else 0
    mean = np.zeros((m, q + 1, p))
    coef_map = np.zeros((m, q + 1, p, z.shape[1]))
    residual = np.zeros_like(resp)
    penalties = []
    for b in range(m):  # one penalty per mode (shared by its intensities and indicators)
        flat = resp[:, b].reshape(k, -1)
        coef, dof, lam = _ridge(z[:, :c], flat, penalty)
        penalties.append(lam)
        mean[b] = coef[0].reshape(q + 1, p)
        coef_map[b, ..., :c] = np.moveaxis(coef[1:].reshape(c, q + 1, p), 0, -1)
        fitted = np.column_stack([np.ones(k), z[:, :c]]) @ coef
        # (no coordinates: dof = 1 and the DOE units' own responses are drawn, as an empirical law)
        inflate = np.sqrt((k - 1) / (k - dof)) if k - dof >= 1.0 else 1.0
        residual[:, b] = ((flat - fitted) * inflate).reshape(k, q + 1, p)
    pairs, pair_knots, interactions = _interactions(doe, x, valid, modes, knots, unit_index, labels, reps,
                                                    replicate, per, healthy_rows)
    return knots, learnt, mean, coef_map, residual, invalid, penalties, flight, pairs, pair_knots, interactions


def _interactions(doe, x, valid, modes, knots, unit_index, labels, reps, replicate, per, healthy_rows):
    """Pairs of modes flown together, their intensity grid and per-DOE-unit interactions.

    The interaction of modes ``a`` and ``b`` at ``(f_a, f_b)`` is what the pair's flight
    adds to the sum of the two single responses (each unit's own, interpolated between
    knots, same mission): ``I(a + b) - I(a) - I(b) + I(healthy)``, averaged over the
    unit's missions. Returns ``(pairs, pair_knots, interactions)`` with ``interactions``
    of shape (k, n_pairs, g + 1, g + 1, p), 0 on the axes (one mode at 0).
    """
    k, p = len(unit_index), x.shape[1]
    mode = doe["mode"].astype(str).to_numpy()
    is_pair = np.char.find(mode.astype(str), "+") >= 0 if len(mode) else np.zeros(0, dtype=bool)
    if not is_pair.any() or "intensity_2" not in doe.columns:
        return (), np.zeros(0), np.zeros((k, 0, 1, 1, p))
    f1 = pd.to_numeric(doe["intensity"], errors="coerce").to_numpy(dtype=np.float64)
    f2 = pd.to_numeric(doe["intensity_2"], errors="coerce").to_numpy(dtype=np.float64)
    units = doe["unit_id"].to_numpy()
    grid = np.concatenate([[0.0], knots])
    pairs = tuple(pr for pr in dict.fromkeys(tuple(md.split("+")) for md in mode[is_pair])
                  if len(pr) == 2 and pr[0] in modes and pr[1] in modes)
    pair_knots = np.unique(np.concatenate([f1[is_pair], f2[is_pair]]))
    pair_knots = pair_knots[np.isfinite(pair_knots) & (pair_knots > 0)]
    g = len(pair_knots)
    inter = np.full((k, len(pairs), g + 1, g + 1, p), np.nan)
    inter[:, :, 0, :, :] = 0.0
    inter[:, :, :, 0, :] = 0.0

    def single(a, e, b, f):  # unit a's own response to mode b at f on mission e (linear between knots)
        curve = per[a, e, b]
        i0 = min(max(int(np.searchsorted(grid, f, side="right")) - 1, 0), len(grid) - 2)
        w = (f - grid[i0]) / (grid[i0 + 1] - grid[i0])
        return curve[i0] + w * (curve[i0 + 1] - curve[i0])

    for a, ui in enumerate(unit_index):
        for t, (ma, mb) in enumerate(pairs):
            ba, bb = modes.index(ma), modes.index(mb)
            for i, fa in enumerate(pair_knots):
                for j, fb in enumerate(pair_knots):
                    vals = []
                    for e, rep_id in enumerate(reps):
                        h = healthy_rows.get((a, e))
                        rows = np.flatnonzero((units == labels[ui]) & (mode == f"{ma}+{mb}") & np.isclose(f1, fa)
                                              & np.isclose(f2, fb) & (replicate == rep_id))
                        if h is None or not len(rows) or len(grid) < 2:
                            continue
                        r = rows[0]
                        both = np.where(valid[r] & valid[h], x[r] - x[h], np.nan)
                        vals.append(both - single(a, e, ba, fa) - single(a, e, bb, fb))
                    if vals:
                        with np.errstate(invalid="ignore"), warnings.catch_warnings():
                            warnings.simplefilter("ignore", RuntimeWarning)
                            inter[a, t, i + 1, j + 1] = np.nanmean(vals, axis=0)
    known = np.isfinite(inter)
    with np.errstate(invalid="ignore", divide="ignore"):
        fill = np.where(known, inter, 0.0).sum(axis=0) / known.sum(axis=0)
    fill = np.where(np.isfinite(fill), fill, 0.0)
    return pairs, pair_knots, np.where(known, inter, fill[None])


@dataclass(frozen=True, eq=False)
class SurrogateModel:
    """A fitted surrogate (see the module docstring); build it with :func:`fit_surrogate`.

    Parameters
    ----------
    names : tuple of str
        Indicator columns drawn, in order (units: those of the physics tables,
        mA, mm/s, mm/s/mA for the ten of Table I; the extended indicators too).
    modes : tuple of str
        Degradation modes, in the order of the intensity columns.
    mean : ndarray of shape (p,)
        Healthy mean of a unit at the nominal coordinates (``z = 0``).
    unit_factor : ndarray of shape (p, p)
        ``L`` with ``L L^T = B``, the between-unit covariance the coordinates do not explain.
    residuals : ndarray of shape (r, p)
        Pooled within-unit residuals of the healthy physics flights (0 where invalid).
    residual_valid : ndarray of shape (r, p), bool
        Validity of those flights' indicators.
    knots : ndarray of shape (q,)
        DOE intensities (fraction of the Table III maximum), increasing, > 0.
    responses : ndarray of shape (k, m, q + 1, p)
        What the coordinates do not explain of each DOE unit's response to each mode at 0 and at each knot.
    response_invalid : ndarray of shape (k, m, q + 1, p), bool
        Indicators the degradation made invalid on that DOE flight.
    coordinates : tuple of str, default=()
        Dispersed parameters whose standardised values (:func:`~fuelhm_bench.physics.model.dispersion_coordinates`) the unit effect and the
        responses are regressed on; empty: no regression (``coordinate_map`` and ``response_map`` of width 0).
    coordinate_map : ndarray of shape (p, c) or None
        Healthy unit mean per unit coordinate.
    response_mean : ndarray of shape (m, q + 1, p) or None
        Response at ``z = 0`` (None: the mean of ``responses``, which are then not centred).
    response_map : ndarray of shape (m, q + 1, p, c) or None
        Response per unit coordinate.
    learnt : ndarray of shape (m,), bool, or None
        Modes the DOE flew (None: all); an intensity of another mode is refused.
    response_flight : ndarray of shape (s, m, q + 1, p) or None
        Pool of flight-to-flight deviations of a response from its unit's mean response
        (one per DOE unit and mission, from a DOE that flew each unit on several missions);
        each degraded flight adds one drawn from the pool. None or one row of zeros: none.
    pairs : tuple of (str, str), default=()
        Pairs of modes whose interaction the DOE flew.
    pair_knots : ndarray of shape (g,) or None
        Intensities of each mode of a pair in that DOE, increasing, > 0.
    interactions : ndarray of shape (k, len(pairs), g + 1, g + 1, p) or None
        Per DOE unit, what two modes together add to the sum of their responses, at
        ``(0, pair_knots...)`` squared (0 on the axes); bilinear between the knots, held beyond.
    faults : tuple of str, default=()
        Faults outside the seven modes learnt from the DOE (their ``mode`` labels,
        :func:`~fuelhm_bench.datasets.doe.fault_case`), in the order of the columns of
        ``faults`` in :meth:`degrade`.
    fault_mean : ndarray of shape (f, p) or None
        Response to each fault (at full strength) of a unit at ``z = 0``.
    fault_map : ndarray of shape (f, p, c) or None
        Response to each fault per unit coordinate.
    fault_responses : ndarray of shape (k, f, p) or None
        What the coordinates do not explain of each DOE unit's response to each fault.
    fault_invalid : ndarray of shape (k, f, p), bool, or None
        Indicators the fault made invalid on that DOE unit's flight.
    fault_flight : ndarray of shape (s, f, p) or None
        Pool of flight-to-flight deviations of a fault response from its DOE unit's mean
        response (as ``response_flight``).
    fault_learnt : ndarray of shape (f,), bool, or None
        Faults the DOE flew (None: all); the presence of another is refused.
    fit_info : dict
        Sizes of the physics sample (``healthy_units``, ``healthy_flights``,
        ``residual_rows``, ``doe_units``) and unit-bootstrap standard errors
        (``std_se``, ``unit_share_se``, arrays of shape (p,)).
    """

    names: tuple
    modes: tuple
    mean: np.ndarray
    unit_factor: np.ndarray
    residuals: np.ndarray
    residual_valid: np.ndarray
    knots: np.ndarray
    responses: np.ndarray
    response_invalid: np.ndarray
    coordinates: tuple = ()
    coordinate_map: np.ndarray | None = None
    response_mean: np.ndarray | None = None
    response_map: np.ndarray | None = None
    learnt: np.ndarray | None = None
    response_flight: np.ndarray | None = None
    pairs: tuple = ()
    pair_knots: np.ndarray | None = None
    interactions: np.ndarray | None = None
    faults: tuple = ()
    fault_mean: np.ndarray | None = None
    fault_map: np.ndarray | None = None
    fault_responses: np.ndarray | None = None
    fault_invalid: np.ndarray | None = None
    fault_flight: np.ndarray | None = None
    fault_learnt: np.ndarray | None = None
    fit_info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        names, modes = tuple(map(str, self.names)), tuple(map(str, self.modes))
        coords = tuple(map(str, self.coordinates))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "modes", modes)
        object.__setattr__(self, "coordinates", coords)
        p, m, c = len(names), len(modes), len(coords)
        q = len(np.atleast_1d(self.knots))
        k = np.shape(self.responses)[0] if np.ndim(self.responses) == 4 else -1
        r = np.shape(self.residuals)[0] if np.ndim(self.residuals) == 2 else -1
        if self.coordinate_map is None:
            object.__setattr__(self, "coordinate_map", np.zeros((p, c)))
        if self.response_map is None:
            object.__setattr__(self, "response_map", np.zeros((m, q + 1, p, c)))
        if self.learnt is None:
            object.__setattr__(self, "learnt", np.ones(m, dtype=bool))
        if self.response_flight is None:
            object.__setattr__(self, "response_flight", np.zeros((1, m, q + 1, p)))
        pairs = tuple(tuple(map(str, pr)) for pr in self.pairs)
        bad = [pr for pr in pairs if len(pr) != 2 or pr[0] == pr[1] or not set(pr) <= set(modes)]
        if bad:
            raise DataFormatError(f"The 'pairs' parameter of SurrogateModel must hold pairs of two different modes "
                                  f"of {list(modes)}. Got {bad} instead.")
        object.__setattr__(self, "pairs", pairs)
        if self.pair_knots is None:
            object.__setattr__(self, "pair_knots", np.zeros(0))
        g = len(np.atleast_1d(self.pair_knots))
        if self.interactions is None:
            object.__setattr__(self, "interactions", np.zeros((max(k, 0), len(pairs), g + 1, g + 1, p)))
        s_rows = np.shape(self.response_flight)[0] if np.ndim(self.response_flight) == 4 else -1
        faults = tuple(map(str, self.faults))
        object.__setattr__(self, "faults", faults)
        nf = len(faults)
        for name, shape, dtype in (("fault_mean", (nf, p), np.float64), ("fault_map", (nf, p, c), np.float64),
                                   ("fault_responses", (max(k, 0), nf, p), np.float64),
                                   ("fault_invalid", (max(k, 0), nf, p), bool),
                                   ("fault_flight", (1, nf, p), np.float64), ("fault_learnt", (nf,), bool)):
            if getattr(self, name) is None or not nf:  # (no fault: empty arrays that follow the other shapes)
                object.__setattr__(self, name, np.ones(shape, dtype) if name == "fault_learnt"
                                   else np.zeros(shape, dtype))
        sf_rows = np.shape(self.fault_flight)[0] if np.ndim(self.fault_flight) == 3 else -1
        if self.response_mean is None and k >= 1 and np.shape(self.responses)[1:] == (m, q + 1, p):
            resp = np.asarray(self.responses, dtype=np.float64)
            object.__setattr__(self, "response_mean", resp.mean(axis=0))
            object.__setattr__(self, "responses", resp - resp.mean(axis=0))
        shapes = {"mean": (p,), "unit_factor": (p, p), "residuals": (r, p), "residual_valid": (r, p),
                  "knots": (q,), "responses": (k, m, q + 1, p), "response_invalid": (k, m, q + 1, p),
                  "coordinate_map": (p, c), "response_mean": (m, q + 1, p), "response_map": (m, q + 1, p, c),
                  "learnt": (m,), "response_flight": (s_rows, m, q + 1, p), "pair_knots": (g,),
                  "interactions": (k, len(pairs), g + 1, g + 1, p), "fault_mean": (nf, p), "fault_map": (nf, p, c),
                  "fault_responses": (k, nf, p), "fault_invalid": (k, nf, p), "fault_flight": (sf_rows, nf, p),
                  "fault_learnt": (nf,)}
        for name, shape in shapes.items():
            dtype = (bool if name in ("residual_valid", "response_invalid", "learnt", "fault_invalid", "fault_learnt")
                     else np.float64)
            value = getattr(self, name)
            arr = np.array(value if value is not None else np.nan, dtype=dtype, copy=True)
            if arr.shape != shape or min(shape, default=1) < 0 or not np.all(np.isfinite(arr)):
                raise DataFormatError(f"The '{name}' parameter of SurrogateModel must be a finite array of shape "
                                      f"{shape}. Got shape {arr.shape} instead.")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if r < 1 or k < 1:
            raise DataFormatError(f"A SurrogateModel needs at least one residual row and one DOE unit. Got {r} "
                                  f"residual rows and {k} DOE units instead.")
        if q and not (np.all(np.diff(self.knots) > 0) and self.knots[0] > 0):
            raise DataFormatError(f"The 'knots' parameter of SurrogateModel must be increasing and > 0. "
                                  f"Got {self.knots.tolist()} instead.")
        if g and not (np.all(np.diff(self.pair_knots) > 0) and self.pair_knots[0] > 0):
            raise DataFormatError(f"The 'pair_knots' parameter of SurrogateModel must be increasing and > 0. "
                                  f"Got {self.pair_knots.tolist()} instead.")
        grid = np.concatenate([[0.0], self.knots])
        # derived once for the draws (never part of the parameters): knot spacing, modes that lose indicators
        object.__setattr__(self, "_grid", grid)
        object.__setattr__(self, "_lossy", self.response_invalid.any(axis=(2, 3)))
        object.__setattr__(self, "_flight_pool", bool(np.any(self.response_flight)))
        object.__setattr__(self, "_pair_index", tuple((modes.index(a), modes.index(b)) for a, b in pairs))
        object.__setattr__(self, "_fault_pool", bool(np.any(self.fault_flight)))
        object.__setattr__(self, "_dgrid", np.diff(grid))
        object.__setattr__(self, "_all_learnt", bool(self.learnt.all()))
        object.__setattr__(self, "_plans", {})  # unit_coordinates' lookup per dispersion

    @classmethod
    def from_knowledge(cls, knowledge) -> SurrogateModel:
        """:func:`fit_surrogate` on a :class:`~fuelhm_bench.datasets.knowledge.KnowledgeResult`'s ``healthy_table`` and ``doe_table``."""
        return fit_surrogate(knowledge.healthy_table, knowledge.doe_table)

    def unit_coordinates(self, unit, nominal, dispersion) -> np.ndarray:
        """The coordinates (:attr:`coordinates`) of a unit manufactured around ``nominal`` with ``dispersion``.

        ``unit``: the manufactured :class:`~fuelhm_bench.physics.model.LoopModel`
        (:func:`~fuelhm_bench.physics.model.dispersion_coordinates`), or the
        ``numpy.random.Generator`` :func:`~fuelhm_bench.physics.model.manufacture`
        would build it from (its draws are read without building the unit).
        """
        if isinstance(unit, np.random.Generator):
            if float(dispersion.scale) == 0.0:
                return np.zeros(len(self.coordinates))
            plan = self._plans.get(dispersion)
            if plan is None:  # where each coordinate is among the draws, and whether it is dispersed at all
                order = [p for p, _ in dispersion.relative] + [p for p, _ in dispersion.additive]
                where = {p: i for i, p in enumerate(order)}
                stds = dict(dispersion.relative) | dict(dispersion.additive)
                missing = [c for c in self.coordinates if c not in where]
                if missing:
                    raise DataFormatError(f"The surrogate's unit coordinates {missing} are not dispersed parameters "
                                          f"of this fleet (dispersed: {order}).")
                plan = (np.array([where[c] for c in self.coordinates], dtype=np.intp),
                        np.array([bool(stds[c]) for c in self.coordinates], dtype=bool))
                self._plans[dispersion] = plan
            index, dispersed = plan
            return np.where(dispersed, manufacturing_draws(unit, dispersion)[index], 0.0)
        return dispersion_coordinates(unit, nominal, dispersion, self.coordinates)

    def columns(self, names) -> np.ndarray:
        """Positions in :attr:`names` of the indicators ``names`` (e.g. ``EXTENDED_INDICATOR_NAMES``).

        Raises
        ------
        DataFormatError
            An indicator the surrogate was not learnt on (its physics tables lacked the column).
        """
        names = [str(n) for n in names]
        missing = [n for n in names if n not in self.names]
        if missing:
            raise DataFormatError(f"The surrogate was not learnt on the indicator(s) {missing} (its physics "
                                  f"tables have {list(self.names)}).")
        return np.array([self.names.index(n) for n in names], dtype=np.intp)

    # ------------------------------------------------------------------ draws
    def draw_unit(self, rng: np.random.Generator, intensities: np.ndarray,
                  coordinates: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Indicators of the flights of one new unit.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of every draw of the unit.
        intensities : ndarray of shape (n_flights, len(modes))
            Mode intensities of each flight (fraction of the Table III maximum).
        coordinates : ndarray of shape (len(coordinates),) or None, default=None
            The unit's manufacturing coordinates (:meth:`unit_coordinates`); None: drawn.

        Returns
        -------
        values : ndarray of shape (n_flights, p)
            float64, ``names`` order (extended indicators included); 0 where invalid.
        valid : ndarray of shape (n_flights, p), bool
        """
        parts = self.draw_parts(rng, len(intensities), coordinates)
        return self.degrade(parts, intensities)

    def draw_parts(self, rng: np.random.Generator, n_flights: int, coordinates: np.ndarray | None = None) -> dict:
        """The random parts of one unit: healthy flights, chosen DOE unit per mode, uniforms for invalid patterns.

        Calls of ``rng``: ``standard_normal(p)`` (the unexplained unit effect),
        ``random(n_flights * (1 + len(modes)) + len(modes))`` (residual rows, DOE
        units, invalid-pattern uniforms), only when ``coordinates`` is None,
        ``standard_normal(c)`` clipped at 3 (the unit's coordinates, drawn as
        :func:`~fuelhm_bench.physics.model.manufacture` draws them), and only
        when the model has a pool of flight-to-flight response deviations
        (:attr:`response_flight`), ``random((n_flights, len(modes)))`` (the
        deviation each flight draws per mode); then, only when the model learnt
        faults outside the seven modes (:attr:`faults`), ``random(len(faults))``
        (the DOE unit drawn per fault) and, with a pool of their deviations
        (:attr:`fault_flight`), ``random((n_flights, len(faults)))``. A model
        without faults draws exactly what it drew before faults existed.

        Returns
        -------
        dict
            ``healthy`` (n_flights, p): every column of :attr:`names` (the ten of
            Table I and any extended indicator), invalid ones arbitrary;
            ``valid`` (n_flights, p), bool; ``doe_units`` (m,); ``uniforms``
            (n_flights, m); ``coordinates`` (c,); ``deviations`` (n_flights, m),
            rows of :attr:`response_flight`; with faults, ``fault_units`` (f,) and
            ``fault_deviations`` (n_flights, f), rows of :attr:`fault_flight`. The
            per-flight entries are those :meth:`tail` slices.
        """
        m, c = len(self.modes), len(self.coordinates)
        z = rng.standard_normal(len(self.names))
        u = rng.random(n_flights * (1 + m) + m)
        if coordinates is None:
            coordinates = np.clip(rng.standard_normal(c), -3.0, 3.0) if c else np.zeros(0)
        coordinates = np.asarray(coordinates, dtype=np.float64)
        if coordinates.shape != (c,) or not np.isfinite(coordinates).all():
            raise DataFormatError(f"The 'coordinates' of SurrogateModel.draw_parts must be {c} finite numbers (one "
                                  f"per coordinate {list(self.coordinates)}). Got {coordinates!r:.80} instead.")
        rows = (u[:n_flights] * len(self.residuals)).astype(np.intp)
        doe_units = (u[n_flights:n_flights + m] * self.responses.shape[0]).astype(np.intp)
        uniforms = u[n_flights + m:].reshape(n_flights, m)
        healthy = (self.mean + self.coordinate_map @ coordinates + self.unit_factor @ z) + self.residuals[rows]
        if self._flight_pool:
            deviations = (rng.random((n_flights, m)) * self.response_flight.shape[0]).astype(np.intp)
        else:
            deviations = np.zeros((n_flights, m), dtype=np.intp)
        parts = {"healthy": healthy, "valid": self.residual_valid[rows], "doe_units": doe_units,
                 "uniforms": uniforms, "coordinates": coordinates, "deviations": deviations}
        if self.faults:
            nf = len(self.faults)
            parts["fault_units"] = (rng.random(nf) * self.fault_responses.shape[0]).astype(np.intp)
            parts["fault_deviations"] = ((rng.random((n_flights, nf)) * self.fault_flight.shape[0]).astype(np.intp)
                                         if self._fault_pool else np.zeros((n_flights, nf), dtype=np.intp))
        return parts

    _PER_FLIGHT = ("healthy", "valid", "uniforms", "deviations", "fault_deviations")

    def tail(self, parts: dict, start: int) -> dict:
        """The parts of a unit's flights ``start ..`` (:meth:`draw_parts`; per-unit entries kept)."""
        return {key: (value[start:] if key in self._PER_FLIGHT else value) for key, value in parts.items()}

    def response_curve(self, mode: int, doe_unit: int, coordinates: np.ndarray) -> np.ndarray:
        """Response of a unit to mode ``mode`` at 0 and at each knot, shape (q + 1, p)."""
        return (self.response_mean[mode] + self.response_map[mode] @ coordinates
                + self.responses[doe_unit, mode])

    def degrade(self, parts: dict, intensities: np.ndarray, faults: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """Add the mode responses (and fault responses) to a unit's healthy flights (:meth:`draw_parts`).

        Parameters
        ----------
        parts : dict
            From :meth:`draw_parts` (any suffix of its flights may be passed by slicing
            ``healthy``, ``valid`` and ``uniforms`` alike). Not modified.
        intensities : ndarray of shape (n, len(modes))
        faults : ndarray of shape (n, len(faults)) or None, default=None
            Presence (0 or 1, bool) of each fault outside the seven modes (:attr:`faults`) on
            each flight: a present fault adds its full-strength response (the DOE unit's own,
            with its flight-to-flight deviation and invalid indicators). None: none present.

        Returns
        -------
        values : ndarray of shape (n, p)
            0 where invalid.
        valid : ndarray of shape (n, p), bool

        Raises
        ------
        ParameterError
            A positive intensity of a mode the surrogate was not learnt for (:attr:`learnt`), a
            fault it was not learnt for (:attr:`fault_learnt`), or ``faults`` of the wrong shape or
            not 0/1.
        """
        out = parts["healthy"]
        valid = parts["valid"]
        coordinates = parts.get("coordinates")
        if coordinates is None:
            coordinates = np.zeros(len(self.coordinates))
        grid, lossy, dgrid = self._grid, self._lossy, self._dgrid
        last = len(grid) - 1
        intensities = np.asarray(intensities, dtype=np.float64)
        active = ((intensities.max(axis=0) > 0).nonzero()[0] if intensities.size
                  else np.zeros(0, dtype=np.intp))
        unlearnt = [] if self._all_learnt else [self.modes[j] for j in active if not self.learnt[j]]
        if unlearnt:
            from fuelhm_bench.errors import ParameterError

            raise ParameterError(f"The surrogate was not learnt for the mode(s) {unlearnt} (its design of "
                                 f"experiments flew only {[m for m, ok in zip(self.modes, self.learnt) if ok]}); "
                                 f"use the physics fidelity for them.")
        if last:
            pool_on, inner = self._flight_pool, grid[1:last]
            for j in active.tolist():
                f = intensities[:, j]
                d = parts["doe_units"][j]
                curve = self.response_mean[j] + self.response_map[j] @ coordinates + self.responses[d, j]
                slopes = (curve[1:] - curve[:-1]) / dgrid[:, None]  # np.diff, without its Python layer
                # segment [grid[i0], grid[i0 + 1]]; beyond the largest knot the last segment continues (searching
                # the inner knots is searching the grid and clamping to [0, last - 1])
                i0 = inner.searchsorted(f, side="right")
                offset = f - grid[i0]
                out = out + curve[i0] + offset[:, None] * slopes[i0]
                if pool_on or lossy[d, j]:
                    w = offset / dgrid[i0]  # = (f - grid[i0]) / (grid[i0 + 1] - grid[i0])
                if pool_on:  # this flight's deviation from the unit's mean response
                    pool, pick = self.response_flight[:, j], parts["deviations"][:, j]
                    lo, hi = pool[pick, i0], pool[pick, i0 + 1]  # (n, p) each
                    out = out + lo + w[:, None] * (hi - lo)
                if lossy[d, j]:
                    nearest = np.minimum(i0 + (parts["uniforms"][:, j] < w), last)
                    valid = valid & ~self.response_invalid[d, j, nearest]
            if self._pair_index:
                out = self._interact(out, intensities, parts["doe_units"], set(active.tolist()))
        if faults is not None:
            out, valid = self._add_faults(out, valid, parts, faults, coordinates)
        return np.where(valid, out, 0.0), valid

    def _add_faults(self, out, valid, parts, faults, coordinates):
        """Add the full-strength responses of the faults present on each flight (see :meth:`degrade`)."""
        from fuelhm_bench.errors import ParameterError

        present = np.asarray(faults)
        if present.shape != (len(out), len(self.faults)) or not np.isin(present, (0, 1)).all():
            raise ParameterError(f"The 'faults' parameter of SurrogateModel.degrade must be an array of 0/1 of shape "
                                 f"{(len(out), len(self.faults))} (flights, faults {list(self.faults)}). Got "
                                 f"{present!r:.80} instead.")
        present = present.astype(bool)
        on = np.flatnonzero(present.any(axis=0))
        unlearnt = [self.faults[j] for j in on if not self.fault_learnt[j]]
        if unlearnt:
            raise ParameterError(f"The surrogate was not learnt for the fault(s) outside the seven modes {unlearnt} "
                                 f"(its design of experiments did not fly them); use the physics fidelity for "
                                 f"them.")
        for j in on:
            d = parts["fault_units"][j]
            response = self.fault_mean[j] + self.fault_map[j] @ coordinates + self.fault_responses[d, j]
            if self._fault_pool:  # this flight's deviation from the DOE unit's mean response
                response = response + self.fault_flight[parts["fault_deviations"][:, j], j]
            rows = present[:, j][:, None]
            out = out + np.where(rows, response, 0.0)
            valid = valid & ~(rows & self.fault_invalid[d, j])
        return out, valid

    def _interact(self, out: np.ndarray, intensities: np.ndarray, doe_units: np.ndarray, active: set) -> np.ndarray:
        """Add the interactions of the pairs of active modes (bilinear on the pair grid, held beyond its last knot)."""
        if not self._pair_index:
            return out
        grid = np.concatenate([[0.0], self.pair_knots])
        last = len(grid) - 1

        def locate(f):
            f = np.minimum(f, grid[-1])
            i0 = np.clip(np.searchsorted(grid, f, side="right") - 1, 0, last - 1)
            return i0, ((f - grid[i0]) / (grid[i0 + 1] - grid[i0]))[:, None]

        for t, (a, b) in enumerate(self._pair_index):
            if a not in active or b not in active:
                continue
            fa, fb = intensities[:, a], intensities[:, b]
            both = (fa > 0) & (fb > 0)
            if not both.any():
                continue
            table = self.interactions[doe_units[a], t]  # (g + 1, g + 1, p)
            ia, wa = locate(fa)
            ib, wb = locate(fb)
            value = ((1 - wa) * (1 - wb) * table[ia, ib] + wa * (1 - wb) * table[ia + 1, ib]
                     + (1 - wa) * wb * table[ia, ib + 1] + wa * wb * table[ia + 1, ib + 1])
            out = out + np.where(both[:, None], value, 0.0)
        return out

    # ------------------------------------------------------------------ summaries
    @property
    def unit_cov(self) -> np.ndarray:
        """Between-unit covariance: explained by the coordinates (``z ~ N(0, I)``) plus ``B``."""
        a = self.coordinate_map
        return a @ a.T + self.unit_factor @ self.unit_factor.T

    @property
    def flight_cov(self) -> np.ndarray:
        """Covariance of the pooled residuals (rows with every indicator valid)."""
        r = self.residuals[self.residual_valid.all(axis=1)]
        return r.T @ r / max(len(r), 1)

    @property
    def unit_share(self) -> np.ndarray:
        """Fraction of each indicator's healthy variance that is unit-to-unit."""
        b = np.diag(self.unit_cov)
        total = b + np.diag(self.flight_cov)
        return b / np.where(total > 0, total, 1.0)

    def describe(self) -> pd.DataFrame:
        """Mean, standard deviation, unit share (with unit-bootstrap standard errors) and invalid rate per indicator."""
        std = np.sqrt(np.diag(self.unit_cov) + np.diag(self.flight_cov))
        nan = np.full(len(self.names), np.nan)
        return pd.DataFrame({"mean": self.mean, "std": std, "std_se": self.fit_info.get("std_se", nan),
                             "unit_share": self.unit_share,
                             "unit_share_se": self.fit_info.get("unit_share_se", nan),
                             "invalid_rate": 1.0 - self.residual_valid.mean(axis=0)},
                            index=pd.Index(self.names, name="indicator"))


def _fit_healthy(x, valid, units, z, penalty, names):
    mean, coef_map, between, resid, rvalid, c, lam = _healthy_parts(x, valid, units, z, penalty)
    if not len(resid):
        raise DataFormatError("The healthy table of the surrogate needs at least one unit with two flights or "
                              "more (its flight-to-flight residuals). Got none.")
    if not np.all(np.isfinite(mean)):
        bad = ", ".join(names[i] for i in np.flatnonzero(~np.isfinite(mean)))
        raise DataFormatError(f"The healthy table of the surrogate has no valid value of the indicator(s) {bad}: "
                              f"its flights never excite them.")
    return mean, coef_map, between, resid, rvalid, c, lam


def _fault_responses(doe: pd.DataFrame, names: tuple[str, ...], faults: tuple[str, ...], coords: tuple[str, ...],
                     penalty: float):
    """Learnt flags, mean responses, coordinate maps, per-DOE-unit residuals, invalidity and flight pool of faults.

    A fault outside the seven modes is flown at full strength only: it is learnt like a mode
    with the one DOE intensity of its flights (:func:`_responses` on its label), and its
    response is the one at that intensity (the last knot), held whatever the flight.
    """
    (knots, learnt, mean, coef_map, residual, invalid, penalties, flight,
     *_) = _responses(doe, names, faults, coords, penalty)
    if not len(knots):  # the DOE flew none of them
        k, p, c = residual.shape[0], len(names), len(coords)
        return (np.zeros(len(faults), dtype=bool), np.zeros((len(faults), p)), np.zeros((len(faults), p, c)),
                np.zeros((k, len(faults), p)), np.zeros((k, len(faults), p), dtype=bool),
                np.zeros((1, len(faults), p)), penalties)
    return (learnt, mean[:, -1], coef_map[:, -1], residual[:, :, -1], invalid[:, :, -1], flight[:, :, -1],
            penalties)


def fit_surrogate(healthy: pd.DataFrame, doe: pd.DataFrame, *, modes: tuple | None = None,
                  bootstrap: int = 50, seed: int = 0, penalty: float | None = None,
                  faults: tuple | None = None) -> SurrogateModel:
    """Learn a :class:`SurrogateModel` from physics indicator tables (a pure function of the tables).

    Parameters
    ----------
    healthy : pandas.DataFrame
        Healthy flights: ``unit_id``, the indicator columns and their ``<name>_valid``
        companions (:func:`fuelhm_bench.datasets.fleet_indicators`). At least one
        unit with two flights; two units or more for the unit-to-unit part.
        Optional ``unit_z:<parameter path>`` columns: the unit's manufacturing
        coordinates (:func:`~fuelhm_bench.physics.model.dispersion_coordinates`), the same on every row of a unit.
    doe : pandas.DataFrame
        Design-of-experiments table (:func:`fuelhm_bench.datasets.doe.run_doe`):
        ``unit_id``, ``mode`` (``"healthy"`` or a mode id), ``intensity`` and the
        same indicator columns (and the same ``unit_z:`` columns when the healthy
        table has them).
    modes : tuple of str or None, default=None
        Mode order of the intensities the surrogate is given; None: ``MODE_IDS``.
        A mode the DOE did not fly is not learnt (its intensities are refused).
    bootstrap : int, default=50
        Unit-bootstrap replicates for the standard errors of :meth:`SurrogateModel.describe`
        (0: none).
    seed : int, default=0
        Seed of the bootstrap.
    penalty : float or None, default=None
        Ridge penalty of the regressions on the unit coordinates (per unit of squared
        standardised coordinate; the intercept is not penalised), >= 0; None: chosen per
        regression by generalised cross-validation.
    faults : tuple of str or None, default=None
        Faults outside the seven modes to learn, by their DOE ``mode`` label
        (:func:`~fuelhm_bench.datasets.doe.fault_case`); None: every such label of ``doe``
        (prefix ``"unknown:"``), in order of appearance. A fault the DOE did not fly is not
        learnt (its presence is refused).

    Returns
    -------
    SurrogateModel

    Raises
    ------
    DataFormatError
        Missing columns, no indicator column, no usable residual or DOE unit.
    """
    from fuelhm_bench.taxonomy import MODE_IDS

    modes = tuple(MODE_IDS) if modes is None else tuple(modes)
    for name, table, needed in (("healthy", healthy, ("unit_id",)), ("doe", doe, ("unit_id", "mode", "intensity"))):
        if not isinstance(table, pd.DataFrame):
            raise DataFormatError(f"The '{name}' table of fit_surrogate must be a pandas DataFrame. "
                                  f"Got {type(table).__name__} instead.")
        missing = [c for c in needed if c not in table.columns]
        if missing:
            raise DataFormatError(f"The '{name}' table of fit_surrogate lacks the column(s) {missing}.")
    names = indicator_columns(healthy)
    if not names:
        raise DataFormatError("The 'healthy' table of fit_surrogate has no indicator column (a column 'c' with a "
                              "'c_valid' companion).")
    absent = [n for n in names if n not in doe.columns or f"{n}_valid" not in doe.columns]
    if absent:
        raise DataFormatError(f"The 'doe' table of fit_surrogate lacks the indicator column(s) {absent} of the "
                              f"healthy table.")
    coords = coordinate_columns(healthy)
    absent = [c for c in coords if COORDINATE_PREFIX + c not in doe.columns]
    if absent:
        raise DataFormatError(f"The 'doe' table of fit_surrogate lacks the unit-coordinate column(s) "
                              f"{[COORDINATE_PREFIX + c for c in absent]} of the healthy table.")
    x, valid = _values(healthy, names)
    labels, inverse, z = _unit_rows(healthy, coords)
    mean, coef_map, between, resid, rvalid, c, h_pen = _fit_healthy(x, valid, inverse, z, penalty, names)
    coords = coords[:c]
    (knots, learnt, r_mean, r_map, resp, invalid, r_pen, flight, pairs, pair_knots,
     interactions) = _responses(doe, names, modes, coords, penalty)
    if resp.shape[0] < 1:
        raise DataFormatError("The 'doe' table of fit_surrogate has no unit with a healthy flight.")
    if faults is None:
        from fuelhm_bench.datasets.doe import FAULT_PREFIX

        faults = tuple(str(md) for md in pd.unique(doe["mode"].astype(str)) if str(md).startswith(FAULT_PREFIX))
    faults = tuple(map(str, faults))
    fault_parts = _fault_responses(doe, names, faults, coords, penalty) if faults else (None,) * 7
    info = {"healthy_units": int(len(labels)), "healthy_flights": int(len(healthy)),
            "residual_rows": int(len(resid)), "doe_units": int(resp.shape[0]),
            "doe_intensities": knots.tolist(), "coordinates": len(coords), "penalty_healthy": h_pen,
            "doe_missions": int(flight.shape[0] // max(resp.shape[0], 1)) if np.any(flight) else 1,
            "doe_pairs": [list(pr) for pr in pairs], "doe_pair_intensities": pair_knots.tolist(),
            "penalty_responses": dict(zip(modes, r_pen))}
    if faults:
        info["penalty_faults"] = dict(zip(faults, fault_parts[6]))
    if bootstrap and len(labels) >= 3:
        rng = np.random.default_rng(seed)
        stds, shares = [], []
        index = [np.flatnonzero(inverse == i) for i in range(len(labels))]
        for _ in range(int(bootstrap)):
            pick = rng.integers(0, len(labels), len(labels))
            rows = np.concatenate([index[i] for i in pick])
            new_units = np.concatenate([np.full(len(index[i]), b) for b, i in enumerate(pick)])
            try:
                _, a, b_cov, r, rv, _, _ = _fit_healthy(x[rows], valid[rows], new_units, z[pick][:, :c], h_pen,
                                                        names)
            except DataFormatError:
                continue
            rr = r[rv.all(axis=1)]
            w = np.diag(rr.T @ rr / max(len(rr), 1))
            bd = np.diag(b_cov) + np.sum(a ** 2, axis=1)
            stds.append(np.sqrt(bd + w))
            shares.append(bd / np.where(bd + w > 0, bd + w, 1.0))
        if len(stds) >= 2:
            info["std_se"] = np.std(stds, axis=0, ddof=1)
            info["unit_share_se"] = np.std(shares, axis=0, ddof=1)
    return SurrogateModel(names=names, modes=modes, mean=mean, unit_factor=_factor(between), residuals=resid,
                          residual_valid=rvalid, knots=knots, responses=resp, response_invalid=invalid,
                          coordinates=coords, coordinate_map=coef_map, response_mean=r_mean, response_map=r_map,
                          learnt=learnt, response_flight=flight, pairs=pairs, pair_knots=pair_knots,
                          interactions=interactions, faults=faults, fault_learnt=fault_parts[0],
                          fault_mean=fault_parts[1], fault_map=fault_parts[2], fault_responses=fault_parts[3],
                          fault_invalid=fault_parts[4], fault_flight=fault_parts[5], fit_info=info)
