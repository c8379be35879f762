"""The paper's method: Mahalanobis global score, eq. 10 threshold, collinearity diagnosis.

Lamoureux, Massé & Mechbal (IEEE PHM 2012), section VI.B and VI.C:

1. learn a Gaussian model of the indicators on healthy flights (eq. 6);
2. turn a flight's indicators into Z-scores (eq. 7) and combine them into a
   global score with the Mahalanobis distance; raise an alarm when the score
   crosses ``Thr = mu + A * sigma`` of the healthy global-score distribution
   (eq. 10);
3. on an alarm, give each mode a probability of guilt proportional to the
   collinearity of the flight's Z-score signature (eq. 8) with the mode's
   reference signature at maximal intensity (eq. 9, Table IV).

Written against the public API only (``fuelhm_bench.methods``,
``fuelhm_bench.diagnosis``, ``fuelhm_bench.taxonomy``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from fuelhm_bench.diagnosis import HealthyModel
from fuelhm_bench.methods import BaseMethod, Decision, Knowledge
from fuelhm_bench.methods.params import Interval, Options, RandomState

from fuelhm_baselines._common import (ModeSubset, collinearity_guilt_7, cross_fit_folds,
                               indicator_values, reference_signatures, row_values,
                               training_sequences, window_mean)

__all__ = ["PaperMahalanobis"]


class PaperMahalanobis(BaseMethod):
    """Mahalanobis detector with the eq. 10 threshold and collinearity diagnosis (the paper).

    **Detection.** ``fit`` learns a :class:`~fuelhm_bench.diagnosis.HealthyModel`
    (per-indicator mean and standard deviation, Ledoit-Wolf-shrunk correlation)
    on the healthy training flights. For a flight, the Z-scores (eq. 7) are
    averaged over the last ``window`` flights of the unit (causal moving
    average, NaN-aware; ``window=1`` is the paper) and the score is the
    Mahalanobis distance of that average, ``sqrt(z^T R^-1 z)``
    (``HealthyModel.global_score``: flights with missing indicators are scored
    on the available ones and mapped to the 10-indicator scale by equal tail
    probability). A flight without any available indicator scores 0 and never
    alarms. The alarm is ``score > threshold_`` (strict, as in the scorer).

    **Threshold (paper eq. 10).** ``threshold_ = mu_ + a * sigma_`` where
    ``mu_`` and ``sigma_`` (maximum likelihood, ``ddof=0``) are the mean and
    standard deviation of the *out-of-fold* global scores of the healthy
    training flights (``training_scores_``): with ``cv="loo"`` each training
    flight is scored by a healthy model fitted on all the other training
    flights, so the scores are distributed like those of fresh healthy
    flights. In-sample scores (``cv=None``, the paper's literal recipe) are
    biased low (a model always fits the flights it has seen), which lowers the
    threshold and raises the false-alarm rate, the more so the fewer training
    flights there are. With ``window > 1`` the out-of-fold Z-scores are
    smoothed along each training unit (grouped by ``unit_id``, in
    ``flight_index`` order) exactly as in ``decide``, so the threshold refers
    to the smoothed statistic. For a Gaussian healthy population the score is
    chi-distributed with 10 degrees of freedom; ``a=2`` then gives a
    false-alarm rate of about 2.9 % (the Gaussian approximation of the paper
    says 2.3 %, one-sided).

    **Diagnosis.** Only on an alarm (otherwise the guilt is all zeros): guilt of
    mode ``m`` proportional to ``max(0, cos(z, r_m))`` between the (smoothed)
    Z-score signature ``z`` and the reference signature ``r_m``
    (``fuelhm_bench.diagnosis.collinearity_guilt``), ``|cos|`` for the modes
    in ``symmetric_modes``. References come from ``knowledge.signatures``
    (``references="signatures"``) or are recomputed from ``knowledge.itl`` and
    ``knowledge.max_intensity`` with this model's healthy standard deviations
    (``references="itl"``, eq. 9). Modes without a reference get no guilt.
    When the knowledge provides no reference at all (no knowledge, no
    signatures), or no reference is positively collinear, the guilt is
    uniform over the candidate modes (all seven without references): the
    method knows something is wrong but not what.

    Parameters
    ----------
    a : float, default=2.0
        ``A`` of eq. 10, in standard deviations of the healthy global score,
        >= 0.
    window : int, default=1
        Number of most recent flights of the unit (current one included) whose
        Z-scores are averaged before scoring and diagnosis; 1 = the paper
        (no smoothing).
    cv : {"units", "loo"}, int >= 2 or None, default="units"
        How the healthy training scores behind the threshold are obtained:
        ``"units"`` leave-one-unit-out (one healthy model per training unit,
        scoring that unit's flights: the scores are distributed like those of a
        new engine, unit-to-unit dispersion included; falls back to ``"loo"``
        without ``unit_id``, with fewer than 3 units, or when leaving a unit out
        leaves fewer flights than a 10-indicator model needs (11)), ``"loo"``
        leave-one-flight-out (one model per flight; other flights of the same
        unit stay in training, so the threshold ignores unit-to-unit dispersion:
        on paper_2012 it gave 33 % false alarms on new units instead of ~6 %),
        ``k`` k-fold cross-fitting over a random permutation of the flights
        (uses ``random_state``), None in-sample.
    shrinkage : {"auto"} or float in [0, 1], default="auto"
        Shrinkage of the healthy correlation matrix toward the identity
        (``HealthyModel``; "auto" = Ledoit-Wolf).
    references : {"signatures", "itl"}, default="signatures"
        Source of the reference signatures for the diagnosis (see above).
    symmetric_modes : tuple of str, default=("null_bias_drift",)
        Modes whose signature may appear with either sign. The null-bias
        drift moves the whole curve left *or* right (docs/physics.md §6 Degradation modes:
        ``ΔI_nb 0 → ±20 % I_r``), so a negative drift must still point at it.
        ``()`` gives the plain signed collinearity.
    random_state : int, numpy.random.Generator or None, default=None
        Seed; used only by k-fold ``cv``.

    Attributes
    ----------
    healthy_model_ : fuelhm_bench.diagnosis.HealthyModel
        Healthy model fitted on all the training flights (used by ``decide``).
    training_scores_ : numpy.ndarray of shape (n_training_flights,)
        Out-of-fold (in-sample for ``cv=None``) global scores of the training
        flights, dimensionless (the threshold is set on them).
    mu_, sigma_ : float
        Mean and ``ddof=0`` standard deviation of ``training_scores_``.
    threshold_ : float
        ``mu_ + a * sigma_``.
    references_ : pandas.DataFrame or None
        Reference signatures used by the diagnosis (modes x indicators).
    n_training_flights_ : int
        Number of healthy training flights.

    Examples
    --------
    >>> from fuelhm_bench.methods import make_check_data
    >>> data = make_check_data(0)
    >>> method = PaperMahalanobis(a=2.0).fit(data.healthy, knowledge=data.knowledge,
    ...                                      random_state=0)
    >>> decisions = method.decide_table(data.units)   # check-0 healthy, the others degrade
    >>> decisions.groupby("unit_id")["alarm"].sum().to_dict()
    {'check-0': 0, 'check-1': 8, 'check-2': 7}
    >>> decisions.filter(like="guilt_").iloc[-13].idxmax()   # last flight of check-1
    'guilt_null_bias_drift'
    """

    _parameter_constraints = {
        "a": (Interval(float, 0.0, None, closed="left"),),
        "window": (Interval(int, 1, None, closed="left"),),
        "cv": (Options({"loo", "units"}), Interval(int, 2, None, closed="left"), None),
        "shrinkage": (Options({"auto"}), Interval(float, 0.0, 1.0, closed="both")),
        "references": (Options({"signatures", "itl"}),),
        "symmetric_modes": (ModeSubset(),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, a: float = 2.0, window: int = 1, cv: Any = "units",
                 shrinkage: Any = "auto", references: str = "signatures",
                 symmetric_modes: tuple[str, ...] = ("null_bias_drift",),
                 random_state: Any = None) -> None:
        self.a = a
        self.window = window
        self.cv = cv
        self.shrinkage = shrinkage
        self.references = references
        self.symmetric_modes = symmetric_modes
        self.random_state = random_state

    # ------------------------------------------------------------------ fit
    def _healthy_model(self, x: np.ndarray) -> HealthyModel:
        return HealthyModel(shrinkage=self.shrinkage).fit(x)

    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        owner = type(self).__name__
        x = indicator_values(healthy_indicators)
        n = x.shape[0]
        model = self._healthy_model(x)

        # Out-of-fold Z-scores, and which fold model produced each of them.
        groups = healthy_indicators["unit_id"].to_numpy() if "unit_id" in healthy_indicators else None
        folds = cross_fit_folds(n, self.cv, rng, owner, groups, min_train=x.shape[1] + 1)
        z_oof = np.full_like(x, np.nan)
        fold_of = np.empty(n, dtype=np.int64)
        fold_models = []
        for f, (train, held) in enumerate(folds):
            m = model if self.cv is None else self._healthy_model(x[train])
            z_oof[held] = m.zscores(x[held])
            fold_of[held] = f
            fold_models.append(m)

        # Smooth along each training unit exactly as decide() does, then score each
        # smoothed signature with the model that did not see the current flight.
        z_smooth = z_oof
        if self.window > 1:
            z_smooth = np.full_like(z_oof, np.nan)
            for seq in training_sequences(healthy_indicators):
                for i, pos in enumerate(seq):
                    z_smooth[pos] = window_mean(z_oof[seq[max(0, i - self.window + 1):i + 1]])
        scores = np.empty(n)
        for f, m in enumerate(fold_models):
            rows = fold_of == f
            scores[rows] = m.global_score(m.mean_ + m.std_ * z_smooth[rows])
        scores = np.where(np.isfinite(scores), scores, 0.0)  # no indicator at all: score 0

        self.healthy_model_ = model
        self.training_scores_ = scores
        self.mu_ = float(scores.mean())
        self.sigma_ = float(scores.std(ddof=0))
        self.threshold_ = self.mu_ + float(self.a) * self.sigma_
        self.references_ = reference_signatures(knowledge, self.references, model.std_)
        self.n_training_flights_ = n

    # --------------------------------------------------------------- decide
    def _start_unit(self, unit_id: Any) -> None:
        self._unit_zscores: list[np.ndarray] = []

    def _decide(self, row: pd.Series) -> Decision:
        model = self.healthy_model_
        self._unit_zscores.append(model.zscores(row_values(row))[0])
        del self._unit_zscores[:-self.window]
        z = window_mean(np.asarray(self._unit_zscores))
        score = float(model.global_score((model.mean_ + model.std_ * z)[None, :])[0])
        if not np.isfinite(score):
            score = 0.0
        if score <= self.threshold_:
            return Decision.no_alarm(score)
        guilt = collinearity_guilt_7(z, self.references_, tuple(self.symmetric_modes))
        return Decision(score=score, alarm=True, guilt=guilt)
