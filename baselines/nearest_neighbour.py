"""Nearest-neighbour detector: mean distance to the closest healthy training flights.

A local, non-parametric method (scikit-learn ``NearestNeighbors``): a flight
is abnormal when no healthy training flight is near it, whatever the shape of
the healthy population.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.neighbors import NearestNeighbors

from fuelhm_bench.methods.params import Interval, Options, RandomState

from fuelhm_baselines._common import ModeSubset
from fuelhm_baselines._detector import HealthyScoreDetector

__all__ = ["NearestNeighbourMethod"]


class NearestNeighbourMethod(HealthyScoreDetector):
    """Mean Euclidean distance to the ``n_neighbors`` nearest healthy flights; quantile threshold.

    Features, threshold and diagnosis: see :mod:`baselines._detector`. The
    score is the mean distance (standardised units) from the flight to its
    ``n_neighbors`` nearest training flights (capped by the number of
    training flights).

    Parameters
    ----------
    n_neighbors : int >= 1, default=5
    quantile : float in (0, 1), default=0.975
    cv : int >= 2, "loo", "units" or None, default=5
    symmetric_modes : tuple of str, default=("null_bias_drift",)
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the folds.

    Examples
    --------
    >>> from fuelhm_bench.methods import make_check_data
    >>> data = make_check_data(0)
    >>> method = NearestNeighbourMethod().fit(data.healthy, knowledge=data.knowledge, random_state=0)
    >>> method.threshold_ > 0
    True
    """

    _parameter_constraints = {
        "n_neighbors": (Interval(int, 1, None, closed="left"),),
        "quantile": (Interval(float, 0.0, 1.0, closed="neither"),),
        "cv": (Interval(int, 2, None, closed="left"), Options({"loo", "units"}), None),
        "symmetric_modes": (ModeSubset(),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, n_neighbors: int = 5, quantile: float = 0.975, cv: Any = 5,
                 symmetric_modes: tuple[str, ...] = ("null_bias_drift",),
                 random_state: Any = None) -> None:
        self.n_neighbors = n_neighbors
        self.quantile = quantile
        self.cv = cv
        self.symmetric_modes = symmetric_modes
        self.random_state = random_state

    def _fit_scorer(self, z: np.ndarray, seed: int) -> NearestNeighbors:
        return NearestNeighbors(n_neighbors=max(1, min(self.n_neighbors, len(z)))).fit(z)

    def _score(self, scorer: NearestNeighbors, z: np.ndarray) -> np.ndarray:
        distance, _ = scorer.kneighbors(z)
        return distance.mean(axis=1)
