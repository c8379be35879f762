"""The surrogate fidelity learnt from indicator tables (:func:`fuelhm_bench.envs.surrogate.fit_surrogate`).

Synthetic physics-like tables with known structure (an exact linear relation, a tiny flight-to-flight
direction, a unit share, invalid indicators, curved per-unit responses, an extended indicator) go in; the
tests check that the fitted surrogate's draws carry the same structure. Pure numpy: no simulation, except
the slow test against physics flights at the end.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.envs.surrogate import SurrogateModel, fit_surrogate, indicator_columns
from fuelhm_bench.errors import DataFormatError, ParameterError

NAMES = ["A", "B", "C", "D", "EXT"]  # C = (A + B) / 2 exactly; EXT stands for an extended indicator
MODES = ("m1", "m2")


def _table(values, valid, units, extra=None):
    data = {"flight_id": np.arange(len(values)), "unit_id": units, **(extra or {})}
    for j, n in enumerate(NAMES):
        data[n] = np.where(valid[:, j], values[:, j], np.nan)
    for j, n in enumerate(NAMES):
        data[f"{n}_valid"] = valid[:, j]
    return pd.DataFrame(data)


def healthy_table(seed=0, n_units=60, n_flights=10, invalid_rate=0.1):
    """Unit share 0.7 on A, B and D; C = (A + B) / 2; D has a tiny flight-to-flight variance; EXT is mostly unit."""
    rng = np.random.default_rng(seed)
    unit = rng.standard_normal((n_units, 5)) * np.array([2.0, 1.0, 0.0, 1.0, 3.0])
    flight = rng.standard_normal((n_units, n_flights, 5)) * np.array([1.2, 0.6, 0.0, 1e-3, 0.1])
    x = (unit[:, None, :] + flight).reshape(-1, 5) + np.array([1.0, 2.0, 0.0, 5.0, -3.0])
    x[:, 2] = 0.5 * (x[:, 0] + x[:, 1])
    valid = np.ones_like(x, dtype=bool)
    valid[:, 3] = rng.random(len(x)) >= invalid_rate  # D invalid on about 10 % of the flights
    return _table(x, valid, np.repeat(np.arange(n_units), n_flights),
                  {"flight_index": np.tile(np.arange(n_flights), n_units)})


def doe_table(seed=1, n_units=5, knots=(0.25, 0.5, 1.0)):
    """m1 moves A (and C) as gain_u * f**2, gain_u different per unit; m2 makes B invalid from f = 1, moves D
    by 4 f and A by f."""
    rng = np.random.default_rng(seed)
    rows, valid, units, mode, intensity = [], [], [], [], []
    for u in range(n_units):
        h = rng.standard_normal(5)
        h[2] = 0.5 * (h[0] + h[1])
        gain = 2.0 + u
        for md, f in [("healthy", 0.0)] + [(m, f) for m in MODES for f in knots]:
            x = h.copy()
            ok = np.ones(5, dtype=bool)
            if md == "m1":
                x[0] += gain * f ** 2
            elif md == "m2":
                x[3] += 4.0 * f
                x[0] += 1.0 * f
                ok[1] = f < 1.0
            x[2] = 0.5 * (x[0] + x[1])
            rows.append(x)
            valid.append(ok)
            units.append(u)
            mode.append(md)
            intensity.append(f)
    return _table(np.array(rows), np.array(valid), np.array(units),
                  {"mode": mode, "intensity": intensity})


@pytest.fixture(scope="module")
def model():
    return fit_surrogate(healthy_table(), doe_table(), modes=MODES, bootstrap=20)


def draw(model, intensities, n_units=400, seed=0):
    rng = np.random.default_rng(seed)
    out = [model.draw_unit(rng, intensities) for _ in range(n_units)]
    return np.stack([v for v, _ in out]), np.stack([k for _, k in out])


def test_indicator_columns_are_those_with_a_valid_companion():
    assert indicator_columns(healthy_table(n_units=2, n_flights=2)) == tuple(NAMES)


def test_healthy_draws_keep_the_joint_structure(model):
    values, valid = draw(model, np.zeros((10, 2)))
    assert model.names == tuple(NAMES) and values.shape == (400, 10, 5)
    complete = valid.all(axis=2)
    v = values[complete]
    # the exact relation of the physics holds on every drawn flight (no variance across it)
    np.testing.assert_allclose(v[:, 2], 0.5 * (v[:, 0] + v[:, 1]), atol=1e-9)
    # flight-to-flight spread: the tiny direction stays tiny, the others keep their size
    within = np.nanmean(np.where(valid, values, np.nan).var(axis=1, ddof=1), axis=0)
    np.testing.assert_allclose(within[[0, 1]], [1.44, 0.36], rtol=0.15)
    assert within[3] < 1e-5
    # unit share of the variance
    share = model.unit_share
    np.testing.assert_allclose(share[[0, 1, 4]], [4 / 5.44, 1 / 1.36, 9 / 9.01], atol=0.12)
    # invalid indicator pattern: D invalid on about 10 % of the flights, the others never
    rate = 1.0 - valid.mean(axis=(0, 1))
    assert 0.06 < rate[3] < 0.14 and rate[[0, 1, 2, 4]].max() == 0.0
    assert (values[~valid] == 0.0).all()


def test_describe_reports_estimation_error(model):
    d = model.describe()
    assert list(d.index) == NAMES
    assert (d.loc[["A", "B", "EXT"], "std_se"] > 0).all()
    assert (d["std_se"] < d["std"]).all()
    assert model.fit_info["healthy_units"] == 60 and model.fit_info["doe_units"] == 5


def test_degraded_response_is_curved_with_unit_spread(model):
    f = np.zeros((10, 2))
    f[:, 0] = np.linspace(0.0, 1.0, 10)
    healthy, _ = draw(model, np.zeros((10, 2)), seed=3)
    degraded, _ = draw(model, f, seed=3)  # same seed: same units, same residuals
    delta = (degraded - healthy)[:, :, 0]
    gains = np.arange(5) + 2.0
    # at the DOE knots the mean response is the mean of the units' gain * f**2 (not a line through 0)
    knots = {0.5: 0.25, 1.0: 1.0}
    for fi, sq in knots.items():
        k = int(np.argmin(np.abs(f[:, 0] - fi)))
        if np.isclose(f[k, 0], fi):
            np.testing.assert_allclose(delta[:, k].mean(), gains.mean() * sq, rtol=0.1)
    assert delta[:, -1].std() > 1.0  # unit-to-unit spread (gains 2..6)
    assert set(np.round(delta[:, -1], 6)) <= set(np.round(gains, 6))
    # Inb-like relation survives the degradation
    np.testing.assert_allclose(degraded[:, :, 2], 0.5 * (degraded[:, :, 0] + degraded[:, :, 1]), atol=1e-9)


def test_degradation_invalidates_and_simultaneous_modes_add(model):
    f = np.zeros((4, 2))
    f[:, 1] = [0.0, 0.5, 1.0, 1.0]
    f[3, 0] = 1.0
    healthy, _ = draw(model, np.zeros((4, 2)), seed=5)
    degraded, valid = draw(model, f, seed=5)
    assert valid[:, :2, 1].all() and not valid[:, 2:, 1].any()  # m2 at full intensity: B invalid, as in the DOE
    d = degraded - healthy
    ok = valid[:, 2, 3] & valid[:, 3, 3]
    np.testing.assert_allclose(d[ok, 2, 3], 4.0, rtol=1e-9)
    np.testing.assert_allclose(d[ok, 3, 3], 4.0, rtol=1e-9)  # m1 does not move D; m2 still does
    only_m1 = f.copy()
    only_m1[:, 1] = 0.0
    single_m1 = draw(model, only_m1, seed=5)[0][:, 3, 0] - healthy[:, 3, 0]
    np.testing.assert_allclose(d[:, 3, 0], single_m1 + 1.0, rtol=1e-9)  # responses add


def test_draws_are_deterministic_and_extrapolate_the_last_segment(model):
    a = draw(model, np.full((3, 2), 0.3), n_units=3, seed=9)
    b = draw(model, np.full((3, 2), 0.3), n_units=3, seed=9)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    healthy, _ = draw(model, np.zeros((1, 2)), n_units=50, seed=2)
    beyond, _ = draw(model, np.array([[1.5, 0.0]]), n_units=50, seed=2)
    gains = np.arange(5) + 2.0
    # last segment (0.5 -> 1.0) continued: gain * (1 + 1.5 * (1.5 - 1.0))
    assert set(np.round(beyond[:, 0, 0] - healthy[:, 0, 0], 6)) <= set(np.round(gains * 1.75, 6))


@pytest.mark.parametrize("mutate, message", [
    (lambda h, d: (h.drop(columns=["unit_id"]), d), r"'healthy' table .* lacks the column\(s\) \['unit_id'\]"),
    (lambda h, d: (h, d.drop(columns=["mode"])), r"'doe' table .* lacks the column\(s\) \['mode'\]"),
    (lambda h, d: (h, d.drop(columns=["EXT"])), r"lacks the indicator column\(s\) \['EXT'\]"),
    (lambda h, d: (h[[c for c in h.columns if not c.endswith("_valid")]], d), r"no indicator column"),
    (lambda h, d: (h.drop_duplicates("unit_id"), d), r"at least one unit with two flights"),
    (lambda h, d: ("table.csv", d), r"must be a pandas DataFrame"),
    # an indicator never valid (a scenario whose flights never excite it) is named, not numbered ([4])
    (lambda h, d: (h.assign(EXT=np.nan, EXT_valid=False), d), r"no valid value of the indicator\(s\) EXT: "),
])
def test_bad_tables_raise_clear_errors(mutate, message):
    h, d = mutate(healthy_table(n_units=4, n_flights=3), doe_table(n_units=2))
    with pytest.raises(DataFormatError, match=message):
        fit_surrogate(h, d, modes=MODES)


def test_model_validates_its_arrays(model):
    with pytest.raises(DataFormatError, match="'mean' parameter of SurrogateModel"):
        SurrogateModel(names=model.names, modes=model.modes, mean=np.zeros(3), unit_factor=model.unit_factor,
                       residuals=model.residuals, residual_valid=model.residual_valid, knots=model.knots,
                       responses=model.responses, response_invalid=model.response_invalid)


@pytest.mark.slow  # about 230 two-minute physics flights
def test_surrogate_healthy_flights_sit_where_physics_flights_do(tmp_path):
    """Under the covariance of physics healthy flights, surrogate healthy flights are as far from the mean
    as fresh physics flights (the old Gaussian surrogate's median distance was 3.7 times the physics')."""
    from fuelhm_bench.datasets.cache import surrogate_knowledge, training_indicators
    from fuelhm_bench.envs import KnowledgeSize
    from fuelhm_bench.taxonomy import INDICATOR_NAMES

    size = KnowledgeSize(doe_units=1, doe_intensities=(1.0,), healthy_units=2, healthy_flights=6,
                         surrogate_units=16, surrogate_flights=6, surrogate_doe_units=1,
                         surrogate_doe_intensities=(1.0,))
    knowledge = surrogate_knowledge("paper_2012", flight_minutes=2.0, size=size, cache_dir=tmp_path)
    model = SurrogateModel.from_knowledge(knowledge)
    physics = training_indicators("paper_2012", flight_minutes=2.0, units=16, flights=6, cache_dir=tmp_path)
    x = physics[list(INDICATOR_NAMES)].to_numpy(dtype=float)
    x = x[np.isfinite(x).all(axis=1)]
    mean, cov = x.mean(axis=0), np.cov(x, rowvar=False)
    inv = np.linalg.pinv(cov, rcond=1e-10)
    rng = np.random.default_rng(0)
    cols = [model.names.index(n) for n in INDICATOR_NAMES]
    draws = [model.draw_unit(rng, np.zeros((6, 7))) for _ in range(200)]
    s = np.concatenate([v[k.all(axis=1)][:, cols] for v, k in draws])

    def median_distance(rows):
        d = rows - mean
        return float(np.median(np.sqrt(np.einsum("ij,jk,ik->i", d, inv, d))))

    ratio = median_distance(s) / median_distance(x)
    # physics flights are in-sample for their own covariance (biased low), so the ratio sits a little above 1
    assert 0.8 <= ratio <= 1.6, ratio


# --------------------------------------------------------------------------- unit coordinates
def _with_coordinates(table, z_of_unit, coords):
    extra = pd.DataFrame(z_of_unit[table["unit_id"].to_numpy()], columns=[f"unit_z:{c}" for c in coords],
                         index=table.index)
    return pd.concat([table, extra], axis=1)


def test_unit_means_and_responses_follow_the_unit_coordinates():
    """Unit means linear in 3 coordinates (plus a small unexplained part), an m1 response that scales
    with a coordinate: the fit recovers both maps, and a unit drawn at given coordinates sits there."""
    rng = np.random.default_rng(4)
    coords = ("a", "b", "c")
    z = rng.standard_normal((80, 3))
    slope = np.array([[2.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0, -0.5, 0.0], [0.0, 0.0, 0.5], [0.0, 3.0, 0.0]])
    unit = z @ slope.T + 0.05 * rng.standard_normal((80, 5))
    x = (unit[:, None, :] + 0.3 * rng.standard_normal((80, 4, 5))).reshape(-1, 5) + 1.0
    x[:, 2] = 0.5 * (x[:, 0] + x[:, 1])
    h = _with_coordinates(_table(x, np.ones_like(x, dtype=bool), np.repeat(np.arange(80), 4)), z, coords)
    d = doe_table(n_units=20)
    zd = rng.standard_normal((20, 3))
    gain = 4.0 + 2.0 * zd[:, 0]  # m1 moves A by gain * f**2: its response depends on coordinate a
    m1 = (d["mode"] == "m1").to_numpy()
    u = d["unit_id"].to_numpy()
    f = d["intensity"].to_numpy()
    base = d["A"].to_numpy() - np.where(m1, (2.0 + u) * f ** 2, 0.0)
    d["A"] = base + np.where(m1, gain[u] * f ** 2, 0.0)
    d["C"] = 0.5 * (d["A"] + d["B"])
    d = _with_coordinates(d, zd, coords)
    model = fit_surrogate(h, d, modes=MODES, bootstrap=0)
    assert model.coordinates == coords and model.fit_info["coordinates"] == 3
    np.testing.assert_allclose(model.coordinate_map[[0, 1, 3, 4]], slope[[0, 1, 3, 4]], atol=0.25)
    at = np.array([1.5, -2.0, 0.0])
    values, valid = model.draw_unit(np.random.default_rng(0), np.zeros((200, 2)), coordinates=at)
    unit_mean = values.mean(axis=0)
    expected = model.mean + slope @ at
    np.testing.assert_allclose(unit_mean, expected, atol=0.15)  # unexplained unit sd 0.05, flight sd 0.3
    np.testing.assert_allclose(values[:, 2], 0.5 * (values[:, 0] + values[:, 1]), atol=1e-9)
    # the response at f = 1 follows gain(a) = 4 + 2 a (the unexplained DOE spread is small here)
    for a in (-1.0, 1.0):
        c = np.array([a, 0.0, 0.0])
        curve = [model.response_curve(0, k, c)[-1, 0] for k in range(model.responses.shape[0])]
        assert abs(np.mean(curve) - (4.0 + 2.0 * a)) < 0.5


def test_a_mode_the_doe_did_not_fly_is_refused():
    d = doe_table(n_units=3)
    d = d[d["mode"] != "m2"]
    model = fit_surrogate(healthy_table(n_units=6, n_flights=3), d, modes=MODES, bootstrap=0)
    assert model.learnt.tolist() == [True, False]
    model.draw_unit(np.random.default_rng(0), np.array([[0.5, 0.0]]))
    with pytest.raises(ParameterError, match=r"not learnt for the mode\(s\) \['m2'\]"):
        model.draw_unit(np.random.default_rng(0), np.array([[0.0, 0.5]]))


def test_coordinates_of_a_unit_are_its_manufacturing_draws():
    """From the built unit or from the generator manufacture would use: the same coordinates."""
    from fuelhm_bench.flights.fleet import unit_rng
    from fuelhm_bench.physics.model import Dispersion, LoopModel, dispersion_coordinates, manufacture

    disp = Dispersion(scale=1.5)
    model = fit_surrogate(healthy_table(n_units=4, n_flights=3), doe_table(n_units=2), modes=MODES, bootstrap=0)
    names = tuple(p for p, _ in disp.relative) + tuple(p for p, _ in disp.additive)
    model = dataclasses.replace(model, coordinates=names, coordinate_map=np.zeros((5, len(names))),
                                response_map=np.zeros((2, 4, 5, len(names))))
    unit = manufacture(LoopModel(), unit_rng(7, 3), disp)
    from_unit = model.unit_coordinates(unit, LoopModel(), disp)
    from_rng = model.unit_coordinates(unit_rng(7, 3), LoopModel(), disp)
    np.testing.assert_allclose(from_unit, from_rng, atol=1e-9)
    np.testing.assert_allclose(from_unit, dispersion_coordinates(unit, LoopModel(), disp))
    assert np.abs(from_unit).max() <= 3.0 and np.abs(from_unit).min() > 0.0


def test_every_learnt_column_is_drawn_and_addressable_by_name(model):
    """Extended indicators are drawn like the others: values and validity of every learnt column."""
    parts = model.draw_parts(np.random.default_rng(1), 6)
    values, valid = model.degrade(parts, np.zeros((6, 2)))
    assert parts["healthy"].shape == values.shape == valid.shape == (6, len(NAMES))
    j = model.columns(["EXT"])
    assert j.tolist() == [4] and np.all(valid[:, j]) and np.all(np.isfinite(values[:, j]))
    with pytest.raises(DataFormatError, match=r"not learnt on the indicator\(s\) \['V_in9'\]"):
        model.columns(["EXT", "V_in9"])


def doe_missions_table(seed=3, n_units=8, missions=3, knots=(0.5, 1.0), spread=0.5, pairs=False):
    """Each unit flies every case on ``missions`` missions. m1 moves A by (2 + e) f, where e ~ N(0, spread^2)
    is drawn per (unit, mission): the flight-to-flight part of the response. With ``pairs``, m1 and m2
    together add 3 f1 f2 to D on top of the two single responses (m2 moves D by 4 f)."""
    rng = np.random.default_rng(seed)
    rows, units, mode, intensity, second, rep = [], [], [], [], [], []
    cases = [("healthy", 0.0, 0.0)] + [(m, f, 0.0) for m in MODES for f in knots]
    if pairs:
        cases += [("m1+m2", fa, fb) for fa in knots for fb in knots]
    for u in range(n_units):
        base = rng.standard_normal(5)
        for r in range(missions):
            h = base + 0.3 * rng.standard_normal(5)
            e = spread * rng.standard_normal()
            for md, f, f2 in cases:
                x = h.copy()
                fa = f if md in ("m1", "m1+m2") else 0.0
                fb = f if md == "m2" else (f2 if md == "m1+m2" else 0.0)
                x[0] += (2.0 + e) * fa
                x[3] += 4.0 * fb + (3.0 * fa * fb if md == "m1+m2" else 0.0)
                x[2] = 0.5 * (x[0] + x[1])
                rows.append(x)
                units.append(u)
                mode.append(md)
                intensity.append(f)
                second.append(f2)
                rep.append(r)
    extra = {"replicate": rep, "mode": mode, "intensity": intensity}
    if pairs:
        extra["intensity_2"] = second
    x = np.array(rows)
    return _table(x, np.ones_like(x, dtype=bool), np.array(units), extra)


def test_several_missions_give_the_flight_to_flight_part_of_a_response():
    h = healthy_table(n_units=20, n_flights=4)
    model = fit_surrogate(h, doe_missions_table(n_units=40), modes=MODES, bootstrap=0)
    assert model.response_flight.shape == (40 * 3, 2, 3, 5) and model.fit_info["doe_missions"] == 3
    pool = model.response_flight[:, 0, 2, 0]  # deviations of the response of A to m1 at f = 1
    assert abs(np.sqrt(np.mean(pool ** 2)) - 0.5) < 0.1  # the missions' spread, 0.5 (80 degrees of freedom)
    at = np.zeros((4000, 2))
    at[:, 0] = 1.0
    rng = np.random.default_rng(5)
    parts = model.draw_parts(rng, len(at))
    values, _ = model.degrade(parts, at)
    healthy, _ = model.degrade(parts, np.zeros_like(at))
    response = values[:, 0] - healthy[:, 0]  # one unit: its mean response, plus a deviation per flight
    assert abs(response.std() / np.sqrt(np.mean(pool ** 2)) - 1.0) < 0.05  # the drawn spread is the pool's
    assert np.all(values[:, 3] == healthy[:, 3])  # m1 does not move D, on any flight
    # a one-mission DOE has no flight-to-flight part: the response is the same on every flight
    one = fit_surrogate(h, doe_missions_table(missions=1), modes=MODES, bootstrap=0)
    parts = one.draw_parts(np.random.default_rng(5), 50)
    diff = one.degrade(parts, at[:50])[0][:, 0] - one.degrade(parts, np.zeros((50, 2)))[0][:, 0]
    np.testing.assert_allclose(diff, diff[0])


def test_pairs_flown_together_give_the_interaction_of_simultaneous_modes():
    h = healthy_table(n_units=20, n_flights=4)
    model = fit_surrogate(h, doe_missions_table(pairs=True, spread=0.0), modes=MODES, bootstrap=0)
    assert model.pairs == (("m1", "m2"),) and model.pair_knots.tolist() == [0.5, 1.0]
    np.testing.assert_allclose(model.interactions[:, 0, 2, 2, 3], 3.0, atol=1e-9)  # 3 f1 f2 at (1, 1)
    np.testing.assert_allclose(model.interactions[:, 0, 0, :, :], 0.0)
    parts = model.draw_parts(np.random.default_rng(2), 4)
    f = np.array([[1.0, 1.0], [0.75, 1.0], [1.0, 0.0], [0.0, 0.5]])
    both = model.degrade(parts, f)[0][:, 3]
    alone = sum(model.degrade(parts, np.where(np.arange(2) == j, f, 0.0))[0][:, 3] for j in range(2))
    healthy = model.degrade(parts, np.zeros_like(f))[0][:, 3]
    extra = both - alone + healthy  # what the pair adds to the two single responses
    np.testing.assert_allclose(extra, [3.0, 2.25, 0.0, 0.0], atol=1e-9)  # bilinear between knots, 0 alone


def test_tail_keeps_the_units_draws_for_its_later_flights(model):
    parts = model.draw_parts(np.random.default_rng(4), 6)
    f = np.tile([[0.5, 0.25]], (6, 1))
    whole = model.degrade(parts, f)
    later = model.degrade(model.tail(parts, 2), f[2:])
    np.testing.assert_array_equal(whole[0][2:], later[0])
    np.testing.assert_array_equal(whole[1][2:], later[1])
