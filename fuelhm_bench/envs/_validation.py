"""Argument checks of the environments: misspelt keyword arguments and options, with did-you-mean."""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping

from fuelhm_bench.errors import ParameterError

__all__ = ["did_you_mean", "reject_unknown"]


def did_you_mean(name: object, options: Iterable[str]) -> str:
    """``" Did you mean 'x'?"`` for the closest option (difflib, then prefix), or ``""``."""
    if not isinstance(name, str) or not name:
        return ""
    options = list(options)
    close = difflib.get_close_matches(name, options, n=1, cutoff=0.6)
    if not close:
        close = [o for o in options if o.lower().startswith(name.lower())][:1]
    return f" Did you mean '{close[0]}'?" if close else ""


def reject_unknown(given: Mapping[str, object], allowed: Iterable[str], *, what: str, owner: str) -> None:
    """Raise :class:`ParameterError` for the first key of ``given`` not in ``allowed``.

    Parameters
    ----------
    given : mapping
        The keyword arguments or options received.
    allowed : iterable of str
        The accepted names.
    what : str
        ``"argument"`` or ``"option"`` (used in the message).
    owner : str
        E.g. ``"ActuationLoopEnv"`` or ``"ActuationLoopEnv.reset"``.
    """
    allowed = list(allowed)
    for key in given:
        if key not in allowed:
            raise ParameterError(f"{owner} has no {what} {key!r}. Its {what}s: {', '.join(allowed)}."
                                 f"{did_you_mean(key, allowed)}")
