"""Operating excitation of a flight (docs/physics.md §5 Mission and excitation).

N2 is the output of engine dynamics (band-limited, lagging the throttle); the
position demand is the VSV schedule of that N2; nothing adds per-frame noise.
The current's scatter at steady cruise then comes from the LVDT noise and ADC
quantization through the controller and from the loop's own small-step motion
(spool friction dead zone, integrator dead band): docs/physics.md §5 states
0.020 mA about the 1-s moving mean (0.009-0.013 mA of it with an ideal sensor).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch

from fuelhm_bench.flights.mission import PHASE_NAMES, MissionProfile
from fuelhm_bench.physics.model import LoopModel
from fuelhm_bench.physics.simulate import simulate

MISSION = MissionProfile(duration_s=1200.0)


@pytest.fixture(scope="module")
def flights():
    return [MISSION.sample(np.random.default_rng(seed)) for seed in range(2)]


def test_n2_is_band_limited(flights):
    """Power of N2 above 3 Hz is more than 8 decades below its level under 0.05 Hz (per-frame noise gives 3e-6)."""
    for inp in flights:
        n2 = inp.n2_frac[int(MISSION.start_duration_s / MISSION.frame_s):]
        f, p = welch(n2, fs=1.0 / MISSION.frame_s, nperseg=2 ** 13)
        ratio = p[f >= 3.0].mean() / p[(f > 0) & (f <= 0.05)].mean()
        assert ratio < 1e-8, ratio


def test_n2_lags_a_throttle_step():
    """With no fluctuation, N2 after a step of the phase set point follows the first-order engine lag."""
    mp = MissionProfile(duration_s=600.0, n2_noise_std=0.0, throttle_step_std=0.0)
    inp = mp.sample(np.random.default_rng(3))
    n2 = inp.n2_frac
    frame_steps = np.abs(np.diff(n2))
    # the largest frame-to-frame change is bounded by (set-point jump) * T / tau
    assert frame_steps.max() <= 0.5 * mp.frame_s / mp.engine_time_constant_s
    assert np.all(np.isfinite(n2))


def test_demand_is_the_schedule_of_n2(flights):
    for inp in flights:
        after = slice(int(MISSION.start_duration_s / MISSION.frame_s), None)
        np.testing.assert_allclose(inp.demand_m[after], MISSION.demand_from_n2(inp.n2_frac[after]), rtol=0, atol=1e-15)


def test_same_seed_same_flight():
    a = MISSION.sample(np.random.default_rng(7))
    b = MISSION.sample(np.random.default_rng(7))
    np.testing.assert_array_equal(a.n2_frac, b.n2_frac)


def _cruise_scatter_ma(out, inp) -> float:
    cruise = np.flatnonzero(inp.extras["phase"] == PHASE_NAMES.index("cruise"))[:6000]
    i = out.current_a[cruise] * 1e3
    mean = np.convolve(i, np.ones(100) / 100, "same")
    return float((i - mean)[50:-50].std())


def test_cruise_current_scatter_comes_from_sensor_and_loop(flights):
    """Stated figure: about 0.020 mA at cruise; an ideal sensor removes part of it, not all."""
    ideal = LoopModel().with_parameters({"lvdt.noise_std_m": 0.0, "lvdt.adc_bits": 0})
    for inp in flights:
        real, perfect = simulate([LoopModel(), ideal], [inp, inp], [np.random.default_rng(1), np.random.default_rng(1)])
        s_real, s_ideal = _cruise_scatter_ma(real, inp), _cruise_scatter_ma(perfect, inp)
        assert 0.010 < s_real < 0.030, s_real
        assert s_ideal < 0.8 * s_real


@pytest.mark.parametrize("seed", range(40))
def test_first_order_filter_is_lfilter_bit_for_bit(seed):
    """The compiled recursion of MissionProfile.sample gives scipy.signal.lfilter's bytes (the flights' N2 depends on it)."""
    from scipy.signal import lfilter

    from fuelhm_bench.flights.mission import first_order_filter

    r = np.random.default_rng(seed)
    n = int(r.integers(1, 3000))
    x = r.normal(size=n) * 10 ** r.uniform(-5, 3)
    x[r.integers(0, n, 3)] = 0.0
    pole = float(np.exp(-r.uniform(1e-4, 2.0)))
    gain = 1.0 - pole if seed % 2 else 1.0
    z0 = 0.0 if seed % 5 == 0 else float(r.normal())
    expected = lfilter([gain], [1.0, -pole], x, zi=[z0])[0]
    assert first_order_filter(x, gain, pole, z0).tobytes() == expected.tobytes()


def test_demand_from_n2_takes_scalars_and_arrays():
    n2 = np.array([0.3, 0.55, 0.8, 1.0, 1.2])
    expected = MISSION.sweep_low_m + np.clip((n2 - MISSION.schedule_n2_low) / (
        MISSION.schedule_n2_high - MISSION.schedule_n2_low), 0.0, 1.0) * (MISSION.sweep_high_m - MISSION.sweep_low_m)
    assert MISSION.demand_from_n2(n2).tobytes() == expected.tobytes()
    assert MISSION.demand_from_n2(0.8) == expected[2] and np.ndim(MISSION.demand_from_n2(0.8)) == 0
    assert MISSION.demand_from_n2(n2) is not n2 and n2[0] == 0.3  # the input is not modified


@pytest.mark.parametrize("seed", range(12))
def test_flight_channels_are_the_filters_and_schedule_bit_for_bit(seed):
    """The one compiled pass of MissionProfile.sample gives the bytes of its three steps done one after the other:
    the Gauss-Markov fluctuation added to the speed demand, the spool lag (both lfilter), the clip and schedule."""
    from scipy.signal import lfilter

    from fuelhm_bench.flights.mission import _flight_channels

    r = np.random.default_rng(seed)
    n = int(r.integers(2, 4000))
    n_start = int(r.integers(0, n)) if seed % 3 else 0
    target = r.uniform(-0.1, 1.3, n)
    drive = r.normal(0.0, 0.05, n - n_start) if seed % 4 else np.empty(0)
    b, a = float(np.exp(-r.uniform(1e-3, 1.0))), float(np.exp(-r.uniform(1e-3, 1.0)))
    start = float(r.normal())
    sweep = r.uniform(0.0, 0.06, int(r.integers(0, n))) if seed % 2 else np.empty(0)
    args = (1.15, 0.55, 0.45, 0.003, 0.054)
    expected_target = target.copy()
    if drive.size:
        expected_target[n_start:] += lfilter([1.0], [1.0, -b], drive, zi=[start])[0]
    n2 = np.clip(lfilter([1.0 - a], [1.0, -a], expected_target, zi=[a * expected_target[0]])[0], 0.0, 1.15)
    demand = np.clip((n2 - 0.55) / 0.45, 0.0, 1.0) * 0.054 + 0.003
    demand[:sweep.size] = sweep
    got = _flight_channels(target, n_start, drive, b, start, a, *args, sweep)
    for g, e in zip(got, (n2, demand, 100.0 * n2, 1e3 * demand)):
        assert g.tobytes() == e.tobytes()
