"""Tests of the method interface: Knowledge, Decision, BaseMethod, harness, trivial methods."""

from __future__ import annotations

import pickle
import re

import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone as sklearn_clone

from fuelhm_bench.errors import DataFormatError, MethodError, ParameterError
from fuelhm_bench.methods import (DECISION_COLUMNS, BaseMethod, Decision, Knowledge, NullMethod,
                                  RandomMethod, clone_method, decision_problem, make_check_data,
                                  normalize_guilt, run_table, run_unit)
from fuelhm_bench.methods.params import Interval, Options, RandomState, validate_params
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS


class ZScore(BaseMethod):
    """Small correct method: windowed RMS Z-score, guilt by collinearity with signatures."""

    _parameter_constraints = {"a": (Interval(float, 0.0, None),),
                              "window": (Interval(int, 1, None),),
                              "jitter": (Interval(float, 0.0, None),),
                              "random_state": (RandomState(),)}

    def __init__(self, *, a=3.0, window=2, jitter=0.0, random_state=None):
        self.a = a
        self.window = window
        self.jitter = jitter
        self.random_state = random_state

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        x = healthy[list(INDICATOR_NAMES)].to_numpy(float)
        self.mu_ = np.nanmean(x, axis=0)
        self.sd_ = np.nanstd(x, axis=0) + 1e-12
        sig = knowledge.signature_matrix() if knowledge is not None else np.eye(7, 10)
        self.signatures_ = np.nan_to_num(sig)
        self.offset_ = float(rng.normal(0.0, self.jitter)) if self.jitter else 0.0

    def _start_unit(self, unit_id):
        self.history_ = []

    def _decide(self, row):
        z = (row[list(INDICATOR_NAMES)].to_numpy(float) - self.mu_) / self.sd_
        z = np.nan_to_num(z)
        self.history_.append(z)
        zbar = np.mean(self.history_[-self.window:], axis=0)
        score = float(np.sqrt(np.mean(zbar**2))) + self.offset_
        if self.jitter:
            score += float(self.unit_rng_.normal(0.0, self.jitter))
        alarm = score > self.a
        if not alarm:
            return Decision.no_alarm(score)
        norms = np.linalg.norm(self.signatures_, axis=1) * (np.linalg.norm(zbar) + 1e-12) + 1e-12
        return Decision(score=score, alarm=True,
                        guilt=normalize_guilt(self.signatures_ @ zbar / norms))


@pytest.fixture(scope="module")
def data():
    return make_check_data(0)


# ------------------------------------------------------------------ Decision
def test_decision_coerces_types_and_freezes_guilt():
    d = Decision(score=np.float32(1.5), alarm=np.bool_(True), guilt=[0, 0, 1, 0, 0, 0, 0])
    assert type(d.score) is float and d.alarm is True
    assert d.guilt.dtype == np.float64 and not d.guilt.flags.writeable
    assert d.predicted_mode == "backlash"
    with pytest.raises(AttributeError):
        d.score = 2.0  # frozen
    assert d == Decision(1.5, True, np.eye(7)[2]) and d != Decision(1.5, True, np.eye(7)[3])


@pytest.mark.parametrize("decision, problem", [
    (Decision(float("nan"), False), "score is nan"),
    (Decision(float("inf"), False), "score is inf"),
    (Decision(1.0, 1), "alarm is 1"),
    (Decision(1.0, True, np.zeros(7)), "guilt sums to 0 with alarm=True"),
    (Decision(1.0, True, np.full(7, 0.5)), "guilt sums to 3.5"),
    (Decision(1.0, False, np.ones(6) / 6), r"guilt has shape \(6,\)"),
    (Decision(1.0, True, [2, -1, 0, 0, 0, 0, 0]), "negative"),
    ((1.0, True), "decide returned tuple"),
])
def test_decision_problem_names_the_fault(decision, problem):
    assert decision_problem(decision) is not None
    assert re.search(problem, decision_problem(decision))


def test_valid_decisions_have_no_problem():
    assert decision_problem(Decision(0.0, False)) is None
    assert decision_problem(Decision(0.0, False, np.ones(7) / 7)) is None
    assert decision_problem(Decision(9.0, True, normalize_guilt([1, 1, 0, 0, 0, 0, 0]))) is None


def test_normalize_guilt_handles_nan_negative_and_zero():
    assert normalize_guilt([np.nan, -1, 2, 2, 0, 0, 0]).tolist() == [0, 0, 0.5, 0.5, 0, 0, 0]
    np.testing.assert_allclose(normalize_guilt(np.zeros(7)), np.full(7, 1 / 7))


# ------------------------------------------------------------------ Knowledge
def test_knowledge_validates_and_copies(data):
    sig = data.knowledge.signatures.copy()
    k = Knowledge(signatures=sig, max_intensity={"backlash": 2})
    sig.iloc[0, 0] = 1e9
    assert k.signatures.iloc[0, 0] != 1e9
    assert k.max_intensity == {"backlash": 2.0}
    assert k.signature_matrix().shape == (len(MODE_IDS), len(INDICATOR_NAMES))
    assert np.isnan(Knowledge().signature_matrix()).all()


@pytest.mark.parametrize("kwargs, match", [
    ({"itl": pd.DataFrame({"mode": ["backlash"]})}, "Missing"),
    ({"itl": pd.DataFrame({"mode": ["rust"], "indicator": ["X1"], "A": [1.0], "r2": [1.0],
                           "residual_std": [0.1], "n": [3]})}, "unknown modes \\['rust'\\]"),
    ({"signatures": pd.DataFrame(np.zeros((1, 3)), index=["backlash"])}, "exactly the columns"),
    ({"max_intensity": {"backlash": 0.0}}, "must be a finite float > 0"),
    ({"max_intensity": {"rust": 1.0}}, "Got 'rust' instead"),
])
def test_knowledge_rejects_bad_tables(kwargs, match):
    with pytest.raises(DataFormatError, match=match):
        Knowledge(**kwargs)


# ------------------------------------------------------------------ params
def test_params_template_message():
    with pytest.raises(ParameterError, match=r"^The 'alarm_probability' parameter of RandomMethod "
                                             r"must be a float in \[0, 1\]. Got 2 instead.$"):
        RandomMethod(alarm_probability=2).fit(make_check_data(0).healthy)
    with pytest.raises(ParameterError, match="must be one of 'a' or None. Got 'b' instead"):
        validate_params("X", {"p": "b"}, {"p": (Options({"a"}), None)})
    validate_params("X", {"p": None}, {"p": (Options({"a"}), None)})
    assert not Interval(int, 0, None).is_satisfied_by(True)
    assert not Interval(float, 0, 1, closed="neither").is_satisfied_by(1.0)
    assert not RandomState().is_satisfied_by(-1)


def test_get_set_params_and_clone():
    m = ZScore(a=2.0, window=3)
    assert m.get_params() == {"a": 2.0, "jitter": 0.0, "random_state": None, "window": 3}
    assert m.set_params(window=5) is m and m.window == 5
    with pytest.raises(ParameterError, match="The 'windw' parameter of ZScore must be one of"):
        m.set_params(windw=1)
    assert repr(m) == "ZScore(a=2.0, jitter=0.0, random_state=None, window=5)"
    for twin in (clone_method(m), sklearn_clone(m)):
        assert type(twin) is ZScore and twin.get_params() == m.get_params()
        assert not hasattr(twin, "mu_")


# ------------------------------------------------------------------ harness
def test_decide_requires_fit_and_start_unit(data):
    m = ZScore()
    with pytest.raises(MethodError, match="ZScore is not fitted: call fit before start_unit"):
        m.start_unit("u")
    m.fit(data.healthy, knowledge=data.knowledge, random_state=0)
    with pytest.raises(MethodError, match="decide was called before start_unit"):
        m.decide(data.units.iloc[0])


def test_decide_rejects_out_of_order_and_foreign_rows(data):
    m = ZScore().fit(data.healthy, random_state=0)
    unit = data.units[data.units["unit_id"] == "check-1"]
    m.start_unit("check-1")
    m.decide(unit.iloc[3])
    with pytest.raises(DataFormatError, match="increasing flight_index order. Got flight 2 after "
                                              "flight 3 instead"):
        m.decide(unit.iloc[2])
    with pytest.raises(DataFormatError, match="must belong to unit 'check-1'. Got unit 'check-0'"):
        m.decide(data.units.iloc[0])


def test_fit_rejects_bad_inputs(data):
    with pytest.raises(DataFormatError, match=r"Missing \['X1'\]"):
        ZScore().fit(data.healthy.drop(columns="X1"))
    with pytest.raises(DataFormatError, match="must be a pandas DataFrame. Got ndarray"):
        ZScore().fit(np.zeros((3, 10)))
    with pytest.raises(ParameterError, match="'knowledge' parameter of ZScore.fit must be a "
                                             "Knowledge or None. Got dict"):
        ZScore().fit(data.healthy, knowledge={})
    with pytest.raises(ParameterError, match="'random_state' parameter of ZScore.fit"):
        ZScore().fit(data.healthy, random_state=-3)
    with pytest.raises(ParameterError, match="'window' parameter of ZScore must be an int in "
                                             r"\[1, inf\). Got 0 instead"):
        ZScore(window=0).fit(data.healthy)


def test_run_unit_output_and_order(data):
    m = ZScore(a=2.0).fit(data.healthy, knowledge=data.knowledge, random_state=0)
    unit = data.units[data.units["unit_id"] == "check-1"]
    out = m.decide_unit(unit.iloc[::-1])
    assert list(out.columns) == list(DECISION_COLUMNS)
    assert out["flight_index"].tolist() == sorted(unit["flight_index"])
    assert out["alarm"].dtype == bool and out["score"].dtype == np.float64
    assert out["alarm"].iloc[-1] and not out["alarm"].iloc[0]  # degraded at end of life
    alarmed = out[out["alarm"]]
    np.testing.assert_allclose(alarmed.filter(like="guilt_").sum(axis=1), 1.0)
    # the degrading mode of unit check-1 is MODE_IDS[1]
    assert alarmed.filter(like="guilt_").iloc[-1].idxmax() == f"guilt_{MODE_IDS[1]}"


def test_run_table_and_errors(data):
    m = NullMethod().fit(data.healthy)
    out = run_table(m, data.units)
    assert len(out) == len(data.units) and not out["alarm"].any()
    assert out["unit_id"].unique().tolist() == ["check-0", "check-1", "check-2"]
    with pytest.raises(DataFormatError, match="must hold a single unit. Got 3 units"):
        run_unit(m, data.units)
    dup = pd.concat([data.units.iloc[:2], data.units.iloc[:1]])
    with pytest.raises(DataFormatError, match="unique flight_index values. Got flight 0 twice"):
        run_unit(m, dup)


def test_per_unit_rng_depends_on_seed_and_unit_only(data):
    a = RandomMethod(alarm_probability=0.5).fit(data.healthy, random_state=7)
    b = RandomMethod(alarm_probability=0.5, random_state=7).fit(data.healthy)
    units = dict(data.unit_tables())
    first = run_unit(a, units["check-2"])
    run_unit(b, units["check-0"])
    pd.testing.assert_frame_equal(first, run_unit(b, units["check-2"]))
    c = RandomMethod(alarm_probability=0.5).fit(data.healthy, random_state=8)
    assert not run_unit(c, units["check-2"])["score"].equals(first["score"])


def test_integer_unit_ids_keep_their_dtype(data):
    units = data.units.assign(unit_id=data.units["unit_id"].str[-1].astype(np.int64))
    out = run_table(ZScore().fit(data.healthy, random_state=0), units)
    assert out["unit_id"].dtype == np.int64 and out["unit_id"].unique().tolist() == [0, 1, 2]


def test_random_method_extremes_and_generator_seed(data):
    never = run_table(RandomMethod(alarm_probability=0.0).fit(data.healthy, random_state=0),
                      data.units)
    always = run_table(RandomMethod(alarm_probability=1.0).fit(data.healthy, random_state=0),
                       data.units)
    assert not never["alarm"].any() and always["alarm"].all()
    gen = RandomMethod().fit(data.healthy, random_state=np.random.default_rng(3))
    assert isinstance(gen.seed_entropy_, int)


def test_fitted_method_pickles(data):
    m = ZScore(jitter=0.1).fit(data.healthy, knowledge=data.knowledge, random_state=0)
    restored = pickle.loads(pickle.dumps(m))
    pd.testing.assert_frame_equal(run_table(m, data.units), run_table(restored, data.units))


def test_harness_validates_duck_typed_outputs(data):
    class Duck:
        def start_unit(self, unit_id):
            return None

        def decide(self, row):
            return Decision(float("nan"), False)

    with pytest.raises(MethodError, match="Duck returned an invalid decision for unit 'check-0', "
                                          "flight 0: score is nan"):
        run_unit(Duck(), data.units[data.units["unit_id"] == "check-0"])
