"""Physics: sanity of the healthy curve, degradation directions, effects, determinism, bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fuelhm_bench.errors import NumericalError, ParameterError, UnknownNameError
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.flights.sweep import VelocityGainSweep, run_sweep
from fuelhm_bench.physics.controller import ControllerParams
from fuelhm_bench.physics.cylinder import CylinderParams
from fuelhm_bench.physics.effects import make_effect, parse_effect_spec
from fuelhm_bench.physics.lvdt import LvdtParams
from fuelhm_bench.physics.model import Dispersion, LoopModel, load_model, manufacture, save_model
from fuelhm_bench.physics.servovalve import ServovalveParams
from fuelhm_bench.physics.simulate import FlightInputs, simulate
from fuelhm_bench.taxonomy import EFFECT_IDS, MODE_IDS

NOMINAL = LoopModel()


@pytest.fixture(scope="module")
def healthy():
    return run_sweep(NOMINAL)


def _curve_features(r):
    """Sweep features: idle currents [mA], hysteresis [mA], gains [mm/s/mA], saturation velocities [mm/s]."""
    up, dn = r.zero_crossing_a(True) * 1e3, r.zero_crossing_a(False) * 1e3
    v = lambda i_ma: r.velocity_at(i_ma * 1e-3) * 1e3  # noqa: E731
    return {
        "I0": 0.5 * (up + dn),
        "hys": abs(up - dn),
        "g_null": (v(1.5) - v(-0.5)) / 2.0,
        "g_out": (v(6.0) - v(4.0)) / 2.0,
        "g_in": (v(-3.0) - v(-5.0)) / 2.0,
        "v_max": v(9.8),
        "v_min": v(-9.8),
        "v_at_0p5": v(0.5),
    }


def test_healthy_curve_shape(healthy):
    f = _curve_features(healthy)
    inb = NOMINAL.servovalve.null_bias_a * 1e3
    # Velocity sign follows the current relative to the idle current.
    assert healthy.velocity_at((f["I0"] + 1.0) * 1e-3) > 0 > healthy.velocity_at((f["I0"] - 1.0) * 1e-3)
    # Saturation at both ends: the last mA adds almost nothing.
    v = lambda i_ma: healthy.velocity_at(i_ma * 1e-3) * 1e3  # noqa: E731
    assert abs(v(9.8) - v(9.0)) < 0.05 * abs(v(9.8)) and 60 < v(9.8) < 110
    assert abs(v(-9.8) - v(-9.0)) < 0.05 * abs(v(-9.8)) and -110 < v(-9.8) < -50
    # Two slope changes: the outer gain is about twice the null-region gain (dual-gain slots).
    assert 1.6 < f["g_out"] / f["g_null"] < 2.6
    assert 1.6 < f["g_in"] / f["g_null"] < 2.6
    # Idle current offset from the null bias by the cooling flow (a few % of the rated current).
    assert 0.1 < abs(f["I0"] - inb) < 0.08 * 8.0
    # Hysteresis at idle.
    assert f["hys"] > 0.02


# mode: (features it moves, with direction), (features it must not change) - docs/physics.md §6 Degradation modes.
# "Unchanged" means within 0.5 % (gains, saturation velocities) or 0.02 mA (I0, hysteresis).
MECHANISMS = {
    "filter_contamination": ([("hys", +1)], ["g_out", "g_in", "v_max", "v_min", "I0"]),
    "null_bias_drift": ([("I0", +1)], ["hys", "g_in", "v_min"]),
    "backlash": ([("hys", +1)], ["I0", "g_out", "g_in", "v_max", "v_min"]),
    "spool_friction": ([("hys", +1)], ["I0", "g_out", "g_in", "v_max", "v_min"]),
    "radial_clearance": ([("g_null", +1)], ["hys", "v_max", "v_min"]),
    "internal_leakage": ([("I0", -1)], ["hys", "g_out", "g_in"]),
    "diaphragm_clogging": ([("I0", +1)], ["hys", "g_out", "g_in"]),
}


@pytest.mark.parametrize("mode", MODE_IDS)
def test_degradation_mechanism_direction_and_side_effects(mode, healthy):
    base = _curve_features(healthy)
    deg = _curve_features(run_sweep(NOMINAL.degraded({mode: 1.0})))
    moves, unchanged = MECHANISMS[mode]
    for feature, sign in moves:
        change = deg[feature] - base[feature]
        scale = max(abs(base[feature]), 0.1)
        assert sign * change > 0.1 * scale, f"{mode}: {feature} {base[feature]:.3f} -> {deg[feature]:.3f}"
    for feature in unchanged:
        tol = 0.02 if feature in ("I0", "hys") else 0.005 * abs(base[feature])
        assert abs(deg[feature] - base[feature]) <= tol, f"{mode} must not change {feature}: " \
            f"{base[feature]:.3f} -> {deg[feature]:.3f}"


def test_filter_contamination_slows_the_spool():
    """The pilot stage starves: after a current step the rod accelerates more slowly (spool rate halved)."""
    i = np.concatenate([np.zeros(20), np.full(20, 3e-3)])
    inp = FlightInputs(np.zeros(40), np.full(40, 0.82), 0.01, open_loop_current_a=i, end_stops=False)
    models = [NOMINAL, NOMINAL.degraded({"filter_contamination": 1.0})]
    clean, dirty = simulate(models, [inp, inp], [np.random.default_rng(0), np.random.default_rng(0)])
    transient = dirty.true_velocity_m_s[20] / clean.true_velocity_m_s[20]
    steady = dirty.true_velocity_m_s[-1] / clean.true_velocity_m_s[-1]  # lower by the 4x friction dead zone only
    assert transient < 0.85 * steady and steady > 0.85
    assert NOMINAL.degraded({"filter_contamination": 1.0}).servovalve.spool_rate_per_s == pytest.approx(
        0.5 * NOMINAL.servovalve.spool_rate_per_s)


def test_leakage_at_full_intensity_is_the_rejection_limit_and_keeps_the_curve_monotone():
    """7 cm^3/s at 70 bar (about the cooling diaphragm's flow); no negative-slope region near null."""
    model = NOMINAL.degraded({"internal_leakage": 1.0})
    assert model.cylinder.leakage_coefficient_m3_s_pa * 7e6 == pytest.approx(7e-6)
    r = run_sweep(model)
    sel = r.increasing & (np.abs(r.current_a - r.zero_crossing_a()) < 1.5e-3)
    i, v = r.current_a[sel], r.velocity_m_s[sel]
    order = np.argsort(i)
    smooth = np.convolve(v[order], np.ones(15) / 15, "valid")
    assert np.all(np.diff(smooth) > 0)


def test_null_bias_drift_shifts_whole_curve(healthy):
    deg = run_sweep(NOMINAL.degraded({"null_bias_drift": 1.0}))
    shift = (deg.zero_crossing_a() - healthy.zero_crossing_a()) * 1e3
    assert shift == pytest.approx(1.6, abs=0.15)
    # Far from null the curve is the same curve shifted by 1.6 mA.
    assert deg.velocity_at(5.6e-3) == pytest.approx(healthy.velocity_at(4.0e-3), rel=0.05)


def test_diaphragm_clogging_shrinks_idle_offset(healthy):
    inb = NOMINAL.servovalve.null_bias_a * 1e3
    before = abs(_curve_features(healthy)["I0"] - inb)
    after = abs(_curve_features(run_sweep(NOMINAL.degraded({"diaphragm_clogging": 1.0})))["I0"] - inb)
    assert after < 0.5 * before


def test_intensity_is_monotone_for_leakage(healthy):
    i0 = [_curve_features(run_sweep(NOMINAL.degraded({"internal_leakage": f})))["I0"] for f in (0.0, 0.5, 1.0)]
    assert i0[0] > i0[1] > i0[2]


def test_several_modes_act_at_once(healthy):
    both = run_sweep(NOMINAL.degraded({"null_bias_drift": 1.0, "spool_friction": 1.0}))
    f = _curve_features(both)
    assert f["I0"] > _curve_features(healthy)["I0"] + 0.5
    assert f["hys"] > _curve_features(healthy)["hys"] + 0.3


def _short_flight(model, seed=0, minutes=3.0):
    mp = MissionProfile(duration_s=minutes * 60.0, start_duration_s=60.0, frame_s=model.controller.frame_s)
    inp = mp.sample(np.random.default_rng(seed))
    return inp, simulate([model], [inp], [np.random.default_rng(seed + 1)])[0]


@pytest.mark.parametrize("effect_id", EFFECT_IDS)
def test_each_effect_changes_the_flight(effect_id):
    params = {"rod_friction": {"coulomb_n": 1500.0}, "lvdt_lag": {"time_constant_s": 0.05}}.get(effect_id, {})
    inp, base = _short_flight(NOMINAL)
    _, eff = _short_flight(NOMINAL.with_effect(effect_id, **params))
    # Same inputs and noise: any difference comes from the effect.
    diff_pos = np.max(np.abs(eff.measured_position_m - base.measured_position_m))
    diff_cur = np.max(np.abs(eff.current_a - base.current_a))
    assert diff_pos > 50e-6 or diff_cur > 0.2e-3, (effect_id, diff_pos, diff_cur)


def test_effects_off_by_default_and_composable():
    assert NOMINAL.effects == ()
    m = NOMINAL.with_effect("spool_overlap", overlap_m=2e-5).with_effect("lvdt_lag")
    assert m.effect("spool_overlap").overlap_m == 2e-5
    assert m.get("effect.spool_overlap.overlap_m") == 2e-5
    m2 = m.with_parameters({"effect.spool_overlap.overlap_m": 3e-5})
    assert m2.effect("spool_overlap").overlap_m == 3e-5 and m2.effect("lvdt_lag") is not None
    assert m2.without_effect("lvdt_lag").effect("lvdt_lag") is None
    assert parse_effect_spec("rod_friction:coulomb_n=200,static_ratio=2").static_ratio == 2.0


def test_model_yaml_round_trip(tmp_path):
    m = manufacture(NOMINAL, np.random.default_rng(3)).with_effect("rod_friction", coulomb_n=300.0)
    path = save_model(m, tmp_path / "m.yaml")
    assert load_model(path) == m
    with pytest.raises(Exception, match="exists"):
        save_model(m, path)


@pytest.mark.parametrize("content, match", [
    (b"\xff\xfe\x00\x01", r"m.yaml: cannot read the model file: it is not UTF-8 text"),
    (b"effects: [rod_friction]\n", r"m.yaml: section 'effects' must be a mapping of effect id .* Got list"),
    (b"effects:\n  rod_friction: 5\n", r"m.yaml: effects.rod_friction must be a mapping of the effect's parameters .* Got 5"),
    (b"effects:\n  rod_friction: [1, 2]\n", r"effects.rod_friction must be a mapping .* Got \[1, 2\]"),
    (b"servovalve: {null_bias_a: [1\n", r"m.yaml: not valid YAML \(line 2\)"),
])
def test_bad_model_files_name_the_file_and_section(tmp_path, content, match):
    """Each of these was a traceback (UnicodeDecodeError, AttributeError, TypeError) before."""
    from fuelhm_bench.errors import ModelFileError

    path = tmp_path / "m.yaml"
    path.write_bytes(content)
    with pytest.raises(ModelFileError, match=match):
        load_model(path)


def test_model_file_reads_exponent_notation(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("servovalve: {null_bias_a: 1e-4}\neffects: {rod_friction: {coulomb_n: 5e2}}\n")
    model = load_model(path)
    assert model.servovalve.null_bias_a == 1e-4 and model.effects[0].coulomb_n == 500.0


def test_manufacture_is_seeded_and_disperses():
    a = manufacture(NOMINAL, np.random.default_rng(1))
    b = manufacture(NOMINAL, np.random.default_rng(1))
    c = manufacture(NOMINAL, np.random.default_rng(2))
    assert a == b and a != c
    same = manufacture(NOMINAL, np.random.default_rng(2), Dispersion(scale=0.0))
    assert same == NOMINAL


def test_fast_path_deterministic_and_batch_invariant():
    inp, _ = _short_flight(NOMINAL)
    units = [manufacture(NOMINAL, np.random.default_rng(s)) for s in range(3)]
    batch = simulate(units, [inp] * 3, [np.random.default_rng(10 + s) for s in range(3)])
    alone = simulate(units[1:2], [inp], [np.random.default_rng(11)])[0]
    again = simulate(units, [inp] * 3, [np.random.default_rng(10 + s) for s in range(3)])
    assert batch[1].measured_position_m.tobytes() == alone.measured_position_m.tobytes()
    for x, y in zip(batch, again):
        assert x.current_a.tobytes() == y.current_a.tobytes()


def test_table_mode_matches_direct_solver():
    """Sample by sample while the loop is driven (engine-start sweep); in statistics once it sits still.

    With no per-frame excitation the loop hunts slowly at constant demand (spool friction dead zone
    and integrator dead band); the phase of that hunting is not reproducible to the last bit, so after
    the sweep the two paths are compared by the level (1-s moving mean) and scatter of the signals.
    """
    inp, _ = _short_flight(NOMINAL)
    m = NOMINAL.with_parameters({"lvdt.noise_std_m": 0.0, "lvdt.adc_bits": 0})
    a = simulate([m], [inp], [np.random.default_rng(0)], use_table=True)[0]
    b = simulate([m], [inp], [np.random.default_rng(0)], use_table=False)[0]
    quantum = (NOMINAL.lvdt.range_max_m - NOMINAL.lvdt.range_min_m) / 4096
    n_start = int(60.0 / inp.frame_s)
    assert np.max(np.abs(a.true_position_m[:n_start] - b.true_position_m[:n_start])) < quantum
    w = np.ones(100) / 100
    level = np.abs(np.convolve(a.true_position_m, w, "valid") - np.convolve(b.true_position_m, w, "valid"))
    assert level.max() < 2 * quantum
    scatter = [float((o.current_a[n_start:] - np.convolve(o.current_a[n_start:], w, "same"))[50:-50].std())
               for o in (a, b)]
    assert scatter[0] == pytest.approx(scatter[1], rel=0.05)


def test_velocity_table_interpolation_error():
    from fuelhm_bench.physics import kernel
    from fuelhm_bench.physics.cylinder import velocity_direct

    c, k, _ = kernel.pack_model(NOMINAL)
    table = kernel.build_velocity_table(c, k, kernel.TABLE_N2, kernel.TABLE_NX)
    rng = np.random.default_rng(0)
    smax = k[kernel.K_SSTROKE]
    step = kernel.TABLE_N2[1] - kernel.TABLE_N2[0]
    worst = 0.0
    for _ in range(3000):
        xs, n2 = rng.uniform(-smax, smax), rng.uniform(kernel.TABLE_N2[0], kernel.TABLE_N2[-1])
        vd, _ = velocity_direct(xs, k[kernel.K_DPS100] * n2 * n2, k[kernel.K_FAERO100] * n2 * n2, np.nan, c)
        w = (n2 - kernel.TABLE_N2[0]) / step
        j = min(int(w), len(kernel.TABLE_N2) - 2)
        vt = kernel._table_lookup(table, xs, j, w - j, n2, smax, (table.shape[0] - 1) / (2 * smax))
        worst = max(worst, abs(vt - vd))
    # 0.1 mm/s is 0.1 % of the full-scale velocity and well below the ADC velocity quantum (1.7 mm/s).
    assert worst < 1e-4


def test_rod_friction_velocity_solves_the_rod_force_balance():
    """The rod velocity with friction is the fixed point v = V(load + F(v)) of the friction-free
    solver, or 0 when the static friction holds the rod; the spool position's metering
    coefficients are computed once for all the forces tried (velocity_metered)."""
    from fuelhm_bench.physics import kernel
    from fuelhm_bench.physics.cylinder import metering_coefficients, velocity_direct, velocity_metered

    model = NOMINAL.with_effect("rod_friction", coulomb_n=500.0, static_ratio=1.5, viscous_n_s_m=2e3)
    c, k, _ = kernel.pack_model(model)
    rng = np.random.default_rng(1)
    smax = k[kernel.K_SSTROKE]
    moving = stuck = 0
    for _ in range(400):
        xs, n2 = rng.uniform(-0.3 * smax, 0.3 * smax), rng.uniform(0.6, 1.0)
        dps, f_load = k[kernel.K_DPS100] * n2 * n2, k[kernel.K_FAERO100] * n2 * n2
        coeffs = metering_coefficients(xs, c)[:4]
        for force in (f_load - 800.0, f_load, f_load + 800.0):
            assert velocity_metered(*coeffs, dps, force, np.nan, c) == velocity_direct(xs, dps, force, np.nan, c)
        v, _ = kernel.rod_velocity(xs, dps, f_load, np.nan, c, k)
        if v == 0.0:
            stuck += 1
            # held: the static friction exceeds the net force both ways
            assert velocity_direct(xs, dps, f_load + k[kernel.K_FS], np.nan, c)[0] <= 0.0
            assert velocity_direct(xs, dps, f_load - k[kernel.K_FS], np.nan, c)[0] >= 0.0
        else:
            moving += 1
            v_free, _ = velocity_direct(xs, dps, f_load + kernel.friction_force(v, k), np.nan, c)
            assert v == pytest.approx(v_free, abs=1e-8)
            # friction slows the rod: same direction as, and slower than, the friction-free rod
            v0, _ = velocity_direct(xs, dps, f_load, np.nan, c)
            assert v * v0 > 0.0 and abs(v) < abs(v0)
    assert moving > 100 and stuck > 10


def test_closed_loop_tracks_demand_and_saturates():
    inp, out = _short_flight(NOMINAL)
    err = inp.demand_m - out.true_position_m
    settled = np.abs(np.diff(inp.demand_m, prepend=inp.demand_m[0])) < 1e-9
    assert np.median(np.abs(err[settled])) < 0.2e-3
    assert np.isclose(out.current_a.max(), NOMINAL.controller.current_saturation_a)
    assert np.isclose(out.current_a.min(), -NOMINAL.controller.current_saturation_a)
    # ADC quantization: measured positions sit on the quantum grid.
    q = NOMINAL.lvdt.quantum_m
    codes = (out.measured_position_m - NOMINAL.lvdt.range_min_m) / q
    assert np.allclose(codes, np.round(codes), atol=1e-6)


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("factory, match", [
    (lambda: ServovalveParams(rated_current_a=0.0), r"ServovalveParams.rated_current_a' parameter must be > 0\. Got 0.0"),
    (lambda: ServovalveParams(spool_time_constant_s=-1.0), r"spool_time_constant_s"),
    (lambda: CylinderParams(bore_m=-0.04), r"CylinderParams.bore_m"),
    (lambda: CylinderParams(rod_m=0.05), r"rod_m' parameter must be < bore_m"),
    (lambda: ControllerParams(frame_s=0.0), r"frame_s' parameter must be in \[0.0001, 1\]"),
    (lambda: LvdtParams(adc_bits=40), r"adc_bits' parameter must be an integer in \[0, 24\]"),
    (lambda: LvdtParams(noise_std_m=float("nan")), r"must be finite"),
    (lambda: MissionProfile(duration_s=0.0), r"MissionProfile.duration_s' parameter must be in \(0, 86400\]"),
    (lambda: MissionProfile(duration_s=30.0), r"duration_s' parameter must be >= start_duration_s \+ 60"),
    (lambda: VelocityGainSweep(current_max_a=-0.02), r"current_max_a"),
])
def test_bad_parameters_name_field_range_and_value(factory, match):
    with pytest.raises(ParameterError, match=match):
        factory()


def test_bad_intensity_and_names():
    with pytest.raises(ParameterError, match=r"in \[0, 1\]\. Got 1.5"):
        NOMINAL.degraded({"backlash": 1.5})
    with pytest.raises(ParameterError, match=r"in \[0, 1\]\. Got -0.1"):
        NOMINAL.degraded({"backlash": -0.1})
    with pytest.raises(UnknownNameError, match="Did you mean 'backlash'"):
        NOMINAL.degraded({"backlsh": 0.5})
    with pytest.raises(UnknownNameError, match="Did you mean 'rod_friction'"):
        make_effect("rod_fricton")
    with pytest.raises(UnknownNameError, match="Unknown parameter 'coulomb' for effect 'rod_friction'"):
        make_effect("rod_friction", coulomb=3.0)
    with pytest.raises(ParameterError, match="coulomb_n"):
        make_effect("rod_friction", coulomb_n=-3.0)
    with pytest.raises(UnknownNameError, match="Unknown parameter path"):
        NOMINAL.with_parameters({"servovalve.nope": 1.0})
    with pytest.raises(ParameterError, match="FlightInputs.demand_m"):
        FlightInputs(np.zeros(0), np.zeros(0), 0.01)


def test_non_finite_result_names_the_flight():
    n = 50
    demand = np.full(n, 0.03)
    demand[10] = np.nan
    inp = FlightInputs(demand, np.full(n, 0.8), 0.01)
    with pytest.raises(NumericalError, match="unit 7, flight 3"):
        simulate([NOMINAL], [inp], [np.random.default_rng(0)], labels=["unit 7, flight 3"])


def test_frame_mismatch_is_rejected():
    inp = FlightInputs(np.full(10, 0.03), np.full(10, 0.8), 0.02)
    with pytest.raises(ParameterError, match="controller frame"):
        simulate([NOMINAL], [inp], [np.random.default_rng(0)])


def test_dataclasses_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        NOMINAL.servovalve.rated_current_a = 1.0  # type: ignore[misc]
