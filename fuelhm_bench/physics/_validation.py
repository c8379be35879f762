"""Shared validation helpers for the frozen parameter dataclasses."""

from __future__ import annotations

import dataclasses
import math

from fuelhm_bench.errors import range_error


def check_fields(obj: object, rules: dict[str, tuple[float | None, float | None, bool]]) -> None:
    """Validate numeric fields of a dataclass instance against ranges.

    Parameters
    ----------
    obj : dataclass instance
        The parameter set to validate.
    rules : dict
        ``field -> (low, high, low_inclusive)``; ``None`` means unbounded. The
        upper bound is always inclusive.

    Raises
    ------
    ParameterError
        Naming ``Class.field``, the allowed range and the value given.
    """
    cls = type(obj).__name__
    for name, (low, high, low_inclusive) in rules.items():
        value = getattr(obj, name)
        label = f"{cls}.{name}"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise range_error(label, "a real number", value)
        if not math.isfinite(value):
            raise range_error(label, "finite", value)
        if low is not None:
            bad = value < low if low_inclusive else value <= low
            if bad:
                op = ">=" if low_inclusive else ">"
                allowed = f"{op} {low:g}" if high is None else f"in {'[' if low_inclusive else '('}{low:g}, {high:g}]"
                raise range_error(label, allowed, value)
        if high is not None and value > high:
            allowed = f"<= {high:g}" if low is None else f"in {'[' if low_inclusive else '('}{low:g}, {high:g}]"
            raise range_error(label, allowed, value)


POSITIVE = (0.0, None, False)
NON_NEGATIVE = (0.0, None, True)
UNIT_INTERVAL = (0.0, 1.0, True)


def field_names(cls: type) -> tuple[str, ...]:
    """Names of the dataclass fields of ``cls``."""
    return tuple(f.name for f in dataclasses.fields(cls))
