"""Current driver: turns the commanded current into the torque-motor coil current.

``i_coil = gain * i_cmd + offset_a``. The recorded current is the *commanded*
one (what the FADEC logs), so driver gain and offset errors are invisible in the
data except through the curve they produce. Units differ by manufacturing
dispersion of both terms.
"""

from __future__ import annotations

from dataclasses import dataclass

from fuelhm_bench.physics._validation import check_fields


@dataclass(frozen=True)
class CurrentDriverParams:
    """Current driver parameters.

    Parameters
    ----------
    gain : float, default=1.0
        Coil current per commanded current [-].
    offset_a : float, default=0.0
        Coil current offset [A].
    """

    gain: float = 1.0
    offset_a: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, {"gain": (0.5, 2.0, True), "offset_a": (-2e-3, 2e-3, True)})
