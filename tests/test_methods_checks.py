"""Tests of the conformance checker: broken methods are caught with precise messages."""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.errors import MethodError
from fuelhm_bench.methods import (BaseMethod, CheckData, Decision, Knowledge, NullMethod, RandomMethod,
                                  check_method, iter_checks, make_check_data,
                                  parametrize_with_checks)
from fuelhm_bench.methods.base import run_unit
from fuelhm_bench.taxonomy import INDICATOR_NAMES

from test_methods_base import ZScore


# ---------------------------------------------------------------- broken methods
class Nondeterministic(ZScore):
    """Draws from an unseeded generator."""

    def _decide(self, row):
        d = super()._decide(row)
        return Decision(d.score + np.random.default_rng().random(), d.alarm, d.guilt)


class GlobalRng(ZScore):
    """Uses NumPy's global RNG in fit."""

    def _fit(self, healthy, **kwargs):
        super()._fit(healthy, **kwargs)
        self.offset_ = np.random.random()


class LookAhead(ZScore):
    """Scales every score by the unit's largest raw value: needs the whole unit."""

    def decide_unit(self, unit_table):
        out = super().decide_unit(unit_table)
        out["score"] = out["score"] / out["score"].max()
        return out


class MutatesInput(ZScore):
    """Centres the training table in place."""

    def _fit(self, healthy, **kwargs):
        super()._fit(healthy, **kwargs)
        healthy["X1"] = healthy["X1"] - healthy["X1"].mean()


class MutatesRow(ZScore):
    """Writes into the observation row."""

    def _decide(self, row):
        row["X1"] = 0.0
        return super()._decide(row)


class NaNScore(ZScore):
    def _decide(self, row):
        d = super()._decide(row)
        return Decision(float("nan") if row["flight_index"] == 4 else d.score, d.alarm, d.guilt)


class HalfGuilt(ZScore):
    def _decide(self, row):
        d = super()._decide(row)
        return Decision(d.score, d.alarm, d.guilt / 2)


class DerivedInInit(ZScore):
    def __init__(self, *, a=3.0, window=2, jitter=0.0, random_state=None):
        super().__init__(a=a, window=window, jitter=jitter, random_state=random_state)
        self.a_squared_ = a**2


class ConvertsInInit(ZScore):
    def __init__(self, *, a=3.0, window=2, jitter=0.0, random_state=None):
        super().__init__(a=a, window=window, jitter=jitter, random_state=random_state)
        self.window = list(range(window))


class Positional(ZScore):
    def __init__(self, a=3.0, *, window=2, jitter=0.0, random_state=None):
        super().__init__(a=a, window=window, jitter=jitter, random_state=random_state)


class NoDefault(ZScore):
    def __init__(self, *, a, window=2, jitter=0.0, random_state=None):
        super().__init__(a=a, window=window, jitter=jitter, random_state=random_state)


class Float32Batch(BaseMethod):
    """Single-precision arithmetic, vectorised in the batch path: rounds differently from row by row."""

    def __init__(self, *, a=1.0):
        self.a = a

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        x = healthy[list(INDICATOR_NAMES)].to_numpy(np.float32)
        self.mu_ = np.nanmean(x, axis=0)
        self.sd_ = np.nanstd(x, axis=0) + np.float32(1e-6)

    def _z(self, x):
        return np.nan_to_num((x.astype(np.float32) - self.mu_) / self.sd_)

    def _decide(self, row):
        z = self._z(row[list(INDICATOR_NAMES)].to_numpy(float)[None, :])
        score = float(np.sqrt(np.mean(z * z, axis=1, dtype=np.float32))[0])
        return Decision(score, score > self.a, np.full(7, 1 / 7) if score > self.a else None)

    def _decide_batch(self, rows):
        z = self._z(rows[list(INDICATOR_NAMES)].to_numpy(float))
        score = np.sqrt(np.einsum("ij,ij->i", z, z, dtype=np.float32) / np.float32(z.shape[1])).astype(float)
        alarm = score > self.a
        return score, alarm, np.where(alarm[:, None], 1 / 7, 0.0) * np.ones((len(score), 7))


class NotPicklable(ZScore):
    def _fit(self, healthy, **kwargs):
        super()._fit(healthy, **kwargs)
        self.transform_ = lambda x: x


class Accumulates(ZScore):
    """Each fit adds to the previous fit's statistics."""

    def _fit(self, healthy, **kwargs):
        previous = getattr(self, "mu_", 0.0)
        super()._fit(healthy, **kwargs)
        self.mu_ = self.mu_ + 0.5 * previous


class NoReset(ZScore):
    """Keeps the history across units."""

    def _fit(self, healthy, **kwargs):
        super()._fit(healthy, **kwargs)
        self.history_ = []

    def _start_unit(self, unit_id):
        return None


class ReturnsNone(ZScore):
    def fit(self, *args, **kwargs):
        super().fit(*args, **kwargs)


class Reversed(ZScore):
    """decide_unit that returns the flights latest first."""

    def decide_unit(self, unit_table):
        return run_unit(self, unit_table).iloc[::-1].reset_index(drop=True)


@pytest.mark.parametrize("method, match", [
    (Nondeterministic(), r"^check_seeded_determinism failed for Nondeterministic: two fits with "
                         r"random_state=0 gave different decisions: decision at flight 0 of unit "
                         r"'check-0' differs \(score \d\.\d+ vs \d\.\d+\)$"),
    (GlobalRng(), r"^check_seeded_determinism failed for GlobalRng: "),
    (LookAhead(), r"^check_no_lookahead failed for LookAhead: decision at flight 0 of unit "
                  r"'check-0' changed when flight 5 changed$"),
    (MutatesInput(), r"^check_inputs_not_mutated failed for MutatesInput: fit modified "
                     r"'healthy_indicators': the values of column 'X1' changed$"),
    (MutatesRow(), r"^check_inputs_not_mutated failed for MutatesRow: decide modified its "
                   r"observation row \(flight 0 of unit 'check-0'\)$"),
    (NaNScore(), r"^check_outputs_valid failed for NaNScore: decide raised MethodError at flight "
                 r"4 of unit 'check-0': NaNScore returned an invalid decision for unit 'check-0': "
                 r"score is nan, not a finite float\.$"),
    (HalfGuilt(a=1.0), r"^check_outputs_valid failed for HalfGuilt: .*guilt sums to 0\.5 with "
                       r"alarm=True, not 1"),
    (DerivedInInit(), r"^check_constructor_stores_params failed for DerivedInInit: __init__ set "
                      r"attribute\(s\) \['a_squared_'\] that are not constructor parameters"),
    (ConvertsInInit(), r"^check_constructor_stores_params failed for ConvertsInInit: __init__ "
                       r"modified the 'window' parameter \(stored \[0, 1\] instead of 2\)"),
    (Positional(), r"^check_constructor_stores_params failed for Positional: constructor "
                   r"parameter 'a' is not keyword-only"),
    (NoDefault(a=2.0), r"^check_constructor_stores_params failed for NoDefault: constructor parameter 'a' has no "
                       r"default; give every hyperparameter one"),
    (NotPicklable(), r"^check_pickle_roundtrip failed for NotPicklable: pickling the fitted "
                     r"method raised \w+: "),
    (Accumulates(), r"^check_refit_idempotent failed for Accumulates: refitting a used method "
                    r"gave different decisions than fitting once: decision at flight 0 of unit "
                    r"'check-0' differs"),
    (NoReset(window=4), r"^check_start_unit_resets failed for NoReset: decisions for unit "
                        r"'check-2' depend on the units processed before it"),
    (ReturnsNone(), r"^check_fit_returns_self failed for ReturnsNone: fit returned NoneType "
                    r"instead of self$"),
    (Reversed(), r"^check_outputs_valid failed for Reversed: decide_unit must return one row "
                 r"per flight in flight order for unit 'check-0'$"),
])
def test_checker_catches_broken_method(method, match):
    with pytest.raises(MethodError, match=match):
        check_method(method, sealed=False)


def test_checker_reports_exceptions_raised_by_the_method():
    class Crashes(ZScore):
        def _decide(self, row):
            if row["flight_index"] == 2:
                raise ZeroDivisionError("boom")
            return super()._decide(row)

    with pytest.raises(MethodError, match=r"^check_outputs_valid failed for Crashes: decide raised "
                                          r"ZeroDivisionError at flight 2 of unit 'check-0': boom"):
        check_method(Crashes(), sealed=False)


def test_lookahead_on_truncation_only_is_caught():
    class PeeksAtLength(ZScore):
        def decide_unit(self, unit_table):
            out = super().decide_unit(unit_table)
            out["score"] = out["score"] + len(unit_table)
            return out

    with pytest.raises(MethodError, match=r"^check_no_lookahead failed for PeeksAtLength: decision "
                                          r"at flight 0 of unit 'check-0' changed when flights "
                                          r"after 4 were removed$"):
        check_method(PeeksAtLength(), sealed=False)


@pytest.mark.parametrize("method", [ZScore(), ZScore(a=1.0, window=3, jitter=0.2, random_state=4),
                                    NullMethod(), RandomMethod(alarm_probability=0.3)])
def test_correct_methods_pass(method):
    check_method(method, sealed=False)


def test_checks_do_not_touch_the_given_instance():
    m = ZScore(a=1.0)
    check_method(m, sealed=False)
    assert not hasattr(m, "mu_") and m.get_params()["a"] == 1.0


def test_iter_checks_names_and_custom_data():
    data = make_check_data(5, n_units=2, n_flights=8)
    checks = list(iter_checks(ZScore(), data=data))
    names = [c.name for c in checks]
    assert names[0] == "check_constructor_stores_params" and len(set(names)) == len(names) == 11
    assert {"check_no_lookahead", "check_pickle_roundtrip", "check_seeded_determinism",
            "check_refit_idempotent", "check_clone", "check_inputs_not_mutated",
            "check_outputs_valid", "check_start_unit_resets"} <= set(names)
    for check in checks:
        check()
    assert data.units["unit_id"].nunique() == 2


def test_checks_accept_data_without_knowledge():
    base = make_check_data(0)
    data = CheckData(healthy=base.healthy, other_healthy=base.other_healthy, units=base.units,
                     knowledge=Knowledge())
    check_method(ZScore(), data=data, sealed=False)
    with pytest.raises(MethodError, match="check_inputs_not_mutated failed for MutatesInput"):
        check_method(MutatesInput(), data=data, sealed=False)


def test_check_data_is_reproducible_and_realistic():
    a, b = make_check_data(0), make_check_data(0)
    assert a.units.equals(b.units) and a.healthy.equals(b.healthy)
    assert not a.units.equals(make_check_data(1).units)
    assert a.units[list(INDICATOR_NAMES)].isna().sum().sum() == 1
    missing = a.units[a.units["Hys0"].isna()]
    assert not missing["Hys0_valid"].iloc[0]


@parametrize_with_checks([NullMethod(), RandomMethod(alarm_probability=0.1)])
def test_parametrize_with_checks(check):
    check()


# --------------------------------------------------------------------------- sealed check_method
def test_sealed_checker_names_methods_that_hang_exit_or_die():
    """Each check runs in a sealed child with a time limit; the caller survives and gets a named message."""
    from submissions import Exits, Hangs, Segfaults, SysExit

    cases = [(Hangs(), r"check_\w+ failed for Hangs: timeout: .*did not finish within 5 s"),
             (Exits(), r"check_\w+ failed for Exits: crash: .*exit code 7"),
             (SysExit(), r"check_\w+ failed for SysExit: error: .*SystemExit\(0\) raised"),
             (Segfaults(), r"check_\w+ failed for Segfaults: crash: .*signal SIGSEGV")]
    for method, match in cases:
        with pytest.raises(MethodError, match=match):
            check_method(method, timeout_s=5.0)
    check_method(NullMethod(), timeout_s=60.0)  # and a correct method passes sealed


def test_sealed_checks_pass_a_class_defined_in_a_script_or_notebook():
    """A class from a notebook cell or a script (a module the sealed process cannot import) reaches the
    sealed checks by value. Before, check_pickle_roundtrip failed it there ("Can't pickle <class
    '__main__.ZScoreMethod'>: attribute lookup failed") although it pickles in the user's own process
    and evaluates fine: the docs' own example, run as a script, did not pass check_method."""
    import inspect
    import textwrap
    import types

    import test_methods_base

    cell = types.ModuleType("__main__")  # a script's or notebook's classes live in __main__ (here: not the real one)
    source = "import numpy as np\nfrom fuelhm_bench.methods import BaseMethod, Decision, normalize_guilt\n" \
             "from fuelhm_bench.taxonomy import INDICATOR_NAMES\nfrom fuelhm_bench.methods.params import " \
             "Interval, RandomState\n" + textwrap.dedent(inspect.getsource(test_methods_base.ZScore))
    exec(compile(source, "<notebook cell>", "exec"), cell.__dict__)
    check_method(cell.ZScore(a=2.0), timeout_s=120.0)


def test_check_data_have_exactly_the_columns_the_benchmark_sends():
    """The checks' tables and the harness's observation rows carry the same columns, in order. Before, the
    check data had n_points / quality_reason (not observed in the benchmark) and lacked the 11 extended
    indicators: a method reading n_points passed the checks and failed in evaluate with KeyError."""
    from fuelhm_bench.benchmark.harness import observation_row
    from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, OBSERVATION_COLUMNS

    data = make_check_data(0)
    for table in (data.healthy, data.other_healthy, data.units):
        assert tuple(table.columns) == OBSERVATION_COLUMNS
    row = observation_row({"indicators": np.zeros(10), "valid": np.ones(10), "extended": np.zeros(11),
                           "extended_valid": np.ones(11)}, unit_id=0, flight_index=0)
    assert tuple(row.index) == OBSERVATION_COLUMNS
    v_in7 = data.units["V_in7"]
    assert 0.2 < v_in7.isna().mean() < 0.8 and (data.units["V_in7_valid"] == v_in7.notna()).all()
    assert data.units[list(EXTENDED_INDICATOR_NAMES)].drop(columns="V_in7").notna().all().all()


def test_a_float32_batch_path_passes_the_consistency_check():
    """The batch path and row-by-row decisions of single-precision arithmetic differ by float32 rounding;
    the check allowed 1e-9 (float64 only) and failed such a method (reported: 1.4387415647506714 vs
    1.438741683959961)."""
    method = Float32Batch()
    fitted = method.fit(make_check_data(0).healthy, random_state=0)
    rows = make_check_data(0).units
    by_row = run_unit(fitted, rows[rows["unit_id"] == "check-1"])["score"].to_numpy()
    batch = fitted.decide_batch(rows[rows["unit_id"] == "check-1"])["score"].to_numpy()
    assert not np.array_equal(by_row, batch)  # the two paths really do round differently here
    check_method(method, sealed=False)
