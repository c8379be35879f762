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

import contextlib
import copy
import inspect
import pickle
import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Sequence

import numpy as np
import pandas as pd

from fuelhm_bench.errors import MethodError, show_value
from fuelhm_bench.methods.base import (clone_method, has_batch_path, method_needs_raw, run_table,
                                       run_unit)
from fuelhm_bench.methods.decision import decision_problem
from fuelhm_bench.methods.knowledge import Knowledge
from fuelhm_bench.methods.tables import DECISION_COLUMNS, GUILT_COLUMNS
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES, MODE_IDS, OBSERVATION_COLUMNS

__all__ = ["CheckData", "MethodCheck", "check_method", "iter_checks", "make_check_data",
           "parametrize_with_checks"]

#: Healthy means and standard deviations of the synthetic indicators, in the
#: units of :data:`fuelhm_bench.taxonomy.INDICATOR_UNITS` (mA, mm/s, mm/s/mA).
_HEALTHY_MEAN = np.array([-3.0, -20.0, 3.0, 20.0, 0.1, 0.2, 0.05, 6.0, 6.0, 3.0])
_HEALTHY_STD = np.array([0.05, 0.5, 0.05, 0.5, 0.02, 0.02, 0.01, 0.1, 0.1, 0.1])
# Extended indicators (EXTENDED_INDICATOR_NAMES): mean and scatter of paper_2012's healthy training fleet.
_EXT_MEAN = np.array([-4.58, 4.67, -15.33, 15.35, -50.6, 51.9, 0.499, 0.844, 0.0494, 0.0231, 0.0005])
_EXT_STD = np.array([0.22, 0.21, 0.031, 0.082, 0.92, 0.82, 0.020, 0.012, 0.0066, 0.0017, 0.0001])

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
    raw : dict
        ``(unit_id, flight_index) -> RawFlight`` for every row of the three
        tables (:func:`make_check_data` with ``raw=True``; empty otherwise):
        short synthetic full-rate flights of a position loop whose valve gain
        and null bias follow the same degradation as the indicators.
    """

    healthy: pd.DataFrame
    other_healthy: pd.DataFrame
    units: pd.DataFrame
    knowledge: Knowledge
    raw: dict = field(default_factory=dict)

    def unit_tables(self) -> list[tuple[Any, pd.DataFrame]]:
        """``(unit_id, table)`` pairs of ``units`` in order of first appearance."""
        return [(u, g) for u, g in self.units.groupby("unit_id", sort=False)]

    def raw_for(self, row: Any) -> Any:
        """The RawFlight of an indicator row (the raw provider of :func:`run_unit`)."""
        key = (row["unit_id"], int(row["flight_index"]))
        if key not in self.raw:
            raise MethodError(f"The check data has no raw flight for unit {key[0]!r}, flight "
                              f"{key[1]} (build it with make_check_data(raw=True)).")
        return self.raw[key]

    def raw_flights(self, table: pd.DataFrame) -> Iterator[Any]:
        """The raw flights of a table's rows, one at a time (the ``raw_flights`` of ``fit``)."""
        for _, row in table.iterrows():
            yield self.raw_for(row)


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
    # The extended indicators, as the benchmark gives them: healthy scatter of a physics fleet
    # (paper_2012), about half of the flights without V_in7 (NaN, flag False).
    ext = _EXT_MEAN + _EXT_STD * rng.standard_normal((n, len(EXTENDED_INDICATOR_NAMES)))
    ext[rng.random(n) < 0.5, EXTENDED_INDICATOR_NAMES.index("V_in7")] = np.nan
    for j, name in enumerate(EXTENDED_INDICATOR_NAMES):
        data[name] = ext[:, j]
    for j, name in enumerate(EXTENDED_INDICATOR_NAMES):
        data[f"{name}_valid"] = np.isfinite(ext[:, j])
    return pd.DataFrame(data, columns=list(OBSERVATION_COLUMNS))


def _healthy_table(n_units: int, n_flights: int, prefix: str,
                   rng: np.random.Generator) -> pd.DataFrame:
    z = rng.standard_normal((n_units * n_flights, len(INDICATOR_NAMES)))
    values = _HEALTHY_MEAN + _HEALTHY_STD * z
    unit_ids = [f"{prefix}-{u}" for u in range(n_units) for _ in range(n_flights)]
    index = np.tile(np.arange(n_flights), n_units)
    return _indicator_frame(values, unit_ids, index, prefix, rng)


def _raw_flight(unit_id: Any, k: int, gain: float, bias: float, rng: np.random.Generator,
                n_samples: int = 600) -> Any:
    """A short synthetic full-rate flight: position loop, valve velocity gain and null bias.

    The position follows the demand with a lag; the current is what a valve of velocity
    gain ``gain`` [mm/s/mA] and null bias ``bias`` [mA] needs to move it so, plus noise.
    """
    from fuelhm_bench.methods.raw import RawFlight

    t = np.arange(n_samples) * 0.02
    phase = rng.uniform(0.0, 2 * np.pi)
    demand = 20.0 + 8.0 * np.sin(2 * np.pi * 0.1 * t + phase) + 3.0 * np.sin(2 * np.pi * 0.37 * t)
    position = np.interp(t - 0.1, t, demand) + rng.normal(0.0, 0.005, t.size)
    velocity = np.gradient(np.interp(t - 0.1, t, demand), t)
    current = velocity / gain + bias + rng.normal(0.0, 0.01, t.size)
    n2 = 80.0 + rng.normal(0.0, 0.2, t.size)
    return RawFlight(unit_id, int(k), t, current, position, demand, n2)


def _raw_table(table: pd.DataFrame, intensity: np.ndarray, rng: np.random.Generator) -> dict:
    out = {}
    gains = 6.0 + 0.05 * rng.standard_normal(len(table))
    for i, (u, k) in enumerate(zip(table["unit_id"], table["flight_index"])):
        out[(u, int(k))] = _raw_flight(u, int(k), gains[i] * (1.0 - 0.4 * intensity[i]),
                                       0.05 + 0.3 * intensity[i], rng)
    return out


def make_check_data(random_state: int = 0, *, n_units: int = 3,
                    n_flights: int = 12, raw: bool = False) -> CheckData:
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
    raw : bool, default=False
        Also build a synthetic raw flight for every row (:attr:`CheckData.raw`),
        for methods with ``needs_raw``; its degradation follows the unit's.

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
    blocks, unit_ids, intensities = [], [], []
    for u in range(n_units):
        k = np.arange(n_flights)
        intensity = np.clip((k - onset + 1) / (n_flights - onset), 0.0, 1.0) if u else 0.0 * k
        intensities.append(intensity)
        sig = signatures[u % len(MODE_IDS)]
        z = rng.standard_normal((n_flights, len(INDICATOR_NAMES))) + np.outer(intensity, sig)
        blocks.append(_HEALTHY_MEAN + _HEALTHY_STD * z)
        unit_ids += [f"check-{u}"] * n_flights
    values = np.vstack(blocks)
    if n_units > 1:
        values[n_flights + 2, INDICATOR_NAMES.index("Hys0")] = np.nan
    units = _indicator_frame(values, unit_ids, np.tile(np.arange(n_flights), n_units), "check",
                             rng)
    raw_flights: dict = {}
    if raw:
        raw_rng = np.random.default_rng([random_state, 7])
        raw_flights.update(_raw_table(healthy, np.zeros(len(healthy)), raw_rng))
        raw_flights.update(_raw_table(other, np.full(len(other), 0.05), raw_rng))
        raw_flights.update(_raw_table(units, np.concatenate(intensities), raw_rng))
    return CheckData(healthy=healthy, other_healthy=other, units=units, knowledge=knowledge,
                     raw=raw_flights)


# --------------------------------------------------------------------------- helpers
class _CheckFailure(Exception):
    """Raised inside a check; turned into a MethodError by MethodCheck."""


def _fit(method: Any, data: CheckData, *, table: pd.DataFrame | None = None,
         seed: int = _SEED) -> Any:
    table = data.healthy if table is None else table
    raw = data.raw_flights(table) if _needs_raw(method) else None
    out = method.fit(table, knowledge=data.knowledge, raw_flights=raw, random_state=seed)
    return method if out is None else out


def _needs_raw(method: Any) -> bool:
    return method_needs_raw(method)


def _decide(method: Any, row: pd.Series, data: CheckData) -> Any:
    """``method.decide(row)``, with the row's raw flight for a method with ``needs_raw``."""
    if _needs_raw(method):
        return method.decide(row, raw=data.raw_for(row))
    return method.decide(row)


def _raw_arg(method: Any, data: CheckData) -> dict:
    """``{"raw": provider}`` for run_unit / decide_unit of a raw method, else ``{}``."""
    return {"raw": data.raw_for} if _needs_raw(method) else {}


#: The last fitted method of :func:`_fresh` (key, fitted): the checks that only need "a method
#: fitted on the healthy table with seed s" share one fit (a deep copy each), so that
#: check_method fits an expensive estimator a handful of times instead of once per check. The
#: checks about fitting itself (determinism, refit, clone, fit returns self) always fit anew.
_FITTED: list = []


def _fingerprint(data: CheckData, seed: int) -> tuple:
    table = data.healthy
    hashed = int(pd.util.hash_pandas_object(table, index=True).sum()) if len(table) else 0
    return (seed, hashed, tuple(table.columns), id(type(data.knowledge)), len(data.raw))


def _fresh(method: Any, data: CheckData, seed: int = _SEED, *, shared: bool = True) -> Any:
    m = clone_method(method)
    key = None
    if shared:
        try:
            key = (type(method), repr(m.get_params(deep=False)), _fingerprint(data, seed))
        except Exception:  # noqa: BLE001 - an unhashable parameter: fit anew
            key = None
        if key is not None and _FITTED and _FITTED[0][0] == key:
            with contextlib.suppress(Exception):  # not deep-copyable: fit anew
                return copy.deepcopy(_FITTED[0][1])
    _fit(m, data, seed=seed)
    if key is not None:
        try:
            _FITTED[:] = [(key, copy.deepcopy(m))]
        except Exception:  # noqa: BLE001
            _FITTED.clear()
    return m


def _run_units(method: Any, data: CheckData) -> pd.DataFrame:
    """Decisions for every check unit: row by row per unit, or one batch for a batch method.

    A method with a batch path decides every row on its own (its agreement with start_unit +
    decide is checked by check_decide_unit_consistent, and its causality by
    check_no_lookahead), so the checks that compare two runs use one ``decide_batch`` call over
    the whole table instead of the harness's causal waves (a dozen calls of the estimator).
    """
    if has_batch_path(method):
        ordered = data.units.assign(_u=pd.factorize(data.units["unit_id"])[0]).sort_values(
            ["_u", "flight_index"], kind="stable").drop(columns="_u")
        return method.decide_batch(ordered).reset_index(drop=True)
    return run_table(method, data.units, raw=data.raw_for if _needs_raw(method) else None)


#: Relative tolerance between the batch path and row-by-row decisions of a method with a batch
#: path: the same arithmetic on arrays of another size may round differently (BLAS kernels), by a
#: few units of the last place in single precision (float32 epsilon 1.2e-7). Alarms must agree.
_BATCH_RTOL = 1e-6


def _first_difference(a: pd.DataFrame, b: pd.DataFrame, close: bool = False) -> str | None:
    """Describe the first flight whose decision differs between two decision tables.

    With ``close`` True, scores and guilt may differ by a relative ``_BATCH_RTOL``.
    """
    cols = ["score", "alarm", *GUILT_COLUMNS]
    if len(a) != len(b):
        return f"{len(a)} decisions vs {len(b)}"
    for i in range(len(a)):
        ra, rb = a.iloc[i], b.iloc[i]
        where = f"flight {ra['flight_index']} of unit {show_value(ra['unit_id'])}"
        if ra["unit_id"] != rb["unit_id"] or ra["flight_index"] != rb["flight_index"]:
            return f"row {i} is {where} in one run and flight {rb['flight_index']} of unit " \
                   f"{show_value(rb['unit_id'])} in the other"
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
    """__init__ takes keyword-only hyperparameters, each with a default, and stores them unchanged, nothing else."""
    cls = type(method)
    defaults: dict[str, Any] = {}
    if cls.__init__ is not object.__init__:
        for p in list(inspect.signature(cls.__init__).parameters.values())[1:]:
            if p.kind is not p.KEYWORD_ONLY:
                raise _CheckFailure(f"constructor parameter {p.name!r} is not keyword-only "
                                    f"(declare it after '*')")
            if p.default is p.empty and p.kind is p.KEYWORD_ONLY:
                raise _CheckFailure(f"constructor parameter {p.name!r} has no default; give every "
                                    f"hyperparameter one (the method is re-created from its defaults, "
                                    f"as scikit-learn's clone and grid searches do)")
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
    raw = data.raw_flights(data.healthy) if _needs_raw(method) else None
    out = m.fit(data.healthy, knowledge=data.knowledge, raw_flights=raw, random_state=_SEED)
    if out is not m:
        raise _CheckFailure(f"fit returned {type(out).__name__} instead of self")


def check_outputs_valid(method: Any, data: CheckData) -> None:
    """Every decision is valid: finite score, bool alarm, guilt (7,) >= 0 summing to 1 on alarm.

    A method with a batch path is decided row by row on its first unit only (every row of every
    unit is compared with its batch decision by check_decide_unit_consistent).
    """
    m = _fresh(method, data)
    for n_unit, (unit_id, table) in enumerate(data.unit_tables()):
        ordered = table.sort_values("flight_index")
        m.start_unit(unit_id)
        for i in range(len(ordered) if n_unit == 0 or not has_batch_path(method) else 0):
            row = ordered.iloc[i]
            k = row["flight_index"]
            try:
                d = _decide(m, row, data)
            except Exception as exc:  # report where the method failed
                raise _CheckFailure(f"decide raised {type(exc).__name__} at flight {k} of unit "
                                    f"{show_value(unit_id)}: {exc}") from exc
            problem = decision_problem(d)
            if problem is not None:
                raise _CheckFailure(f"decision at flight {k} of unit {show_value(unit_id)} is invalid: "
                                    f"{problem}")
        out = m.decide_unit(table, **_raw_arg(method, data))
        if not isinstance(out, pd.DataFrame) or list(out.columns) != list(DECISION_COLUMNS):
            cols = list(out.columns) if isinstance(out, pd.DataFrame) else type(out).__name__
            raise _CheckFailure(f"decide_unit must return a DataFrame with columns "
                                f"{list(DECISION_COLUMNS)}; got {cols}")
        if len(out) != len(table) or not np.array_equal(
                out["flight_index"].to_numpy(), np.sort(table["flight_index"].to_numpy())):
            raise _CheckFailure(f"decide_unit must return one row per flight in flight order for "
                                f"unit {show_value(unit_id)}")
        if out["alarm"].dtype != bool or not np.all(np.isfinite(out["score"].to_numpy(float))):
            raise _CheckFailure(f"decide_unit returned a non-bool alarm column or a non-finite "
                                f"score for unit {show_value(unit_id)}")


def check_seeded_determinism(method: Any, data: CheckData) -> None:
    """Two fits with the same seed give identical decisions."""
    a = _run_units(_fresh(method, data, shared=False), data)
    b = _run_units(_fresh(method, data, shared=False), data)
    diff = _first_difference(a, b)
    if diff is not None:
        raise _CheckFailure(f"two fits with random_state={_SEED} gave different decisions: "
                            f"{diff}")


def check_no_lookahead(method: Any, data: CheckData) -> None:
    """The decision for flight k does not change when later flights change or are removed."""
    fitted = _fresh(method, data)  # each run below starts from a copy of the same fitted state
    for unit_id, table in data.unit_tables():
        table = table.sort_values("flight_index", kind="stable").reset_index(drop=True)
        full = copy.deepcopy(fitted).decide_unit(table, **_raw_arg(method, data))
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
                raw = {"raw": _changed_raw(data, unit_id, int(table["flight_index"][cut]))} \
                    if _needs_raw(method) else {}
                out = copy.deepcopy(fitted).decide_unit(variant, **raw)
                for i in range(cut + 1):
                    diff = _first_difference(full.iloc[[i]], out.iloc[[i]],
                                             close=has_batch_path(method))
                    if diff is not None:
                        raise _CheckFailure(f"decision at flight {table['flight_index'][i]} of "
                                            f"unit {show_value(unit_id)} changed when {what}")


def _changed_raw(data: CheckData, unit_id: Any, last: int) -> Callable[[Any], Any]:
    """A raw provider whose flights of ``unit_id`` after flight ``last`` are changed."""
    from fuelhm_bench.methods.raw import RawFlight

    def provider(row: Any) -> Any:
        flight = data.raw_for(row)
        if row["unit_id"] != unit_id or int(row["flight_index"]) <= last:
            return flight
        return RawFlight(flight.unit_id, flight.flight_index, flight.time_s,
                         1.5 * flight.current_mA + 0.3, flight.position_mm + 2.0,
                         flight.demand_mm, flight.n2_pct)

    return provider


def check_decide_unit_consistent(method: Any, data: CheckData) -> None:
    """decide_unit equals start_unit + decide flight by flight, whatever the row order."""
    rng = np.random.default_rng(_SEED)
    fitted = _fresh(method, data)  # each run below starts from a copy of the same fitted state
    raw = _raw_arg(method, data)
    for _, table in data.unit_tables():
        a = copy.deepcopy(fitted).decide_unit(table, **raw)
        b = run_unit(copy.deepcopy(fitted), table, **raw)
        diff = _first_difference(a, b, close=has_batch_path(method))
        if diff is not None:
            raise _CheckFailure(f"decide_unit differs from start_unit + decide: {diff}")
        shuffled = table.iloc[rng.permutation(len(table))]
        c = copy.deepcopy(fitted).decide_unit(shuffled, **raw)
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
    for n_unit, (unit_id, table) in enumerate(data.unit_tables()):
        snapshot = table.copy(deep=True)
        m.decide_unit(table, **_raw_arg(method, data))
        change = _frame_change(snapshot, table)
        if change is not None:
            raise _CheckFailure(f"decide_unit modified 'unit_table' of unit {show_value(unit_id)}: {change}")
        m.start_unit(unit_id)
        ordered = table.sort_values("flight_index")
        # a batch method's rows are decided on their own: one unit shows a mutation as well as all
        for i in range(len(ordered) if n_unit == 0 or not has_batch_path(method) else 0):
            row = ordered.iloc[i]
            row_before = row.copy(deep=True)
            _decide(m, row, data)
            if not row.equals(row_before) or list(row.index) != list(row_before.index):
                raise _CheckFailure(f"decide modified its observation row (flight "
                                    f"{row_before['flight_index']} of unit {show_value(unit_id)})")


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
    raw = _raw_arg(method, data)
    alone = run_unit(_fresh(method, data), last, **raw)
    m = _fresh(method, data)
    # a batch method declares no per-unit state: one unit before is enough to show a leak
    for _, table in (tables[:1] if has_batch_path(method) and not raw else tables):
        run_unit(m, table, **raw)
    m.start_unit(first_id)  # an interrupted unit
    ordered = first.sort_values("flight_index")
    for i in range(len(ordered) // 2):
        _decide(m, ordered.iloc[i], data)
    diff = _first_difference(alone, run_unit(m, last, **raw))
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


def _dumps(m: Any) -> bytes:
    """``pickle.dumps(m)``, or by value when its class cannot be found by name in this process.

    A class defined in a script or a notebook (module ``__main__``) reaches the sealed process by
    value (cloudpickle); there ``pickle`` cannot look it up by name, although it can in the user's
    own process. Pickling it by value there checks what the user's process would do.
    """
    cls = type(m)
    owner = sys.modules.get(cls.__module__)
    for part in cls.__qualname__.split("."):
        owner = getattr(owner, part, None)
    if owner is cls or "<locals>" in cls.__qualname__:
        return pickle.dumps(m)
    import cloudpickle

    return cloudpickle.dumps(m)


def check_pickle_roundtrip(method: Any, data: CheckData) -> None:
    """A fitted method survives pickle.dumps/loads and then decides identically."""
    m = _fresh(method, data)
    try:
        blob = _dumps(m)
        restored = pickle.loads(blob)
    except Exception as exc:
        raise _CheckFailure(f"pickling the fitted method raised {type(exc).__name__}: "
                            f"{exc}") from exc
    diff = _first_difference(_run_units(m, data), _run_units(restored, data))
    if diff is not None:
        raise _CheckFailure(f"the unpickled method gave different decisions: {diff}")


def check_raw_used(method: Any, data: CheckData) -> None:
    """A method declaring ``needs_raw`` decides from the raw flight: other samples, other scores.

    The check units are decided twice from the same fitted state, with their own raw flights and
    with those of healthy training flights in their place (the indicator rows unchanged); at
    least one score must differ, or the method declares raw flights it does not use (and would
    score like a method that ignores them). Skipped for methods without ``needs_raw``.
    """
    if not _needs_raw(method):
        return
    from fuelhm_bench.methods.raw import RawFlight

    fitted = _fresh(method, data)
    donors = [data.raw_for(row) for _, row in data.healthy.iterrows()]

    def swapped(row: Any) -> Any:
        i = data.units.index.get_loc(row.name) if row.name in data.units.index else 0
        d = donors[i % len(donors)]
        return RawFlight(row["unit_id"], int(row["flight_index"]), d.time_s, d.current_mA,
                         d.position_mm, d.demand_mm, d.n2_pct)

    own = run_table(copy.deepcopy(fitted), data.units, raw=data.raw_for)
    other = run_table(copy.deepcopy(fitted), data.units, raw=swapped)
    if np.array_equal(own["score"].to_numpy(float), other["score"].to_numpy(float)):
        raise _CheckFailure("it declares needs_raw = True but its scores did not change when every "
                            "raw flight was replaced by another one (the method does not use the "
                            "raw samples it asks for)")


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
    check_raw_used,
)


def _checks_for(method: Any) -> tuple[Callable[[Any, CheckData], None], ...]:
    """The checks that apply to ``method`` (check_raw_used only with ``needs_raw``)."""
    return tuple(f for f in _CHECKS if f is not check_raw_used or _needs_raw(method))


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
        data = (make_check_data(_SEED, raw=_needs_raw(self.method)) if self.data is None
                else _copy_data(self.data))
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
    shared = make_check_data(_SEED, raw=_needs_raw(method)) if data is None else data
    for func in _checks_for(method):
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

    shared = make_check_data(_SEED, raw=_needs_raw(method)) if data is None else data
    name = type(method).__name__
    sandbox = SealedMethod(method, limits=Limits(wall_s=float(timeout_s)))
    try:
        try:
            sandbox.start()
        except SealedFailure as exc:
            raise MethodError(f"{name} could not be started in a sealed process: {exc.status}: "
                              f"{exc.message}") from None
        for n_check, func in enumerate(_checks_for(method)):
            try:  # the data travels once; the sealed process keeps it for the next checks
                reply = sandbox.call("check", {"name": func.__name__, "data": shared if n_check == 0 else None},
                                     phase=func.__name__, timeout_s=float(timeout_s))
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

    data = make_check_data(_SEED, raw=any(_needs_raw(m) for m in methods))
    checks = [c for m in methods for c in iter_checks(m, data=data)]
    ids = [f"{type(c.method).__name__}-{c.name}" for c in checks]
    return pytest.mark.parametrize("check", checks, ids=ids)


def _copy_data(data: CheckData) -> CheckData:
    """A deep copy, so that a method that mutates its inputs cannot affect other checks."""
    return copy.deepcopy(data)
