"""Effect laws shared by the library and the second simulator (docs/discrepancy.md §10, fifth round).

* The library's flow force follows the pressure drops across the two open metering edges
  (Merritt's steady flow force), not the supply pressure alone; with a torque-motor command
  limit (``command_limit_ratio``) the spool stops short of its stroke at a saturated current.
* The altsim's ``tanh`` rod friction is integrated stably: with the explicit update its slope
  (``F_c / 1 mm/s``) made the rod velocity chatter around zero at the 0.25 ms sub-step, and the
  mean friction vanished below a few mm/s. The default sub-step now agrees with a 25x finer one.
"""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.physics import kernel
from fuelhm_bench.physics.model import LoopModel
from fuelhm_bench.validation.altsim import AltEffects, simulate_flights


def test_flow_force_scales_with_the_open_edges_pressure_drops():
    model = LoopModel().with_effect("spool_flow_force", stiffness_ratio=0.3)
    _, k, _ = kernel.pack_model(model)
    plain = LoopModel()
    _, k0, _ = kernel.pack_model(plain)
    assert k[kernel.K_DIRECT] == 1.0 and k0[kernel.K_DIRECT] == 0.0  # the law reads the chamber pressures
    dps = 7e6
    i = 2e-3  # opens P->A (x_c > 0)
    free = kernel.spool_command(i, dps, k0)
    at_rest = kernel.spool_command(i, dps, k, 0.0)
    loaded = kernel.spool_command(i, dps, k, 3e6)  # p1 - p2 > 0 lowers the drops of P->A and B->T
    assert 0.0 < at_rest < loaded < free
    # no load pressure: the ratio at 70 bar and null width is the documented stiffness ratio
    assert at_rest == pytest.approx(free / (1.0 + 0.3 * _width_ratio(free, k)), rel=1e-12)
    # the other direction opens P->B and A->T: the same p1 - p2 raises their drops
    assert kernel.spool_command(-i, dps, k, 3e6) > kernel.spool_command(-i, dps, k, 0.0)
    # open edges without a drop: no flow force
    assert kernel.spool_command(i, dps, k, dps + 1e6) == free


def test_flow_force_command_limit_stops_the_spool_short_of_its_stroke_at_saturation():
    """``command_limit_ratio``: the torque motor's authority ends at r x stroke, before the flow force acts."""
    base = LoopModel()
    stroke = base.servovalve.spool_stroke_m
    _, k0, _ = kernel.pack_model(base)
    _, k_free, _ = kernel.pack_model(base.with_effect("spool_flow_force", stiffness_ratio=0.12))
    _, k_lim, _ = kernel.pack_model(base.with_effect("spool_flow_force", stiffness_ratio=0.12,
                                                     command_limit_ratio=1.0))
    assert k_free[kernel.K_FFLIM] == np.inf and k_lim[kernel.K_FFLIM] == pytest.approx(stroke)
    dps = 7e6
    i_sat = base.controller.current_saturation_a
    for sign in (1.0, -1.0):
        raw = kernel.spool_command(sign * i_sat, dps, k0)
        assert abs(raw) > 1.3 * stroke  # the saturated command lies beyond the stroke
        # no limit: the reduced command still exceeds the stroke, so the spool reaches its stop
        assert abs(kernel.spool_command(sign * i_sat, dps, k_free)) > stroke
        # limited at the stroke: clipped first, then reduced by the flow force at the outer width
        lim = kernel.spool_command(sign * i_sat, dps, k_lim)
        ratio = k_lim[kernel.K_WOUT] / k_lim[kernel.K_WNULL]
        assert lim == pytest.approx(sign * stroke / (1.0 + 0.12 * ratio), rel=1e-12)
    # within the limit the two laws are the same
    i = 2e-3
    assert kernel.spool_command(i, dps, k_lim, 1e6) == kernel.spool_command(i, dps, k_free, 1e6)


def test_flow_force_command_limit_lowers_the_saturation_velocity_only_when_set():
    from fuelhm_bench.physics.simulate import FlightInputs, simulate

    base = LoopModel().with_parameters({"lvdt.noise_std_m": 0.0, "lvdt.adc_bits": 0})
    d = np.concatenate([np.full(50, 0.010), np.full(150, 0.050)])  # a step that saturates the current
    inp = FlightInputs(d, np.full(d.size, 0.82), 0.01)

    def peak_velocity_mm_s(model):
        out = simulate([model], [inp], [np.random.default_rng(0)])[0]
        return float(np.max(np.diff(out.true_position_m)) / 0.01 * 1e3)

    v0 = peak_velocity_mm_s(base)
    v_free = peak_velocity_mm_s(base.with_effect("spool_flow_force", stiffness_ratio=0.12))
    v_lim = peak_velocity_mm_s(base.with_effect("spool_flow_force", stiffness_ratio=0.12, command_limit_ratio=1.0))
    assert v_free == pytest.approx(v0, rel=0.01)  # the spool still reaches its stop
    assert v_lim < 0.95 * v0  # it stops short of it: less saturation flow


@pytest.mark.parametrize("bad", [0.5, -1.0, 11.0, float("nan")])
def test_flow_force_command_limit_rejects_values_outside_its_range(bad):
    from fuelhm_bench.errors import ParameterError

    with pytest.raises(ParameterError, match=r"command_limit_ratio"):
        LoopModel().with_effect("spool_flow_force", stiffness_ratio=0.1, command_limit_ratio=bad)


def _width_ratio(x_c, k):
    ax = abs(x_c)
    if ax <= k[kernel.K_OA]:
        w = k[kernel.K_WNULL]
    elif ax >= k[kernel.K_OB]:
        w = k[kernel.K_WOUT]
    else:
        w = k[kernel.K_WNULL] + (k[kernel.K_WOUT] - k[kernel.K_WNULL]) * (ax - k[kernel.K_OA]) / (
            k[kernel.K_OB] - k[kernel.K_OA])
    return w / k[kernel.K_WNULL]


def test_altsim_friction_is_converged_in_its_substep():
    """500 N ``tanh`` friction, one 2-minute flight: the default 0.25 ms sub-step against 10 us."""
    kw = dict(n_units=1, n_flights=1, minutes=2.0, seed=3)
    coarse = simulate_flights(AltEffects(coulomb_n=500.0), **kw)
    fine = simulate_flights(AltEffects(coulomb_n=500.0), substep_s=1e-5, **kw)
    # the healthy loop's discretisation error at this sub-step is 0.0076 mA RMS (measured); the
    # explicit friction update gave 0.27 mA
    d_i = np.sqrt(np.mean((coarse.current_mA.to_numpy() - fine.current_mA.to_numpy()) ** 2))
    assert d_i < 0.02
    assert np.max(np.abs(coarse.position_mm.to_numpy() - fine.position_mm.to_numpy())) < 0.1


@pytest.mark.slow
@pytest.mark.parametrize("effect", ["rod_friction", "spool_flow_force"])
def test_library_law_reproduces_the_altsim_lookalike(effect):
    """The law check (healthy-recalibrated units, reference magnitude): slope near 1 where it matters."""
    from fuelhm_bench.validation.study import law_check

    rows = {(r["data"], r["band"]): r for r in law_check(effect)}
    assert abs(rows[("healthy", "all")]["slope"]) < 0.05
    assert 0.8 < rows[("effect", "all")]["slope"] < 1.2
    assert 0.8 < rows[("effect", "10-40")]["slope"] < 1.2 and rows[("effect", "10-40")]["correlation"] > 0.9
    if effect == "spool_flow_force":  # the saturated motions too, with the command limit at the stroke
        assert 0.9 < rows[("effect", "40-inf")]["slope"] < 1.1 and rows[("effect", "40-inf")]["correlation"] > 0.95


@pytest.mark.slow
def test_flow_force_fast_path_agrees_with_reference():
    """The edge-drop flow force in the fast path and in the reference integrator (same frame-start pressures)."""
    from fuelhm_bench.physics.reference import simulate_reference
    from fuelhm_bench.physics.simulate import FlightInputs, simulate

    base = LoopModel().with_parameters({"lvdt.noise_std_m": 0.0, "lvdt.adc_bits": 0})
    d = np.concatenate([np.full(50, 0.030), np.full(150, 0.045), np.linspace(0.045, 0.020, 100),
                        np.full(60, 0.020), np.full(40, 0.0205), np.full(40, 0.0195), np.full(100, 0.005)])
    inp = FlightInputs(d, np.full(d.size, 0.82), 0.01)
    for limit in (0.0, 1.0):  # the last step saturates the current: the command limit acts there
        model = base.with_effect("spool_flow_force", stiffness_ratio=0.5, command_limit_ratio=limit)
        fast = simulate([model], [inp], [np.random.default_rng(0)])[0]
        ref = simulate_reference(model, inp, np.random.default_rng(0))
        assert np.max(np.abs(fast.true_position_m - ref.true_position_m)) <= 10e-6
        assert np.max(np.abs(fast.current_a - ref.current_a)) <= 0.03e-3
