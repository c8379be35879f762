"""LVDT position sensor: demodulation filter, noise and ADC quantization.

The demodulation filter is second order, ``y'' + 2*zeta*w*y' + w^2*y = w^2*x``
(``w = 2*pi*bandwidth``). An optional extra first-order lag (the ``lvdt_lag``
effect, ``tau*y_l' = y - y_l``) can follow it. The filter is discretised exactly
for a position that varies linearly within a frame (first-order hold), via the
matrix exponential of the augmented system. Each frame the measured position is
``quantize(y + noise)`` with a uniform ADC over ``[range_min, range_max]``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from fuelhm_bench.errors import range_error
from fuelhm_bench.physics._validation import check_fields


#: Largest LVDT noise standard deviation [m]: 10 mm, a seventh of the 70 mm range (beyond it the reading
#: is noise; a scenario's ``sensor.noise_std_um`` and ``simulate --noise-um`` are held to it).
MAX_NOISE_STD_M: float = 0.01


@dataclass(frozen=True)
class LvdtParams:
    """LVDT and its acquisition chain.

    Parameters
    ----------
    bandwidth_hz : float, default=160.0
        Natural frequency of the demodulation filter [Hz].
    damping : float, default=0.6
        Damping ratio of the demodulation filter [-].
    noise_std_m : float, default=3e-6
        Standard deviation of the additive white noise [m], in [0, :data:`MAX_NOISE_STD_M`].
    adc_bits : int, default=12
        ADC resolution [bits]; 0 disables quantization.
    range_min_m : float, default=-0.005
        Lower end of the ADC range [m].
    range_max_m : float, default=0.065
        Upper end of the ADC range [m].
    """

    bandwidth_hz: float = 160.0
    damping: float = 0.6
    noise_std_m: float = 3e-6
    adc_bits: int = 12
    range_min_m: float = -0.005
    range_max_m: float = 0.065

    def __post_init__(self) -> None:
        check_fields(self, {
            "bandwidth_hz": (1.0, 1e5, True),
            "damping": (0.05, 5.0, True),
            "noise_std_m": (0.0, MAX_NOISE_STD_M, True),
            "range_min_m": (-1.0, 1.0, True),
            "range_max_m": (-1.0, 1.0, True),
        })
        if not isinstance(self.adc_bits, int) or isinstance(self.adc_bits, bool) or not 0 <= self.adc_bits <= 24:
            raise range_error("LvdtParams.adc_bits", "an integer in [0, 24]", self.adc_bits)
        if self.range_max_m <= self.range_min_m:
            raise range_error("LvdtParams.range_max_m", f"> range_min_m ({self.range_min_m:g})", self.range_max_m)

    @property
    def quantum_m(self) -> float:
        """ADC quantum [m] (0 when quantization is disabled)."""
        if self.adc_bits == 0:
            return 0.0
        return (self.range_max_m - self.range_min_m) / 2 ** self.adc_bits


def lvdt_state_matrix(lvdt: LvdtParams, lag_time_constant_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time (A, B) of the 3-state filter ``[y, y', y_lag]`` driven by position.

    ``lag_time_constant_s <= 0`` means no extra lag (the lag state then tracks
    ``y`` with a 0.1 ms time constant and is not read).
    """
    w = 2.0 * math.pi * lvdt.bandwidth_hz
    tau = lag_time_constant_s if lag_time_constant_s > 0.0 else 1e-4
    a = np.array([[0.0, 1.0, 0.0], [-w * w, -2.0 * lvdt.damping * w, 0.0], [1.0 / tau, 0.0, -1.0 / tau]])
    b = np.array([0.0, w * w, 0.0])
    return a, b


@functools.lru_cache(maxsize=1024)
def _discretization_cached(lvdt: LvdtParams, lag_time_constant_s: float, frame_s: float) -> np.ndarray:
    a, b = lvdt_state_matrix(lvdt, lag_time_constant_s)
    aug = np.zeros((5, 5))
    aug[:3, :3] = a
    aug[:3, 3] = b
    aug[3, 4] = 1.0
    e = expm(aug * frame_s)
    out = np.ascontiguousarray(e[:3, :])
    out.flags.writeable = False
    return out


def lvdt_discretization(lvdt: LvdtParams, lag_time_constant_s: float, frame_s: float) -> np.ndarray:
    """Exact first-order-hold discretisation of the LVDT filter over one frame.

    Returns
    -------
    ndarray of shape (3, 5)
        ``[E_s | E_u | E_du]`` such that ``s_next = E_s @ s + E_u * x0 + E_du * (x1 - x0) / frame_s``
        where ``x0, x1`` are the true positions at the start and end of the frame [m].
        Memoised (the parameter sets are immutable); the returned array is read-only.
    """
    return _discretization_cached(lvdt, float(lag_time_constant_s), float(frame_s))
