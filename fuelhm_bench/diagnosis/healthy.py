"""Gaussian model of the healthy indicators: Z-scores and global Mahalanobis score.

Paper (Lamoureux, Massé & Mechbal 2012), section VI.B: a Gaussian model of the
indicators is learned on healthy flights (eq. 6), each indicator is turned into
a Z-score (eq. 7), and the Z-scores are combined into a global abnormality
score with the Mahalanobis distance.
"""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np
import pandas as pd
from scipy.linalg import pinvh
from scipy.special import chdtrc, chdtri, gammaln
from sklearn.base import BaseEstimator
from sklearn.covariance import ledoit_wolf_shrinkage

from fuelhm_bench.diagnosis._validation import (
    HEALTHY,
    NotFittedError,
    check_features,
    indicator_matrix,
    param_error,
)
from fuelhm_bench.errors import DataFormatError

#: Eigenvalues of a (regularised) correlation matrix below ``PINV_RTOL`` times
#: the largest one are treated as zero when it is inverted (pseudo-inverse).
PINV_RTOL: float = 1e-10

#: Below this upper-tail probability the chi-square equivalence of
#: :func:`chi2_equivalent` switches from the exact quantile map to its
#: asymptotic form (the exact one underflows near 1e-308).
_TAIL_SWITCH: float = 1e-150


class HealthyModel(BaseEstimator):
    """Gaussian model of the indicators over healthy flights (paper eqs. 6-7).

    ``fit`` learns the mean, the standard deviation and the (regularised)
    covariance of the indicators over healthy flights; ``zscores`` standardises
    new flights (eq. 7) and ``global_score`` combines the Z-scores into the
    Mahalanobis distance (section VI.B.2).

    **Global score.** ``global_score`` returns the square root of the quadratic
    form ``d = sqrt(z^T R^-1 z)`` where ``z`` are the Z-scores and ``R`` the
    regularised *correlation* matrix. This is the same number as
    ``sqrt((x - mean_)^T precision_ (x - mean_))`` computed on the indicator
    vector ``x`` with ``cov_ = diag(std_) R diag(std_)``. Working on Z-scores
    makes the regularisation independent of the indicators' units.

    **Regularisation.** Indicators are strongly related (``Inb = (X1 + X2)/2``
    by construction), so the sample covariance can be singular. The correlation
    matrix ``S`` of the healthy Z-scores is shrunk toward the identity,
    ``R = (1 - lambda) S + lambda I``, with ``lambda`` from ``shrinkage``
    (Ledoit-Wolf estimate by default), then inverted with a pseudo-inverse that
    zeroes eigenvalues below ``PINV_RTOL = 1e-10`` times the largest. With
    ``lambda > 0`` ``R`` is positive definite and the pseudo-inverse is the
    inverse; with ``shrinkage=0`` and a singular ``S`` the distance ignores the
    directions the healthy data never spanned. A standard deviation is floored
    at ``std_floor * max(|mean|, 1)`` (in the indicator's unit) so a constant
    indicator never causes a division by zero; such an indicator gets zero
    correlation with the others.

    **Missing indicators (NaN).** A value is missing when it is NaN or when its
    ``<name>_valid`` column is False.

    - ``fit``: ``mean_`` and ``std_`` of each indicator use every healthy
      flight where that indicator is available; the correlation matrix uses the
      complete cases (flights with all selected indicators available), which
      keeps it positive semi-definite.
    - ``zscores``: NaN where the indicator is missing.
    - ``global_score``: a flight with ``k < p`` available indicators is scored
      with the marginal Gaussian of the available ones (Mahalanobis distance
      on the sub-vector with the sub-matrix of ``R``), whose square is
      chi-square with ``k`` degrees of freedom under the healthy model. It is
      then mapped to the ``p``-indicator scale by matching upper-tail
      probabilities (:func:`chi2_equivalent`), so a threshold on the global
      score keeps the same false-alarm rate whatever is missing. A flight with
      no available indicator scores NaN.

    Parameters
    ----------
    features : sequence of str or None, default=None
        Indicators to model, names from ``INDICATOR_NAMES``; ``None`` means all
        ten, in the paper's order.
    shrinkage : {"auto"} or float in [0, 1], default="auto"
        Shrinkage of the correlation matrix toward the identity. ``"auto"``
        uses the Ledoit-Wolf estimate (``sklearn.covariance.ledoit_wolf_shrinkage``
        on the complete-case Z-scores); ``0`` gives the sample covariance.
    std_floor : float, default=1e-6
        Relative floor of the standard deviations (see above); must be > 0.
    min_flights : int or None, default=None
        Minimum number of healthy flights, counted per indicator and for the
        complete cases. ``None`` means ``len(features) + 1``, the smallest
        sample whose covariance can be of full rank. Must be >= 2.

    Attributes
    ----------
    features_ : tuple of str
        Indicators modelled, in column order of every fitted array.
    mean_ : ndarray of shape (n_features,)
        Healthy mean of each indicator (eq. 6), in the indicator's unit
        (``INDICATOR_UNITS``: mA, mm/s or mm/s/mA).
    std_ : ndarray of shape (n_features,)
        Healthy standard deviation (ddof=1, floored), same units as ``mean_``.
    cov_ : ndarray of shape (n_features, n_features)
        Regularised covariance ``diag(std_) correlation_ diag(std_)``, in the
        product of the two indicators' units.
    precision_ : ndarray of shape (n_features, n_features)
        (Pseudo-)inverse of ``cov_``, in inverse units.
    correlation_ : ndarray of shape (n_features, n_features)
        Regularised correlation matrix ``R`` (dimensionless).
    shrinkage_ : float
        Shrinkage ``lambda`` actually used.
    rank_ : int
        Rank of ``correlation_``: ``n_features`` unless ``shrinkage=0`` and
        the healthy data are degenerate. It is the number of degrees of
        freedom of the healthy chi-square distribution of the squared score.
    n_samples_ : int
        Number of healthy flights passed to ``fit``.
    n_complete_ : int
        Number of them with every selected indicator available.
    n_features_in_ : int
        ``len(features_)``.

    Examples
    --------
    >>> import numpy as np
    >>> from fuelhm_bench.diagnosis import HealthyModel
    >>> from fuelhm_bench.testing.diagnosis import make_healthy_table
    >>> rng = np.random.default_rng(0)
    >>> healthy = make_healthy_table(500, rng=rng)
    >>> model = HealthyModel().fit(healthy)
    >>> model.zscores(healthy.head(2)).shape
    (2, 10)
    >>> scores = model.global_score(healthy)
    >>> bool(8.0 < float(np.mean(scores**2)) < 12.0)  # about chi-square(10)
    True
    """

    def __init__(self, *, features=None, shrinkage="auto", std_floor=1e-6, min_flights=None):
        self.features = features
        self.shrinkage = shrinkage
        self.std_floor = std_floor
        self.min_flights = min_flights

    # ------------------------------------------------------------------ fit
    def _checked_params(self) -> tuple[tuple[str, ...], int]:
        owner = type(self).__name__
        features = check_features(self.features, owner)
        s = self.shrinkage
        if not (s == "auto" if isinstance(s, str) else isinstance(s, Real) and not isinstance(s, bool) and 0.0 <= s <= 1.0):
            raise param_error("shrinkage", owner, "'auto' or a float in [0, 1]", s)
        f = self.std_floor
        if isinstance(f, bool) or not isinstance(f, Real) or not np.isfinite(f) or f <= 0:
            raise param_error("std_floor", owner, "a finite float > 0", f)
        m = self.min_flights
        if m is None:
            m = len(features) + 1
        elif isinstance(m, bool) or not isinstance(m, Integral) or m < 2:
            raise param_error("min_flights", owner, "an int >= 2 or None", m)
        return features, int(m)

    def fit(self, indicator_table, y=None):
        """Learn the healthy Gaussian model.

        Every row is taken as a healthy flight: select the healthy flights
        beforehand (for a DOE table, ``doe[doe["mode"] == "healthy"]``; a
        table with a ``mode`` column holding anything else is rejected).

        Parameters
        ----------
        indicator_table : pandas.DataFrame or array-like of shape (n_flights, n_features)
            Indicator table with (at least) the ``features`` columns, or a
            plain array whose columns are the features in order.
        y : None
            Ignored; present for scikit-learn API compatibility.

        Returns
        -------
        self : HealthyModel

        Raises
        ------
        ParameterError
            A hyperparameter is out of range.
        DataFormatError
            A column is missing, a ``mode`` column holds a degraded mode, or
            there are fewer than ``min_flights`` healthy flights (overall, per
            indicator, or complete cases).
        """
        features, min_flights = self._checked_params()
        if isinstance(indicator_table, pd.DataFrame) and "mode" in indicator_table.columns:
            modes = set(indicator_table["mode"].astype(str)) - {HEALTHY}
            if modes:
                raise DataFormatError(
                    f"HealthyModel.fit takes healthy flights only; the table has rows with mode {sorted(modes)}. "
                    "Select them with table[table['mode'] == 'healthy']."
                )
        x = indicator_matrix(indicator_table, features, "healthy indicator table")
        n, p = x.shape
        hint = "min_flights=None means len(features) + 1"
        if n < min_flights:
            raise DataFormatError(
                f"HealthyModel needs at least {min_flights} healthy flights to fit "
                f"{p} indicators ({hint}). Got {n} instead."
            )
        available = np.isfinite(x)
        n_valid = available.sum(axis=0)
        short = [f"{f!r} ({k})" for f, k in zip(features, n_valid) if k < min_flights]
        if short:
            raise DataFormatError(
                f"HealthyModel needs at least {min_flights} healthy flights with each indicator available "
                f"({hint}); too few for {', '.join(short)}. Exclude such indicators with the 'features' parameter."
            )
        complete = available.all(axis=1)
        n_complete = int(complete.sum())
        if n_complete < min_flights:
            worst = features[int(np.argmin(n_valid))]
            raise DataFormatError(
                f"HealthyModel needs at least {min_flights} healthy flights with all {p} indicators available "
                f"to estimate their correlation ({hint}). Got {n_complete} complete flights instead; "
                f"{worst!r} is the most often missing."
            )

        mean = np.nanmean(x, axis=0)
        floor = self.std_floor * np.maximum(np.abs(mean), 1.0)
        std = np.maximum(np.nanstd(x, axis=0, ddof=1), floor)

        z = _standardise_columns(x[complete], floor)
        corr = z.T @ z / (n_complete - 1)
        np.fill_diagonal(corr, 1.0)  # also for a constant column (z = 0): uncorrelated, unit variance
        if self.shrinkage == "auto":
            lam = float(np.clip(ledoit_wolf_shrinkage(z, assume_centered=True), 0.0, 1.0))
        else:
            lam = float(self.shrinkage)
        corr = (1.0 - lam) * corr + lam * np.eye(p)
        corr_inv, rank = pinvh(corr, rtol=PINV_RTOL, return_rank=True)

        self.features_ = features
        self.n_features_in_ = p
        self.mean_ = mean
        self.std_ = std
        self.correlation_ = corr
        self.shrinkage_ = lam
        self.cov_ = corr * np.outer(std, std)
        self.precision_ = corr_inv / np.outer(std, std)
        self.rank_ = int(rank)
        self.n_samples_ = n
        self.n_complete_ = n_complete
        return self

    # -------------------------------------------------------------- scoring
    def _check_fitted(self) -> None:
        if not hasattr(self, "mean_"):
            raise NotFittedError(
                f"This {type(self).__name__} instance is not fitted yet. Call 'fit' with healthy flights first."
            )

    def _z(self, table) -> np.ndarray:
        self._check_fitted()
        x = indicator_matrix(table, self.features_, "indicator table")
        return (x - self.mean_) / self.std_

    def zscores(self, table):
        """Z-score of each indicator, ``(I - mean_) / std_`` (paper eq. 7).

        Parameters
        ----------
        table : pandas.DataFrame or array-like of shape (n_flights, n_features)
            Indicator table with the ``features_`` columns (a missing value is
            NaN or has ``<name>_valid`` False), or an array whose columns are
            ``features_`` in order.

        Returns
        -------
        pandas.DataFrame or ndarray of shape (n_flights, n_features)
            Dimensionless Z-scores, NaN where the indicator is missing. A
            DataFrame (same index, columns ``features_``) for a DataFrame
            input, an ndarray otherwise.
        """
        z = self._z(table)
        if isinstance(table, pd.DataFrame):
            return pd.DataFrame(z, index=table.index, columns=list(self.features_))
        return z

    def global_score(self, table) -> np.ndarray:
        """Global abnormality score: Mahalanobis distance to the healthy model.

        ``d = sqrt(z^T R^-1 z)`` on the Z-scores with the regularised
        correlation matrix ``R`` (equivalently, on the indicator vector with
        ``cov_``). Flights with missing indicators are scored on the available
        ones and mapped to the full-dimension scale (see the class notes).

        Parameters
        ----------
        table : pandas.DataFrame or array-like of shape (n_flights, n_features)
            As for :meth:`zscores`.

        Returns
        -------
        ndarray of shape (n_flights,)
            Non-negative, dimensionless; NaN for a flight with no indicator.
        """
        z = self._z(table)
        available = np.isfinite(z)
        z0 = np.where(available, z, 0.0)
        out = np.full(z.shape[0], np.nan)
        patterns, inverse = np.unique(available, axis=0, return_inverse=True)
        for j, mask in enumerate(patterns):
            rows = inverse.ravel() == j
            if not mask.any():
                continue
            if mask.all():
                inv, rank = self.precision_ * np.outer(self.std_, self.std_), self.rank_
            else:
                inv, rank = pinvh(self.correlation_[np.ix_(mask, mask)], rtol=PINV_RTOL, return_rank=True)
            zs = z0[np.ix_(rows, mask)]
            d2 = np.maximum(np.einsum("ij,jk,ik->i", zs, inv, zs), 0.0)
            out[rows] = np.sqrt(chi2_equivalent(d2, rank, self.rank_))
        return out


def _standardise_columns(x: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Centre and scale columns (ddof=1); a column whose spread is <= ``floor`` becomes zero.

    Comparing with the floor rather than with 0 matters: a constant column of
    0.1 has a rounding-error spread of about 1e-17, not 0.
    """
    centred = x - x.mean(axis=0)
    scale = np.sqrt((centred**2).sum(axis=0) / (x.shape[0] - 1))
    return np.divide(centred, scale, out=np.zeros_like(centred), where=scale > floor)


def chi2_equivalent(d2, k: int, p: int) -> np.ndarray:
    """Map a chi-square(k) statistic to the chi-square(p) value of equal tail probability.

    Returns ``x_p`` with ``P(chi2_p > x_p) = P(chi2_k > d2)``: a squared
    Mahalanobis distance over ``k`` available indicators becomes comparable
    to one over all ``p``. Exact (``scipy.special.chdtri``) while the tail
    probability exceeds 1e-150; beyond, the asymptotic expansion
    ``log P(chi2_k > x) = -x/2 + (k/2 - 1) log(x/2) - lgamma(k/2)
    + log(1 + (k/2-1)/(x/2) + (k/2-1)(k/2-2)/(x/2)^2)`` is solved for ``x_p``
    by fixed-point iteration (relative error < 1e-7 there), so the result stays
    finite and increasing for arbitrarily large ``d2``.

    Parameters
    ----------
    d2 : array-like
        Non-negative chi-square(k) values.
    k, p : int
        Degrees of freedom, ``1 <= k <= p``.

    Returns
    -------
    ndarray
        Same shape as ``d2``.

    Examples
    --------
    >>> from fuelhm_bench.diagnosis.healthy import chi2_equivalent
    >>> round(float(chi2_equivalent(3.84, 1, 1)), 2)  # identity when k == p
    3.84
    >>> round(float(chi2_equivalent(3.84, 1, 10)), 1)  # both are 95 % quantiles
    18.3
    """
    d2 = np.asarray(d2, dtype=np.float64)
    if k == p:
        return d2.copy()
    q = chdtrc(k, d2)
    out = chdtri(p, np.where(q > _TAIL_SWITCH, q, 0.5))
    tail = ~(q > _TAIL_SWITCH)
    if np.any(tail):
        out = np.where(tail, _chi2_tail_equivalent(np.where(tail, d2, 1e3), k, p), out)
    return out


def _log_chi2_sf_asymptotic(y: np.ndarray, s: float) -> np.ndarray:
    """Asymptotic log upper-tail of chi-square with 2s dof at x = 2y (y >> s)."""
    return -y + (s - 1.0) * np.log(y) - gammaln(s) + np.log1p((s - 1.0) / y + (s - 1.0) * (s - 2.0) / y**2)


def _chi2_tail_equivalent(d2: np.ndarray, k: int, p: int) -> np.ndarray:
    log_q = _log_chi2_sf_asymptotic(d2 / 2.0, k / 2.0)
    sp = p / 2.0
    y = d2 / 2.0
    for _ in range(8):
        y = -log_q + (sp - 1.0) * np.log(y) - gammaln(sp) + np.log1p((sp - 1.0) / y + (sp - 1.0) * (sp - 2.0) / y**2)
    return 2.0 * y
