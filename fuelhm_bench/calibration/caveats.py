"""Caveats of a discrepancy verdict: properties of the data that weaken its evidence.

The verdict's thresholds were calibrated on data of a plausible but different model (the second
simulator, ``docs/discrepancy.md`` section 10) at the sizes of the study: several units, flights of
10-20 min, three or more held-out flights. Some data fall outside what that calibration covers, and
on some of them false discoveries were measured. The workflow still answers; these caveats say, with
the measurement behind each, why the answer deserves less trust, and what data would remove the
doubt. They never change the verdict.

=====================  =============================================  ========================================
code                   condition                                      what was measured / why it matters
=====================  =============================================  ========================================
``short_flights``      median flight shorter than 5 min               healthy second-simulator data with 3-min
                                                                      flights: a load stiffness named or kept
                                                                      in 7 of 10 data sets (6.5-7.7 kN/m); with
                                                                      4-6 min flights in none of 12
``few_heldout``        fewer than 3 held-out flights                  the leave-one-flight-out check of the
                                                                      sample-wise held-out reduction
                                                                      (``heldout_gain_robust``) cannot run
``one_unit``           a single unit                                  a mismatch of that unit cannot be told
                                                                      from a missing effect of the fleet, and
                                                                      every value beyond 5 sigma counts as
                                                                      absorbing (``flags.fleet_wide``)
=====================  =============================================  ========================================
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Shortest median flight [s] the verdict's thresholds were checked on without a false discovery.
SHORT_FLIGHT_S = 300.0
#: Held-out flights the leave-one-flight-out check needs (``heldout_gain_robust``).
MIN_HELDOUT_FLIGHTS = 3


@dataclass(frozen=True)
class Caveat:
    """One property of the data that weakens the verdict's evidence.

    Attributes
    ----------
    code : str
        ``"short_flights"``, ``"few_heldout"`` or ``"one_unit"``.
    message : str
        What was found, why it matters (with the measurement) and what data would remove it.
    """

    code: str
    message: str

    def as_json(self) -> dict:
        """``{"code": ..., "message": ...}``."""
        return {"code": self.code, "message": self.message}


def data_caveats(flight_durations_s: Sequence[float], n_units: int, n_heldout_flights: int) -> tuple[Caveat, ...]:
    """The caveats that apply to a data set.

    Parameters
    ----------
    flight_durations_s : sequence of float
        Duration of every flight in the input (last minus first time stamp, plus one sample period) [s].
    n_units : int
        Number of units in the input.
    n_heldout_flights : int
        Held-out flights of the split (a single-flight unit's held-out blocks count as one flight).

    Returns
    -------
    tuple of Caveat
        In the order of the table above; empty when none applies.
    """
    out = []
    durations = np.asarray(list(flight_durations_s), dtype=float)
    if durations.size:
        median_s = float(np.median(durations))
        if median_s < SHORT_FLIGHT_S:
            out.append(Caveat("short_flights", (
                f"short flights (median {median_s / 60:.1f} min, under {SHORT_FLIGHT_S / 60:g} min) cover few "
                "operating conditions, so a model's structural mismatch in one of them can look like an effect "
                "(healthy data of the second simulator, whose 60-s engine start with its test sweep is a third of a "
                "3-min flight: a load stiffness of 6.5-7.7 kN/m named or kept in 7 of 10 data sets with 3-min "
                "flights, none of 12 with 4-6 min flights). Longer flights remove this doubt.")))
    if n_heldout_flights < MIN_HELDOUT_FLIGHTS:
        out.append(Caveat("few_heldout", (
            f"{n_heldout_flights} held-out flight(s): the check that no single held-out flight carries the "
            f"sample-wise held-out reduction needs {MIN_HELDOUT_FLIGHTS} or more, so the decision rests on "
            "fewer independent confirmations. More flights (or more units) remove this doubt.")))
    if n_units == 1:
        out.append(Caveat("one_unit", (
            "a single unit: a mismatch of this unit alone cannot be told from an effect missing from the whole "
            "fleet, and any recalibrated value beyond 5 sigma counts as absorbing a missing effect. Flights of "
            "a second unit remove this doubt.")))
    return tuple(out)


__all__ = ["Caveat", "MIN_HELDOUT_FLIGHTS", "SHORT_FLIGHT_S", "data_caveats"]
