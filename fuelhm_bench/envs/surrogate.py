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

The indicators are every column ``c`` of the tables that has a ``c_valid``
companion (the ten of Table I, and any extended indicator the extractor adds).
A unit's flights are then drawn as::

    I[flight] = mean + u + r[flight] + sum_m D_m(f_m[flight])

1. ``mean``: the healthy mean of the table.
2. ``u ~ N(0, B)``, drawn once per unit: the unit-to-unit part. ``B`` is the
   one-way random-effects (ANOVA) estimate of the between-unit covariance,
   ``(MS_between - MS_within) / n0``, with negative eigenvalues set to 0. Its
   small directions are those of the physics: an exact relation of the
   indicators (``Inb = (X1 + X2) / 2``) holds for every unit mean, so ``B`` has
   no variance across it.
3. ``r``: a flight-to-flight residual *resampled* from the physics: a row of
   the pooled within-unit residuals ``x - unit mean`` (inflated by
   ``sqrt(n_u / (n_u - 1))`` so that their variance is unbiased), drawn with
   replacement, together with its pattern of invalid indicators. The full
   flight-to-flight covariance, its small directions, its non-Gaussian tails
   and the joint patterns of invalid indicators are those of real flights,
   not of a fitted Gaussian.
4. ``D_m(f)``: the response of mode ``m`` at intensity ``f``, piecewise linear
   between the DOE intensities (0 at 0, the last segment continued beyond
   the largest), of a DOE unit drawn once per unit and mode: the curvature of
   the laws and their unit-to-unit spread are those of the DOE. A DOE flight
   that made an indicator invalid makes it invalid in the surrogate (between
   two DOE intensities the nearer one's pattern is used with a probability
   given by the distance). Simultaneous modes add their responses.

Estimation error. Everything is estimated from a finite physics sample, and
the fitted surrogate says how much (:attr:`SurrogateModel.fit_info`,
:meth:`SurrogateModel.describe`): the number of units and residual rows, and
a unit-bootstrap standard error of every indicator's healthy standard
deviation and unit share (the tables are resampled by unit, the estimators
refitted). The residual pool reuses physics rows: a surrogate fleet of ``n``
flights repeats each of the ``R`` pooled rows about ``n / R`` times (the
residuals are combined with fresh unit effects and responses, so whole
flights are not repeated).

What the surrogate does not reproduce: interactions between simultaneous
modes (their responses add), flight-to-flight variation of a mode's response
(the DOE flies one mission per unit, so a unit's response is the same on
every flight at a given intensity: this is what backlash, whose limit cycle
depends on the flight, misses most), any dependence of a mode's response on the
unit's healthy state or on the flight's conditions beyond what the DOE unit
drawn carries, correlation between consecutive flights of a unit beyond the
shared unit effect, and unit effects that are far from Gaussian (their
covariance is kept, their shape is not).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError

__all__ = ["SurrogateModel", "fit_surrogate", "indicator_columns"]


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


def _healthy_parts(x: np.ndarray, valid: np.ndarray, units: np.ndarray):
    """Mean, between-unit covariance, pooled residuals (0 where invalid) and their validity."""
    p = x.shape[1]
    n_valid = valid.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):  # an indicator never valid: NaN mean, no warning
        mean = np.where(n_valid > 0, np.where(valid, x, 0.0).sum(axis=0) / n_valid, np.nan)
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
    # residual rows that carry information: the unit flew more than one flight
    keep = (n_row > 1).any(axis=1)
    # Between-unit covariance on complete rows (one-way ANOVA, unbalanced: n0).
    complete = valid.all(axis=1)
    between = np.zeros((p, p))
    if complete.any():
        lab_c, inv_c, cnt_c = np.unique(inverse[complete], return_inverse=True, return_counts=True)
        xc = x[complete]
        kc, nc = len(lab_c), len(xc)
        if kc >= 2 and nc - kc >= 1:
            means = np.zeros((kc, p))
            np.add.at(means, inv_c, xc)
            means /= cnt_c[:, None]
            within = xc - means[inv_c]
            ms_within = within.T @ within / (nc - kc)
            dev = means - xc.mean(axis=0)
            ms_between = (dev * cnt_c[:, None]).T @ dev / (kc - 1)
            n0 = (nc - (cnt_c ** 2).sum() / nc) / (kc - 1)
            between = _psd((ms_between - ms_within) / n0)
    return mean, between, resid[keep], valid[keep]


def _responses(doe: pd.DataFrame, names: tuple[str, ...], modes: tuple[str, ...]):
    """Knot intensities, per-DOE-unit responses ``(k, m, q + 1, p)`` and their invalidity."""
    x, valid = _values(doe, names)
    mode = doe["mode"].astype(str).to_numpy()
    intensity = pd.to_numeric(doe["intensity"], errors="coerce").to_numpy(dtype=np.float64)
    units = doe["unit_id"].to_numpy()
    deg = mode != "healthy"
    knots = np.unique(intensity[deg & np.isin(mode, modes)])
    knots = knots[np.isfinite(knots) & (knots > 0)]
    unit_labels = [u for u in pd.unique(units) if ((units == u) & (mode == "healthy")).any()]
    k, m, q, p = len(unit_labels), len(modes), len(knots), len(names)
    resp = np.full((k, m, q + 1, p), np.nan)
    invalid = np.zeros((k, m, q + 1, p), dtype=bool)
    resp[:, :, 0, :] = 0.0
    for a, u in enumerate(unit_labels):
        h = np.flatnonzero((units == u) & (mode == "healthy"))[0]
        for b, md in enumerate(modes):
            for c, f in enumerate(knots):
                rows = np.flatnonzero((units == u) & (mode == md) & np.isclose(intensity, f))
                if not len(rows):
                    continue
                r = rows[0]
                resp[a, b, c + 1] = np.where(valid[r] & valid[h], x[r] - x[h], np.nan)
                invalid[a, b, c + 1] = valid[h] & ~valid[r]
    # A response that is unknown (invalid flight, missing case) takes the mean of the other DOE units; else 0.
    known = np.isfinite(resp)
    with np.errstate(invalid="ignore", divide="ignore"):
        fill = np.where(known, resp, 0.0).sum(axis=0) / known.sum(axis=0)
    fill = np.where(np.isfinite(fill), fill, 0.0)
    resp = np.where(np.isfinite(resp), resp, fill[None])
    return knots, resp, invalid


@dataclass(frozen=True, eq=False)
class SurrogateModel:
    """A fitted surrogate (see the module docstring); build it with :func:`fit_surrogate`.

    Parameters
    ----------
    names : tuple of str
        Indicator columns drawn, in order (units: those of the physics tables,
        mA, mm/s, mm/s/mA for the ten of Table I).
    modes : tuple of str
        Degradation modes, in the order of the intensity columns.
    mean : ndarray of shape (p,)
        Healthy mean.
    unit_factor : ndarray of shape (p, p)
        ``L`` with ``L L^T = B``, the between-unit covariance.
    residuals : ndarray of shape (r, p)
        Pooled within-unit residuals of the healthy physics flights (0 where invalid).
    residual_valid : ndarray of shape (r, p), bool
        Validity of those flights' indicators.
    knots : ndarray of shape (q,)
        DOE intensities (fraction of the Table III maximum), increasing, > 0.
    responses : ndarray of shape (k, m, q + 1, p)
        Response of each DOE unit to each mode at 0 and at each knot.
    response_invalid : ndarray of shape (k, m, q + 1, p), bool
        Indicators the degradation made invalid on that DOE flight.
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
    fit_info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        names, modes = tuple(map(str, self.names)), tuple(map(str, self.modes))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "modes", modes)
        p, m = len(names), len(modes)
        q = len(np.atleast_1d(self.knots))
        k = np.shape(self.responses)[0] if np.ndim(self.responses) == 4 else -1
        r = np.shape(self.residuals)[0] if np.ndim(self.residuals) == 2 else -1
        shapes = {"mean": (p,), "unit_factor": (p, p), "residuals": (r, p), "residual_valid": (r, p),
                  "knots": (q,), "responses": (k, m, q + 1, p), "response_invalid": (k, m, q + 1, p)}
        for name, shape in shapes.items():
            dtype = bool if name in ("residual_valid", "response_invalid") else np.float64
            arr = np.array(getattr(self, name), dtype=dtype, copy=True)
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
        grid = np.concatenate([[0.0], self.knots])
        # derived once for the draws (never part of the parameters): segment slopes, modes that lose indicators
        object.__setattr__(self, "_grid", grid)
        object.__setattr__(self, "_slopes", np.diff(self.responses, axis=2) / np.diff(grid)[None, None, :, None])
        object.__setattr__(self, "_lossy", self.response_invalid.any(axis=(2, 3)))

    @classmethod
    def from_knowledge(cls, knowledge) -> SurrogateModel:
        """:func:`fit_surrogate` on a :class:`~fuelhm_bench.datasets.knowledge.KnowledgeResult`'s ``healthy_table`` and ``doe_table``."""
        return fit_surrogate(knowledge.healthy_table, knowledge.doe_table)

    # ------------------------------------------------------------------ draws
    def draw_unit(self, rng: np.random.Generator, intensities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Indicators of the flights of one new unit.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of every draw of the unit.
        intensities : ndarray of shape (n_flights, len(modes))
            Mode intensities of each flight (fraction of the Table III maximum).

        Returns
        -------
        values : ndarray of shape (n_flights, p)
            float64, ``names`` order; 0 where invalid.
        valid : ndarray of shape (n_flights, p), bool
        """
        parts = self.draw_parts(rng, len(intensities))
        return self.degrade(parts, intensities)

    def draw_parts(self, rng: np.random.Generator, n_flights: int) -> dict:
        """The random parts of one unit: healthy flights, chosen DOE units, uniforms for invalid patterns.

        Two calls of ``rng``: ``standard_normal(p)`` (the unit effect) and
        ``random(n_flights * (1 + len(modes)) + len(modes))`` (residual rows, DOE
        units, invalid-pattern uniforms).
        """
        m = len(self.modes)
        z = rng.standard_normal(len(self.names))
        u = rng.random(n_flights * (1 + m) + m)
        rows = (u[:n_flights] * len(self.residuals)).astype(np.intp)
        doe_units = (u[n_flights:n_flights + m] * self.responses.shape[0]).astype(np.intp)
        uniforms = u[n_flights + m:].reshape(n_flights, m)
        healthy = (self.mean + self.unit_factor @ z) + self.residuals[rows]
        return {"healthy": healthy, "valid": self.residual_valid[rows], "doe_units": doe_units,
                "uniforms": uniforms}

    def degrade(self, parts: dict, intensities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Add the mode responses to a unit's healthy flights (:meth:`draw_parts`).

        Parameters
        ----------
        parts : dict
            From :meth:`draw_parts` (any suffix of its flights may be passed by slicing
            ``healthy``, ``valid`` and ``uniforms`` alike). Not modified.
        intensities : ndarray of shape (n, len(modes))

        Returns
        -------
        values : ndarray of shape (n, p)
            0 where invalid.
        valid : ndarray of shape (n, p), bool
        """
        out = parts["healthy"]
        valid = parts["valid"]
        grid, slopes, lossy = self._grid, self._slopes, self._lossy
        last = len(grid) - 1
        intensities = np.asarray(intensities, dtype=np.float64)
        if last:
            for j in np.flatnonzero(intensities.max(axis=0) > 0):
                f = intensities[:, j]
                d = parts["doe_units"][j]
                # segment [grid[i0], grid[i0 + 1]]; beyond the largest knot the last segment continues
                i0 = np.searchsorted(grid, f, side="right") - 1
                np.minimum(i0, last - 1, out=i0)
                np.maximum(i0, 0, out=i0)
                out = out + self.responses[d, j, i0] + (f - grid[i0])[:, None] * slopes[d, j, i0]
                if lossy[d, j]:
                    w = (f - grid[i0]) / (grid[i0 + 1] - grid[i0])
                    nearest = np.minimum(i0 + (parts["uniforms"][:, j] < w), last)
                    valid = valid & ~self.response_invalid[d, j, nearest]
        return np.where(valid, out, 0.0), valid

    # ------------------------------------------------------------------ summaries
    @property
    def unit_cov(self) -> np.ndarray:
        """Between-unit covariance ``B``."""
        return self.unit_factor @ self.unit_factor.T

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


def _fit_healthy(x, valid, units):
    mean, between, resid, rvalid = _healthy_parts(x, valid, units)
    if not len(resid):
        raise DataFormatError("The healthy table of the surrogate needs at least one unit with two flights or "
                              "more (its flight-to-flight residuals). Got none.")
    if not np.all(np.isfinite(mean)):
        bad = np.flatnonzero(~np.isfinite(mean))
        raise DataFormatError(f"The healthy table of the surrogate has no valid value of indicator(s) "
                              f"{bad.tolist()}.")
    return mean, between, resid, rvalid


def fit_surrogate(healthy: pd.DataFrame, doe: pd.DataFrame, *, modes: tuple | None = None,
                  bootstrap: int = 50, seed: int = 0) -> SurrogateModel:
    """Learn a :class:`SurrogateModel` from physics indicator tables (a pure function of the tables).

    Parameters
    ----------
    healthy : pandas.DataFrame
        Healthy flights: ``unit_id``, the indicator columns and their ``<name>_valid``
        companions (:func:`fuelhm_bench.datasets.fleet_indicators`). At least one
        unit with two flights; two units or more for the unit-to-unit part.
    doe : pandas.DataFrame
        Design-of-experiments table (:func:`fuelhm_bench.datasets.doe.run_doe`):
        ``unit_id``, ``mode`` (``"healthy"`` or a mode id), ``intensity`` and the
        same indicator columns.
    modes : tuple of str or None, default=None
        Mode order of the intensities the surrogate is given; None: ``MODE_IDS``.
    bootstrap : int, default=50
        Unit-bootstrap replicates for the standard errors of :meth:`SurrogateModel.describe`
        (0: none).
    seed : int, default=0
        Seed of the bootstrap.

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
    x, valid = _values(healthy, names)
    units = healthy["unit_id"].to_numpy()
    mean, between, resid, rvalid = _fit_healthy(x, valid, units)
    knots, resp, invalid = _responses(doe, names, modes)
    if resp.shape[0] < 1:
        raise DataFormatError("The 'doe' table of fit_surrogate has no unit with a healthy flight.")
    labels = pd.unique(units)
    info = {"healthy_units": int(len(labels)), "healthy_flights": int(len(healthy)),
            "residual_rows": int(len(resid)), "doe_units": int(resp.shape[0]),
            "doe_intensities": knots.tolist()}
    if bootstrap and len(labels) >= 3:
        rng = np.random.default_rng(seed)
        stds, shares = [], []
        index = {u: np.flatnonzero(units == u) for u in labels}
        for _ in range(int(bootstrap)):
            pick = rng.integers(0, len(labels), len(labels))
            rows = np.concatenate([index[labels[i]] for i in pick])
            new_units = np.concatenate([np.full(len(index[labels[i]]), b) for b, i in enumerate(pick)])
            try:
                _, b_cov, r, rv = _fit_healthy(x[rows], valid[rows], new_units)
            except DataFormatError:
                continue
            rr = r[rv.all(axis=1)]
            w = np.diag(rr.T @ rr / max(len(rr), 1))
            bd = np.diag(b_cov)
            stds.append(np.sqrt(bd + w))
            shares.append(bd / np.where(bd + w > 0, bd + w, 1.0))
        if len(stds) >= 2:
            info["std_se"] = np.std(stds, axis=0, ddof=1)
            info["unit_share_se"] = np.std(shares, axis=0, ddof=1)
    return SurrogateModel(names=names, modes=modes, mean=mean, unit_factor=_factor(between), residuals=resid,
                          residual_valid=rvalid, knots=knots, responses=resp, response_invalid=invalid,
                          fit_info=info)
