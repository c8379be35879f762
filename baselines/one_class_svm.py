"""One-class SVM detector: a kernel boundary around the healthy flights.

A boundary method (scikit-learn ``OneClassSVM``, RBF kernel): no density is
estimated, only the support of the healthy data, with smooth (kernel)
extrapolation.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.svm import OneClassSVM

from fuelhm_bench.methods.params import Interval, Options, RandomState

from fuelhm_baselines._common import ModeSubset
from fuelhm_baselines._detector import HealthyScoreDetector

__all__ = ["OneClassSVMMethod"]


class OneClassSVMMethod(HealthyScoreDetector):
    """RBF one-class SVM on standardised indicators; quantile threshold.

    Features, threshold and diagnosis: see :mod:`baselines._detector`. The
    score is ``-OneClassSVM.decision_function(z)`` (positive outside the
    learnt boundary).

    Parameters
    ----------
    nu : float in (0, 1], default=0.1
        Upper bound of the fraction of training flights outside the boundary.
    gamma : "scale" or float > 0, default="scale"
        RBF kernel coefficient (per squared standardised unit).
    quantile : float in (0, 1), default=0.975
    cv : int >= 2, "loo", "units" or None, default=5
    symmetric_modes : tuple of str, default=("null_bias_drift",)
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the folds (the SVM itself is deterministic).

    Examples
    --------
    >>> from fuelhm_bench.methods import make_check_data
    >>> data = make_check_data(0)
    >>> method = OneClassSVMMethod().fit(data.healthy, knowledge=data.knowledge, random_state=0)
    >>> bool(np.isfinite(method.threshold_))
    True
    """

    _parameter_constraints = {
        "nu": (Interval(float, 0.0, 1.0, closed="right"),),
        "gamma": (Options({"scale"}), Interval(float, 0.0, None, closed="neither")),
        "quantile": (Interval(float, 0.0, 1.0, closed="neither"),),
        "cv": (Interval(int, 2, None, closed="left"), Options({"loo", "units"}), None),
        "symmetric_modes": (ModeSubset(),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, nu: float = 0.1, gamma: Any = "scale", quantile: float = 0.975, cv: Any = 5,
                 symmetric_modes: tuple[str, ...] = ("null_bias_drift",),
                 random_state: Any = None) -> None:
        self.nu = nu
        self.gamma = gamma
        self.quantile = quantile
        self.cv = cv
        self.symmetric_modes = symmetric_modes
        self.random_state = random_state

    def _fit_scorer(self, z: np.ndarray, seed: int) -> OneClassSVM:
        return OneClassSVM(kernel="rbf", nu=self.nu, gamma=self.gamma).fit(z)

    def _score(self, scorer: OneClassSVM, z: np.ndarray) -> np.ndarray:
        return -scorer.decision_function(z)
