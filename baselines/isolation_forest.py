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

__all__ = ["FlatForest", "IsolationForestMethod"]


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
    (about 0.5 or less for typical healthy flights). ``decide`` scores its one
    flight with :class:`FlatForest`, the fitted trees walked as flat arrays,
    which gives the same bits as ``score_samples`` (checked at the end of
    ``fit`` on the training flights; ``score_samples`` is used where it does
    not) at a fraction of its cost: ``score_samples`` on a single row spends
    1-4.5 ms dispatching its 100 trees one by one through joblib.

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
    flat_forest_ : FlatForest or None
        ``forest_`` as flat arrays (None where it does not reproduce
        ``forest_.score_samples`` on the training flights bit for bit).

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
        self.flat_forest_ = FlatForest.if_exact(forest, _features(model, x))
        self.training_scores_ = scores
        self.threshold_ = float(np.quantile(scores, self.quantile))
        self.references_ = (reference_signatures(knowledge, "signatures", model.std_)
                            if self.diagnosis == "collinearity" else None)
        self.n_training_flights_ = n

    def _decide(self, row: pd.Series) -> Decision:
        x = row_values(row)
        z = _features(self.healthy_model_, x)
        flat = getattr(self, "flat_forest_", None)
        score = float(flat.score(z[0]) if flat is not None else -self.forest_.score_samples(z)[0])
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


def _mean_path_length(n_samples: np.ndarray) -> np.ndarray:
    """``c(n)``: mean path length of an unsuccessful search in a binary search tree of ``n`` points.

    Liu, Ting & Zhou (2008), eq. 1: ``c(n) = 2 H(n - 1) - 2 (n - 1) / n`` with
    ``H(i) = ln(i) + 0.5772156649`` (Euler's constant); ``c(1) = 0``, ``c(2) = 1``.
    The operations are those of scikit-learn's forest, so the scores agree to the bit.
    """
    n = np.asarray(n_samples, dtype=float)
    out = np.zeros(n.shape)
    out[n == 2] = 1.0
    big = n > 2
    out[big] = 2.0 * (np.log(n[big] - 1.0) + np.euler_gamma) - 2.0 * (n[big] - 1.0) / n[big]
    return out


class FlatForest:
    """A fitted :class:`~sklearn.ensemble.IsolationForest` as flat node arrays, to score one row fast.

    Every tree's nodes are concatenated; a row walks all the trees at once, one
    level per step (as many steps as the deepest tree). A leaf contributes its
    depth plus ``c(n)`` of the training points left in it, summed over the
    trees in their order, and the score is ``2 ** (-mean / c(max_samples))``,
    the opposite of ``IsolationForest.score_samples``. The row is rounded to
    float32 first, as the trees compare it.

    Parameters
    ----------
    forest : sklearn.ensemble.IsolationForest
        A fitted forest (its trees' public ``tree_`` arrays are read).
    """

    def __init__(self, forest: IsolationForest) -> None:
        left, right, feature, threshold, term, roots = [], [], [], [], [], []
        offset, depth = 0, 0
        for tree, columns in zip(forest.estimators_, forest.estimators_features_):
            t = tree.tree_
            leaf = t.children_left < 0
            roots.append(offset)
            left.append(np.where(leaf, np.arange(t.node_count), t.children_left) + offset)
            right.append(np.where(leaf, np.arange(t.node_count), t.children_right) + offset)
            columns = np.asarray(columns)
            feature.append(np.where(leaf, 0, columns[np.maximum(t.feature, 0)]))
            threshold.append(np.where(leaf, np.inf, t.threshold))
            depths = t.compute_node_depths()
            term.append(depths + _mean_path_length(t.n_node_samples) - 1.0)
            offset += t.node_count
            depth = max(depth, int(depths.max()))
        self.left, self.right = np.concatenate(left), np.concatenate(right)
        self.feature, self.threshold = np.concatenate(feature), np.concatenate(threshold)
        self.term, self.roots = np.concatenate(term), np.asarray(roots)
        self.steps = depth - 1
        self.denominator = float(len(forest.estimators_) * _mean_path_length(np.array([forest.max_samples_]))[0])

    @classmethod
    def if_exact(cls, forest: IsolationForest, x: np.ndarray) -> FlatForest | None:
        """The flat forest when it scores ``x`` exactly as ``forest.score_samples`` does, else None."""
        flat = cls(forest)
        mine = np.array([flat.score(row) for row in x])
        return flat if np.array_equal(mine, -forest.score_samples(x)) else None

    def score(self, row: np.ndarray) -> float:
        """Anomaly score of one row of features (``-score_samples``, in (0, 1])."""
        x = np.asarray(row, dtype=np.float32).astype(float)
        node = self.roots
        for _ in range(self.steps):  # a leaf points to itself, and its threshold is +inf
            node = np.where(x[self.feature[node]] <= self.threshold[node], self.left[node], self.right[node])
        depth = np.cumsum(self.term[node])[-1]  # summed tree by tree, in order, like the forest
        # one training point per tree: c(1) = 0, and the forest takes the ratio as 1 (score 0.5)
        ratio = depth / self.denominator if self.denominator != 0.0 else 1.0
        return float(np.power(2.0, -ratio))
