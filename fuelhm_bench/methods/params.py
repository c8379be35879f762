"""Declared hyperparameter constraints, checked in ``fit`` (scikit-learn style).

A method class declares ``_parameter_constraints``, a dict mapping each
constructor parameter to a tuple of allowed :class:`Constraint` objects (``None``
in the tuple allows ``None``). :meth:`BaseMethod.fit` calls
:func:`validate_params`, which raises :class:`~fuelhm_bench.errors.ParameterError`
with the project's template
"The 'x' parameter of Y must be Z. Got W instead."

Examples
--------
>>> from fuelhm_bench.methods.params import Interval, Options, RandomState
>>> constraints = {"a": (Interval(float, 0, None, closed="left"),),
...                "metric": (Options({"mahalanobis", "euclidean"}),),
...                "random_state": (RandomState(),)}
"""

from __future__ import annotations

import abc
import math
import numbers
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from fuelhm_bench.errors import ParameterError

__all__ = ["Constraint", "InstanceOf", "Interval", "Options", "RandomState", "validate_params"]


class Constraint(abc.ABC):
    """Base class of a declared constraint: a predicate plus a description."""

    @abc.abstractmethod
    def is_satisfied_by(self, value: Any) -> bool:
        """Return True when ``value`` satisfies the constraint."""

    @abc.abstractmethod
    def describe(self) -> str:
        """Return a human-readable description, e.g. ``"a float in [0, inf)"``."""


@dataclass(frozen=True)
class Interval(Constraint):
    """A real or integer number inside an interval.

    Parameters
    ----------
    kind : {float, int}
        ``int`` accepts integral numbers only (not bool); ``float`` accepts any
        real number (not bool).
    left, right : float or None
        Bounds; ``None`` means unbounded.
    closed : {"both", "left", "right", "neither"}, default="both"
        Which bounds are included.
    """

    kind: type
    left: float | None
    right: float | None
    closed: str = "both"

    def is_satisfied_by(self, value: Any) -> bool:
        if isinstance(value, (bool, np.bool_)):
            return False
        if self.kind is int:
            if not isinstance(value, numbers.Integral):
                return False
        elif not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
            return False
        v = float(value)
        if self.left is not None:
            if self.closed in ("both", "left") and v < self.left:
                return False
            if self.closed in ("right", "neither") and v <= self.left:
                return False
        if self.right is not None:
            if self.closed in ("both", "right") and v > self.right:
                return False
            if self.closed in ("left", "neither") and v >= self.right:
                return False
        return True

    def describe(self) -> str:
        lb = "[" if self.closed in ("both", "left") and self.left is not None else "("
        rb = "]" if self.closed in ("both", "right") and self.right is not None else ")"
        left = "-inf" if self.left is None else f"{self.left:g}"
        right = "inf" if self.right is None else f"{self.right:g}"
        name = "an int" if self.kind is int else "a float"
        return f"{name} in {lb}{left}, {right}{rb}"


@dataclass(frozen=True)
class Options(Constraint):
    """One value out of a finite set."""

    values: frozenset

    def __init__(self, values: Any) -> None:
        object.__setattr__(self, "values", frozenset(values))

    def is_satisfied_by(self, value: Any) -> bool:
        try:
            return value in self.values
        except TypeError:  # unhashable value
            return False

    def describe(self) -> str:
        return "one of " + ", ".join(repr(v) for v in sorted(self.values, key=repr))


@dataclass(frozen=True)
class InstanceOf(Constraint):
    """An instance of the given type(s)."""

    types: tuple

    def __init__(self, *types: type) -> None:
        object.__setattr__(self, "types", tuple(types))

    def is_satisfied_by(self, value: Any) -> bool:
        return isinstance(value, self.types)

    def describe(self) -> str:
        return "an instance of " + " or ".join(t.__name__ for t in self.types)


@dataclass(frozen=True)
class RandomState(Constraint):
    """A seed: a non-negative int, a :class:`numpy.random.Generator` or None."""

    def is_satisfied_by(self, value: Any) -> bool:
        if value is None or isinstance(value, np.random.Generator):
            return True
        return (isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
                and int(value) >= 0)

    def describe(self) -> str:
        return "a non-negative int, a numpy.random.Generator or None"


def _describe(options: tuple) -> str:
    parts = ["None" if c is None else c.describe() for c in options]
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " or " + parts[-1]


def validate_params(owner: str, params: Mapping[str, Any],
                    constraints: Mapping[str, tuple]) -> None:
    """Check ``params`` against declared ``constraints``.

    Parameters
    ----------
    owner : str
        Class name used in the message.
    params : mapping of str to object
        Parameter values (``get_params(deep=False)``).
    constraints : mapping of str to tuple
        Allowed constraints per parameter; ``None`` inside a tuple allows None.
        Parameters without an entry are not checked.

    Raises
    ------
    ParameterError
        "The 'x' parameter of Owner must be Z. Got W instead."
    """
    for name, options in constraints.items():
        if name not in params:
            continue
        value = params[name]
        ok = any((value is None) if c is None else c.is_satisfied_by(value) for c in options)
        if not ok:
            raise ParameterError(f"The '{name}' parameter of {owner} must be "
                                 f"{_describe(tuple(options))}. Got {value!r} instead.")
