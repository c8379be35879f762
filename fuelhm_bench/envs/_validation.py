"""Argument checks of the environments: misspelt keyword arguments and options, with did-you-mean."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from fuelhm_bench.errors import ParameterError, did_you_mean

__all__ = ["did_you_mean", "reject_unknown"]




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
