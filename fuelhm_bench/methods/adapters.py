"""Adapters: a scikit-learn or PyOD anomaly detector as a benchmark method.

Both adapters share one recipe (:class:`_DetectorAdapter`):

1. **Features.** The ten indicators of a flight (``INDICATOR_NAMES`` order). A
   missing indicator (NaN, or ``<name>_valid`` False) is imputed by its healthy
   training mean; with ``standardize=True`` every indicator is divided by its
   healthy standard deviation after centring (Z-scores, paper eq. 7), so
   detectors based on distances see comparable axes (the raw units span
   0.01 mm/s/mA to 20 mm/s).
2. **Held-out units.** The healthy training units are split, with the seed,
   into *fit* units and *calibration* units (``calibration_fraction`` of the
   units, at least one). The detector and the feature statistics are fitted on
   the fit units only.
3. **Threshold.** The detector scores the calibration units (flights it never
   saw, from engines it never saw); the alarm threshold ``threshold_`` is the
   ``quantile`` quantile of those scores. Scored flights are never used.
4. **Decisions.** Score = the detector's abnormality score (higher = more
   abnormal); alarm = ``score > threshold_``. On an alarm the guilt is
   proportional to the collinearity of the flight's Z-scores with the published
   reference signatures (``diagnosis="signatures"``, paper section VI.B.3) or
   uniform (``diagnosis="uniform"``). No per-unit state: the methods have a
   batch decision path (:meth:`~fuelhm_bench.methods.BaseMethod.decide_batch`).

With a single training unit the calibration part is the last
``calibration_fraction`` of its flights in flight order instead.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import pandas as pd

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.methods.base import BaseMethod
from fuelhm_bench.methods.decision import Decision
from fuelhm_bench.methods.knowledge import Knowledge
from fuelhm_bench.methods.params import InstanceOf, Interval, Options, RandomState
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

__all__ = ["PyODMethod", "SklearnMethod"]

_MIN_FIT_FLIGHTS = 2
_MIN_CALIBRATION_FLIGHTS = 2


def indicator_matrix(table: pd.DataFrame) -> np.ndarray:
    """Indicator matrix of a table, NaN where an indicator is missing.

    Parameters
    ----------
    table : pandas.DataFrame
        Indicator table; ``<name>_valid`` columns, when present, mark invalid
        values (anything but True counts as invalid).

    Returns
    -------
    numpy.ndarray of shape (n_flights, 10)
        float64, ``INDICATOR_NAMES`` order, indicator units.
    """
    names = list(INDICATOR_NAMES)
    block = table[names]
    if all(pd.api.types.is_numeric_dtype(t) for t in block.dtypes):
        out = np.array(block.to_numpy(dtype=np.float64, na_value=np.nan), copy=True)
    else:  # e.g. an object row from the environment
        out = np.array(block.apply(pd.to_numeric, errors="coerce").to_numpy(
            dtype=np.float64, na_value=np.nan), copy=True)
    valid = [f"{n}_valid" for n in names]
    present = [j for j, v in enumerate(valid) if v in table.columns]
    if present:
        flags = table[[valid[j] for j in present]]
        if all(pd.api.types.is_bool_dtype(t) for t in flags.dtypes):
            ok = flags.to_numpy(dtype=bool)
        else:  # anything but True (None, NA, NaN, False) is invalid
            ok = np.vectorize(lambda f: f is True or f is np.True_ or f == 1, otypes=[bool])(
                flags.to_numpy(dtype=object)) if len(flags) else np.zeros(flags.shape, bool)
        out[:, present] = np.where(ok, out[:, present], np.nan)
    return out


class _DetectorAdapter(BaseMethod):
    """Shared recipe of the adapters (see the module docstring)."""

    #: Name of the constructor parameter holding the wrapped detector.
    _detector_param: ClassVar[str] = "estimator"

    # Defaults of the shared hyperparameters, as class attributes: a subclass may declare only
    # the hyperparameters it wants to expose (see the README recipe) and inherit the others.
    quantile: ClassVar[float] = 0.99
    calibration_fraction: ClassVar[float] = 0.25
    standardize: ClassVar[bool] = True
    diagnosis: ClassVar[str] = "signatures"
    random_state: ClassVar[Any] = None

    _parameter_constraints: ClassVar[dict[str, tuple]] = {
        "quantile": (Interval(float, 0.5, 1.0, closed="neither"),),
        "calibration_fraction": (Interval(float, 0.0, 1.0, closed="neither"),),
        "standardize": (InstanceOf(bool),),
        "diagnosis": (Options(["signatures", "uniform"]),),
        "random_state": (RandomState(),),
    }

    # -- hooks -------------------------------------------------------------
    def _make_detector(self) -> Any:
        """The unfitted detector: the ``make_detector()`` of a subclass, else the parameter.

        The parameter may be an instance or a ``"module:Class"`` string, built with the
        ``<param>_params`` mapping (so that a leaderboard YAML entry can name it).
        """
        maker = getattr(self, "make_detector", None)
        if callable(maker):
            return maker()
        value = getattr(self, self._detector_param, None)
        if isinstance(value, str):
            return _build(value, getattr(self, f"{self._detector_param}_params", None),
                          f"{type(self).__name__}.{self._detector_param}")
        return value

    @abc.abstractmethod
    def _check_detector(self, detector: Any) -> None:
        """Raise :class:`~fuelhm_bench.errors.ParameterError` unless ``detector`` is of the adapted kind."""

    @abc.abstractmethod
    def _abnormality(self, model: Any, x: np.ndarray) -> np.ndarray:
        """Abnormality of each row of ``x`` under the fitted ``model`` (higher = more abnormal)."""

    # -- fit ---------------------------------------------------------------
    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        owner = type(self).__name__
        detector = self._make_detector()
        self._check_detector(detector)
        fit_rows, cal_rows = _split_units(healthy_indicators, self.calibration_fraction, rng,
                                          owner)
        x = indicator_matrix(healthy_indicators)
        x_fit = x[fit_rows]
        finite = np.isfinite(x_fit)
        count = finite.sum(axis=0)
        if (count == 0).any():
            missing = [INDICATOR_NAMES[j] for j in np.flatnonzero(count == 0)]
            raise ParameterError(f"The 'healthy_indicators' parameter of {owner}.fit must have "
                                 f"at least one valid value of every indicator in the fit units. "
                                 f"Got none for {missing} instead.")
        mean = np.where(finite, x_fit, 0.0).sum(axis=0) / count
        centred = np.where(np.isfinite(x_fit), x_fit - mean, 0.0)
        std = np.sqrt((centred ** 2).sum(axis=0) / np.maximum(count - 1, 1))
        std = np.where(std > 0, std, 1.0)
        self.feature_mean_ = mean
        self.feature_std_ = std
        model = _seeded_clone(detector, rng)
        model.fit(self._features(x_fit))
        self.detector_ = model
        cal_scores = self._abnormality(model, self._features(x[cal_rows]))
        if not np.all(np.isfinite(cal_scores)):
            raise ParameterError(f"The detector of {owner} returned non-finite scores on the "
                                 f"healthy calibration flights; check its parameters.")
        self.calibration_scores_ = cal_scores
        self.threshold_ = float(np.quantile(cal_scores, self.quantile))
        self.n_fit_flights_ = int(len(fit_rows))
        self.n_calibration_flights_ = int(len(cal_rows))
        self.references_ = None
        if self.diagnosis == "signatures" and knowledge is not None:
            sig = pd.DataFrame(knowledge.signature_matrix(), index=list(MODE_IDS),
                               columns=list(INDICATOR_NAMES))
            keep = (np.isfinite(sig.to_numpy(float)) & (sig.to_numpy(float) != 0)).any(axis=1)
            self.references_ = sig.loc[keep] if keep.any() else None

    def _features(self, x: np.ndarray) -> np.ndarray:
        filled = np.where(np.isfinite(x), x, self.feature_mean_)
        return (filled - self.feature_mean_) / self.feature_std_ if self.standardize else filled

    # -- decide ------------------------------------------------------------
    def _decide_batch(self, rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = indicator_matrix(rows)
        score = np.asarray(self._abnormality(self.detector_, self._features(x)),
                           dtype=np.float64).reshape(-1)
        alarm = score > self.threshold_
        guilt = np.zeros((len(rows), len(MODE_IDS)))
        if alarm.any():
            guilt[alarm] = self._guilt(x[alarm])
        return score, alarm, guilt

    def _decide(self, row: pd.Series) -> Decision:
        score, alarm, guilt = self._decide_batch(row.to_frame().T)
        return Decision(score=float(score[0]), alarm=bool(alarm[0]), guilt=guilt[0])

    def _guilt(self, x: np.ndarray) -> np.ndarray:
        uniform = np.full((len(x), len(MODE_IDS)), 1.0 / len(MODE_IDS))
        if self.references_ is None:
            return uniform
        from fuelhm_bench.diagnosis import collinearity_guilt

        z = (x - self.feature_mean_) / self.feature_std_  # NaN where missing: ignored
        symmetric = [m for m in ("null_bias_drift",) if m in self.references_.index]
        prob = np.asarray(collinearity_guilt(z, self.references_, symmetric=symmetric),
                          dtype=float).reshape(len(x), -1)
        out = np.zeros((len(x), len(MODE_IDS)))
        out[:, [MODE_IDS.index(m) for m in self.references_.index]] = prob
        total = out.sum(axis=1, keepdims=True)
        return np.where(total > 0, out / np.where(total > 0, total, 1.0), uniform)


class SklearnMethod(_DetectorAdapter):
    """A scikit-learn novelty/outlier estimator or Pipeline as a benchmark method.

    The estimator (anything with ``fit(X)`` and ``score_samples(X)`` or
    ``decision_function(X)``, scikit-learn convention: higher = more normal,
    e.g. ``IsolationForest``, ``OneClassSVM``, ``LocalOutlierFactor(novelty=True)``,
    ``EllipticEnvelope`` or a ``Pipeline`` ending in one) is cloned and fitted
    on the healthy fit units; the method's score is minus that output. See the
    module docstring for the features, the held-out calibration units and the
    threshold.

    Parameters
    ----------
    estimator : scikit-learn estimator or str
        Unfitted estimator (cloned in ``fit``; never modified), or its
        ``"package.module:Class"`` name (built with ``estimator_params``). A
        ``None`` ``random_state`` anywhere in it is drawn from the method's seed.
        A subclass may instead define ``make_detector()`` returning the estimator
        and declare only the hyperparameters it needs (README recipe).
    estimator_params : dict or None, default=None
        Keyword arguments of the estimator when ``estimator`` is a string.
    score : {"auto", "score_samples", "decision_function"}, default="auto"
        Output used; ``"auto"`` takes ``score_samples`` when the estimator has it.
    quantile : float in (0.5, 1), default=0.99
        Quantile of the calibration-unit scores used as threshold.
    calibration_fraction : float in (0, 1), default=0.25
        Fraction of the healthy training units held out to set the threshold.
    standardize : bool, default=True
        Feed Z-scores (healthy mean and standard deviation) rather than raw units.
    diagnosis : {"signatures", "uniform"}, default="signatures"
        Guilt on an alarm: collinearity with the published signatures, or uniform.
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the unit split and of the estimator.

    Attributes
    ----------
    detector_ : estimator
        The fitted clone.
    threshold_ : float
        Alarm threshold on the score.
    calibration_scores_ : numpy.ndarray
        Scores of the held-out calibration flights.
    feature_mean_, feature_std_ : numpy.ndarray of shape (10,)
        Healthy statistics of the fit units (indicator units).

    Examples
    --------
    >>> from sklearn.ensemble import IsolationForest
    >>> from fuelhm_bench.methods.adapters import SklearnMethod
    >>> SklearnMethod(estimator=IsolationForest(n_estimators=50), quantile=0.98)
    SklearnMethod(calibration_fraction=0.25, diagnosis='signatures', estimator=IsolationForest(n_estimators=50), estimator_params=None, quantile=0.98, random_state=None, score='auto', standardize=True)
    """

    _detector_param: ClassVar[str] = "estimator"
    _parameter_constraints: ClassVar[dict[str, tuple]] = {
        **_DetectorAdapter._parameter_constraints,
        "score": (Options(["auto", "score_samples", "decision_function"]),),
    }

    estimator: ClassVar[Any] = None
    estimator_params: ClassVar[Any] = None
    score: ClassVar[str] = "auto"

    def __init__(self, *, estimator: Any = None, estimator_params: Any = None,
                 score: str = "auto", quantile: float = 0.99,
                 calibration_fraction: float = 0.25, standardize: bool = True,
                 diagnosis: str = "signatures", random_state: Any = None) -> None:
        self.estimator = estimator
        self.estimator_params = estimator_params
        self.score = score
        self.quantile = quantile
        self.calibration_fraction = calibration_fraction
        self.standardize = standardize
        self.diagnosis = diagnosis
        self.random_state = random_state

    def _output(self, estimator: Any) -> str:
        if self.score != "auto":
            return self.score
        return "score_samples" if hasattr(estimator, "score_samples") else "decision_function"

    def _check_detector(self, detector: Any) -> None:
        name = type(self).__name__
        if detector is None or isinstance(detector, type) or not hasattr(detector, "fit") \
                or not hasattr(detector, "get_params"):  # noqa: E501
            raise ParameterError(f"The 'estimator' parameter of {name} must be an unfitted "
                                 f"scikit-learn estimator instance (with fit and get_params). "
                                 f"Got {detector!r} instead.")
        output = self._output(detector)
        if not hasattr(detector, output):
            raise ParameterError(f"The 'estimator' parameter of {name} must provide "
                                 f"{'score_samples or decision_function' if self.score == 'auto' else output} "
                                 f"(higher = more normal). Got {type(detector).__name__}, which "
                                 f"does not (for LocalOutlierFactor pass novelty=True).")

    def _abnormality(self, model: Any, x: np.ndarray) -> np.ndarray:
        return -np.asarray(getattr(model, self._output(model))(x), dtype=np.float64).reshape(-1)


class PyODMethod(_DetectorAdapter):
    """A PyOD detector as a benchmark method (optional extra ``pyod``).

    The detector (any ``pyod.models`` detector: ``ECOD``, ``IForest``, ``KNN``,
    ``COPOD``...) is cloned and fitted on the healthy fit units; the method's
    score is its ``decision_function`` (PyOD convention: higher = more
    abnormal), computed one flight at a time (ECOD and COPOD score a batch
    jointly, which would let flights of a batch influence each other). PyOD's own ``threshold_`` (set from its ``contamination`` on the
    training flights) is not used: the threshold comes from the held-out
    calibration units, as in :class:`SklearnMethod`.

    Parameters
    ----------
    detector : pyod.models.base.BaseDetector or str
        Unfitted detector (cloned in ``fit``; never modified), or its
        ``"package.module:Class"`` name, e.g. ``"pyod.models.ecod:ECOD"``.
    detector_params : dict or None, default=None
        Keyword arguments of the detector when ``detector`` is a string.
    quantile, calibration_fraction, standardize, diagnosis, random_state
        As in :class:`SklearnMethod`.

    Attributes
    ----------
    detector_, threshold_, calibration_scores_, feature_mean_, feature_std_
        As in :class:`SklearnMethod`.

    Examples
    --------
    >>> from fuelhm_bench.methods.adapters import PyODMethod
    >>> PyODMethod(quantile=0.98)
    PyODMethod(calibration_fraction=0.25, detector=None, detector_params=None, diagnosis='signatures', quantile=0.98, random_state=None, standardize=True)
    """

    _detector_param: ClassVar[str] = "detector"

    detector: ClassVar[Any] = None
    detector_params: ClassVar[Any] = None

    def __init__(self, *, detector: Any = None, detector_params: Any = None,
                 quantile: float = 0.99, calibration_fraction: float = 0.25,
                 standardize: bool = True, diagnosis: str = "signatures",
                 random_state: Any = None) -> None:
        self.detector = detector
        self.detector_params = detector_params
        self.quantile = quantile
        self.calibration_fraction = calibration_fraction
        self.standardize = standardize
        self.diagnosis = diagnosis
        self.random_state = random_state

    def _check_detector(self, detector: Any) -> None:
        if detector is None or isinstance(detector, type) or not all(
                hasattr(detector, a) for a in ("fit", "decision_function", "get_params")):
            raise ParameterError(f"The 'detector' parameter of {type(self).__name__} must be an "
                                 f"unfitted PyOD detector instance (with fit, decision_function "
                                 f"and get_params), e.g. pyod.models.ecod.ECOD(). Got "
                                 f"{detector!r} instead.")

    def _abnormality(self, model: Any, x: np.ndarray) -> np.ndarray:
        # One row per call: some PyOD detectors (ECOD, COPOD) score a batch jointly with the
        # training data, so a flight's score would depend on the other flights of the batch.
        return np.array([float(np.asarray(model.decision_function(x[i:i + 1]),
                                          dtype=np.float64).reshape(-1)[0])
                         for i in range(len(x))], dtype=np.float64)


# --------------------------------------------------------------------------- helpers
def _build(spec: str, params: Any, where: str) -> Any:
    """Instantiate ``"module:Class"`` with keyword ``params`` (a mapping or None)."""
    import importlib

    module_name, sep, cls_name = spec.partition(":")
    if not sep or not module_name or not cls_name:
        raise ParameterError(f"The '{where.split('.')[-1]}' parameter of {where.split('.')[0]} "
                             f"must be an estimator instance or a 'package.module:Class' string. "
                             f"Got {spec!r} instead.")
    if params is not None and not isinstance(params, Mapping):
        raise ParameterError(f"The '{where.split('.')[-1]}_params' parameter of "
                             f"{where.split('.')[0]} must be a mapping or None. Got "
                             f"{params!r} instead.")
    try:
        cls = getattr(importlib.import_module(module_name), cls_name)
    except (ImportError, AttributeError) as exc:
        raise ParameterError(f"The '{where.split('.')[-1]}' parameter of {where.split('.')[0]} "
                             f"names {spec!r}, which cannot be imported: {exc}.") from None
    try:
        return cls(**dict(params or {}))
    except TypeError as exc:
        raise ParameterError(f"The '{where.split('.')[-1]}_params' parameter of "
                             f"{where.split('.')[0]} does not fit {cls_name}: {exc}.") from None


def _seeded_clone(detector: Any, rng: np.random.Generator) -> Any:
    """An unfitted copy; every ``random_state`` parameter that is None gets a seed from ``rng``."""
    from sklearn.base import clone

    model = clone(detector)
    params = model.get_params(deep=True)
    seeds = {k: int(rng.integers(0, 2**31 - 1)) for k in sorted(params)
             if (k == "random_state" or k.endswith("__random_state")) and params[k] is None}
    if seeds:
        model.set_params(**seeds)
    return model


def _split_units(table: pd.DataFrame, fraction: float, rng: np.random.Generator,
                 owner: str) -> tuple[np.ndarray, np.ndarray]:
    """Row positions of the fit part and of the held-out calibration part.

    Whole units are held out (``ceil``-free rounding, at least one unit, at
    least one unit kept for fitting); with a single unit (or no ``unit_id``
    column) the last ``fraction`` of its flights in flight order is held out.
    """
    n = len(table)
    units = (pd.factorize(table["unit_id"], use_na_sentinel=False)[0]
             if "unit_id" in table.columns else np.zeros(n, dtype=np.int64))
    n_units = int(units.max()) + 1 if n else 0
    if n_units >= 2:
        n_cal = min(n_units - 1, max(1, int(round(fraction * n_units))))
        cal_units = rng.permutation(n_units)[:n_cal]
        cal = np.isin(units, cal_units)
    else:
        order = (np.argsort(pd.to_numeric(table["flight_index"], errors="coerce").to_numpy(
            dtype=float, na_value=np.inf), kind="stable")
                 if "flight_index" in table.columns else np.arange(n))
        n_cal = max(1, int(math.floor(fraction * n)))
        cal = np.zeros(n, dtype=bool)
        cal[order[n - n_cal:]] = True
    fit_rows, cal_rows = np.flatnonzero(~cal), np.flatnonzero(cal)
    if len(fit_rows) < _MIN_FIT_FLIGHTS or len(cal_rows) < _MIN_CALIBRATION_FLIGHTS:
        raise ParameterError(f"The 'healthy_indicators' parameter of {owner}.fit must leave at "
                             f"least {_MIN_FIT_FLIGHTS} flights to fit and "
                             f"{_MIN_CALIBRATION_FLIGHTS} held-out flights to set the threshold "
                             f"(calibration_fraction={fraction}). Got {len(fit_rows)} and "
                             f"{len(cal_rows)} from {n} flights of {n_units} unit(s) instead.")
    return fit_rows, cal_rows
