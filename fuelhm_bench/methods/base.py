"""The common method interface: :class:`BaseMethod`, and the causal harness.

A method sees healthy training flights once (``fit``), then, unit by unit,
flight by flight, one observation at a time (``start_unit`` then ``decide``).
The harness functions :func:`run_unit` / :func:`run_table` only ever call
``start_unit`` and ``decide``, so whatever a method does it cannot look ahead.
"""

from __future__ import annotations

import abc
import copy
import hashlib
import inspect
import numbers
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError, MethodError, ParameterError, show_value
from fuelhm_bench.methods.decision import GUILT_SUM_TOLERANCE, Decision, _raise_if_invalid
from fuelhm_bench.methods.knowledge import Knowledge
from fuelhm_bench.methods.params import validate_params
from fuelhm_bench.methods.tables import (DECISION_COLUMNS, GUILT_COLUMNS,
                                         check_indicator_table, empty_decisions)
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["BaseMethod", "clone_method", "has_batch_path", "method_needs_raw", "run_table", "run_unit"]


class BaseMethod(abc.ABC):
    """Base class of every detection/diagnosis method (scikit-learn style).

    Subclasses declare their hyperparameters as keyword-only arguments of
    ``__init__`` and store each one unchanged under the same name; nothing
    else happens in ``__init__`` (validation and derived quantities belong to
    ``fit``; fitted attributes end with ``_``). They implement:

    * ``_fit(healthy_indicators, *, knowledge, raw_flights, rng)``: learn from
      healthy flights only;
    * ``_decide(row) -> Decision``: decide for one flight, using only the
      current row and the per-unit history the method keeps itself;
    * optionally ``_start_unit(unit_id)``: reset that per-unit history;
    * optionally ``_decide_batch(rows) -> (score, alarm, guilt)``: the batch
      decision path of a method **without per-unit state**, see
      :meth:`decide_batch`.

    Declarations (class attributes):

    * ``needs_raw`` (bool, default False): the method works on the raw
      full-rate flight samples. It then receives the raw healthy training
      flights in ``fit(raw_flights=...)`` and the current flight's samples with
      each decision, ``decide(row, raw=...)``, its hook being ``_decide(row, raw)``
      (the input is :class:`fuelhm_bench.methods.raw.RawFlight`).

    The public ``fit``, ``start_unit`` and ``decide`` wrap them with input
    checks, seeding and output validation.

    Attributes
    ----------
    seed_entropy_ : int
        Entropy of the seed resolved in ``fit``.
    rng_ : numpy.random.Generator
        Generator for ``_fit`` (derived from ``seed_entropy_``).
    unit_rng_ : numpy.random.Generator
        Generator for the current unit, re-created by ``start_unit`` from
        ``seed_entropy_`` and the unit id, so that a unit's decisions do not
        depend on which units were processed before.
    is_fitted_ : bool
        True after a successful ``fit``.

    Examples
    --------
    >>> import numpy as np
    >>> from fuelhm_bench.methods import BaseMethod, Decision
    >>> from fuelhm_bench.taxonomy import INDICATOR_NAMES
    >>> class FirstIndicator(BaseMethod):
    ...     def __init__(self, *, a=3.0):
    ...         self.a = a
    ...     def _fit(self, healthy, *, knowledge, raw_flights, rng):
    ...         x = healthy["X1"].to_numpy(float)
    ...         self.mu_, self.sigma_ = np.nanmean(x), np.nanstd(x)
    ...     def _decide(self, row):
    ...         z = abs(row["X1"] - self.mu_) / self.sigma_
    ...         z = 0.0 if np.isnan(z) else float(z)
    ...         guilt = np.eye(7)[1] if z > self.a else np.zeros(7)
    ...         return Decision(score=z, alarm=z > self.a, guilt=guilt)
    >>> FirstIndicator(a=2.0)
    FirstIndicator(a=2.0)
    """

    #: Declared hyperparameter constraints, see :mod:`fuelhm_bench.methods.params`.
    _parameter_constraints: ClassVar[dict[str, tuple]] = {}

    #: True for a method that needs the raw full-rate flight samples (see the class docstring).
    needs_raw: ClassVar[bool] = False

    #: Batch decision hook of a method without per-unit state (None: no batch path).
    #: ``_decide_batch(rows: DataFrame) -> (score (n,), alarm (n,), guilt (n, 7))``: every row
    #: must be decided on its own (no per-unit history, no randomness), exactly as ``_decide``
    #: would decide it; ``check_method`` verifies that both paths agree.
    _decide_batch: ClassVar[Any] = None

    # ------------------------------------------------------------------ params
    @classmethod
    def _get_param_names(cls) -> list[str]:
        init = cls.__init__
        if init is object.__init__:
            return []
        sig = inspect.signature(init)
        names = []
        for p in sig.parameters.values():
            if p.name == "self":
                continue
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                raise MethodError(f"{cls.__name__}.__init__ must declare its hyperparameters "
                                  f"explicitly; it has *{p.name}.")
            names.append(p.name)
        return sorted(names)

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Hyperparameters of this method (the constructor arguments).

        Parameters
        ----------
        deep : bool, default=True
            Also return the parameters of nested methods as ``name__param``.

        Returns
        -------
        dict of str to object
        """
        out: dict[str, Any] = {}
        for name in self._get_param_names():
            value = getattr(self, name)
            if deep and hasattr(value, "get_params") and not isinstance(value, type):
                out.update({f"{name}__{k}": v for k, v in value.get_params(deep=True).items()})
            out[name] = value
        return out

    def set_params(self, **params: Any) -> "BaseMethod":
        """Set hyperparameters (``name`` or ``nested__name``); returns self.

        Raises
        ------
        ParameterError
            For an unknown parameter name.
        """
        valid = set(self._get_param_names())
        nested: dict[str, dict[str, Any]] = {}
        for key, value in params.items():
            name, sep, sub = key.partition("__")
            if name not in valid:
                raise ParameterError(f"The '{name}' parameter of {type(self).__name__} must be "
                                     f"one of {sorted(valid)}. Got {name!r} instead.")
            if sep:
                nested.setdefault(name, {})[sub] = value
            else:
                setattr(self, name, value)
        for name, sub_params in nested.items():
            getattr(self, name).set_params(**sub_params)
        return self

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params(deep=False).items())
        return f"{type(self).__name__}({args})"

    # --------------------------------------------------------------- fitting
    def fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None = None,
            raw_flights: Any = None, random_state: Any = None) -> "BaseMethod":
        """Learn from healthy training flights only.

        Parameters
        ----------
        healthy_indicators : pandas.DataFrame
            Indicator table of healthy flights (one row per flight; see
            docs/methods.md). Not modified.
        knowledge : Knowledge or None, default=None
            Published knowledge (ITL, signatures, maximal intensities).
        raw_flights : iterable of RawFlight or None, default=None
            Raw full-rate samples of the same healthy flights
            (:class:`fuelhm_bench.methods.raw.RawFlight`, one at a time); required
            by a method with ``needs_raw = True``, None otherwise.
        random_state : int, numpy.random.Generator or None, default=None
            Seed. When None, the ``random_state`` hyperparameter is used if the
            method has one; when both are None a fresh OS seed is drawn (the
            benchmark runner always passes one).

        Returns
        -------
        self
        """
        owner = f"{type(self).__name__}.fit"
        validate_params(type(self).__name__, self.get_params(deep=False),
                        type(self)._parameter_constraints)
        check_indicator_table(healthy_indicators, name="healthy_indicators", owner=owner)
        if knowledge is not None and not isinstance(knowledge, Knowledge):
            raise ParameterError(f"The 'knowledge' parameter of {owner} must be a Knowledge or "
                                 f"None. Got {type(knowledge).__name__} instead.")
        seed = random_state if random_state is not None else getattr(self, "random_state", None)
        self.seed_entropy_ = _resolve_entropy(seed, owner)
        self.rng_ = np.random.default_rng(np.random.SeedSequence(self.seed_entropy_,
                                                                 spawn_key=(0,)))
        self._stream_unit = None
        self._stream_last_index = None
        self.is_fitted_ = False
        if type(self).needs_raw and raw_flights is None:
            raise MethodError(f"{type(self).__name__} needs the raw healthy training flights "
                              f"(needs_raw = True): pass raw_flights, an iterable of RawFlight.")
        self._fit(healthy_indicators, knowledge=knowledge, raw_flights=raw_flights, rng=self.rng_)
        self.is_fitted_ = True
        return self

    @abc.abstractmethod
    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        """Learn from healthy flights (subclass hook; must not modify its inputs)."""

    # -------------------------------------------------------------- deciding
    def start_unit(self, unit_id: Any) -> None:
        """Start the flight sequence of a unit: reset the per-unit history.

        Parameters
        ----------
        unit_id : int or str
            Identifier of the unit (actuator / engine serial).
        """
        self._check_fitted("start_unit")
        self._stream_unit = unit_id
        self._stream_last_index = None
        self.unit_rng_ = np.random.default_rng(np.random.SeedSequence(
            self.seed_entropy_, spawn_key=(1, _stable_key(unit_id))))
        self._start_unit(unit_id)

    def _start_unit(self, unit_id: Any) -> None:
        """Reset the per-unit history (subclass hook; default: nothing to reset)."""
        return None

    def decide(self, observation_row: pd.Series | Mapping, *, raw: Any = None) -> Decision:
        """Decide for the next flight of the current unit.

        Parameters
        ----------
        observation_row : pandas.Series or mapping
            One row of the indicator table: the columns of
            :data:`fuelhm_bench.taxonomy.OBSERVATION_COLUMNS` (ids, the ten
            indicators, the extended ones, their ``<name>_valid`` flags). Flights
            must come in increasing ``flight_index``.
        raw : RawFlight or None, default=None
            The flight's full-rate samples (:class:`fuelhm_bench.methods.raw.RawFlight`);
            required by, and only passed to, a method with ``needs_raw = True``,
            whose hook is then ``_decide(row, raw)``.

        Returns
        -------
        Decision

        Raises
        ------
        MethodError
            When the method is not fitted, ``start_unit`` was not called, or the
            method returns an invalid decision.
        DataFormatError
            When the row belongs to another unit or comes out of order.
        """
        self._check_fitted("decide")
        if getattr(self, "_stream_unit", None) is None:
            raise MethodError(f"{type(self).__name__}.decide was called before start_unit.")
        row = observation_row if isinstance(observation_row, pd.Series) else pd.Series(
            dict(observation_row))
        if "unit_id" in row.index and row["unit_id"] != self._stream_unit:
            raise DataFormatError(f"The 'observation_row' parameter of {type(self).__name__}"
                                  f".decide must belong to unit {show_value(self._stream_unit)}. Got unit "
                                  f"{show_value(row['unit_id'])} instead.")
        if "flight_index" in row.index:
            k = int(row["flight_index"])
            if self._stream_last_index is not None and k <= self._stream_last_index:
                raise DataFormatError(f"The 'observation_row' parameter of {type(self).__name__}"
                                      f".decide must come in increasing flight_index order. Got "
                                      f"flight {k} after flight {self._stream_last_index} instead.")
            self._stream_last_index = k
        if type(self).needs_raw:
            if raw is None:
                raise MethodError(f"{type(self).__name__} needs the raw flight (needs_raw = True): "
                                  f"call decide(row, raw=RawFlight).")
            decision = self._decide(row, raw)
        else:
            decision = self._decide(row)
        return _raise_if_invalid(decision, type(self).__name__, f"for unit {show_value(self._stream_unit)}")

    @abc.abstractmethod
    def _decide(self, row: pd.Series) -> Decision:
        """Decide for one flight (subclass hook)."""

    def decide_batch(self, rows: pd.DataFrame) -> pd.DataFrame:
        """Decide for many flights at once (methods without per-unit state only).

        Only available when the class defines ``_decide_batch``
        (:func:`has_batch_path`). Each row is decided on its own, so the result
        equals ``decide`` called row by row; the harness
        (:func:`run_table`) shows a batch at most one flight per unit, all at
        the same position in their units' lives, so no batch holds a flight
        later than one not yet decided.

        Parameters
        ----------
        rows : pandas.DataFrame
            Indicator rows (``unit_id``, ``flight_index`` and the indicators).
            Not modified.

        Returns
        -------
        pandas.DataFrame
            Decisions (:data:`DECISION_COLUMNS`), one per row, in the input order.

        Raises
        ------
        MethodError
            When the method has no batch path, is not fitted, or returns
            invalid decisions (the first bad flight is named).
        """
        name = type(self).__name__
        if not has_batch_path(self):
            raise MethodError(f"{name} has no batch decision path (it does not define "
                              f"_decide_batch); use start_unit and decide.")
        self._check_fitted("decide_batch")
        check_indicator_table(rows, name="rows", owner=f"{name}.decide_batch",
                              keys=("unit_id", "flight_index"))
        out = self._decide_batch(rows)
        return _batch_frame(rows, out, name)

    def decide_unit(self, unit_table: pd.DataFrame, *, raw: Any = None) -> pd.DataFrame:
        """Decide for every flight of one unit, causally (see :func:`run_unit`).

        A method with a batch path (:func:`has_batch_path`) decides the whole
        unit in one :meth:`decide_batch` call (its rows are independent).
        ``raw``: for a method with ``needs_raw``, ``raw(row) -> RawFlight`` (see :func:`run_unit`).
        """
        if method_needs_raw(self):
            return run_unit(self, unit_table, raw=raw)
        if has_batch_path(self):
            check_indicator_table(unit_table, name="unit_table", owner="decide_unit",
                                  keys=("unit_id", "flight_index"))
            ordered = unit_table.sort_values("flight_index", kind="stable")
            return self.decide_batch(ordered).reset_index(drop=True)
        return run_unit(self, unit_table)

    def decide_table(self, indicators: pd.DataFrame, *, raw: Any = None) -> pd.DataFrame:
        """Decide for every flight of every unit, causally (see :func:`run_table`)."""
        return run_table(self, indicators, raw=raw)

    def _check_fitted(self, what: str) -> None:
        if not getattr(self, "is_fitted_", False):
            raise MethodError(f"{type(self).__name__} is not fitted: call fit before {what}.")


# ---------------------------------------------------------------------------
def method_needs_raw(method: Any) -> bool:
    """True when ``method`` (an instance or a class) declares ``needs_raw = True``.

    Such a method receives the raw healthy training flights in ``fit`` and the
    flight's full-rate samples with each decision (:mod:`fuelhm_bench.methods.raw`).
    """
    cls = method if isinstance(method, type) else type(method)
    return bool(getattr(cls, "needs_raw", False))


def _raw_of(raw: Any, row: pd.Series, name: str) -> Any:
    """The RawFlight of ``row`` from the provider ``raw`` (a callable), checked."""
    from fuelhm_bench.methods.raw import RawFlight

    if raw is None:
        raise MethodError(f"{name} needs the raw flights (needs_raw = True): pass raw=, a callable "
                          f"returning the RawFlight of an indicator row.")
    flight = raw(row)
    if not isinstance(flight, RawFlight):
        raise DataFormatError(f"The raw-flight provider must return a RawFlight for unit "
                              f"{row.get('unit_id')!r}, flight {row.get('flight_index')}. Got "
                              f"{type(flight).__name__} instead.")
    return flight


def run_unit(method: Any, unit_table: pd.DataFrame, *, raw: Any = None) -> pd.DataFrame:
    """Run a fitted method on one unit, flight by flight, in flight order.

    Only ``method.start_unit`` and ``method.decide`` are called (never a
    method's own ``decide_unit``), one row at a time: the decision for flight
    ``k`` is made before flight ``k + 1`` is shown.

    Parameters
    ----------
    method : BaseMethod
        A fitted method.
    unit_table : pandas.DataFrame
        Indicator rows of a single unit (columns ``unit_id``, ``flight_index`` and
        the indicators); sorted by ``flight_index`` here (the input is not
        modified).
    raw : callable or None, default=None
        For a method with ``needs_raw``: ``raw(row) -> RawFlight``, the
        full-rate samples of the flight of an indicator row, called once per
        flight just before its decision (so one flight at a time is in memory).

    Returns
    -------
    pandas.DataFrame
        Columns :data:`DECISION_COLUMNS`: ``unit_id, flight_index, score, alarm,
        guilt_<mode>`` x 7, one row per flight in flight order.

    Raises
    ------
    DataFormatError
        When the table holds several units or repeated flight indices.
    """
    owner = "run_unit"
    check_indicator_table(unit_table, name="unit_table", owner=owner,
                          keys=("unit_id", "flight_index"))
    units = pd.unique(unit_table["unit_id"])
    if len(units) != 1:
        raise DataFormatError(f"The 'unit_table' parameter of {owner} must hold a single unit. "
                              f"Got {len(units)} units instead.")
    if unit_table["flight_index"].duplicated().any():
        dup = unit_table["flight_index"][unit_table["flight_index"].duplicated()].iloc[0]
        raise DataFormatError(f"The 'unit_table' parameter of {owner} must have unique "
                              f"flight_index values. Got flight {dup} twice instead.")
    ordered = unit_table.sort_values("flight_index", kind="stable")
    unit_id = units[0]
    method.start_unit(unit_id)
    n = len(ordered)
    scores = np.empty(n)
    alarms = np.empty(n, dtype=bool)
    guilt = np.empty((n, len(MODE_IDS)))
    name = type(method).__name__
    with_raw = method_needs_raw(method)
    for i in range(n):
        row = ordered.iloc[i]
        d = method.decide(row, raw=_raw_of(raw, row, name)) if with_raw else method.decide(row)
        d = _raise_if_invalid(d, name,
                              f"for unit {show_value(unit_id)}, flight {row['flight_index']}")
        scores[i], alarms[i], guilt[i] = d.score, d.alarm, d.guilt
    out = {"unit_id": ordered["unit_id"].to_numpy(),
           "flight_index": ordered["flight_index"].to_numpy(dtype=np.int64),
           "score": scores, "alarm": alarms}
    out.update({c: guilt[:, j] for j, c in enumerate(GUILT_COLUMNS)})
    return pd.DataFrame(out, columns=list(DECISION_COLUMNS))


def has_batch_path(method: Any) -> bool:
    """True when ``method`` declares a batch decision path (defines ``_decide_batch``).

    Such a method keeps no per-unit state: :func:`run_table` then decides
    in batches instead of row by row.
    """
    return callable(getattr(type(method), "_decide_batch", None))


def _batch_frame(rows: pd.DataFrame, out: Any, name: str) -> pd.DataFrame:
    """Validate what ``_decide_batch`` returned and build the decisions table."""
    n = len(rows)
    try:
        score, alarm, guilt = out
        score = np.asarray(score, dtype=np.float64).reshape(-1)
        alarm = np.asarray(alarm)
        guilt = np.asarray(guilt, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MethodError(f"{name}._decide_batch must return (score, alarm, guilt) arrays. Got "
                          f"{type(out).__name__} instead ({exc}).") from None
    if score.shape != (n,) or alarm.shape != (n,) or guilt.shape != (n, len(MODE_IDS)):
        raise MethodError(f"{name}._decide_batch must return shapes ({n},), ({n},) and "
                          f"({n}, {len(MODE_IDS)}) for {n} rows. Got {score.shape}, "
                          f"{alarm.shape} and {guilt.shape} instead.")
    if alarm.dtype != bool:
        raise MethodError(f"{name}._decide_batch must return a bool alarm array. Got dtype "
                          f"{alarm.dtype} instead.")
    total = guilt.sum(axis=1) if n else np.zeros(0)
    bad_guilt = (~np.isfinite(guilt) | (guilt < 0)).any(axis=1)
    bad_guilt |= alarm & (np.abs(total - 1.0) > GUILT_SUM_TOLERANCE)
    bad_guilt |= ~alarm & (total != 0.0) & (np.abs(total - 1.0) > GUILT_SUM_TOLERANCE)
    for bad, what in ((~np.isfinite(score), "a non-finite score"),
                      (bad_guilt, "an invalid guilt (>= 0, summing to 1 on an alarm, 0 or 1 "
                                  "otherwise)")):
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise MethodError(f"{name} returned an invalid decision for unit "
                              f"{rows['unit_id'].iloc[i]!r}, flight "
                              f"{rows['flight_index'].iloc[i]}: {what}.")
    data = {"unit_id": rows["unit_id"].to_numpy(),
            "flight_index": rows["flight_index"].to_numpy(dtype=np.int64),
            "score": score, "alarm": alarm.astype(bool)}
    data.update({c: guilt[:, j] for j, c in enumerate(GUILT_COLUMNS)})
    return pd.DataFrame(data, columns=list(DECISION_COLUMNS))


def _run_table_batch(method: Any, indicators: pd.DataFrame) -> pd.DataFrame:
    """Batch decisions in causal waves: wave ``k`` holds the ``k``-th flight of every unit."""
    units = indicators["unit_id"]
    if indicators[["unit_id", "flight_index"]].duplicated().any():
        raise DataFormatError("The 'indicators' parameter of run_table must have unique "
                              "(unit_id, flight_index) pairs.")
    order = indicators.assign(_unit=pd.factorize(units, use_na_sentinel=False)[0]).sort_values(
        ["_unit", "flight_index"], kind="stable")
    wave = order.groupby("_unit", sort=False).cumcount().to_numpy()
    ordered = order.drop(columns="_unit")
    parts = []
    for k in range(int(wave.max()) + 1):
        parts.append(method.decide_batch(ordered[wave == k]).set_axis(
            ordered.index[wave == k]))
    out = pd.concat(parts).loc[ordered.index]
    return out.reset_index(drop=True)


def run_table(method: Any, indicators: pd.DataFrame, *, raw: Any = None) -> pd.DataFrame:
    """Run a fitted method on every unit of an indicator table (:func:`run_unit` per unit).

    A method with a batch path (:func:`has_batch_path`, no per-unit state) is
    run by :meth:`BaseMethod.decide_batch` in causal waves instead: wave ``k``
    holds the ``k``-th flight (in ``flight_index`` order) of every unit, so no
    batch shows a flight later than one still to be decided. The result is
    the same table.

    Parameters
    ----------
    method : BaseMethod
        A fitted method.
    indicators : pandas.DataFrame
        Indicator table with ``unit_id`` and ``flight_index``.
    raw : callable or None, default=None
        The raw-flight provider of a method with ``needs_raw`` (see
        :func:`run_unit`); such a method is always run row by row.

    Returns
    -------
    pandas.DataFrame
        Decisions table (:data:`DECISION_COLUMNS`), units in order of first
        appearance, flights in flight order.
    """
    check_indicator_table(indicators, name="indicators", owner="run_table",
                          keys=("unit_id", "flight_index"))
    if has_batch_path(method) and not method_needs_raw(method):
        return _run_table_batch(method, indicators)
    parts = [run_unit(method, group, raw=raw)
             for _, group in indicators.groupby("unit_id", sort=False, dropna=False)]
    if not parts:
        return empty_decisions()
    return pd.concat(parts, ignore_index=True)


def clone_method(method: Any) -> Any:
    """An unfitted copy with the same hyperparameters (like ``sklearn.base.clone``).

    Parameters
    ----------
    method : BaseMethod
        Any object with ``get_params``.

    Returns
    -------
    BaseMethod
        ``type(method)(**params)``, nested methods cloned, other values deep-copied.
    """
    params = method.get_params(deep=False)
    new_params = {k: (clone_method(v) if hasattr(v, "get_params") and not isinstance(v, type)
                      else copy.deepcopy(v)) for k, v in params.items()}
    return type(method)(**new_params)


def _resolve_entropy(seed: Any, owner: str) -> int:
    if seed is None:
        return int(np.random.SeedSequence().entropy)
    if isinstance(seed, np.random.Generator):
        return int(seed.integers(0, 2**63 - 1))
    if isinstance(seed, numbers.Integral) and not isinstance(seed, (bool, np.bool_)) and seed >= 0:
        return int(seed)
    raise ParameterError(f"The 'random_state' parameter of {owner} must be a non-negative int, a "
                         f"numpy.random.Generator or None. Got {seed!r} instead.")


def _stable_key(unit_id: Any) -> int:
    """A platform- and session-independent 32-bit key for a unit id."""
    if isinstance(unit_id, numbers.Integral) and not isinstance(unit_id, (bool, np.bool_)):
        text = f"int:{int(unit_id)}"
    else:
        text = f"str:{unit_id}"
    return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=4).digest(), "little")
