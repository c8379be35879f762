"""FuelHM/ActuationLoop-v3: conformance (check_env on every id x shipped scenario x fidelity), determinism,
vectorisation, pickling, the cost model, truth handling, the surrogate against the physics, the knowledge
cache and bad input.

Everything flies 2-minute flights (``flight_minutes=2``, the shortest mission: 60 s engine start + 60 s) and
builds the knowledge with ``KnowledgeSize.small()`` into a per-module cache directory.
"""

from __future__ import annotations

import dataclasses
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env

import fuelhm_bench.envs  # noqa: F401 - registers the environment ids
from fuelhm_bench.envs import KnowledgeSize
from fuelhm_bench.envs.actuation_loop import EXTENDED_INDICATOR_BOUNDS, INDICATOR_BOUNDS, ActuationLoopEnv
from fuelhm_bench.datasets.cache import (cache_key, clear_memory_cache, default_cache_dir, published_knowledge,
                                     surrogate_knowledge, training_indicators)
from fuelhm_bench.errors import DataFormatError, ParameterError, UnknownNameError
from sizes import FLIGHT_MINUTES, TINY_FLIGHTS, TINY_UNITS, knowledge_size
from fuelhm_bench.scenarios import CostSpec, DegradationSpec, list_scenarios, load_scenario
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES, MODE_IDS

ENV_ID = "FuelHM/ActuationLoop-v3"
ENV_IDS = sorted(i for i in gym.registry if i.startswith("FuelHM/"))
MINUTES = FLIGHT_MINUTES
SMALL = knowledge_size()
NO_ALARM = {"alarm": 0, "guilt": np.zeros(7, dtype=np.float32)}
ALARM = {"alarm": 1, "guilt": np.eye(7, dtype=np.float32)[1]}


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuelhm-cache")


def make(cache_dir, scenario="paper_2012", fidelity="surrogate", env_id=ENV_ID, **kwargs):
    kwargs.setdefault("flight_minutes", MINUTES)
    if fidelity == "surrogate" and "knowledge" not in kwargs:
        kwargs.setdefault("knowledge_size", SMALL)
        kwargs.setdefault("cache_dir", cache_dir)
    return gym.make(env_id, scenario=scenario, fidelity=fidelity, **kwargs)


def episode(env, actions=None, *, seed=None, options=None):
    """Run one episode; returns (observations, rewards, last info)."""
    obs, info = env.reset(seed=seed, options=options)
    observations, rewards = [obs], []
    for t in range(10_000):
        action = actions(t) if callable(actions) else (NO_ALARM if actions is None else actions)
        obs, reward, terminated, truncated, info = env.step(action)
        assert truncated is False
        rewards.append(reward)
        if terminated:
            return observations, rewards, info
        observations.append(obs)
    raise AssertionError("the episode did not terminate")


def small_scenario(base="paper_2012", *, units=TINY_UNITS, flights=TINY_FLIGHTS, degradations=None, costs=None,
                   **changes):
    """A shipped scenario shrunk (and optionally given other degradations / costs)."""
    sc = load_scenario(base)
    fields = {"fleet": dataclasses.replace(sc.fleet, units=units, flights_per_unit=flights), **changes}
    if degradations is None:  # the scenario's own modes, with onsets and ramps that fit the shorter life
        onset_max = max(1, flights // 2)
        degradations = [dataclasses.replace(d, onset_min=1, onset_max=onset_max, ramp_flights=max(1, flights // 3))
                        for d in sc.degradations]
        fields["degradations"] = tuple(degradations)
    else:
        fields.update(degradations=tuple(degradations), simultaneous=True, healthy_probability=None)
    if costs is not None:
        fields["costs"] = costs
    return dataclasses.replace(sc, **fields)


def step_fault(mode, onset, *, growth="step", ramp=1):
    return DegradationSpec(mode=mode, probability=1.0, onset_min=onset, onset_max=onset, growth=growth,
                           ramp_flights=ramp, max_intensity=1.0)


# --------------------------------------------------------------------------- registry and conformance
def test_registration_is_lazy_and_idempotent():
    code = ("import sys, gymnasium as gym, fuelhm_bench.envs as e; e.register_envs(); "
            "assert 'fuelhm_bench.envs.actuation_loop' not in sys.modules; "
            "assert gym.spec('FuelHM/ActuationLoop-v3').entry_point.endswith(':ActuationLoopEnv'); print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr
    assert ENV_IDS == ["FuelHM/ActuationLoop-v3"]


@pytest.mark.parametrize("fidelity", ["physics", "surrogate"])
@pytest.mark.parametrize("scenario", list_scenarios())
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_every_id_scenario_and_fidelity(cache_dir, env_id, scenario, fidelity):
    env = make(cache_dir, scenario, fidelity, env_id=env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        check_env(env.unwrapped)
    assert env.unwrapped.n_flights == load_scenario(scenario).fleet.flights_per_unit


def test_unknown_version_names_the_current_one():
    with pytest.raises(gym.error.Error, match="v3"):
        gym.make("FuelHM/ActuationLoop-v4")


@pytest.mark.parametrize("retired", ["v0", "v1", "v2"])
def test_retired_version_names_the_current_one(retired):
    with pytest.raises(gym.error.DeprecatedEnv, match=rf"{retired}.*deprecated.*FuelHM/ActuationLoop-v3"):
        gym.make(f"FuelHM/ActuationLoop-{retired}")


def test_make_with_module_prefix_and_path(cache_dir, tmp_path):
    import yaml

    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(small_scenario(name="mine").to_dict(), sort_keys=False))
    env = gym.make("fuelhm_bench.envs:FuelHM/ActuationLoop-v3", scenario=str(path), fidelity="physics",
                   flight_minutes=MINUTES)
    assert env.unwrapped.scenario.name == "mine"
    assert env.unwrapped.n_flights == 8


# --------------------------------------------------------------------------- determinism, vectors, pickling
@pytest.mark.parametrize("fidelity", ["physics", "surrogate"])
def test_same_seed_same_episode_different_seed_different(cache_dir, fidelity):
    def run(seed):
        env = make(cache_dir, small_scenario(flights=6), fidelity)
        env.action_space.seed(seed)
        obs, rewards, info = episode(env, lambda t: env.action_space.sample(), seed=seed)
        return obs, rewards, info["episode_truth"]

    a, b, c = run(11), run(11), run(12)
    for x, y in zip(a[0], b[0]):
        np.testing.assert_array_equal(x["indicators"], y["indicators"])
        np.testing.assert_array_equal(x["valid"], y["valid"])
    assert a[1] == b[1]
    np.testing.assert_array_equal(a[2]["intensity"], b[2]["intensity"])
    assert not all(np.array_equal(x["indicators"], y["indicators"]) for x, y in zip(a[0], c[0]))


def test_surrogate_and_physics_share_the_truth_of_a_seed(cache_dir):
    phys = episode(make(cache_dir, "all_modes", "physics"), seed=5)[2]["episode_truth"]
    surr = episode(make(cache_dir, "all_modes", "surrogate"), seed=5)[2]["episode_truth"]
    np.testing.assert_array_equal(phys["intensity"], surr["intensity"])
    np.testing.assert_array_equal(phys["onset"], surr["onset"])


def test_physics_replay_is_the_scenarios_fleet(cache_dir):
    """reset(options={"unit": k}) flies exactly the flights of fleet_indicators(Scenario.test_fleet_config())."""
    from fuelhm_bench.datasets.fleets import fleet_indicators

    sc = small_scenario("all_modes", units=3, flights=5)
    env = ActuationLoopEnv(scenario=sc, fidelity="physics", flight_minutes=MINUTES, maintenance=False)
    table, labels = fleet_indicators(env._config)
    for k in range(3):
        observations, _, info = episode(env, seed=99, options={"unit": k})
        got = np.array([np.where(o["valid"] == 1, o["indicators"], np.nan) for o in observations])
        want = table.loc[table["unit_id"] == k, list(INDICATOR_NAMES)].to_numpy()
        np.testing.assert_array_equal(got, want.astype(np.float32))
        got = np.array([np.where(o["extended_valid"] == 1, o["extended"], np.nan) for o in observations])
        want = table.loc[table["unit_id"] == k, list(EXTENDED_INDICATOR_NAMES)].to_numpy(dtype=np.float64)
        np.testing.assert_array_equal(got, np.clip(want, *np.array(list(EXTENDED_INDICATOR_BOUNDS.values())).T)
                                      .astype(np.float32))
        truth = info["episode_truth"]
        lab = labels[labels["unit_id"] == k]
        for j, m in enumerate(MODE_IDS):
            np.testing.assert_array_equal(truth["intensity"][:, j], lab[f"intensity_{m}"].to_numpy())
            assert truth["onset"][j] == lab[f"onset_{m}"].iloc[0]
    served = ActuationLoopEnv(scenario=sc, fidelity="physics", flight_minutes=MINUTES, maintenance=False)
    served.load_replays(table)  # the same flights, simulated once
    for k in range(3):
        live, rewards, info = episode(env, ALARM, options={"unit": k})
        loaded, rewards2, info2 = episode(served, ALARM, options={"unit": k})
        for a, b in zip(live, loaded):
            assert set(a) == set(b)
            for key in a:
                np.testing.assert_array_equal(a[key], b[key])
        assert rewards == rewards2
        np.testing.assert_array_equal(info["episode_truth"]["cost_kusd"], info2["episode_truth"]["cost_kusd"])


def test_load_replays_refuses_what_it_cannot_serve(cache_dir):
    from fuelhm_bench.envs import scored_indicators

    sc = small_scenario(units=2, flights=3)
    table = scored_indicators(sc, flight_minutes=MINUTES, cache_dir=cache_dir)
    with pytest.raises(ParameterError, match="needs fidelity='physics', maintenance=False"):
        make(cache_dir, sc, "physics", maintenance=True).unwrapped.load_replays(table)
    with pytest.raises(ParameterError, match="needs fidelity='physics', maintenance=False"):
        make(cache_dir, sc, "surrogate", maintenance=False).unwrapped.load_replays(table)
    env = make(cache_dir, sc, "physics", maintenance=False).unwrapped
    with pytest.raises(ParameterError, match=r"must hold the columns of every observed indicator.*'Hys_lo'"):
        env.load_replays(table.drop(columns=["Hys_lo"]))
    with pytest.raises(ParameterError, match=r"flights 0..2 of each unit. Got \[0, 2\] for unit 1"):
        env.load_replays(table.drop(index=4))


def test_sync_vector_env(cache_dir):
    sc = small_scenario(flights=4)
    envs = gym.vector.SyncVectorEnv([lambda: make(cache_dir, sc, "surrogate") for _ in range(3)])
    obs, info = envs.reset(seed=[1, 2, 3])
    assert obs["indicators"].shape == (3, 10) and obs["indicators"].dtype == np.float32
    assert obs["valid"].shape == (3, 10)
    assert not np.array_equal(obs["indicators"][0], obs["indicators"][1])
    actions = {"alarm": np.array([0, 1, 0]), "guilt": np.tile(np.eye(7, dtype=np.float32)[2], (3, 1))}
    finished = 0
    for _ in range(4):
        obs, reward, terminated, truncated, info = envs.step(actions)
        assert reward.shape == (3,) and not truncated.any()
        finished += int(terminated.sum())
    assert finished == 3 and "episode_truth" in info
    obs, *_ = envs.step(actions)  # next-step autoreset: new units
    assert envs.observation_space.contains(obs)
    envs.close()


@pytest.mark.parametrize("fidelity", ["physics", "surrogate"])
def test_pickle_round_trip_mid_episode(cache_dir, fidelity):
    env = make(cache_dir, small_scenario("all_modes", flights=6), fidelity, maintenance=True).unwrapped
    env.reset(seed=3)
    env.step(NO_ALARM)
    clone = pickle.loads(pickle.dumps(env))
    for action in (ALARM, NO_ALARM, NO_ALARM):
        a, b = env.step(action), clone.step(action)
        np.testing.assert_array_equal(a[0]["indicators"], b[0]["indicators"])
        assert a[1:4] == b[1:4]
    np.testing.assert_array_equal(env.reset(seed=4)[0]["indicators"], clone.reset(seed=4)[0]["indicators"])


# --------------------------------------------------------------------------- rewards and maintenance
COSTS = CostSpec(false_alarm_kusd=10.0, undetected_flight_kusd=1.0, failure_kusd=100.0, repair_kusd=5.0,
                 detectable_fraction=0.25, failure_fraction=1.0)


@pytest.fixture(scope="module")
def step_env(cache_dir):
    """One unit, 8 flights, backlash at full intensity from flight 3 on (detectable and failed there)."""
    sc = small_scenario(units=1, flights=8, degradations=[step_fault("backlash", 3)], costs=COSTS)
    return lambda maintenance: make(cache_dir, sc, "surrogate", maintenance=maintenance)


def test_rewards_without_maintenance(step_env):
    _, rewards, info = episode(step_env(False), NO_ALARM, options={"unit": 0})
    assert rewards == [0.0, 0.0, 0.0, -101.0, -1.0, -1.0, -1.0, -1.0]  # 5 undetected flights, one failure
    _, rewards, info = episode(step_env(False), ALARM, options={"unit": 0})
    assert rewards == [-10.0, -10.0, -10.0, -105.0, -5.0, -5.0, -5.0, -5.0]  # no fault found, then repairs
    truth = info["episode_truth"]
    assert truth["failure"].tolist() == [False, False, False, True, False, False, False, False]
    assert not truth["repaired"].any()  # only scored: the fault goes on
    assert truth["intensity"][3:, MODE_IDS.index("backlash")].tolist() == [1.0] * 5
    assert truth["cost_kusd"].sum() == 155.0


def test_rewards_worked_example_in_the_docs(step_env):
    """docs/environment.md's example gave the rewards of maintenance=False without saying so (the default is True)."""
    import ast
    import re
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "environment.md").read_text()
    for maintenance in (False, True):
        found = re.search(rf"`maintenance={maintenance}`[^*]*?never alarming\s+`(\[[^`]*\])`,\s+always alarming\s+"
                          rf"`(\[[^`]*\])`", text)
        assert found, f"docs/environment.md: no worked example with maintenance={maintenance}"
        for policy, shown in zip((NO_ALARM, ALARM), found.groups()):
            _, rewards, _ = episode(step_env(maintenance), policy, options={"unit": 0})
            assert rewards == ast.literal_eval(shown), (maintenance, rewards)


def test_rewards_with_maintenance(step_env):
    env = step_env(True)
    _, rewards, info = episode(env, lambda t: ALARM if t in (2, 4) else NO_ALARM, options={"unit": 0})
    # flight 2: false alarm; flight 3: failure (+ undetected), unit repaired; flight 4: false alarm (healthy now)
    assert rewards == [0.0, 0.0, -10.0, -101.0, -10.0, 0.0, 0.0, 0.0]
    truth = info["episode_truth"]
    assert truth["repaired"].tolist() == [False, False, False, True, False, False, False, False]
    assert truth["intensity"][4:].max() == 0.0 and truth["detectable"].tolist() == [False] * 3 + [True] + [False] * 4


def test_correct_maintenance_prevents_the_failure(cache_dir):
    sc = small_scenario(units=1, flights=10, costs=COSTS,
                        degradations=[step_fault("internal_leakage", 2, growth="linear", ramp=4)])
    env = make(cache_dir, sc, "surrogate", maintenance=True)
    _, rewards, info = episode(env, lambda t: ALARM if t == 2 else NO_ALARM, options={"unit": 0})
    # intensities 0.25, 0.5, ... from flight 2: detectable at once, alarm there = repair, no failure ever
    assert rewards == [0.0, 0.0, -5.0] + [0.0] * 7
    assert not info["episode_truth"]["failure"].any()


def test_repair_restores_healthy_surrogate_indicators(cache_dir):
    faulty = small_scenario(units=1, flights=8, costs=COSTS, degradations=[step_fault("null_bias_drift", 3)])
    healthy = small_scenario(units=1, flights=8, costs=COSTS, degradations=[])
    knowledge = surrogate_knowledge(faulty, flight_minutes=MINUTES, size=SMALL, cache_dir=cache_dir)
    repaired, _, _ = episode(make(cache_dir, faulty, "surrogate", maintenance=True, knowledge=knowledge),
                             lambda t: ALARM if t == 3 else NO_ALARM, options={"unit": 0})
    kept, _, _ = episode(make(cache_dir, faulty, "surrogate", maintenance=False, knowledge=knowledge),
                         options={"unit": 0})
    clean, _, _ = episode(make(cache_dir, healthy, "surrogate", knowledge=knowledge), options={"unit": 0})
    x1 = INDICATOR_NAMES.index("X1")
    assert kept[5]["indicators"][x1] > clean[5]["indicators"][x1] + 1.0  # null-bias drift: X1 up ~1.6 mA
    for t in range(8):  # the fault shows on flight 3 only: the alarm there repairs the unit for flight 4 on
        expected = kept[t] if t == 3 else clean[t]
        np.testing.assert_array_equal(repaired[t]["indicators"], expected["indicators"])


# --------------------------------------------------------------------------- truth handling
def test_truth_only_at_the_end_unless_evaluation(cache_dir):
    env = make(cache_dir, small_scenario("all_modes", flights=5), "surrogate")
    obs, info = env.reset(seed=0)
    assert set(obs) == {"indicators", "valid", "extended", "extended_valid"} and set(info) == {"flight_index", "unit"}
    for t in range(5):
        obs, reward, terminated, _, info = env.step(NO_ALARM)
        assert set(obs) == {"indicators", "valid", "extended", "extended_valid"}
        assert set(info) == ({"flight_index", "episode_truth"} if terminated else {"flight_index"})
    obs, info = env.reset(seed=0, options={"evaluation": True})
    assert set(info["truth"]) == {"intensity", "max_intensity", "onset", "detectable", "failure"}
    while True:
        obs, reward, terminated, _, info = env.step(ALARM)
        assert reward == -sum(info["cost_kusd"].values())
        assert ("truth" in info) is not terminated
        if terminated:
            break


def test_raw_observation(cache_dir):
    env = make(cache_dir, "paper_2012", "physics", raw=True, raw_samples=64)
    obs, _ = env.reset(seed=1)
    assert obs["raw"].shape == (2, 64) and obs["raw"].dtype == np.float32
    assert env.observation_space.contains(obs)
    current, position = obs["raw"]
    assert np.abs(current).max() <= 12.5  # FADEC current saturation 12 mA
    assert 0.0 <= position.min() and position.max() <= 60.0  # stroke, mm
    assert position.max() - position.min() > 30.0  # the engine-start test sweep strokes the actuator


# --------------------------------------------------------------------------- surrogate vs physics
@pytest.mark.slow  # 24-30 s of physics and surrogate flights (a statistical run); the default run compares the
# fidelities at a tiny size (tests/test_fidelity.py) and checks each surrogate part (tests/test_envs_surrogate*.py)
def test_surrogate_matches_physics_distributions(cache_dir):
    """Per-indicator means and standard deviations of surrogate and physics flights, healthy and degraded.

    Tolerances (valid indicators, 24 physics units x 2 flights, 2-minute flights): |mean difference| <= 1.0
    healthy physics standard deviation + 15 % of the physics shift (the healthy mean of 24 units is itself
    uncertain by ~0.3 sd; the linear laws come from a 2-unit design; the shifts tested reach 5 to 30 sd, so a
    missing or wrong-signed shift fails), and the ratio of standard deviations in [0.4, 2.5] for healthy flights.
    """
    size = KnowledgeSize(doe_units=2, doe_intensities=(0.5, 1.0), healthy_units=4, healthy_flights=4,
                         surrogate_units=24, surrogate_flights=2)
    base = small_scenario("paper_2012", units=24, flights=2, degradations=[])
    knowledge = surrogate_knowledge(base, flight_minutes=MINUTES, size=size, cache_dir=cache_dir)
    results = {}
    for label, faults in (("healthy", []), ("null_bias_drift", [step_fault("null_bias_drift", 0)]),
                          ("internal_leakage", [step_fault("internal_leakage", 0)])):
        sc = small_scenario("paper_2012", units=24, flights=2, degradations=faults)
        phys = make(cache_dir, sc, "physics").unwrapped
        surr = make(cache_dir, sc, "surrogate", knowledge=knowledge).unwrapped
        p = [o for k in range(24) for o in episode(phys, options={"unit": k})[0]]
        s = [o for seed in range(300) for o in episode(surr, seed=seed)[0]]
        results[label] = [np.array([np.where(o["valid"] == 1, o["indicators"], np.nan) for o in obs], dtype=float)
                          for obs in (p, s)]
    sd_healthy = np.nanstd(results["healthy"][0], axis=0, ddof=1)
    healthy_mean = np.nanmean(results["healthy"][0], axis=0)
    report = {}
    for label, (p, s) in results.items():
        shift = np.abs(np.nanmean(p, axis=0) - healthy_mean)
        excess = np.abs(np.nanmean(s, axis=0) - np.nanmean(p, axis=0)) - 0.15 * shift
        report[label] = pd.Series(excess / sd_healthy, index=INDICATOR_NAMES)
        assert np.all(excess <= 1.0 * sd_healthy), pd.DataFrame(report).round(2)
    ratio = np.nanstd(results["healthy"][1], axis=0) / sd_healthy
    assert np.all((ratio >= 0.4) & (ratio <= 2.5)), pd.Series(ratio, index=INDICATOR_NAMES).round(2)
    shift = np.nanmean(results["null_bias_drift"][0], axis=0) - np.nanmean(results["healthy"][0], axis=0)
    assert shift[INDICATOR_NAMES.index("I0")] > 5 * sd_healthy[INDICATOR_NAMES.index("I0")]  # the test has teeth


# --------------------------------------------------------------------------- cache
def test_knowledge_cache_memory_disk_and_fresh_build_agree(tmp_path):
    from fuelhm_bench.datasets.knowledge import build_knowledge

    from fuelhm_bench.datasets.cache import knowledge_build

    sc = small_scenario()
    clear_memory_cache()  # the knowledge is keyed by its recipe: another test may hold this one in memory
    first = published_knowledge(sc, flight_minutes=MINUTES, size=SMALL, cache_dir=tmp_path)
    assert published_knowledge(sc, flight_minutes=MINUTES, size=SMALL, cache_dir=tmp_path) is first
    entries = list((tmp_path / "fuelhm-v1").iterdir())
    assert len(entries) == 1 and entries[0].name.startswith("knowledge-")  # keyed by its recipe: shared
    clear_memory_cache()
    from_disk = published_knowledge(sc, flight_minutes=MINUTES, size=SMALL, cache_dir=tmp_path)
    fresh = build_knowledge(knowledge_build(sc, flight_minutes=MINUTES, size=SMALL))
    for other in (from_disk, fresh):
        assert other is not first
        pd.testing.assert_frame_equal(other.healthy_table, first.healthy_table)
        pd.testing.assert_frame_equal(other.itl.table, first.itl.table)
        pd.testing.assert_frame_equal(other.signatures, first.signatures)
        np.testing.assert_array_equal(other.healthy_model.cov_, first.healthy_model.cov_)
    (entries[0] / "doe.parquet").write_bytes(b"damaged")
    clear_memory_cache()
    rebuilt = published_knowledge(sc, flight_minutes=MINUTES, size=SMALL, cache_dir=tmp_path)
    pd.testing.assert_frame_equal(rebuilt.doe_table, first.doe_table)


def test_cache_key_tracks_content_not_description():
    sc = load_scenario("paper_2012")
    key = cache_key("knowledge", sc)
    assert cache_key("knowledge", dataclasses.replace(sc, description="reworded")) == key
    assert cache_key("knowledge", sc, flight_minutes=sc.mission.duration_min) == key
    assert cache_key("knowledge", sc, flight_minutes=3.0) != key
    assert cache_key("knowledge", sc, doe_units=2) != key
    assert cache_key("training", sc) != key
    assert cache_key("knowledge", dataclasses.replace(sc, seeds=dataclasses.replace(sc.seeds, master=8))) != key


def test_scenarios_flying_the_same_fleet_share_one_build(tmp_path):
    from fuelhm_bench.datasets.cache import content_key

    clear_memory_cache()
    sc = small_scenario()
    other = dataclasses.replace(sc, name="same_fleet_other_name", description="another story",
                                costs=dataclasses.replace(sc.costs, repair_kusd=sc.costs.repair_kusd + 1.0))
    first = training_indicators(sc, flight_minutes=MINUTES, units=2, flights=2, cache_dir=tmp_path)
    built = sorted(p.name for p in (tmp_path / "fuelhm-v1").iterdir())
    clear_memory_cache()  # the disk entry alone serves the other scenario
    shared = training_indicators(other, flight_minutes=MINUTES, units=2, flights=2, cache_dir=tmp_path)
    pd.testing.assert_frame_equal(shared, first)
    assert sorted(p.name for p in (tmp_path / "fuelhm-v1").iterdir()) == built and built[0].startswith("fleet-")
    # any change of the fleet's recipe is another entry
    config = sc.training_fleet_config()
    key = content_key("fleet", config)
    assert content_key("fleet", dataclasses.replace(config, seed=config.seed + 1)) != key
    assert content_key("fleet", dataclasses.replace(
        config, mission=dataclasses.replace(config.mission, n2_noise_std=0.003))) != key
    assert content_key("fleet", dataclasses.replace(config, nominal=config.nominal.with_effect(
        "viscosity_temperature"))) != key
    assert content_key("fleet", config) == key


def test_a_change_of_the_product_code_is_another_cache_entry(tmp_path, monkeypatch):
    """Keys cover the source of the code that builds products: an edited law (same release, same scenario)
    never reads the entry the old code wrote."""
    from fuelhm_bench.datasets import cache
    from fuelhm_bench.datasets.cache import cache_key, code_fingerprint, content_key, source_digest

    (tmp_path / "physics").mkdir()
    (tmp_path / "physics" / "law.py").write_text("K = 1.0\n")
    (tmp_path / "taxonomy.py").write_text("IDS = ()\n")
    digest = source_digest(tmp_path, ("physics", "taxonomy.py", "absent"))
    assert digest == source_digest(tmp_path, ("taxonomy.py", "physics"))  # sorted by path, missing parts ignored
    (tmp_path / "physics" / "law.py").write_text("K = 2.0\n")
    assert source_digest(tmp_path, ("physics", "taxonomy.py")) != digest
    (tmp_path / "physics" / "notes.txt").write_text("not code")
    assert source_digest(tmp_path, ("physics", "taxonomy.py")) == source_digest(tmp_path, ("physics", "taxonomy.py"))
    assert len(code_fingerprint()) == 64 and code_fingerprint() == code_fingerprint()

    sc = small_scenario()
    config = sc.training_fleet_config()
    keys = (content_key("fleet", config), cache_key("training", sc))
    monkeypatch.setattr(cache, "code_fingerprint", lambda: "0" * 64)
    assert content_key("fleet", config) != keys[0] and cache_key("training", sc) != keys[1]


def test_cache_location_from_environment_and_memory_only(tmp_path, monkeypatch):
    monkeypatch.setenv("FUELHM_BENCH_CACHE", str(tmp_path / "env-cache"))
    assert default_cache_dir() == tmp_path / "env-cache"
    clear_memory_cache()  # fleets are keyed by content: another test may have built this one in memory
    sc = small_scenario(name="elsewhere")
    table = training_indicators(sc, flight_minutes=MINUTES, units=2, flights=2)
    assert len(table) == 4 and (tmp_path / "env-cache" / "fuelhm-v1").is_dir()
    training_indicators(sc, flight_minutes=MINUTES, units=3, flights=2, cache_dir=False)
    assert len(list((tmp_path / "env-cache" / "fuelhm-v1").iterdir())) == 1
    bigger = training_indicators(sc, flight_minutes=MINUTES, units=3, flights=2)  # continues the smaller fleet
    pd.testing.assert_frame_equal(bigger.iloc[[0, 1, 2, 3]].reset_index(drop=True), table)


# --------------------------------------------------------------------------- bad input
def test_unknown_scenario_suggests_the_closest(cache_dir):
    with pytest.raises(UnknownNameError, match="Did you mean 'all_modes'"):
        make(cache_dir, "all_mode", "physics")


@pytest.mark.parametrize("kwargs, match", [
    ({"fidelity": "surogate"}, r"'fidelity' parameter .* must be one of physics, surrogate.*Did you mean 'surrogate'"),
    ({"flight_minuts": 3.0}, r"ActuationLoopEnv has no argument 'flight_minuts'.*Did you mean 'flight_minutes'"),
    ({"maintenace": False}, r"Did you mean 'maintenance'"),
    ({"flight_minutes": 1.0}, r"'flight_minutes' parameter .* >= 2 .*Got 1.0"),
    ({"raw": True}, r"'raw' parameter .* only be True with fidelity='physics'"),
    ({"raw_samples": 1, "fidelity": "physics"}, r"'raw_samples' parameter .* \[2, 100000\]"),
    ({"maintenance": "yes"}, r"'maintenance' parameter .* bool"),
    ({"render_mode": "human"}, r"'render_mode' parameter .* None"),
    ({"knowledge_size": {"doe_unit": 1}}, r"unknown field 'doe_unit'.*Did you mean 'doe_units'"),
    ({"knowledge_size": {"doe_units": 0}}, r"'doe_units' parameter of KnowledgeSize must be an int >= 1"),
    ({"knowledge": "mine"}, r"'knowledge' parameter .* KnowledgeResult"),
])
@pytest.mark.filterwarnings("ignore:.*render_mode='human' that is not in the possible render_modes")
def test_bad_arguments(cache_dir, kwargs, match):
    kwargs = {"fidelity": "surrogate", **kwargs}
    with pytest.raises(ParameterError, match=match):
        make(cache_dir, "paper_2012", **kwargs)


@pytest.mark.parametrize("options, match", [
    ({"unti": 1}, r"reset has no option 'unti'.*Did you mean 'unit'"),
    ({"unit": 30}, r"'unit' option .* \[0, 29\]"),
    ({"unit": -1}, r"'unit' option"),
    ({"evaluation": "yes"}, r"'evaluation' option .* bool"),
])
def test_bad_reset_options(cache_dir, options, match):
    env = make(cache_dir, "paper_2012", "surrogate")
    with pytest.raises(ParameterError, match=match):
        env.reset(options=options)


@pytest.mark.parametrize("action, got", [
    ({"alarm": 2, "guilt": np.zeros(7)}, "alarm=2"),
    ({"alarm": 0.5, "guilt": np.zeros(7)}, "alarm=0.5"),
    ({"alarm": 1, "guilt": np.zeros(6)}, r"guilt of shape \(6,\)"),
    ({"alarm": 1, "guilt": np.full(7, 1.5)}, r"outside \[0, 1\] or NaN"),
    ({"alarm": 1, "guilt": np.full(7, np.nan)}, r"outside \[0, 1\] or NaN"),
    ({"alarm": 1, "guilt": ["a"] * 7}, "dtype <U1"),
    ({"alarm": 1}, "dict"),
    ({"alarm": 1, "guilt": np.zeros(7), "extra": 1}, r"extra key\(s\) \['extra'\]"),
    (1, "int 1"),
])
def test_action_outside_the_space_names_the_space(cache_dir, action, got):
    env = make(cache_dir, "paper_2012", "surrogate").unwrapped
    env.reset(seed=0)
    with pytest.raises(ParameterError, match=r"must be in the action space Dict\('alarm': Discrete\(2\), "
                                             r"'guilt': Box\(0\.0, 1\.0, \(7,\), float32\)\).*Got .*" + got):
        env.step(action)


def test_step_without_a_running_episode(cache_dir):
    env = make(cache_dir, small_scenario(flights=2), "surrogate").unwrapped
    with pytest.raises(ResetNeeded, match="call reset"):
        env.step(NO_ALARM)
    env.reset(seed=0)
    env.step(NO_ALARM)
    assert env.step(NO_ALARM)[2] is True
    with pytest.raises(ResetNeeded):
        env.step(NO_ALARM)


def test_observation_bounds_are_finite_and_documented():
    env_doc = ActuationLoopEnv.__doc__
    for name, (low, high) in {**INDICATOR_BOUNDS, **EXTENDED_INDICATOR_BOUNDS}.items():
        assert np.isfinite(low) and np.isfinite(high) and low < high
        assert f"| {name}" in env_doc
    assert tuple(EXTENDED_INDICATOR_BOUNDS) == EXTENDED_INDICATOR_NAMES
    for section in ("## Action Space", "## Observation Space", "## Rewards", "## Starting State", "## Episode End",
                    "## Arguments", "## Version History"):
        assert section in env_doc


@pytest.mark.parametrize("fidelity", ["physics", "surrogate"])
def test_extended_observation(cache_dir, fidelity):
    env = make(cache_dir, small_scenario("all_modes", flights=3), fidelity)
    space = env.observation_space
    assert space["extended"].shape == (len(EXTENDED_INDICATOR_NAMES),) and space["extended"].dtype == np.float32
    assert space["extended_valid"].n == len(EXTENDED_INDICATOR_NAMES)
    observations, _, _ = episode(env, seed=3)
    for obs in observations:
        assert space.contains(obs)
        ext, ok = obs["extended"], obs["extended_valid"]
        assert np.all(np.isfinite(ext)) and np.all(ext[ok == 0] == 0.0)  # invalid is 0, never NaN
    assert np.array([o["extended_valid"] for o in observations]).any()


def test_surrogate_without_extended_indicators_is_refused(cache_dir):
    env = make(cache_dir, small_scenario(flights=3), "surrogate").unwrapped
    knowledge = surrogate_knowledge(env.scenario, flight_minutes=MINUTES, size=SMALL, cache_dir=cache_dir)
    drop = [c for n in EXTENDED_INDICATOR_NAMES for c in (n, f"{n}_valid")]
    bare = dataclasses.replace(knowledge, healthy_table=knowledge.healthy_table.drop(columns=drop),
                               doe_table=knowledge.doe_table.drop(columns=drop))
    with pytest.raises(DataFormatError, match=r"must also draw the extended indicators.*lacks \['V_in1'"):
        ActuationLoopEnv(scenario=small_scenario(flights=3), fidelity="surrogate", knowledge=bare,
                         flight_minutes=MINUTES)
