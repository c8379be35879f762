"""Bounded least-squares fit of model parameters to replayed velocities, unit by unit.

The residual vector is ``v_meas - v_model`` at the scored samples of each unit's
:class:`~fuelhm_bench.calibration.replay.ReplaySet` [mm/s], where ``v_model`` is the unit's
model replayed on its measured samples and differentiated like the measured position.

Two kinds of parameters are fitted jointly:

* *unit* parameters (the recalibration subset): one value per unit, because units differ
  by manufacturing dispersion and a fleet-average model leaves each unit's own offsets
  in the residuals (where they would look like a missing effect);
* *shared* parameters (a candidate effect's): one value for the whole fleet, because an
  effect missing from the model is a property of the design, not of a unit.

Each parameter is mapped to a normalised variable ``z`` (one unit of ``z`` = a typical
change: the manufacturing dispersion for the recalibration parameters, a factor
``e^typical`` for log-scaled effect parameters), so ``scipy.optimize.least_squares``
(``trf``, exact trust-region solves) sees a well-scaled problem. The Jacobian is computed
by forward differences *grouped over units*: a unit's residuals depend only on its own
parameters and on the shared ones, so the ``j``-th parameter of every unit is perturbed in
the same model evaluation, and a Jacobian costs ``p_unit + p_shared`` replays whatever the
number of units.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from fuelhm_bench.calibration import replay as rp
from fuelhm_bench.errors import NumericalError, ParameterError, range_error

#: A fit whose start value sits on a bound starts this fraction of the search interval inside it, at
#: most ``START_INSET_MAX`` normalised units (typical changes) (:func:`fit_joint`).
START_INSET = 0.02
START_INSET_MAX = 0.1


@dataclass(frozen=True)
class FitParameter:
    """A fitted model parameter: dotted path, scaling and bounds.

    Parameters
    ----------
    path : str
        Dotted path accepted by :meth:`LoopModel.with_parameters` (e.g. ``"servovalve.null_bias_a"``).
    unit : str
        SI unit of the value (for reports).
    typical : float
        Size of one normalised unit: a typical change [SI], or [ln units] when ``log``.
    span : float, default=inf
        Half-width of the search interval around the start value [SI, or ln units when ``log``].
    lower, upper : float, default=-inf, inf
        Hard limits of the value [SI] (the documented range).
    log : bool, default=False
        Fit ``ln(value)`` (positive parameters spanning decades).
    why : str, default=""
        Why the parameter is fitted / identifiable (documentation).
    """

    path: str
    unit: str
    typical: float
    span: float = math.inf
    lower: float = -math.inf
    upper: float = math.inf
    log: bool = False
    why: str = ""

    def __post_init__(self) -> None:
        if not (self.typical > 0 and math.isfinite(self.typical)):
            raise range_error(f"FitParameter({self.path}).typical", "finite and > 0", self.typical)
        if not self.span > 0:
            raise range_error(f"FitParameter({self.path}).span", "> 0", self.span)
        if not self.lower < self.upper:
            raise range_error(f"FitParameter({self.path}).upper", f"> lower ({self.lower:g})", self.upper)
        if self.log and not self.lower > 0:
            raise range_error(f"FitParameter({self.path}).lower", "> 0 for a log-scaled parameter", self.lower)

    def interval(self, start: float) -> tuple[float, float]:
        """Search interval of the value [SI] around ``start``."""
        if self.log:
            return max(self.lower, start * math.exp(-self.span)), min(self.upper, start * math.exp(self.span))
        return max(self.lower, start - self.span), min(self.upper, start + self.span)

    def clip(self, value: float) -> float:
        """``value`` clipped to the hard limits."""
        return min(max(value, self.lower), self.upper)

    def to_z(self, value: float, start: float) -> float:
        """Normalised variable of ``value`` for a fit started at ``start``."""
        if self.log:
            return math.log(value / start) / self.typical
        return (value - start) / self.typical

    def from_z(self, z: float, start: float) -> float:
        """Value [SI] of the normalised variable ``z``."""
        if self.log:
            return start * math.exp(z * self.typical)
        return start + z * self.typical


def apply_values(model, values: Mapping[str, float]):
    """Set parameters by path, keeping the slot-width transition ordered.

    ``transition_end`` is kept at least 0.01 above ``transition_start`` (the default search
    intervals cannot cross; this only guards user-chosen ones).
    """
    values = dict(values)
    ts = values.get("servovalve.transition_start", model.servovalve.transition_start)
    te = values.get("servovalve.transition_end", model.servovalve.transition_end)
    if te < ts + 0.01:
        values["servovalve.transition_end"] = min(ts + 0.01, 1.0)
    if "servovalve.transition_end" in values and ts > model.servovalve.transition_end:
        # Parameters are set one at a time: move the end first when the new start lies beyond the
        # model's current end (e.g. a fleet mean of values fitted far from the input model).
        values = {"servovalve.transition_end": values.pop("servovalve.transition_end"), **values}
    return model.with_parameters(values)


@dataclass(frozen=True)
class JointFit:
    """Outcome of a joint (per-unit + shared) least-squares fit.

    Attributes
    ----------
    unit_models : dict
        Fitted model per unit key.
    unit_values : dict
        Per unit key, fitted value per unit-parameter path [SI].
    shared_values : dict
        Fitted value per shared-parameter path [SI].
    unit_parameters, shared_parameters : tuple of FitParameter
        What was fitted.
    rss : float
        Residual sum of squares [(mm/s)^2].
    n_residuals : int
        Number of residuals (scored samples over all units).
    unit_rss : dict
        RSS per unit key [(mm/s)^2].
    jacobian : numpy.ndarray (n_residuals, p)
        Jacobian in normalised units at the solution [mm/s per unit of z]; columns are the
        unit parameters of each unit (in key order), then the shared parameters.
    column_names : tuple of (key, path)
        Column labels of ``jacobian`` (key None for shared parameters).
    passes : int
        Model evaluations (replays of all units).
    success : bool
        Whether ``least_squares`` reported convergence.
    message : str
        Its message.
    """

    unit_models: dict
    unit_values: dict
    shared_values: dict
    unit_parameters: tuple
    shared_parameters: tuple
    rss: float
    n_residuals: int
    unit_rss: dict
    jacobian: np.ndarray
    column_names: tuple
    passes: int
    success: bool
    message: str

    @property
    def rms(self) -> float:
        """Root-mean-square residual [mm/s]."""
        return math.sqrt(self.rss / max(self.n_residuals, 1))

    @property
    def n_parameters(self) -> int:
        """Number of fitted values (unit parameters x units + shared parameters)."""
        return self.jacobian.shape[1]


class _StopFit(Exception):
    """Raised inside the solver when the ``stop`` rule of :func:`fit_joint` ends a fit early (internal)."""


class _Problem:
    """Residuals and grouped finite-difference Jacobian of a joint fit (internal)."""

    def __init__(self, models: Mapping, sets: Mapping, unit_params: tuple, shared_params: tuple,
                 unit_start: Mapping, shared_start: Mapping, diff_step: float,
                 progress: Callable[[int], None] | None) -> None:
        self.keys = list(models)
        self.models = models
        self.sets = [sets[k] for k in self.keys]
        self.unit_params = unit_params
        self.shared_params = shared_params
        self.unit_start = unit_start
        self.shared_start = shared_start
        self.diff_step = diff_step
        self.progress = progress
        self.passes = 0
        self.n_u = len(unit_params)
        self.rows = []
        start = 0
        for rs in self.sets:
            self.rows.append(slice(start, start + rs.n_scored))
            start += rs.n_scored
        self.n = start
        lo, hi = [], []
        for k in self.keys:
            for p in unit_params:
                a, b = p.interval(unit_start[k][p.path])
                lo.append(p.to_z(a, unit_start[k][p.path]))
                hi.append(p.to_z(b, unit_start[k][p.path]))
        for p in shared_params:
            a, b = p.interval(shared_start[p.path])
            lo.append(p.to_z(a, shared_start[p.path]))
            hi.append(p.to_z(b, shared_start[p.path]))
        self.lo = np.array(lo)
        self.hi = np.maximum(np.array(hi), self.lo + 1e-9)
        self._cache: tuple[bytes, np.ndarray] | None = None
        self.broyden = False
        self.refresh_every = 4
        self._last: tuple | None = None
        self._since_refresh = 0
        self.stop: Callable[[Sequence[float]], bool] | None = None
        self.history: list[float] = []  # RSS at each iterate where a Jacobian was asked for
        self.stopped_at: np.ndarray | None = None

    def unit_z(self, z: np.ndarray, u: int) -> np.ndarray:
        return z[u * self.n_u:(u + 1) * self.n_u]

    def shared_z(self, z: np.ndarray) -> np.ndarray:
        return z[len(self.keys) * self.n_u:]

    def values(self, z: np.ndarray) -> tuple[dict, dict]:
        shared = {p.path: p.from_z(float(v), self.shared_start[p.path])
                  for p, v in zip(self.shared_params, self.shared_z(z))}
        units = {}
        for u, k in enumerate(self.keys):
            units[k] = {p.path: p.from_z(float(v), self.unit_start[k][p.path])
                        for p, v in zip(self.unit_params, self.unit_z(z, u))}
        return units, shared

    def build(self, z: np.ndarray) -> dict:
        units, shared = self.values(z)
        return {k: apply_values(self.models[k], {**units[k], **shared}) for k in self.keys}

    def fun(self, z: np.ndarray) -> np.ndarray:
        key = z.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        self.passes += 1
        if self.progress is not None:
            self.progress(1)
        try:
            built = self.build(z)
            vs = rp.replay_batch([built[k] for k in self.keys], self.sets)
            r = np.concatenate([rs.v_meas_mm_s[rs.scored] - v[rs.scored] for rs, v in zip(self.sets, vs)])
            if not np.all(np.isfinite(r)):
                raise NumericalError("non-finite replay")
        except (ParameterError, NumericalError):
            r = np.full(self.n, 1e3)
        self._cache = (key, r)
        return r

    def _fd(self, z: np.ndarray, r0: np.ndarray, jac: np.ndarray, groups: list) -> None:
        """Forward differences for the given column groups (in place)."""
        p = z.shape[0]
        n_unit_cols = len(self.keys) * self.n_u
        for cols in groups:
            step = np.zeros(p)
            for c in cols:
                h = self.diff_step
                step[c] = h if z[c] + h <= self.hi[c] else -h
            r1 = self.fun(z + step)
            for c in cols:
                if c < n_unit_cols:
                    rows = self.rows[c // self.n_u]
                    jac[rows, c] = (r1[rows] - r0[rows]) / step[c]
                else:
                    jac[:, c] = (r1 - r0) / step[c]

    def jac(self, z: np.ndarray) -> np.ndarray:
        r0 = self.fun(z)
        self.history.append(float(r0 @ r0))
        if self.stop is not None and self._last is not None and self.stop(tuple(self.history)):
            self.stopped_at = z.copy()
            raise _StopFit
        p = z.shape[0]
        n_units = len(self.keys)
        unit_groups = [[u * self.n_u + j for u in range(n_units)] for j in range(self.n_u)]
        shared_groups = [[n_units * self.n_u + j] for j in range(len(self.shared_params))]
        if self.broyden and self._last is not None and self._since_refresh < self.refresh_every:
            z_prev, r_prev, jac = self._last
            jac = jac.copy()
            dz = z - z_prev
            dr = r0 - r_prev
            for u in range(n_units):
                rows = self.rows[u]
                cu = slice(u * self.n_u, (u + 1) * self.n_u)
                du = dz[cu]
                nrm = float(du @ du)
                if nrm > 0.0:
                    predicted = jac[rows, cu] @ du + jac[rows, n_units * self.n_u:] @ dz[n_units * self.n_u:]
                    jac[rows, cu] += np.outer(dr[rows] - predicted, du / nrm)
            self._fd(z, r0, jac, shared_groups)
            self._since_refresh += 1
        else:
            jac = np.zeros((self.n, p))
            self._fd(z, r0, jac, unit_groups + shared_groups)
            self._since_refresh = 0
        self._last = (z.copy(), r0.copy(), jac)
        self.fun(z)  # leave the cache at z
        return jac


def fit_joint(models: Mapping[Hashable, object], sets: Mapping[Hashable, rp.ReplaySet],
              unit_parameters: Sequence[FitParameter], shared_parameters: Sequence[FitParameter] = (), *,
              unit_start: Mapping[Hashable, Mapping[str, float]] | None = None,
              shared_start: Mapping[str, float] | None = None, max_iterations: int = 25, diff_step: float = 0.05,
              broyden: bool = False, progress: Callable[[int], None] | None = None,
              stop: Callable[[Sequence[float]], bool] | None = None) -> JointFit:
    """Fit per-unit and shared parameters to the replayed velocities (bounded least squares).

    Parameters
    ----------
    models : mapping key -> LoopModel
        Start model of each unit (holding the parameters that are not fitted, and the
        effect whose parameters are shared, if any).
    sets : mapping key -> ReplaySet
        Measured samples of each unit (same keys).
    unit_parameters : sequence of FitParameter
        Parameters fitted per unit.
    shared_parameters : sequence of FitParameter, default=()
        Parameters common to all units (paths of an effect enabled in every model).
    unit_start : mapping, optional
        Start values per unit key and path [SI]; default the models' values.
    shared_start : mapping, optional
        Start values of the shared parameters [SI]; default the first model's values.
    max_iterations : int, default=25
        Trust-region iterations (each costs one replay plus one grouped Jacobian).
    diff_step : float, default=0.05
        Forward-difference step [normalised units].
    broyden : bool, default=False
        Cheaper Jacobians: the unit-parameter columns are recomputed by finite differences
        every fourth Jacobian only, and updated in between by Broyden's rank-one rule (unit by
        unit) along the steps taken; the shared columns are always recomputed. A Jacobian
        then costs ``p_shared`` replays instead of ``p_unit + p_shared``.
    progress : callable, optional
        Called with 1 after every replay of all units.
    stop : callable, optional
        Early stopping: called at every iterate after the first (before its Jacobian is computed)
        with the RSS of the iterates so far [(mm/s)^2]; when it returns True the fit ends at that
        iterate (``success`` False, ``message`` "stopped early"; ``jacobian`` is then the one of the
        previous iterate). Used to drop a candidate that cannot earn its parameters.

    Returns
    -------
    JointFit

    Raises
    ------
    NumericalError
        If the models cannot be replayed at the start values.
    """
    keys = list(models)
    unit_params = tuple(unit_parameters)
    shared_params = tuple(shared_parameters)
    first = models[keys[0]]
    u_start = {}
    for k in keys:
        u_start[k] = {}
        for p in unit_params:
            v = float(models[k].get(p.path)) if unit_start is None or p.path not in unit_start.get(k, {}) \
                else float(unit_start[k][p.path])
            u_start[k][p.path] = p.clip(v)
    s_start = {p.path: p.clip(float(first.get(p.path) if shared_start is None or p.path not in shared_start
                                     else shared_start[p.path])) for p in shared_params}
    prob = _Problem(models, sets, unit_params, shared_params, u_start, s_start, diff_step, progress)
    prob.broyden = bool(broyden)
    prob.stop = stop
    # The start must lie strictly inside the bounds. Not by a hair: scipy's trust-region method takes
    # its initial radius from the start scaled by the distances to the bounds, so a value started
    # 1e-9 of its interval from a bound (a value clipped into a narrowed band, or left at a band's limit
    # by an earlier fit) made the radius about 1e-5, the first step tiny, and the fit end on `ftol` at
    # its start point (issue 14, fifteenth round: every second-round fit after a plausible member).
    inset = np.minimum(START_INSET * (prob.hi - prob.lo), START_INSET_MAX)
    z0 = np.clip(np.zeros(prob.lo.shape[0]), prob.lo + inset, prob.hi - inset)
    r0 = prob.fun(z0)
    if np.all(r0 == 1e3):
        raise NumericalError("The model cannot be replayed at the start values of the fit.")
    if z0.size == 0:
        zs, success, message, jac = z0, True, "nothing to fit", np.zeros((prob.n, 0))
    else:
        # Tall, thin problem: one BLAS thread is fastest (and safe in worker processes).
        try:
            with threadpool_limits(1):
                sol = least_squares(prob.fun, z0, jac=prob.jac, bounds=(prob.lo, prob.hi), x_scale=1.0,
                                    method="trf", tr_solver="exact", max_nfev=max_iterations, xtol=1e-3, ftol=1e-5,
                                    gtol=1e-8)
            zs, success, message = sol.x, bool(sol.status > 0), str(sol.message)
            jac = np.asarray(sol.jac)  # the Jacobian at the last accepted point, i.e. at zs
        except _StopFit:
            zs, success, message = prob.stopped_at, False, "stopped early"
            jac = prob._last[2]
    r = prob.fun(zs)
    units, shared = prob.values(zs)
    built = prob.build(zs)
    unit_rss = {k: float(r[prob.rows[u]] @ r[prob.rows[u]]) for u, k in enumerate(keys)}
    names = tuple((k, p.path) for k in keys for p in unit_params) + tuple((None, p.path) for p in shared_params)
    return JointFit(built, units, shared, unit_params, shared_params, float(r @ r), int(r.size), unit_rss, jac, names,
                    prob.passes, success, message)


@dataclass(frozen=True)
class Identifiability:
    """Local identifiability of fitted parameters from the Jacobian at the solution.

    Attributes
    ----------
    names : tuple of str
        Parameter labels.
    condition : float
        Condition number of the Jacobian with unit-norm columns (scale-free) [-].
    correlation : numpy.ndarray (p, p)
        Correlation matrix of the estimates, from ``(J^T J)^-1``.
    std_error_z : numpy.ndarray (p,)
        Standard errors in normalised units (typical changes) with the residual variance
        ``rss / (n - p)`` inflated by ``n / n_eff`` for the correlation of neighbouring samples.
    sensitivity : numpy.ndarray (p,)
        RMS change of the residuals per typical change of each parameter [mm/s].
    """

    names: tuple
    condition: float
    correlation: np.ndarray
    std_error_z: np.ndarray
    sensitivity: np.ndarray

    @property
    def max_abs_correlation(self) -> float:
        """Largest off-diagonal |correlation| [-]."""
        if len(self.names) < 2:
            return 0.0
        c = np.abs(np.array(self.correlation, dtype=float))
        np.fill_diagonal(c, 0.0)
        return float(np.nanmax(c))


def identifiability(jacobian: np.ndarray, rss: float, n_eff: float, names: Sequence[str]) -> Identifiability:
    """Condition number, correlations and standard errors from a Jacobian (see :class:`Identifiability`).

    Parameters
    ----------
    jacobian : numpy.ndarray (n, p)
        Residual Jacobian in normalised units [mm/s per unit].
    rss : float
        Residual sum of squares at the solution [(mm/s)^2].
    n_eff : float
        Effective number of independent residuals.
    names : sequence of str
        Column labels.
    """
    j = np.asarray(jacobian, dtype=float)
    n, p = j.shape
    names = tuple(names)
    if p == 0:
        return Identifiability(names, 1.0, np.zeros((0, 0)), np.zeros(0), np.zeros(0))
    norms = np.linalg.norm(j, axis=0)
    sens = norms / math.sqrt(max(n, 1))
    sv = np.linalg.svd(j / np.where(norms > 0, norms, 1.0), compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    try:
        cov = np.linalg.inv(j.T @ j)
        d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        dd = np.where(d > 0, d, 1.0)
        corr = cov / np.outer(dd, dd)
        s2 = rss / max(n - p, 1)
        se = d * math.sqrt(s2 * n / max(n_eff, 1.0))
    except np.linalg.LinAlgError:
        corr = np.full((p, p), np.nan)
        se = np.full(p, np.nan)
    return Identifiability(names, cond, corr, se, sens)
