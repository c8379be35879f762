"""Measured-like flights with a hidden effect, for testing and studying the discrepancy workflow.

:func:`hidden_effect_flights` simulates a small healthy fleet (closed-loop flights from
:class:`~fuelhm_bench.flights.mission.MissionProfile`, units drawn with
:func:`~fuelhm_bench.physics.model.manufacture`, LVDT noise and quantization) from a nominal
model that has one optional effect switched on: the "truth" a nominal model lacks. The
effect's main parameter is drawn log-uniformly (seeded) in :data:`TEST_RANGES`, a
sub-range of its documented range where the effect matters on the velocity-gain curve of
short flights and stays physically plausible (a load stiffness of 5e5 N/m would need 30 kN
over the stroke). The lower ends are conservative: on 2 units x 3 flights of 4 minutes the
workflow still names every effect at a quarter of them, except ``rod_friction`` (named at
75 N, missed twice in three at 37.5 N; ``docs/discrepancy.md``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from fuelhm_bench.errors import UnknownNameError, range_error
from fuelhm_bench.flights.fleet import FleetConfig, flights_frame, iter_flights
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.physics.effects import EFFECTS
from fuelhm_bench.physics.model import Dispersion, LoopModel
from fuelhm_bench.taxonomy import EFFECT_IDS

#: Main parameter of each effect and the range its magnitude is drawn from in tests [SI].
#: ``load_stiffness`` draws a signed stiffness (either sign, magnitude in the range).
TEST_RANGES: dict[str, tuple[str, float, float]] = {
    "spool_overlap": ("overlap_m", 1e-5, 4e-5),
    "spool_flow_force": ("stiffness_ratio", 0.2, 1.0),
    "rod_friction": ("coulomb_n", 150.0, 600.0),
    "lvdt_lag": ("time_constant_s", 0.01, 0.05),
    "load_stiffness": ("stiffness_n_m", 3e4, 1.5e5),
    "current_driver_lag": ("time_constant_s", 0.01, 0.05),
    "torque_motor_hysteresis": ("width_a", 1e-4, 6e-4),
    "viscosity_temperature": ("leak_at_20c_m3_s_pa", 1e-12, 5e-12),
}


@dataclass(frozen=True)
class HiddenEffectCase:
    """Ground truth of a generated data set.

    Attributes
    ----------
    effect : str
        Hidden effect id, or ``"none"``.
    parameters : dict
        The effect's parameters [SI] (empty for ``"none"``).
    frame_s : float
        Sample period [s].
    noise_std_m : float
        LVDT noise [m].
    seed : int
        Seed of the fleet.
    """

    effect: str
    parameters: dict
    frame_s: float
    noise_std_m: float
    seed: int


def draw_magnitude(effect_id: str, rng: np.random.Generator) -> dict[str, float]:
    """Draw the effect's main parameter log-uniformly in :data:`TEST_RANGES` (other parameters default)."""
    if effect_id not in TEST_RANGES:
        raise UnknownNameError(f"Unknown effect id '{effect_id}'. Allowed: {', '.join(EFFECT_IDS)}.")
    name, lo, hi = TEST_RANGES[effect_id]
    value = math.exp(rng.uniform(math.log(lo), math.log(hi)))
    if effect_id == "load_stiffness" and rng.random() < 0.5:
        value = -value
    return {name: float(value)}


def hidden_effect_flights(effect: str | None, *, parameters: dict | None = None, n_units: int = 2,
                          n_flights: int = 2, minutes: float = 4.0, frame_s: float = 0.01,
                          noise_std_m: float = 3e-6, dispersion: float = 1.0, seed: int = 0
                          ) -> tuple[pd.DataFrame, HiddenEffectCase]:
    """Simulate a healthy fleet whose units have a hidden effect.

    Parameters
    ----------
    effect : str or None
        Effect id to hide, or None / ``"none"`` for no effect.
    parameters : dict, optional
        Effect parameters [SI]; default: :func:`draw_magnitude` with a generator seeded by ``seed``.
    n_units, n_flights : int, default=2, 2
        Units and flights per unit.
    minutes : float, default=4.0
        Flight duration [min] (at least 2: the engine start lasts 60 s of it).
    frame_s : float, default=0.01
        Sample (FADEC frame) period [s].
    noise_std_m : float, default=3e-6
        LVDT noise standard deviation [m].
    dispersion : float, default=1.0
        Scale of the manufacturing dispersion.
    seed : int, default=0
        Master seed (magnitude, units, flights, noise).

    Returns
    -------
    frame : pandas.DataFrame
        Flights in the format of docs/data-format.md (mA, mm, with ``unit_id``, ``n2_pct``, ``phase``, ...).
    case : HiddenEffectCase
        Ground truth.
    """
    if minutes < 2.0:
        raise range_error("minutes", ">= 2 (the engine start alone lasts 1 min)", minutes)
    eff = None if effect in (None, "none") else effect
    if eff is not None and eff not in EFFECTS:
        raise UnknownNameError(f"Unknown effect id '{eff}'. Allowed: {', '.join(EFFECT_IDS)}, none.")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 9001]))
    params = {} if eff is None else dict(parameters if parameters is not None else draw_magnitude(eff, rng))
    nominal = LoopModel().with_parameters({"controller.frame_s": frame_s, "lvdt.noise_std_m": noise_std_m})
    if eff is not None:
        nominal = nominal.with_effect(eff, **params)
        params = {k: float(v) for k, v in dataclasses.asdict(nominal.effect(eff)).items()}
    config = FleetConfig(n_units=n_units, n_flights=n_flights,
                         mission=MissionProfile(duration_s=60.0 * minutes, frame_s=frame_s), nominal=nominal,
                         dispersion=dataclasses.replace(Dispersion(), scale=dispersion), seed=seed)
    flights = [f for batch in iter_flights(config) for f in batch]
    case = HiddenEffectCase("none" if eff is None else eff, params, frame_s, noise_std_m, seed)
    return flights_frame(flights), case
