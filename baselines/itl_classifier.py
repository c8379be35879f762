"""Supervised classifier trained on synthetic degraded flights made with the ITL (scikit-learn).

The paper's ITL (eq. 4) turn any healthy flight into an estimate of the same
flight under a degradation: ``I_deg = I_healthy + A * intensity``. This
baseline uses them as a data generator: it trains a multinomial logistic
regression to tell apart the healthy training flights and synthetic degraded
copies of them, one class per mode, and reads detection (``P(healthy)``) and
diagnosis (the class probabilities of the modes) from the same model.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from sklearn.linear_model import LogisticRegression
from threadpoolctl import threadpool_limits

from fuelhm_bench.diagnosis import HealthyModel
from fuelhm_bench.methods import BaseMethod, Decision, Knowledge, normalize_guilt
from fuelhm_bench.methods.params import Interval, RandomState
from fuelhm_bench.taxonomy import MODE_IDS

from fuelhm_baselines._common import (ModeSubset, cross_fit_folds, indicator_values, itl_coefficients,
                                      row_values, sklearn_seed, standardisation)

__all__ = ["ITLClassifierMethod"]

#: Class label of the healthy flights.
_HEALTHY = 0


class ITLClassifierMethod(BaseMethod):
    """Logistic regression on healthy flights vs. ITL-degraded copies of them.

    **Training set.** From the healthy training flights ``x`` (indicator
    units) and, for every mode ``m`` with a non-zero ITL row and a maximal
    intensity in the knowledge, ``n_synthetic_per_mode`` synthetic flights
    ``x[j] + s * A_m`` (paper eq. 4) with ``j`` drawn uniformly among the
    training flights and ``s = f * max_intensity[m]``, ``f`` uniform in
    ``(detectable_fraction, 1]``, so the classifier learns the modes at the
    intensities the scorer counts as detectable. For a mode of
    ``symmetric_modes`` the sign of ``s`` is drawn at random and each sign is
    its own class (a linear model cannot put both ends of a line in one
    class); their probabilities are added back for the guilt. A NaN law
    coefficient counts as 0 (no known change); a missing indicator stays
    missing in its synthetic copies. The healthy class is the training
    flights themselves. Features are the Z-scores of the indicators (healthy
    mean and standard deviation, ``HealthyModel``; only these are used, so
    the fit needs as few as 3 flights, not 11:
    ``baselines._common.standardisation``), missing ones imputed by the
    healthy mean (Z = 0).

    **Score and alarm.** ``score = -log P(healthy | flight)`` (natural log,
    >= 0, finite: computed from the decision function with a log-sum-exp).
    The alarm is ``P(healthy) < threshold_``, i.e. ``score > -log
    threshold_``, where ``threshold_`` is calibrated on the healthy training
    flights: the ``false_alarm_rate`` quantile of their *out-of-fold*
    ``P(healthy)`` (with ``cv=k`` folds, each fold is predicted by a model
    whose healthy class and synthetic flights were built without it).

    **Diagnosis.** On an alarm, the guilt is the class probabilities of the
    modes renormalised to sum to 1 (modes without a law get 0); no guilt
    otherwise.

    Each flight is decided on its own (no per-unit history). The method needs
    ``knowledge.itl`` and ``knowledge.max_intensity`` for at least one mode;
    ``fit`` raises ``ValueError`` otherwise.

    Parameters
    ----------
    n_synthetic_per_mode : int or None, default=None
        Synthetic flights per mode; None = as many as healthy training flights
        (balanced classes).
    detectable_fraction : float in [0, 1), default=0.25
        Lower end (excluded) of the synthetic intensities, as a fraction of
        the mode's maximal intensity (the scorer's default detectability cut).
    false_alarm_rate : float in (0, 1), default=0.025
        Target share of healthy training flights (out-of-fold) that would
        alarm; sets ``threshold_`` (0.025 is close to the paper's ``A = 2``).
    C : float > 0, default=1.0
        Inverse L2 regularisation strength of the logistic regression.
    cv : int >= 2 or None, default=5
        Folds for the out-of-fold calibration of ``threshold_``; None
        calibrates in-sample (threshold too permissive toward healthy).
    symmetric_modes : tuple of str, default=("null_bias_drift",)
        Modes simulated with both signs of the ITL (see above; the null-bias
        drift may go either way, docs/physics.md §6 Degradation modes).
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the synthetic flights, of the folds and of the classifier
        (integer seeds drawn from ``rng_``).

    Attributes
    ----------
    healthy_model_ : fuelhm_bench.diagnosis.HealthyModel
        Standardisation fitted on all the training flights.
    classifier_ : sklearn.linear_model.LogisticRegression
        Classifier fitted on all the training flights and their synthetic copies.
    class_modes_ : numpy.ndarray of int
        For every column of the classifier's probabilities, the index of its
        mode in ``MODE_IDS``, or -1 for the healthy class.
    modes_ : tuple of str
        Modes the classifier knows.
    training_scores_ : numpy.ndarray of shape (n_training_flights,)
        Out-of-fold scores ``-log P(healthy)`` of the training flights.
    threshold_ : float
        Alarm threshold on ``P(healthy)``.
    score_threshold_ : float
        The same threshold on the score, ``-log threshold_``.
    n_training_flights_ : int
        Number of healthy training flights.

    Examples
    --------
    >>> from fuelhm_bench.methods import make_check_data
    >>> data = make_check_data(0)
    >>> method = ITLClassifierMethod().fit(data.healthy, knowledge=data.knowledge, random_state=0)
    >>> len(method.modes_), 0.0 < method.threshold_ < 1.0
    (7, True)
    """

    _parameter_constraints = {
        "n_synthetic_per_mode": (Interval(int, 1, None, closed="left"), None),
        "detectable_fraction": (Interval(float, 0.0, 1.0, closed="left"),),
        "false_alarm_rate": (Interval(float, 0.0, 1.0, closed="neither"),),
        "C": (Interval(float, 0.0, None, closed="neither"),),
        "cv": (Interval(int, 2, None, closed="left"), None),
        "symmetric_modes": (ModeSubset(),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, n_synthetic_per_mode: Any = None, detectable_fraction: float = 0.25,
                 false_alarm_rate: float = 0.025, C: float = 1.0, cv: Any = 5,
                 symmetric_modes: tuple[str, ...] = ("null_bias_drift",),
                 random_state: Any = None) -> None:
        self.n_synthetic_per_mode = n_synthetic_per_mode
        self.detectable_fraction = detectable_fraction
        self.false_alarm_rate = false_alarm_rate
        self.C = C
        self.cv = cv
        self.symmetric_modes = symmetric_modes
        self.random_state = random_state

    # ------------------------------------------------------------------ fit
    def _laws(self, knowledge: Knowledge | None) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Modes with a non-zero law and a maximal intensity; their slopes (NaN -> 0) and maxima."""
        coef = itl_coefficients(knowledge)
        mi = {} if knowledge is None or knowledge.max_intensity is None else knowledge.max_intensity
        modes = [] if coef is None else [
            m for m in coef.index
            if m in mi and np.any(np.nan_to_num(coef.loc[m].to_numpy(dtype=float)) != 0)]
        if not modes:
            raise ValueError(f"The 'knowledge' parameter of {type(self).__name__}.fit must provide "
                             f"'itl' and 'max_intensity' for at least one mode. Got "
                             f"{'None' if knowledge is None else 'no such mode'} instead.")
        slopes = np.nan_to_num(coef.loc[modes].to_numpy(dtype=float), nan=0.0)
        return modes, slopes, np.array([mi[m] for m in modes], dtype=float)

    def _fit_one(self, x: np.ndarray, modes: list[str], slopes: np.ndarray,
                 max_intensity: np.ndarray, rng: np.random.Generator
                 ) -> tuple[HealthyModel, LogisticRegression, np.ndarray]:
        """Fit standardisation + classifier on healthy flights ``x`` and their synthetic copies."""
        n = x.shape[0]
        n_syn = n if self.n_synthetic_per_mode is None else int(self.n_synthetic_per_mode)
        lo = float(self.detectable_fraction)
        blocks, labels = [x], [np.full(n, _HEALTHY)]
        label_modes = {_HEALTHY: -1}
        for k, mode in enumerate(modes):
            source = x[rng.integers(0, n, size=n_syn)]
            fraction = lo + (1.0 - lo) * (1.0 - rng.random(n_syn))  # uniform in (lo, 1]
            sign = (rng.choice([-1.0, 1.0], size=n_syn) if mode in self.symmetric_modes
                    else np.ones(n_syn))
            blocks.append(source + (sign * fraction * max_intensity[k])[:, None] * slopes[k])
            positive, negative = 1 + 2 * k, 2 + 2 * k
            labels.append(np.where(sign > 0, positive, negative))
            label_modes[positive] = label_modes[negative] = MODE_IDS.index(mode)
        model = standardisation(x)  # Z-scores only: fits from few flights (low_data)
        clf = LogisticRegression(C=float(self.C), max_iter=2000, random_state=sklearn_seed(rng))
        # A small problem (10 features): BLAS threads only add synchronisation (the fit was
        # ~7x slower with them on a loaded 2-core machine); one thread also makes the result
        # independent of the machine's thread count.
        with threadpool_limits(limits=1, user_api="blas"):
            clf.fit(_features(model, np.vstack(blocks)), np.concatenate(labels))
        class_modes = np.array([label_modes[int(c)] for c in clf.classes_], dtype=np.int64)
        return model, clf, class_modes

    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        modes, slopes, max_intensity = self._laws(knowledge)
        x = indicator_values(healthy_indicators)
        n = x.shape[0]
        model, clf, class_modes = self._fit_one(x, modes, slopes, max_intensity, rng)
        scores = np.empty(n)
        for train, held in cross_fit_folds(n, self.cv, rng, type(self).__name__):
            if self.cv is None:
                m, c, cm = model, clf, class_modes
            else:
                m, c, cm = self._fit_one(x[train], modes, slopes, max_intensity, rng)
            scores[held] = _healthy_score(_log_proba(c, _features(m, x[held])), cm)

        self.healthy_model_ = model
        self.classifier_ = clf
        self.class_modes_ = class_modes
        self.modes_ = tuple(modes)
        self.training_scores_ = scores
        self.score_threshold_ = float(np.quantile(scores, 1.0 - float(self.false_alarm_rate)))
        self.threshold_ = math.exp(-self.score_threshold_)
        self.n_training_flights_ = n

    # --------------------------------------------------------------- decide
    def _decide(self, row: pd.Series) -> Decision:
        log_p = _log_proba(self.classifier_, _features(self.healthy_model_, row_values(row)))
        score = float(_healthy_score(log_p, self.class_modes_)[0])
        log_p = log_p[0]
        if score <= self.score_threshold_:
            return Decision.no_alarm(score)
        p = np.exp(log_p)
        weights = np.zeros(len(MODE_IDS))
        np.add.at(weights, self.class_modes_[self.class_modes_ >= 0], p[self.class_modes_ >= 0])
        return Decision(score=score, alarm=True, guilt=normalize_guilt(weights))


def _features(model: HealthyModel, x: np.ndarray) -> np.ndarray:
    """Z-scores with missing values imputed by the healthy mean (Z = 0)."""
    z = model.zscores(x)
    return np.where(np.isfinite(z), z, 0.0)


def _healthy_score(log_p: np.ndarray, class_modes: np.ndarray) -> np.ndarray:
    """``-log P(healthy)`` per row, clipped at 0 (rounding can make a log-probability > 0)."""
    return np.maximum(-log_p[:, class_modes == -1][:, 0], 0.0)


def _log_proba(clf: LogisticRegression, features: np.ndarray) -> np.ndarray:
    """Class log-probabilities, finite (unlike ``log(predict_proba)``), columns = ``clf.classes_``.

    Computed from the fitted ``coef_`` and ``intercept_`` (the decision
    function) with a log-sum-exp, which is also much faster than
    ``decision_function`` for one row.
    """
    d = features @ clf.coef_.T + clf.intercept_
    if d.shape[1] == 1:  # two classes: d is the logit of classes_[1]
        d = np.column_stack([np.zeros(d.shape[0]), d[:, 0]])
    top = d.max(axis=1, keepdims=True)
    return d - (top + np.log(np.exp(d - top).sum(axis=1, keepdims=True)))
