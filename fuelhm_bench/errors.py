"""One error hierarchy and one error vocabulary for the whole package.

Every error a user can trigger with bad input derives from :class:`FuelHMError`,
so callers (the CLI, the leaderboard runner) can catch one class and print a
clean message instead of a traceback. Messages follow one template, in the
style of scikit-learn: *what* (file / field / parameter), *allowed*, *given*::

    The 'x' parameter of Y must be Z. Got W instead.

The vocabulary lives here and nowhere else:

* :func:`parameter_error` -- the template above, as a :class:`ParameterError`
  (:func:`range_error` is its owner-less form);
* :func:`did_you_mean` -- the one "Did you mean 'x'?" suggestion;
* :func:`show_value` -- a bounded rendering of an offending value (never the
  ``repr`` of a huge object: the value is abbreviated *before* formatting).
"""

from __future__ import annotations

import difflib
import reprlib
from collections.abc import Iterable, Sequence

__all__ = [
    "DataFormatError", "FuelHMError", "MethodError", "ModelFileError", "NotFittedError", "NumericalError",
    "OutputPathError", "ParameterError", "ScenarioError", "ScenarioValidationError", "UnknownNameError",
    "did_you_mean", "parameter_error", "range_error", "show_value",
]


class FuelHMError(Exception):
    """Base class of every error raised on purpose by fuelhm-bench."""


class ParameterError(FuelHMError, ValueError):
    """A physical or numerical parameter is outside its allowed range."""


class UnknownNameError(FuelHMError, KeyError):
    """An unknown degradation mode, effect id, indicator or scenario name."""

    def __str__(self) -> str:  # KeyError would quote the message otherwise
        return str(self.args[0]) if self.args else ""


class DataFormatError(FuelHMError, ValueError):
    """A flight file or table does not follow the format of docs/data-format.md."""


class ScenarioError(FuelHMError, ValueError):
    """A scenario YAML file is malformed or fails validation."""


class ScenarioValidationError(ScenarioError):
    """A scenario (or one of its sections) failed validation, with every problem found.

    Parameters
    ----------
    problems : sequence
        Problem records, each with a ``message(owner)`` method (see
        :class:`fuelhm_bench.scenarios.Problem`), in document order where known.
    owner : str, default=""
        Class that raised it (used to name fields of objects built in Python).

    Attributes
    ----------
    problems : tuple
        The problems.
    owner : str
        As given.
    """

    def __init__(self, problems: Sequence, owner: str = "") -> None:
        self.problems = tuple(problems)
        self.owner = owner
        super().__init__("\n".join(p.message(owner) for p in self.problems))

    def __reduce__(self):
        return (type(self), (self.problems, self.owner))


class ModelFileError(FuelHMError, ValueError):
    """A model (parameter set) file cannot be loaded."""


class NumericalError(FuelHMError, ArithmeticError):
    """The simulator produced a non-finite value; names the unit and flight."""


class MethodError(FuelHMError, RuntimeError):
    """A plugged-in detection/diagnosis method misbehaved."""


class NotFittedError(FuelHMError, ValueError, AttributeError):
    """An estimator was used before ``fit``.

    Has the bases of scikit-learn's ``NotFittedError`` (``ValueError`` and
    ``AttributeError``), so code written for scikit-learn estimators catches it.
    """


class OutputPathError(FuelHMError, OSError):
    """An output path cannot be written (or would overwrite without --force)."""


# ----------------------------------------------------------------------------- vocabulary
_REPR = reprlib.Repr()
_REPR.maxlevel = 3
_REPR.maxstring = 60
_REPR.maxother = 60
for _attr in ("maxlist", "maxtuple", "maxdict", "maxset", "maxfrozenset", "maxdeque", "maxarray"):
    setattr(_REPR, _attr, 6)


def show_value(value: object, limit: int = 80) -> str:
    """Render an offending value for a message, bounded in time and length.

    Parameters
    ----------
    value : object
        Any value; containers are abbreviated (:mod:`reprlib`: at most a few
        items per level and three levels) *before* formatting, so a huge or
        deeply shared structure costs nothing to show.
    limit : int, default=80
        Maximum length of the result, in characters.

    Returns
    -------
    str

    Examples
    --------
    >>> show_value(1.5)
    '1.5'
    >>> show_value(list(range(10**6)))
    '[0, 1, 2, 3, 4, 5, ...]'
    """
    if hasattr(value, "item") and getattr(value, "ndim", None) == 0:
        value = value.item()  # numpy scalar: 1.5, not np.float64(1.5)
    try:
        text = _REPR.repr(value)
    except Exception:  # a broken __repr__ must not hide the real error
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def did_you_mean(name: object, options: Iterable[str], *, sep: str = " ") -> str:
    """The project's one "did you mean" suggestion.

    Parameters
    ----------
    name : object
        What the user gave; non-strings get no suggestion.
    options : iterable of str
        The accepted names.
    sep : str, default=" "
        Put before the sentence when there is one (to append it to a message).

    Returns
    -------
    str
        ``sep + "Did you mean 'x'?"`` for the closest option (difflib, then an
        abbreviation: ``'expo'`` -> ``'exponential'``), or ``""``.

    Examples
    --------
    >>> did_you_mean("expo", ["step", "linear", "exponential"])
    " Did you mean 'exponential'?"
    >>> did_you_mean("zzz", ["step"])
    ''
    """
    if not isinstance(name, str) or not name:
        return ""
    options = [str(o) for o in options]
    close = difflib.get_close_matches(name, options, n=1, cutoff=0.6)
    if not close:
        close = [o for o in options if o.lower().startswith(name.lower())][:1]
    return f"{sep}Did you mean '{close[0]}'?" if close else ""


def parameter_error(name: str, owner: str | None, allowed: str, given: object) -> ParameterError:
    """Build a :class:`ParameterError` with the project's message template.

    Parameters
    ----------
    name : str
        Parameter name, e.g. ``"shrinkage"`` or ``"ServovalveParams.rated_current_a"``.
    owner : str or None
        Class or function owning the parameter, e.g. ``"HealthyModel"``; None
        when ``name`` says it all.
    allowed : str
        What the parameter must be, e.g. ``"> 0"`` or ``"a float in [0, 1]"``.
    given : object
        The offending value (rendered with :func:`show_value`).

    Returns
    -------
    ParameterError

    Examples
    --------
    >>> str(parameter_error("alpha", "HealthyModel", "in [0, 1]", 2.0))
    "The 'alpha' parameter of HealthyModel must be in [0, 1]. Got 2.0 instead."
    """
    of = f" of {owner}" if owner else ""
    return ParameterError(f"The '{name}' parameter{of} must be {allowed}. Got {show_value(given)} instead.")


def range_error(name: str, allowed: str, given: object) -> ParameterError:
    """:func:`parameter_error` without an owner (the name is ``Class.field``).

    Parameters
    ----------
    name : str
        Parameter name, e.g. ``"ServovalveParams.rated_current_a"``.
    allowed : str
        Human-readable allowed range, e.g. ``"> 0"`` or ``"in [0, 1]"``.
    given : object
        The offending value.

    Returns
    -------
    ParameterError
    """
    return parameter_error(name, None, allowed, given)
