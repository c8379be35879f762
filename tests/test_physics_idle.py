"""The paper's idle indicators on flights with no artificial dither (docs/physics.md §6, Hys0).

Hys0 (std of the current at idle) measures the band the loop hunts in: the spool dead zone
(friction, and the pilot pressure that fights it) and the feedback play (backlash), seen
through the controller gain. It responds to backlash; it does not tell backlash from friction.
"""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.indicators.batch import extract_indicators
from fuelhm_bench.physics.model import LoopModel
from fuelhm_bench.physics.simulate import simulate

MISSION = MissionProfile(duration_s=900.0)


def _hys0(intensities: dict, n: int = 3) -> np.ndarray:
    inputs = [MISSION.sample(np.random.default_rng(s)) for s in range(n)]
    model = LoopModel().degraded(intensities)
    outs = simulate([model] * n, inputs, [np.random.default_rng(50 + s) for s in range(n)])
    return np.array([extract_indicators(o.time_s, 1e3 * o.current_a, 1e3 * o.measured_position_m).values["Hys0"]
                     for o in outs])


@pytest.fixture(scope="module")
def healthy():
    return _hys0({})


def test_hys0_responds_to_backlash(healthy):
    half, full = _hys0({"backlash": 0.5}), _hys0({"backlash": 1.0})
    assert np.all(np.isfinite(healthy))
    assert half.mean() > 1.5 * healthy.mean()
    assert full.mean() > half.mean()
    # far outside the flight-to-flight scatter of one healthy unit
    assert (full.mean() - healthy.mean()) > 10 * healthy.std()


def test_hys0_rises_with_friction_too(healthy):
    """Friction widens the same band: Hys0 alone cannot separate it from backlash (docs/physics.md §6)."""
    assert _hys0({"spool_friction": 0.5}).mean() > 2 * healthy.mean()
