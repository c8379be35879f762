"""The output of a method for one flight."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fuelhm_bench.errors import MethodError
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["GUILT_SUM_TOLERANCE", "Decision", "decision_problem", "normalize_guilt"]

#: Allowed absolute deviation of ``guilt.sum()`` from 1 when an alarm is raised.
GUILT_SUM_TOLERANCE: float = 1e-6


@dataclass(frozen=True, eq=False)
class Decision:
    """A method's decision for one flight.

    The constructor only coerces types (so that a faulty method can still build
    one and be reported by the harness with a precise message); the values are
    checked by :meth:`BaseMethod.decide` and by the conformance checks, see
    :func:`decision_problem`.

    Parameters
    ----------
    score : float
        Global abnormality score (dimensionless, higher = more abnormal; the
        paper's ``Global_Z_score``). Must be finite. The scorer thresholds it as
        ``score > mu + A * sigma`` of the healthy-training scores.
    alarm : bool
        True when the method declares the flight faulty at its own operating
        point.
    guilt : array-like of shape (7,), default=zeros
        Probability of guilt of every mode, in :data:`~fuelhm_bench.taxonomy.MODE_IDS`
        order. Non-negative; sums to 1 when ``alarm`` is True; either all zeros or
        summing to 1 otherwise. Stored as a read-only float64 array.

    Examples
    --------
    >>> from fuelhm_bench.methods import Decision
    >>> Decision(score=0.3, alarm=False)
    Decision(score=0.3, alarm=False, guilt=[0. 0. 0. 0. 0. 0. 0.])
    >>> d = Decision(score=5.0, alarm=True, guilt=[0, 1, 0, 0, 0, 0, 0])
    >>> d.predicted_mode
    'null_bias_drift'
    """

    score: float
    alarm: bool
    guilt: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        try:
            score = float(self.score)
        except (TypeError, ValueError):
            score = math.nan
        object.__setattr__(self, "score", score)
        if isinstance(self.alarm, (bool, np.bool_)):
            object.__setattr__(self, "alarm", bool(self.alarm))
        guilt = np.zeros(len(MODE_IDS)) if self.guilt is None else self.guilt
        try:
            arr = np.array(guilt, dtype=np.float64, copy=True)
        except (TypeError, ValueError):
            arr = np.full(len(MODE_IDS), np.nan)
        arr.setflags(write=False)
        object.__setattr__(self, "guilt", arr)

    @classmethod
    def no_alarm(cls, score: float) -> "Decision":
        """A decision without alarm and with zero guilt."""
        return cls(score=score, alarm=False)

    @property
    def predicted_mode(self) -> str | None:
        """Mode with the unique largest guilt, or None (no guilt, or a tie)."""
        g = self.guilt
        if g.shape != (len(MODE_IDS),) or not np.all(np.isfinite(g)) or g.max() <= 0:
            return None
        top = np.flatnonzero(g == g.max())
        return MODE_IDS[int(top[0])] if top.size == 1 else None

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Decision):
            return NotImplemented
        same_score = self.score == other.score or (math.isnan(self.score)
                                                   and math.isnan(other.score))
        return (same_score and self.alarm is other.alarm
                and np.array_equal(self.guilt, other.guilt, equal_nan=True))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"Decision(score={self.score!r}, alarm={self.alarm!r}, guilt={self.guilt})"


def decision_problem(decision: Any) -> str | None:
    """Describe what is wrong with a decision, or return None when it is valid.

    Parameters
    ----------
    decision : object
        What a method returned for one flight.

    Returns
    -------
    str or None
        A short description such as ``"score is nan, not a finite float"``.
    """
    if not isinstance(decision, Decision):
        return f"decide returned {type(decision).__name__}, not a Decision"
    if not math.isfinite(decision.score):
        return f"score is {decision.score!r}, not a finite float"
    if not isinstance(decision.alarm, bool):
        return f"alarm is {decision.alarm!r} ({type(decision.alarm).__name__}), not a bool"
    g = decision.guilt
    if g.shape != (len(MODE_IDS),):
        return f"guilt has shape {g.shape}, not ({len(MODE_IDS)},)"
    if not np.all(np.isfinite(g)):
        return f"guilt {g} is not finite"
    if np.any(g < 0):
        return f"guilt {g} has negative entries"
    total = float(g.sum())
    if decision.alarm and abs(total - 1.0) > GUILT_SUM_TOLERANCE:
        return f"guilt sums to {total:.6g} with alarm=True, not 1"
    if not decision.alarm and total != 0.0 and abs(total - 1.0) > GUILT_SUM_TOLERANCE:
        return f"guilt sums to {total:.6g} with alarm=False, not 0 or 1"
    return None


def normalize_guilt(weights: Any) -> np.ndarray:
    """Turn non-negative weights into a guilt distribution summing to 1.

    Parameters
    ----------
    weights : array-like of shape (7,)
        Non-negative weights (NaN and negative values count as 0).

    Returns
    -------
    numpy.ndarray of shape (7,)
        ``weights / weights.sum()``, or the uniform distribution when all
        weights are 0.

    Examples
    --------
    >>> normalize_guilt([0, 3, 1, 0, 0, 0, 0]).tolist()
    [0.0, 0.75, 0.25, 0.0, 0.0, 0.0, 0.0]
    """
    w = np.asarray(weights, dtype=np.float64).reshape(len(MODE_IDS))
    w = np.where(np.isfinite(w) & (w > 0), w, 0.0)
    total = w.sum()
    if total <= 0:
        return np.full(len(MODE_IDS), 1.0 / len(MODE_IDS))
    return w / total


def _raise_if_invalid(decision: Any, method_name: str, where: str) -> Decision:
    problem = decision_problem(decision)
    if problem is not None:
        raise MethodError(f"{method_name} returned an invalid decision {where}: {problem}.")
    return decision
