"""Isolation forest on standardised indicators, with a quantile threshold (scikit-learn).

A standard unsupervised anomaly detector as a point of comparison for the
paper's Gaussian model: it makes no distributional assumption and scores a
flight by how easily random axis-aligned splits isolate it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
from sklearn.ensemble import IsolationForest

from fuelhm_bench.diagnosis import HealthyModel
from fuelhm_bench.methods import BaseMethod, Decision, Knowledge
from fuelhm_bench.methods.params import Interval, Options, RandomState

from fuelhm_baselines._common import (ModeSubset, collinearity_guilt_7, cross_fit_folds,
                                      indicator_values, reference_signatures, row_values, sklearn_seed,
                                      standardisation)

__all__ = ["IsolationForestMethod"]


class IsolationForestMethod(BaseMethod):
    """Isolation forest on healthy-standardised indicators; guilt by collinearity.

    **Features.** The indicators are standardised with the healthy mean and
    standard deviation of the training flights (``HealthyModel``, eq. 7;
    only these are used, so the fit needs as few as 3 flights, not 11:
    ``baselines._common.standardisation``);
    a missing indicator (NaN, or ``<name>_valid`` False) is imputed by its
    healthy mean, i.e. its Z-score is set to 0, in training and in ``decide``
    alike. Each flight is scored on its own (no per-unit history).

    **Score.** ``-IsolationForest.score_samples(z)``: the anomaly score of
    Liu et al. (2008), in (0, 1], higher = easier to isolate = more abnormal
    (about 0.5 or less for typical healthy flights).

    **Threshold.** ``threshold_`` is the ``quantile`` quantile of the
    out-of-fold scores of the healthy training flights (``training_scores_``):
    with ``cv=k`` the training flights are split into ``k`` random folds and
    each fold is scored by a standardisation and a forest fitted on the other
    folds (a forest scores the flights it was grown on as more normal than
    fresh ones). The alarm is ``score > threshold_``, so about
    ``1 - quantile`` of fresh healthy flights raise an alarm. The final
    standardisation and forest used by ``decide`` are fitted on all the
    training flights.

    **Diagnosis.** Only on an alarm: ``diagnosis="collinearity"`` gives guilt
    proportional to the collinearity of the flight's Z-scores (NaN where
    missing) with the published reference signatures, exactly as
    :class:`fuelhm_baselines.paper_mahalanobis.PaperMahalanobis` (uniform when no
    signature is published); ``diagnosis="uniform"`` always gives 1/7 to
    every mode (detection only).

    Parameters
    ----------
    n_estimators : int, default=100
        Number of trees.
    max_samples : "auto", int or float, default="auto"
        Flights drawn to grow each tree (scikit-learn meaning: "auto" =
        ``min(256, n)``, an int = that many, a float in (0, 1] = that fraction).
    quantile : float in (0, 1), default=0.975
        Quantile of the healthy out-of-fold scores used as threshold (0.975
        targets 2.5 % false alarms, close to the paper's ``A = 2``).
    cv : int >= 2 or None, default=5
        Folds for the out-of-fold training scores; None scores the training
        flights in-sample (threshold biased low).
    diagnosis : {"collinearity", "uniform"}, default="collinearity"
        Guilt on an alarm (see above).
    symmetric_modes : tuple of str, default=("null_bias_drift",)
        Modes scored with ``|cos|`` by the collinearity diagnosis (see
        :class:`~fuelhm_baselines.paper_mahalanobis.PaperMahalanobis`).
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the folds and of the forests (integer seeds drawn from
        ``rng_``).

    Attributes
    ----------
    healthy_model_ : fuelhm_bench.diagnosis.HealthyModel
        Standardisation fitted on all the training flights.
    forest_ : sklearn.ensemble.IsolationForest
        Forest fitted on all the training flights.
    training_scores_ : numpy.ndarray of shape (n_training_flights,)
        Out-of-fold anomaly scores of the training flights.
    threshold_ : float
        Alarm threshold on the score.
    references_ : pandas.DataFrame or None
        Reference signatures of the collinearity diagnosis (None with
        ``diagnosis="uniform"`` or without published signatures).
    n_training_flights_ : int
        Number of healthy training flights.

    Examples
    --------
    >>> from fuelhm_bench.methods import make_check_data
    >>> data = make_check_data(0)
    >>> method = IsolationForestMethod(n_estimators=50).fit(
    ...     data.healthy, knowledge=data.knowledge, random_state=0)
    >>> 0.0 < method.threshold_ < 1.0
    True
    """

    _parameter_constraints = {
        "n_estimators": (Interval(int, 1, None, closed="left"),),
        "max_samples": (Options({"auto"}), Interval(int, 1, None, closed="left"),
                        Interval(float, 0.0, 1.0, closed="right")),
        "quantile": (Interval(float, 0.0, 1.0, closed="neither"),),
        "cv": (Interval(int, 2, None, closed="left"), None),
        "diagnosis": (Options({"collinearity", "uniform"}),),
        "symmetric_modes": (ModeSubset(),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, n_estimators: int = 100, max_samples: Any = "auto",
                 quantile: float = 0.975, cv: Any = 5, diagnosis: str = "collinearity",
                 symmetric_modes: tuple[str, ...] = ("null_bias_drift",),
                 random_state: Any = None) -> None:
        self.n_estimators = n_estimators
        self.max_samples = max_samples
        self.quantile = quantile
        self.cv = cv
        self.diagnosis = diagnosis
        self.symmetric_modes = symmetric_modes
        self.random_state = random_state

    def _fit_models(self, x: np.ndarray, seed: int) -> tuple[HealthyModel, IsolationForest]:
        model = standardisation(x)  # Z-scores only: fits from few flights (low_data)
        forest = IsolationForest(n_estimators=self.n_estimators, max_samples=self.max_samples,
                                 random_state=seed)
        forest.fit(_features(model, x))
        return model, forest

    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        x = indicator_values(healthy_indicators)
        n = x.shape[0]
        model, forest = self._fit_models(x, sklearn_seed(rng))
        scores = np.empty(n)
        for train, held in cross_fit_folds(n, self.cv, rng, type(self).__name__):
            if self.cv is None:
                m, f = model, forest
            else:
                m, f = self._fit_models(x[train], sklearn_seed(rng))
            scores[held] = -f.score_samples(_features(m, x[held]))

        self.healthy_model_ = model
        self.forest_ = forest
        self.training_scores_ = scores
        self.threshold_ = float(np.quantile(scores, self.quantile))
        self.references_ = (reference_signatures(knowledge, "signatures", model.std_)
                            if self.diagnosis == "collinearity" else None)
        self.n_training_flights_ = n

    def _decide(self, row: pd.Series) -> Decision:
        x = row_values(row)
        score = float(-self.forest_.score_samples(_features(self.healthy_model_, x))[0])
        if score <= self.threshold_:
            return Decision.no_alarm(score)
        # references_ is None for diagnosis="uniform": collinearity_guilt_7 is then uniform.
        z = self.healthy_model_.zscores(x)[0]
        return Decision(score=score, alarm=True,
                        guilt=collinearity_guilt_7(z, self.references_,
                                                   tuple(self.symmetric_modes)))


def _features(model: HealthyModel, x: np.ndarray) -> np.ndarray:
    """Z-scores with missing values imputed by the healthy mean (Z = 0)."""
    z = model.zscores(x)
    return np.where(np.isfinite(z), z, 0.0)
