"""Detection thresholds from the healthy-training score distribution (paper eq. 10)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import pandas as pd
from scipy.stats import norm

from fuelhm_bench.errors import DataFormatError

__all__ = ["HealthyScoreModel", "fit_healthy_model", "threshold_table"]


@dataclass(frozen=True)
class HealthyScoreModel:
    """Gaussian maximum-likelihood fit of the healthy-training global scores.

    Attributes
    ----------
    mu : float
        Mean of the healthy-training scores (score units).
    sigma : float
        Maximum-likelihood standard deviation (``ddof=0``), as in the paper's
        "maximum likelihood function" (section VI.C.2).
    n : int
        Number of healthy-training scores.
    """

    mu: float
    sigma: float
    n: int

    def threshold(self, a: float) -> float:
        """``Thr = mu + A * sigma`` (paper eq. 10)."""
        return self.mu + float(a) * self.sigma

    def pdf(self, x: Any) -> np.ndarray:
        """Gaussian likelihood of scores ``x`` (for the Fig. 10 overlay)."""
        x = np.asarray(x, dtype=float)
        if self.sigma == 0:
            return np.where(x == self.mu, np.inf, 0.0)
        return norm.pdf(x, loc=self.mu, scale=self.sigma)


def fit_healthy_model(healthy_scores: Any) -> HealthyScoreModel:
    """Fit the Gaussian of paper eq. 10 to the method's healthy-training scores.

    Only the method's scores on its healthy *training* flights may be passed
    here: thresholds never see the scored flights or their labels.

    Parameters
    ----------
    healthy_scores : array-like of float
        At least two finite scores.

    Returns
    -------
    HealthyScoreModel

    Examples
    --------
    >>> m = fit_healthy_model([1.0, 2.0, 3.0])
    >>> round(m.threshold(2), 4)
    3.633
    >>> fit_healthy_model([1e308, -1e308]).sigma  # no overflow
    1e+308
    """
    s = np.asarray(healthy_scores, dtype=float).ravel()
    if s.size < 2 or not np.all(np.isfinite(s)):
        raise DataFormatError(f"The 'healthy_scores' parameter of fit_healthy_model must hold at "
                              f"least 2 finite scores. Got {s.size} scores instead.")
    # Computed on the scores divided by a power of two near the largest |score|: scores near the float
    # range (1e300) would overflow in the sum and the squares (a numpy RuntimeWarning, then mu or sigma =
    # inf). A power of two scales exactly, so mu and sigma keep every bit of the direct computation.
    scale = float(np.ldexp(1.0, int(np.frexp(np.max(np.abs(s)))[1]) - 1))  # max |unit| in [1, 2)
    unit = s / scale
    return HealthyScoreModel(mu=scale * float(unit.mean()), sigma=scale * float(unit.std(ddof=0)), n=int(s.size))


def threshold_table(model: HealthyScoreModel, a_values: Sequence[float]) -> pd.DataFrame:
    """Thresholds for each ``A``, with the false-alarm rate a Gaussian would give.

    Returns
    -------
    pandas.DataFrame
        Columns ``a, threshold, mu, sigma, n_healthy_training,
        gaussian_tail_probability`` (``1 - Phi(A)``: the expected standard FPR
        if healthy scores were exactly Gaussian; e.g. 2.3 % at A = 2).
    """
    a = np.asarray(list(a_values), dtype=float)
    return pd.DataFrame({
        "a": a,
        "threshold": [model.threshold(x) for x in a],
        "mu": model.mu,
        "sigma": model.sigma,
        "n_healthy_training": model.n,
        "gaussian_tail_probability": norm.sf(a),
    })

