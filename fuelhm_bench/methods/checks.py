"""Conformance checks every method must pass (like ``sklearn.utils.estimator_checks``).

:func:`check_method` runs the small named checks of :func:`iter_checks` on a
method instance and raises :class:`~fuelhm_bench.errors.MethodError` at the
first failure, with a message naming the check and the method class::

    check_no_lookahead failed for MyMethod: decision at flight 3 of unit
    'check-1' changed when flight 5 changed

The checks build their own small synthetic data (:func:`make_check_data`:
healthy Gaussian indicators plus a few units whose indicators drift along
random signatures) with a fixed seed, and never touch the instance passed in:
every check works on clones.
"""

from __future__ import annotations

import copy
import inspect
import pickle
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Sequence

import numpy as np
import pandas as pd

from fuelhm_bench.errors import MethodError
from fuelhm_bench.methods.base import clone_method, has_batch_path, run_table, run_unit
from fuelhm_bench.methods.decision import decision_problem
from fuelhm_bench.methods.knowledge import Knowledge
from fuelhm_bench.methods.tables import DECISION_COLUMNS, GUILT_COLUMNS
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

__all__ = ["CheckData", "MethodCheck", "check_method", "iter_checks", "make_check_data",
           "parametrize_with_checks"]

#: Healthy means and standard deviations of the synthetic indicators, in the
#: units of :data:`fuelhm_bench.taxonomy.INDICATOR_UNITS` (mA, mm/s, mm/s/mA).
_HEALTHY_MEAN = np.array([-3.0, -20.0, 3.0, 20.0, 0.1, 0.2, 0.05, 6.0, 6.0, 3.0])
_HEALTHY_STD = np.array([0.05, 0.5, 0.05, 0.5, 0.02, 0.02, 0.01, 0.1, 0.1, 0.1])

#: Seeds used by the checks.
_SEED = 0
_OTHER_SEED = 1


@dataclass(frozen=True, eq=False)
class CheckData:
    """Synthetic data used by the checks.

    Attributes
    ----------
    healthy : pandas.DataFrame
        Healthy training indicator table.
    other_healthy : pandas.DataFrame
        A second, different healthy table (used to test refitting).
    units : pandas.DataFrame
        Indicator table of the evaluation units (one healthy, the others
        drifting along a mode signature from mid-life; one indicator value is
        missing, NaN with ``<name>_valid`` False).
    knowledge : Knowledge
        Synthetic ITL, signatures and maximal intensities consistent with
        ``units``.
    """

    healthy: pd.DataFrame
    other_healthy: pd.DataFrame
    units: pd.DataFrame
    knowledge: Knowledge

    def unit_tables(self) -> list[tuple[Any, pd.DataFrame]]:
        """``(unit_id, table)`` pairs of ``units`` in order of first appearance."""
        return [(u, g) for u, g in self.units.groupby("unit_id", sort=False)]


def _indicator_frame(values: np.ndarray, unit_ids: Sequence[Any], flight_index: np.ndarray,
                     prefix: str, rng: np.random.Generator) -> pd.DataFrame:
    n = values.shape[0]
    data: dict[str, Any] = {
        "flight_id": [f"{prefix}-{i:04d}" for i in range(n)],
        "unit_id": pd.Series(list(unit_ids), dtype=object),
        "flight_index": np.asarray(flight_index, dtype=np.int64),
    }
    for j, name in enumerate(INDICATOR_NAMES):
        data[name] = values[:, j].astype(np.float64)
    for j, name in enumerate(INDICATOR_NAMES):
        data[f"{name}_valid"] = np.isfinite(values[:, j])
    data["n_points"] = rng.integers(500, 2000, size=n).astype(np.int64)
    data["quality_reason"] = np.where(np.isfinite(values).all(axis=1), "", "not_supported")
    return pd.DataFrame(data)


def _healthy_table(n_units: int, n_flights: int, prefix: str,
                   rng: np.random.Generator) -> pd.DataFrame:
    z = rng.standard_normal((n_units * n_flights, len(INDICATOR_NAMES)))
    values = _HEALTHY_MEAN + _HEALTHY_STD * z
    unit_ids = [f"{prefix}-{u}" for u in range(n_units) for _ in range(n_flights)]
    index = np.tile(np.arange(n_flights), n_units)
    return _indicator_frame(values, unit_ids, index, prefix, rng)


def make_check_data(random_state: int = 0, *, n_units: int = 3,
                    n_flights: int = 12) -> CheckData:
    """Build the synthetic data of the checks.

    Parameters
    ----------
    random_state : int, default=0
        Seed.
    n_units : int, default=3
        Number of evaluation units (the first is healthy; unit ``u`` > 0
        degrades along mode ``MODE_IDS[u % 7]`` from flight ``n_flights // 3``).
    n_flights : int, default=12
        Flights per evaluation unit (>= 6).

    Returns
    -------
    CheckData
    """
    rng = np.random.default_rng(random_state)
    healthy = _healthy_table(4, 15, "train", rng)
    other = _healthy_table(3, 10, "other", rng)
    other[list(INDICATOR_NAMES)] = other[list(INDICATOR_NAMES)] + 0.5 * _HEALTHY_STD

    signatures = rng.normal(0.0, 6.0, size=(len(MODE_IDS), len(INDICATOR_NAMES)))
    signatures[np.abs(signatures) < 3.0] = 0.0
    max_intensity = {m: 1.0 for m in MODE_IDS}
    itl_rows = [{"mode": m, "indicator": ind,
                 "A": float(signatures[i, j] * _HEALTHY_STD[j] / max_intensity[m]),
                 "r2": 0.99, "residual_std": float(0.05 * _HEALTHY_STD[j]), "n": 20}
                for i, m in enumerate(MODE_IDS) for j, ind in enumerate(INDICATOR_NAMES)]
    knowledge = Knowledge(
        itl=pd.DataFrame(itl_rows),
        signatures=pd.DataFrame(signatures, index=list(MODE_IDS), columns=list(INDICATOR_NAMES)),
        max_intensity=max_intensity)

    onset = n_flights // 3
    blocks, unit_ids = [], []
    for u in range(n_units):
        k = np.arange(n_flights)
        intensity = np.clip((k - onset + 1) / (n_flights - onset), 0.0, 1.0) if u else 0.0 * k
        sig = signatures[u % len(MODE_IDS)]
        z = rng.standard_normal((n_flights, len(INDICATOR_NAMES))) + np.outer(intensity, sig)
        blocks.append(_HEALTHY_MEAN + _HEALTHY_STD * z)
        unit_ids += [f"check-{u}"] * n_flights
    values = np.vstack(blocks)
    if n_units > 1:
        values[n_flights + 2, INDICATOR_NAMES.index("Hys0")] = np.nan
    units = _indicator_frame(values, unit_ids, np.tile(np.arange(n_flights), n_units), "check",
                             rng)
    return CheckData(healthy=healthy, other_healthy=other, units=units, knowledge=knowledge)


# --------------------------------------------------------------------------- helpers
class _CheckFailure(Exception):
    """Raised inside a check; turned into a MethodError by MethodCheck."""


def _fit(method: Any, data: CheckData, *, table: pd.DataFrame | None = None,
         seed: int = _SEED) -> Any:
    table = data.healthy if table is None else table
    out = method.fit(table, knowledge=data.knowledge, raw_flights=None, random_state=seed)
    return method if out is None else out


def _fresh(method: Any, data: CheckData, seed: int = _SEED) -> Any:
    m = clone_method(method)
    _fit(m, data, seed=seed)
    return m


def _run_units(method: Any, data: CheckData) -> pd.DataFrame:
    # run_table: row by row per unit, or the batch path of a method that has one (its agreement
    # with start_unit + decide is checked by check_decide_unit_consistent).
    return run_table(method, data.units)


#: Relative tolerance between the batch path and row-by-row decisions of a method with a batch
#: path: the same arithmetic on arrays of another size may round differently (BLAS kernels).
_BATCH_RTOL = 1e-9


def _first_difference(a: pd.DataFrame, b: pd.DataFrame, close: bool = False) -> str | None:
    """Describe the first flight whose decision differs between two decision tables.

    With ``close`` True, scores and guilt may differ by a relative ``_BATCH_RTOL``.
    """
    cols = ["score", "alarm", *GUILT_COLUMNS]
    if len(a) != len(b):
        return f"{len(a)} decisions vs {len(b)}"
    for i in range(len(a)):
        ra, rb = a.iloc[i], b.iloc[i]
        where = f"flight {ra['flight_index']} of unit {ra['unit_id']!r}"
        if ra["unit_id"] != rb["unit_id"] or ra["flight_index"] != rb["flight_index"]:
            return f"row {i} is {where} in one run and flight {rb['flight_index']} of unit " \
                   f"{rb['unit_id']!r} in the other"
        va = np.array([ra[c] for c in cols], dtype=float)
        vb = np.array([rb[c] for c in cols], dtype=float)
        same = (np.allclose(va, vb, rtol=_BATCH_RTOL, atol=1e-12, equal_nan=True)
                and va[1] == vb[1]) if close else np.array_equal(va, vb, equal_nan=True)
        if not same:
            what = "score" if va[0] != vb[0] else ("alarm" if va[1] != vb[1] else "guilt")
            detail = f"score {float(va[0])!r} vs {float(vb[0])!r}" if what == "score" else (
                f"{what} {bool(va[1])} vs {bool(vb[1])}" if what == "alarm" else
                f"guilt {va[2:].round(6).tolist()} vs {vb[2:].round(6).tolist()}")
            return f"decision at {where} differs ({detail})"
    return None


def _frame_change(before: pd.DataFrame, after: pd.DataFrame) -> str | None:
    """Describe how a DataFrame changed, or None when it is unchanged."""
    if list(before.columns) != list(after.columns):
        added = [c for c in after.columns if c not in before.columns]
        removed = [c for c in before.columns if c not in after.columns]
        return f"columns changed (added {added}, removed {removed})"
    if not before.index.equals(after.index):
        return "its index changed"
    for c in before.columns:
        if before[c].dtype != after[c].dtype:
            return f"the dtype of column {c!r} changed from {before[c].dtype} to {after[c].dtype}"
        if not before[c].equals(after[c]):
            return f"the values of column {c!r} changed"
    return None


# --------------------------------------------------------------------------- checks
def _check_stored(cls: type, kwargs: dict[str, Any]) -> Any:
    try:
        new = cls(**kwargs)
    except Exception as exc:
        raise _CheckFailure(f"re-creating the method from its parameters {kwargs!r} raised "
                            f"{type(exc).__name__}: {exc}") from exc
    extra = sorted(set(vars(new)) - set(kwargs))
    if extra:
        raise _CheckFailure(f"__init__ set attribute(s) {extra} that are not constructor "
                            f"parameters; derived state belongs in fit")
    for name, value in kwargs.items():
        stored = getattr(new, name, None)
        if stored is not value:
            raise _CheckFailure(f"__init__ modified the {name!r} parameter (stored {stored!r} "
                                f"instead of {value!r}); validation belongs in fit")
    return new


def check_constructor_stores_params(method: Any, data: CheckData) -> None:
    """__init__ takes keyword-only hyperparameters and stores them unchanged, nothing else."""
    cls = type(method)
    defaults: dict[str, Any] = {}
    if cls.__init__ is not object.__init__:
        for p in list(inspect.signature(cls.__init__).parameters.values())[1:]:
            if p.kind is not p.KEYWORD_ONLY:
                raise _CheckFailure(f"constructor parameter {p.name!r} is not keyword-only "
                                    f"(declare it after '*')")
            if p.default is not p.empty:
                defaults[p.name] = p.default
    _check_stored(cls, defaults)
    try:
        params = method.get_params(deep=False)
    except AttributeError as exc:
        raise _CheckFailure(f"get_params failed ({exc}): every constructor parameter must be "
                            f"stored under its own name") from exc
    new = _check_stored(cls, params)
    if new.set_params(**params) is not new:
        raise _CheckFailure("set_params did not return self")
    if repr(new.get_params(deep=False)) != repr(params):
        raise _CheckFailure("get_params after set_params(**get_params()) differs")
    twin = clone_method(method)
    if type(twin) is not cls or repr(twin.get_params(deep=False)) != repr(params):
        raise _CheckFailure("clone_method did not reproduce the hyperparameters")


def check_fit_returns_self(method: Any, data: CheckData) -> None:
    """fit returns the method itself."""
    m = clone_method(method)
    out = m.fit(data.healthy, knowledge=data.knowledge, raw_flights=None, random_state=_SEED)
    if out is not m:
        raise _CheckFailure(f"fit returned {type(out).__name__} instead of self")


def check_outputs_valid(method: Any, data: CheckData) -> None:
    """Every decision is valid: finite score, bool alarm, guilt (7,) >= 0 summing to 1 on alarm."""
    m = _fresh(method, data)
    for unit_id, table in data.unit_tables():
        ordered = table.sort_values("flight_index")
        m.start_unit(unit_id)
        for i in range(len(ordered)):
            row = ordered.iloc[i]
            k = row["flight_index"]
            try:
                d = m.decide(row)
            except Exception as exc:  # report where the method failed
                raise _CheckFailure(f"decide raised {type(exc).__name__} at flight {k} of unit "
                                    f"{unit_id!r}: {exc}") from exc
            problem = decision_problem(d)
            if problem is not None:
                raise _CheckFailure(f"decision at flight {k} of unit {unit_id!r} is invalid: "
                                    f"{problem}")
        out = m.decide_unit(table)
        if not isinstance(out, pd.DataFrame) or list(out.columns) != list(DECISION_COLUMNS):
            cols = list(out.columns) if isinstance(out, pd.DataFrame) else type(out).__name__
            raise _CheckFailure(f"decide_unit must return a DataFrame with columns "
                                f"{list(DECISION_COLUMNS)}; got {cols}")
        if len(out) != len(table) or not np.array_equal(
                out["flight_index"].to_numpy(), np.sort(table["flight_index"].to_numpy())):
            raise _CheckFailure(f"decide_unit must return one row per flight in flight order for "
                                f"unit {unit_id!r}")
        if out["alarm"].dtype != bool or not np.all(np.isfinite(out["score"].to_numpy(float))):
            raise _CheckFailure(f"decide_unit returned a non-bool alarm column or a non-finite "
                                f"score for unit {unit_id!r}")


def check_seeded_determinism(method: Any, data: CheckData) -> None:
    """Two fits with the same seed give identical decisions."""
    a = _run_units(_fresh(method, data), data)
    b = _run_units(_fresh(method, data), data)
    diff = _first_difference(a, b)
    if diff is not None:
        raise _CheckFailure(f"two fits with random_state={_SEED} gave different decisions: "
                            f"{diff}")


def check_no_lookahead(method: Any, data: CheckData) -> None:
    """The decision for flight k does not change when later flights change or are removed."""
    fitted = _fresh(method, data)  # each run below starts from a copy of the same fitted state
    for unit_id, table in data.unit_tables():
        table = table.sort_values("flight_index", kind="stable").reset_index(drop=True)
        full = copy.deepcopy(fitted).decide_unit(table)
        n = len(table)
        for cut in sorted({n // 3, (2 * n) // 3}):
            later = table["flight_index"].to_numpy()[cut + 1:]
            if later.size == 0:
                continue
            variants = []
            changed = table.copy()
            cols = list(INDICATOR_NAMES)
            changed.loc[cut + 1, cols] = (changed.loc[cut + 1, cols].to_numpy(float)
                                          + 40.0 * _HEALTHY_STD)
            variants.append((changed, f"flight {later[0]} changed"))
            changed_all = table.copy()
            changed_all.loc[cut + 1:, cols] = (changed_all.loc[cut + 1:, cols].to_numpy(float)
                                               - 40.0 * _HEALTHY_STD)
            variants.append((changed_all, f"flights after {table['flight_index'][cut]} changed"))
            variants.append((table.iloc[:cut + 1].copy(),
                             f"flights after {table['flight_index'][cut]} were removed"))
            for variant, what in variants:
                out = copy.deepcopy(fitted).decide_unit(variant)
                for i in range(cut + 1):
                    diff = _first_difference(full.iloc[[i]], out.iloc[[i]],
                                             close=has_batch_path(method))
                    if diff is not None:
                        raise _CheckFailure(f"decision at flight {table['flight_index'][i]} of "
                                            f"unit {unit_id!r} changed when {what}")


def check_decide_unit_consistent(method: Any, data: CheckData) -> None:
    """decide_unit equals start_unit + decide flight by flight, whatever the row order."""
    rng = np.random.default_rng(_SEED)
    fitted = _fresh(method, data)  # each run below starts from a copy of the same fitted state
    for _, table in data.unit_tables():
        a = copy.deepcopy(fitted).decide_unit(table)
        b = run_unit(copy.deepcopy(fitted), table)
        diff = _first_difference(a, b, close=has_batch_path(method))
        if diff is not None:
            raise _CheckFailure(f"decide_unit differs from start_unit + decide: {diff}")
        shuffled = table.iloc[rng.permutation(len(table))]
        c = copy.deepcopy(fitted).decide_unit(shuffled)
        diff = _first_difference(a, c, close=has_batch_path(method))
        if diff is not None:
            raise _CheckFailure(f"decide_unit depends on the row order of its input: {diff}")


def check_inputs_not_mutated(method: Any, data: CheckData) -> None:
    """fit, decide and decide_unit leave their input tables (and the knowledge) unchanged."""
    know = data.knowledge
    frames = [("healthy_indicators", data.healthy)]
    frames += [(f"knowledge.{f}", getattr(know, f)) for f in ("itl", "signatures")
               if getattr(know, f) is not None]
    snapshots = [(name, df.copy(deep=True), df) for name, df in frames]
    mi = None if know.max_intensity is None else dict(know.max_intensity)
    m = clone_method(method)
    _fit(m, data)
    for name, before, after in snapshots:
        change = _frame_change(before, after)
        if change is not None:
            raise _CheckFailure(f"fit modified {name!r}: {change}")
    if mi is not None and dict(know.max_intensity) != mi:
        raise _CheckFailure("fit modified 'knowledge.max_intensity'")
    for unit_id, table in data.unit_tables():
        snapshot = table.copy(deep=True)
        m.decide_unit(table)
        change = _frame_change(snapshot, table)
        if change is not None:
            raise _CheckFailure(f"decide_unit modified 'unit_table' of unit {unit_id!r}: {change}")
        m.start_unit(unit_id)
        ordered = table.sort_values("flight_index")
        for i in range(len(ordered)):
            row = ordered.iloc[i]
            row_before = row.copy(deep=True)
            m.decide(row)
            if not row.equals(row_before) or list(row.index) != list(row_before.index):
                raise _CheckFailure(f"decide modified its observation row (flight "
                                    f"{row_before['flight_index']} of unit {unit_id!r})")


def check_refit_idempotent(method: Any, data: CheckData) -> None:
    """Fitting again (after another fit and some decisions) equals fitting once."""
    once = _run_units(_fresh(method, data), data)
    m = clone_method(method)
    _fit(m, data, table=data.other_healthy, seed=_OTHER_SEED)
    _run_units(m, data)
    _fit(m, data)
    diff = _first_difference(once, _run_units(m, data))
    if diff is not None:
        raise _CheckFailure(f"refitting a used method gave different decisions than fitting "
                            f"once: {diff}")
    twice = clone_method(method)
    _fit(twice, data)
    _fit(twice, data)
    diff = _first_difference(once, _run_units(twice, data))
    if diff is not None:
        raise _CheckFailure(f"fitting twice gave different decisions than fitting once: {diff}")


def check_start_unit_resets(method: Any, data: CheckData) -> None:
    """A unit's decisions do not depend on the units processed before it."""
    tables = data.unit_tables()
    if len(tables) < 2:
        return
    (first_id, first), (last_id, last) = tables[0], tables[-1]
    alone = run_unit(_fresh(method, data), last)
    m = _fresh(method, data)
    for _, table in tables:
        run_unit(m, table)
    m.start_unit(first_id)  # an interrupted unit
    ordered = first.sort_values("flight_index")
    for i in range(len(ordered) // 2):
        m.decide(ordered.iloc[i])
    diff = _first_difference(alone, run_unit(m, last))
    if diff is not None:
        raise _CheckFailure(f"decisions for unit {last_id!r} depend on the units processed "
                            f"before it (start_unit must reset the per-unit history): {diff}")


def check_clone(method: Any, data: CheckData) -> None:
    """A clone of a fitted method, fitted with the same seed, decides identically."""
    m = _fresh(method, data)
    twin = clone_method(m)
    if repr(twin.get_params(deep=False)) != repr(m.get_params(deep=False)):
        raise _CheckFailure("the clone has different hyperparameters")
    _fit(twin, data)
    diff = _first_difference(_run_units(m, data), _run_units(twin, data))
    if diff is not None:
        raise _CheckFailure(f"a clone fitted with the same seed gave different decisions: {diff}")


def check_pickle_roundtrip(method: Any, data: CheckData) -> None:
    """A fitted method survives pickle.dumps/loads and then decides identically."""
    m = _fresh(method, data)
    try:
        blob = pickle.dumps(m)
        restored = pickle.loads(blob)
    except Exception as exc:
        raise _CheckFailure(f"pickling the fitted method raised {type(exc).__name__}: "
                            f"{exc}") from exc
    diff = _first_difference(_run_units(m, data), _run_units(restored, data))
    if diff is not None:
        raise _CheckFailure(f"the unpickled method gave different decisions: {diff}")


#: The checks in the order they run; cheap structural checks first.
_CHECKS: tuple[Callable[[Any, CheckData], None], ...] = (
    check_constructor_stores_params,
    check_fit_returns_self,
    check_outputs_valid,
    check_inputs_not_mutated,
    check_seeded_determinism,
    check_no_lookahead,
    check_decide_unit_consistent,
    check_refit_idempotent,
    check_start_unit_resets,
    check_clone,
    check_pickle_roundtrip,
)


@dataclass(frozen=True, eq=False)
class MethodCheck:
    """One named check bound to a method; call it to run it.

    Attributes
    ----------
    name : str
        Check name, e.g. ``"check_no_lookahead"``.
    method : object
        The method under test (never modified; checks work on clones).
    func : callable
        ``func(method, data)``.
    data : CheckData or None
        Data to use; None builds :func:`make_check_data` on call.
    """

    name: str
    method: Any
    func: Callable[[Any, CheckData], None] = field(repr=False)
    data: CheckData | None = field(default=None, repr=False)

    def __call__(self) -> None:
        """Run the check.

        Raises
        ------
        MethodError
            "<check> failed for <MethodClass>: <what happened>".
        """
        data = make_check_data(_SEED) if self.data is None else _copy_data(self.data)
        prefix = f"{self.name} failed for {type(self.method).__name__}: "
        try:
            self.func(self.method, data)
        except _CheckFailure as exc:
            raise MethodError(prefix + str(exc)) from exc.__cause__
        except Exception as exc:
            raise MethodError(f"{prefix}raised {type(exc).__name__}: {exc}") from exc


def iter_checks(method: Any, *, data: CheckData | None = None) -> Iterator[MethodCheck]:
    """Yield the named conformance checks for ``method``.

    Parameters
    ----------
    method : BaseMethod
        An (unfitted) method instance with its hyperparameters set.
    data : CheckData or None, default=None
        Custom check data; None uses :func:`make_check_data` with seed 0.

    Yields
    ------
    MethodCheck
        Call it to run the check.

    Examples
    --------
    >>> from fuelhm_bench.methods import NullMethod, iter_checks
    >>> [c.name for c in iter_checks(NullMethod())][:3]
    ['check_constructor_stores_params', 'check_fit_returns_self', 'check_outputs_valid']
    """
    shared = make_check_data(_SEED) if data is None else data
    for func in _CHECKS:
        yield MethodCheck(name=func.__name__, method=method, func=func, data=shared)


def check_method(method: Any, *, data: CheckData | None = None, sealed: bool = True,
                 timeout_s: float = 120.0) -> None:
    """Run every conformance check on ``method``; raise at the first failure.

    Parameters
    ----------
    method : BaseMethod
        An (unfitted) method instance.
    data : CheckData or None, default=None
        Custom check data; None uses :func:`make_check_data` with seed 0.
    sealed : bool, default=True
        Run the checks in a sealed child process
        (:class:`~fuelhm_bench.methods.sandbox.SealedMethod`), each within
        ``timeout_s``: a method that hangs, calls ``os._exit``, raises
        ``SystemExit`` or is killed fails the check with a named message
        instead of hanging or ending the caller. False: in this process
        (what :func:`iter_checks` and :func:`parametrize_with_checks` do).
    timeout_s : float, default=120.0
        Wall-time limit of each check (and of importing and building the
        method) in the sealed process [s], > 0.

    Raises
    ------
    MethodError
        "<check> failed for <MethodClass>: <details>".

    Examples
    --------
    >>> from fuelhm_bench.methods import RandomMethod, check_method
    >>> check_method(RandomMethod(alarm_probability=0.2), sealed=False)
    """
    if not sealed:
        for check in iter_checks(method, data=data):
            check()
        return
    from fuelhm_bench.methods.sandbox import Limits, SealedFailure, SealedMethod

    shared = make_check_data(_SEED) if data is None else data
    name = type(method).__name__
    sandbox = SealedMethod(method, limits=Limits(wall_s=float(timeout_s)))
    try:
        try:
            sandbox.start()
        except SealedFailure as exc:
            raise MethodError(f"{name} could not be started in a sealed process: {exc.status}: "
                              f"{exc.message}") from None
        for func in _CHECKS:
            try:
                reply = sandbox.call("check", {"name": func.__name__, "data": shared}, phase=func.__name__,
                                     timeout_s=float(timeout_s))
            except SealedFailure as exc:
                raise MethodError(f"{func.__name__} failed for {name}: {exc.status}: {exc.message}") from None
            if reply.get("failed"):
                raise MethodError(str(reply["failed"]))
    finally:
        sandbox.close()


def _run_one_check(method: Any, name: str, data: CheckData) -> dict:
    """Run the check ``name`` in this process (the sealed child); ``{"failed": message}`` when it fails."""
    func = next(f for f in _CHECKS if f.__name__ == name)
    try:
        MethodCheck(name=name, method=method, func=func, data=data)()
    except MethodError as exc:
        return {"failed": str(exc)}
    return {}


def parametrize_with_checks(methods: Sequence[Any]) -> Any:
    """A ``pytest.mark.parametrize`` decorator over (method x check).

    Parameters
    ----------
    methods : sequence of BaseMethod
        Method instances.

    Returns
    -------
    pytest.MarkDecorator
        Parametrizes the argument ``check`` with ids ``"<Class>-<check name>"``.

    Examples
    --------
    >>> from fuelhm_bench.methods import NullMethod, parametrize_with_checks
    >>> @parametrize_with_checks([NullMethod()])
    ... def test_conformance(check):
    ...     check()
    """
    import pytest  # test-time dependency only

    data = make_check_data(_SEED)
    checks = [c for m in methods for c in iter_checks(m, data=data)]
    ids = [f"{type(c.method).__name__}-{c.name}" for c in checks]
    return pytest.mark.parametrize("check", checks, ids=ids)


def _copy_data(data: CheckData) -> CheckData:
    """A deep copy, so that a method that mutates its inputs cannot affect other checks."""
    return copy.deepcopy(data)
