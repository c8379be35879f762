"""Full-covariance Gaussian detector: Mahalanobis distance under the empirical covariance.

Unlike :class:`baselines.paper_mahalanobis.PaperMahalanobis` (Ledoit-Wolf
shrunk correlation, ``mu + A sigma`` threshold), the covariance is the plain
maximum-likelihood estimate (scikit-learn ``EmpiricalCovariance``, inverted
with a pseudo-inverse), so the detector relies on every small direction of
the healthy data: the inductive bias most sensitive to how faithfully a
simulator reproduces the healthy joint structure.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.covariance import EmpiricalCovariance

from fuelhm_bench.methods.params import Interval, Options, RandomState

from fuelhm_baselines._common import ModeSubset
from fuelhm_baselines._detector import HealthyScoreDetector

__all__ = ["FullGaussianMethod"]


class FullGaussianMethod(HealthyScoreDetector):
    """Mahalanobis distance under the empirical (unshrunk) covariance; quantile threshold.

    Features, threshold and diagnosis: see :mod:`baselines._detector`. The
    score is ``sqrt(d^2)`` with ``d^2`` the squared Mahalanobis distance of the
    standardised flight under ``EmpiricalCovariance`` fitted on the healthy
    training flights.

    Parameters
    ----------
    quantile : float in (0, 1), default=0.975
        Quantile of the out-of-fold healthy scores used as threshold.
    cv : int >= 2, "loo", "units" or None, default=5
        Folds of the out-of-fold training scores (see
        ``baselines._common.cross_fit_folds``); None: in-sample.
    symmetric_modes : tuple of str, default=("null_bias_drift",)
        Modes scored with ``|cos|`` by the collinearity diagnosis.
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the folds.

    Examples
    --------
    >>> from fuelhm_bench.methods import make_check_data
    >>> data = make_check_data(0)
    >>> method = FullGaussianMethod().fit(data.healthy, knowledge=data.knowledge, random_state=0)
    >>> method.threshold_ > 0
    True
    """

    _parameter_constraints = {
        "quantile": (Interval(float, 0.0, 1.0, closed="neither"),),
        "cv": (Interval(int, 2, None, closed="left"), Options({"loo", "units"}), None),
        "symmetric_modes": (ModeSubset(),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, quantile: float = 0.975, cv: Any = 5,
                 symmetric_modes: tuple[str, ...] = ("null_bias_drift",),
                 random_state: Any = None) -> None:
        self.quantile = quantile
        self.cv = cv
        self.symmetric_modes = symmetric_modes
        self.random_state = random_state

    def _fit_scorer(self, z: np.ndarray, seed: int) -> EmpiricalCovariance:
        return EmpiricalCovariance(assume_centered=False).fit(z)

    def _score(self, scorer: EmpiricalCovariance, z: np.ndarray) -> np.ndarray:
        return np.sqrt(np.maximum(scorer.mahalanobis(z), 0.0))
