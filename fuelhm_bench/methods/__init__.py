"""The method interface: what a detection/diagnosis method is, and how it is checked.

Public API
----------
Knowledge
    Published knowledge (ITL, signatures, maximal intensities).
Decision
    A method's output for one flight (score, alarm, guilt).
BaseMethod
    Base class: ``fit`` on healthy flights, then ``start_unit`` / ``decide``.
run_unit, run_table, has_batch_path, method_needs_raw
    The causal harness (``start_unit`` and ``decide``, or ``decide_batch`` in causal waves);
    methods that declare ``needs_raw`` get the full-rate flights (:mod:`fuelhm_bench.methods.raw`).
clone_method
    Unfitted copy with the same hyperparameters.
check_method, iter_checks, parametrize_with_checks, make_check_data
    Conformance checks (determinism, no look-ahead, refit, clone/pickle, ...).
NullMethod, RandomMethod
    Trivial reference methods.

See docs/methods.md.
"""

from fuelhm_bench.methods.base import (BaseMethod, clone_method, has_batch_path, method_needs_raw,
                                       run_table, run_unit)
from fuelhm_bench.methods.checks import (CheckData, MethodCheck, check_method, iter_checks,
                                         make_check_data, parametrize_with_checks)
from fuelhm_bench.methods.decision import Decision, decision_problem, normalize_guilt
from fuelhm_bench.methods.knowledge import ITL_COLUMNS, Knowledge
from fuelhm_bench.methods.tables import DECISION_COLUMNS, GUILT_COLUMNS
from fuelhm_bench.methods.trivial import NullMethod, RandomMethod

__all__ = [
    "BaseMethod", "CheckData", "DECISION_COLUMNS", "Decision", "GUILT_COLUMNS", "ITL_COLUMNS",
    "Knowledge", "MethodCheck", "NullMethod", "RandomMethod", "check_method", "clone_method",
    "decision_problem", "has_batch_path", "iter_checks", "make_check_data", "method_needs_raw",
    "normalize_guilt", "parametrize_with_checks", "run_table", "run_unit",
]
