"""Discrete PI position controller of the FADEC.

At each frame ``k`` (period ``frame_s``) the controller reads the LVDT position
``y_k`` and the demand ``r_k`` and commands the servovalve current::

    e_k = r_k - y_k
    z_k = clip(z_{k-1} + ki * e_k * frame_s, -z_max, z_max)   if |e_k| > dead_band
    i_k = clip(kp * e_k + z_k, -i_sat, i_sat)

held constant until the next frame (zero-order hold). Because of the integral
action the current at rest converges to the *idle current* I0 (the current for
which the valve delivers exactly the chamber-to-chamber flow), not to the null
bias Inb.
"""

from __future__ import annotations

from dataclasses import dataclass

from fuelhm_bench.physics._validation import NON_NEGATIVE, POSITIVE, check_fields


@dataclass(frozen=True)
class ControllerParams:
    """Parameters of the discrete PI position loop.

    Parameters
    ----------
    frame_s : float, default=0.01
        Controller (FADEC) frame period [s]; also the recorded sample period.
    kp_a_per_m : float, default=2.0
        Proportional gain [A/m] (2 mA per mm of error).
    ki_a_per_m_s : float, default=6.0
        Integral gain [A/(m s)].
    integrator_clamp_a : float, default=8e-3
        Bound of the integrator state [A].
    dead_band_m : float, default=2e-5
        No integration while ``|error|`` is below this [m].
    current_saturation_a : float, default=12e-3
        Saturation of the commanded current [A]; above the 8 mA rated current so that the
        velocity saturation (spool at full stroke) is seen with unsaturated current.
    """

    frame_s: float = 0.01
    kp_a_per_m: float = 2.0
    ki_a_per_m_s: float = 6.0
    integrator_clamp_a: float = 8e-3
    dead_band_m: float = 2e-5
    current_saturation_a: float = 12e-3

    def __post_init__(self) -> None:
        check_fields(self, {
            "frame_s": (1e-4, 1.0, True),
            "kp_a_per_m": POSITIVE,
            "ki_a_per_m_s": NON_NEGATIVE,
            "integrator_clamp_a": POSITIVE,
            "dead_band_m": NON_NEGATIVE,
            "current_saturation_a": POSITIVE,
        })

    @property
    def frame_rate_hz(self) -> float:
        """Frame rate [Hz]."""
        return 1.0 / self.frame_s
