"""A detector scored by a model of the healthy indicators, with a quantile threshold.

Shared by the reference detectors of different inductive biases
(:mod:`baselines.gaussian_full`, :mod:`baselines.gaussian_mixture`,
:mod:`baselines.one_class_svm`, :mod:`baselines.nearest_neighbour`), written
against the public API only. A subclass says how to fit a novelty model on
standardised healthy flights and how to score new ones
(:meth:`HealthyScoreDetector._fit_scorer`, :meth:`HealthyScoreDetector._score`);
this base does the rest, the same way for all:

* **Features.** Z-scores of the ten indicators with the healthy mean and
  standard deviation of the training flights (``HealthyModel``, eq. 7); a
  missing indicator (NaN, or ``<name>_valid`` False) is imputed by its healthy
  mean (Z = 0), in training and in ``decide`` alike. Flights are scored one
  by one (no per-unit history).
* **Threshold.** ``threshold_`` is the ``quantile`` quantile of the
  out-of-fold scores of the healthy training flights (each fold scored by a
  standardisation and a model fitted on the other folds), so that about
  ``1 - quantile`` of fresh healthy flights raise an alarm. The model used by
  ``decide`` is fitted on all the training flights.
* **Diagnosis.** On an alarm, guilt proportional to the collinearity of the
  Z-scores with the published reference signatures (uniform without them),
  as :class:`baselines.paper_mahalanobis.PaperMahalanobis`.
"""

from __future__ import annotations

from typing import Any

import abc

import numpy as np
import pandas as pd

from fuelhm_bench.diagnosis import HealthyModel
from fuelhm_bench.methods import BaseMethod, Decision, Knowledge

from fuelhm_baselines._common import (collinearity_guilt_7, cross_fit_folds, indicator_values,
                               reference_signatures, row_values, sklearn_seed)

__all__ = ["HealthyScoreDetector", "standardised"]


def standardised(model: HealthyModel, x: np.ndarray) -> np.ndarray:
    """Z-scores with missing values imputed by the healthy mean (Z = 0)."""
    z = model.zscores(x)
    return np.where(np.isfinite(z), z, 0.0)


class HealthyScoreDetector(BaseMethod):
    """Base of the quantile-threshold detectors (see the module docstring).

    Subclasses declare ``quantile``, ``cv`` and ``symmetric_modes`` among their
    hyperparameters and implement ``_fit_scorer(z, seed)`` (returns a fitted
    object) and ``_score(scorer, z)`` (higher = more abnormal).

    Attributes
    ----------
    healthy_model_ : fuelhm_bench.diagnosis.HealthyModel
    scorer_ : object
        The novelty model fitted on all the training flights.
    training_scores_ : numpy.ndarray of shape (n_training_flights,)
        Out-of-fold scores of the training flights.
    threshold_ : float
    references_ : pandas.DataFrame or None
    n_training_flights_ : int
    """

    @abc.abstractmethod
    def _fit_scorer(self, z: np.ndarray, seed: int) -> Any:
        """Fit the novelty model on standardised healthy indicators ``z``; return it."""

    @abc.abstractmethod
    def _score(self, scorer: Any, z: np.ndarray) -> np.ndarray:
        """Abnormality of each row of ``z`` under ``scorer`` (higher = more abnormal)."""

    def _fit_all(self, x: np.ndarray, seed: int) -> tuple[HealthyModel, Any]:
        model = HealthyModel(min_flights=2).fit(x)  # only standardises: means and standard deviations
        return model, self._fit_scorer(standardised(model, x), seed)

    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        x = indicator_values(healthy_indicators)
        n = x.shape[0]
        model, scorer = self._fit_all(x, sklearn_seed(rng))
        scores = np.empty(n)
        for train, held in cross_fit_folds(n, self.cv, rng, type(self).__name__):
            m, s = (model, scorer) if self.cv is None else self._fit_all(x[train], sklearn_seed(rng))
            scores[held] = self._score(s, standardised(m, x[held]))
        self.healthy_model_ = model
        self.scorer_ = scorer
        self.training_scores_ = scores
        self.threshold_ = float(np.quantile(scores, self.quantile))
        self.references_ = reference_signatures(knowledge, "signatures", model.std_)
        self.n_training_flights_ = n

    def _decide(self, row: pd.Series) -> Decision:
        x = row_values(row)
        score = float(self._score(self.scorer_, standardised(self.healthy_model_, x))[0])
        if not np.isfinite(score):
            score = float(np.finfo(np.float64).max)
        if score <= self.threshold_:
            return Decision.no_alarm(score)
        z = self.healthy_model_.zscores(x)[0]
        return Decision(score=score, alarm=True,
                        guilt=collinearity_guilt_7(z, self.references_, tuple(self.symmetric_modes)))
