"""Gaussian-mixture detector: negative log-likelihood under a mixture fitted on healthy flights.

A multi-modal density model (scikit-learn ``GaussianMixture``, full
covariances): it can follow a healthy population made of clusters (units,
operating regimes) where a single Gaussian cannot.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.mixture import GaussianMixture

from fuelhm_bench.methods.params import Interval, Options, RandomState

from fuelhm_baselines._common import ModeSubset
from fuelhm_baselines._detector import HealthyScoreDetector

__all__ = ["GaussianMixtureMethod"]


class GaussianMixtureMethod(HealthyScoreDetector):
    """Negative log-likelihood under a Gaussian mixture; quantile threshold.

    Features, threshold and diagnosis: see :mod:`baselines._detector`. The
    score is ``-GaussianMixture.score_samples(z)`` (nats) of the standardised
    flight. The number of components is capped by the number of training
    flights (at least 2 flights per component).

    Parameters
    ----------
    n_components : int >= 1, default=3
        Mixture components.
    reg_covar : float > 0, default=1e-3
        Added to the diagonal of each covariance (standardised units squared).
    quantile : float in (0, 1), default=0.975
    cv : int >= 2, "loo", "units" or None, default=5
    symmetric_modes : tuple of str, default=("null_bias_drift",)
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the folds and of the mixtures' initialisation.

    Examples
    --------
    >>> from fuelhm_bench.methods import make_check_data
    >>> data = make_check_data(0)
    >>> method = GaussianMixtureMethod(n_components=2).fit(data.healthy, knowledge=data.knowledge,
    ...                                                    random_state=0)
    >>> bool(np.isfinite(method.threshold_))
    True
    """

    _parameter_constraints = {
        "n_components": (Interval(int, 1, None, closed="left"),),
        "reg_covar": (Interval(float, 0.0, None, closed="neither"),),
        "quantile": (Interval(float, 0.0, 1.0, closed="neither"),),
        "cv": (Interval(int, 2, None, closed="left"), Options({"loo", "units"}), None),
        "symmetric_modes": (ModeSubset(),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, n_components: int = 3, reg_covar: float = 1e-3, quantile: float = 0.975,
                 cv: Any = 5, symmetric_modes: tuple[str, ...] = ("null_bias_drift",),
                 random_state: Any = None) -> None:
        self.n_components = n_components
        self.reg_covar = reg_covar
        self.quantile = quantile
        self.cv = cv
        self.symmetric_modes = symmetric_modes
        self.random_state = random_state

    def _fit_scorer(self, z: np.ndarray, seed: int) -> GaussianMixture:
        k = max(1, min(self.n_components, len(z) // 2))
        return GaussianMixture(n_components=k, covariance_type="full", reg_covar=self.reg_covar,
                               random_state=seed).fit(z)

    def _score(self, scorer: GaussianMixture, z: np.ndarray) -> np.ndarray:
        return -scorer.score_samples(z)
