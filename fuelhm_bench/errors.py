"""One error hierarchy for the whole package.

Every error a user can trigger with bad input derives from :class:`FuelHMError`,
so callers (the CLI, the leaderboard runner) can catch one class and print a
clean message instead of a traceback. Messages follow one template, in the
style of scikit-learn: *what* (file / field / parameter), *allowed*, *given*.
"""

from __future__ import annotations


class FuelHMError(Exception):
    """Base class of every error raised on purpose by fuelhm-bench."""


class ParameterError(FuelHMError, ValueError):
    """A physical or numerical parameter is outside its allowed range."""


class UnknownNameError(FuelHMError, KeyError):
    """An unknown degradation mode, effect id, indicator or scenario name."""

    def __str__(self) -> str:  # KeyError would quote the message otherwise
        return str(self.args[0]) if self.args else ""


class DataFormatError(FuelHMError, ValueError):
    """A flight file or table does not follow the flight format of docs/data-format.md."""


class ScenarioError(FuelHMError, ValueError):
    """A scenario YAML file is malformed or fails validation."""


class ModelFileError(FuelHMError, ValueError):
    """A model (parameter set) file cannot be loaded."""


class NumericalError(FuelHMError, ArithmeticError):
    """The simulator produced a non-finite value; names the unit and flight."""


class MethodError(FuelHMError, RuntimeError):
    """A plugged-in detection/diagnosis method misbehaved."""


class OutputPathError(FuelHMError, OSError):
    """An output path cannot be written (or would overwrite without --force)."""


def range_error(name: str, allowed: str, given: object) -> ParameterError:
    """Build a :class:`ParameterError` with the project's message template.

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
    return ParameterError(f"The '{name}' parameter must be {allowed}. Got {given!r} instead.")
