"""Shrinking a fleet for quick looks without losing a degradation mode (``--scale``)."""

from __future__ import annotations

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.flights.fleet import FleetConfig, build_units

__all__ = ["modes_by_unit", "scaled_unit_count"]


def modes_by_unit(config: FleetConfig) -> list[frozenset[str]]:
    """Modes that start within the life of each unit (onset before its last flight).

    Parameters
    ----------
    config : FleetConfig

    Returns
    -------
    list of frozenset of str
        One set per unit, in unit order (draws only the schedules; simulates nothing).
    """
    return [frozenset(s.mode for s, o in zip(u.schedule.schedules, u.schedule.onsets)
                      if o < config.n_flights)
            for u in build_units(config)]


def scaled_unit_count(config: FleetConfig, scale: float, *, minimum: int = 1) -> int:
    """Number of leading units to keep at ``scale`` so that every mode of the fleet stays.

    The scaled fleet is the first ``n`` units (their schedules and flights do
    not change), with ``n = max(minimum, round(scale * n_units))`` extended, when
    needed, until every mode that occurs somewhere in the full fleet occurs in
    one of the kept units.

    Parameters
    ----------
    config : FleetConfig
        The full fleet.
    scale : float
        Fraction of the units (> 0); 1 or more keeps them all.
    minimum : int, default=1
        Fewest units kept.

    Returns
    -------
    int
        Between ``minimum`` (capped at ``n_units``) and ``config.n_units``.

    Raises
    ------
    ParameterError
        When ``scale`` is not a finite number > 0.
    """
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not scale > 0 \
            or scale == float("inf"):
        raise ParameterError(f"The 'scale' parameter of scaled_unit_count must be a finite number "
                             f"> 0. Got {scale!r} instead.")
    total = config.n_units
    n = min(total, max(minimum, int(round(total * scale))))
    if n >= total:
        return total
    modes = modes_by_unit(config)
    wanted = frozenset().union(*modes)
    seen = frozenset().union(*modes[:n])
    while not wanted <= seen:
        seen |= modes[n]
        n += 1
    return n
